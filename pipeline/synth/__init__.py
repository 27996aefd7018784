"""MuJoCo data synthesiser: scenes, LiDAR scan models, simulated recordings and their ground truth.

In memory: `simulate_problem(name, seed)` -> `(CalibrationProblem, Truth)`; on disk:
`write_recording(name, out_dir, seed)` and `load_truth(out_dir)`. Scenarios: `scenario_names()`.
"""

from pipeline.synth.lidar_models import LidarModel, Mid70, Mid360, SpinningLidar
from pipeline.synth.recording import write_recording
from pipeline.synth.scenarios import LidarMount, ScenarioSpec, get_scenario, scenario_names
from pipeline.synth.simulate import LabelledScan, World, make_world, scan, simulate_problem
from pipeline.synth.truth import LidarTruth, PointLabels, ScanLabels, StopTruth, Truth, load_truth

__all__ = [
    "LabelledScan",
    "LidarModel",
    "LidarMount",
    "LidarTruth",
    "Mid70",
    "Mid360",
    "PointLabels",
    "ScanLabels",
    "ScenarioSpec",
    "SpinningLidar",
    "StopTruth",
    "Truth",
    "World",
    "get_scenario",
    "load_truth",
    "make_world",
    "scan",
    "scenario_names",
    "simulate_problem",
    "write_recording",
]
