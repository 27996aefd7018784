"""fleetcal's numerical core: recording -> `CalibrationProblem` -> calibrated extrinsics.

Importable without the service: it never imports FastAPI, SQLAlchemy or the service settings, nor
anything else of fleetcal's (`.importlinter` checks it). `__all__` below is the public API that
`service`, `workers` and `client` use; they import nothing deeper, but `pipeline.io` (recordings
in and out, its own public API) and, for the root command line only, `pipeline.cli`.
"""

import os
from typing import TYPE_CHECKING

from pipeline.errors import BadInputError, ConfigError, PipelineError
from pipeline.lazy import lazy_attributes
from pipeline.runtime import PASSIVE_OPENMP

if TYPE_CHECKING:
    from pipeline.calibrate import CalibrationResult
    from pipeline.calibrate import calibrate as calibrate_problem
    from pipeline.cli.export import export_result, load_result, new_export_path, result_from
    from pipeline.config import PipelineConfig, config_from_mapping
    from pipeline.export import (
        FILE_NAMES,
        MEDIA_TYPES,
        ExportError,
        ExportFormat,
        calibrated_extrinsics,
        render,
    )
    from pipeline.problem import CalibrationProblem, LidarInfo, RecordingInfo, ScanPattern, Stop
    from pipeline.report import REPORT_IMAGES, load_renderer, render_report
    from pipeline.result import result_document
    from pipeline.result_model import ResultDocument, rpy_deg
    from pipeline.stages.sequence import STAGES
    from pipeline.synth import Truth, get_scenario
    from pipeline.synth.recording import archive_recording
    from pipeline.synth.recording import write_recording as synthesise_recording
    from pipeline.transforms import (
        from_translation_xyzw,
        invert,
        pose_difference,
        to_translation_xyzw,
    )
    from pipeline.verdict import DriftEvidence, with_drift

__version__ = "0.1.0"

# Before any kd-tree loads the OpenMP runtime, which reads it once (see `pipeline.runtime`).
os.environ.setdefault(*PASSIVE_OPENMP)

__all__ = [
    "FILE_NAMES",
    "MEDIA_TYPES",
    "REPORT_IMAGES",
    "STAGES",
    "BadInputError",
    "CalibrationProblem",
    "CalibrationResult",
    "ConfigError",
    "DriftEvidence",
    "ExportError",
    "ExportFormat",
    "LidarInfo",
    "PipelineConfig",
    "PipelineError",
    "RecordingInfo",
    "ResultDocument",
    "ScanPattern",
    "Stop",
    "Truth",
    "__version__",
    "archive_recording",
    "calibrate_problem",
    "calibrated_extrinsics",
    "config_from_mapping",
    "export_result",
    "from_translation_xyzw",
    "get_scenario",
    "invert",
    "load_renderer",
    "load_result",
    "new_export_path",
    "pose_difference",
    "render",
    "render_report",
    "result_document",
    "result_from",
    "rpy_deg",
    "synthesise_recording",
    "to_translation_xyzw",
    "with_drift",
]

# Where each lazily loaded name lives ("module" or "module:attribute" where the public name is
# another). They load numpy, scipy, the kd-tree, matplotlib or MuJoCo: only when first used, so
# that `import pipeline` (and `fleetcal --help`) stays instant.
_LAZY = {
    # The calibration: problem in, result out.
    "CalibrationProblem": "pipeline.problem",
    "LidarInfo": "pipeline.problem",
    "RecordingInfo": "pipeline.problem",
    "ScanPattern": "pipeline.problem",
    "Stop": "pipeline.problem",
    # Not `calibrate`: that name is the submodule's once it is loaded.
    "calibrate_problem": "pipeline.calibrate:calibrate",
    "CalibrationResult": "pipeline.calibrate",
    "STAGES": "pipeline.stages.sequence",
    "PipelineConfig": "pipeline.config",
    "config_from_mapping": "pipeline.config",
    "result_document": "pipeline.result",
    "render_report": "pipeline.report",
    "REPORT_IMAGES": "pipeline.report",
    "load_renderer": "pipeline.report",
    # result.json's model, for the service's schemas and stored results.
    "ResultDocument": "pipeline.result_model",
    "rpy_deg": "pipeline.result_model",
    # Poses, for the service's comparisons and the workers' drift checks.
    "from_translation_xyzw": "pipeline.transforms",
    "invert": "pipeline.transforms",
    "pose_difference": "pipeline.transforms",
    "to_translation_xyzw": "pipeline.transforms",
    # Drift against a reference pose, judged as evidence by the verdict (the workers' drift check).
    "DriftEvidence": "pipeline.verdict",
    "with_drift": "pipeline.verdict",
    # A result in the forms a robot's configuration takes (`fleetcal export`, the API's exports).
    "ExportError": "pipeline.export",
    "ExportFormat": "pipeline.export",
    "FILE_NAMES": "pipeline.export",
    "MEDIA_TYPES": "pipeline.export",
    "calibrated_extrinsics": "pipeline.export",
    "render": "pipeline.export",
    "export_result": "pipeline.cli.export",
    "load_result": "pipeline.cli.export",
    "new_export_path": "pipeline.cli.export",
    "result_from": "pipeline.cli.export",
    # Synthetic recordings with their ground truth (`fleetcal demo`).
    "Truth": "pipeline.synth",
    "get_scenario": "pipeline.synth",
    "synthesise_recording": "pipeline.synth.recording:write_recording",
    "archive_recording": "pipeline.synth.recording",
}

__getattr__ = lazy_attributes(__name__, _LAZY)
