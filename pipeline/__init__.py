"""fleetcal's numerical core: recording -> `CalibrationProblem` -> calibrated extrinsics.

Importable without the service: it never imports FastAPI, SQLAlchemy or the service settings.
"""

from typing import TYPE_CHECKING, Any

from pipeline.errors import BadInputError, ConfigError, PipelineError

if TYPE_CHECKING:
    from pipeline.calibrate import CalibrationResult, calibrate
    from pipeline.config import PipelineConfig
    from pipeline.problem import CalibrationProblem, LidarInfo, RecordingInfo, ScanPattern, Stop

__version__ = "0.1.0"

__all__ = [
    "BadInputError",
    "CalibrationProblem",
    "CalibrationResult",
    "ConfigError",
    "LidarInfo",
    "PipelineConfig",
    "PipelineError",
    "RecordingInfo",
    "ScanPattern",
    "Stop",
    "__version__",
    "calibrate",
]

# The problem records and the calibration entry points load numpy, scipy and the kd-tree: only
# when first used, so that `import pipeline` (and `fleetcal --help`) stays instant.
_LAZY = {
    "CalibrationProblem": "pipeline.problem",
    "LidarInfo": "pipeline.problem",
    "RecordingInfo": "pipeline.problem",
    "ScanPattern": "pipeline.problem",
    "Stop": "pipeline.problem",
    "calibrate": "pipeline.calibrate",
    "CalibrationResult": "pipeline.calibrate",
    "PipelineConfig": "pipeline.config",
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'pipeline' has no attribute {name!r}")
