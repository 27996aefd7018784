"""fleetcal's numerical core: recording -> `CalibrationProblem` -> calibrated extrinsics.

Importable without the service: it never imports FastAPI, SQLAlchemy or the service settings.
"""

from pipeline.errors import BadInputError, ConfigError, PipelineError
from pipeline.problem import CalibrationProblem, LidarInfo, RecordingInfo, Stop

__version__ = "0.1.0"

__all__ = [
    "BadInputError",
    "CalibrationProblem",
    "ConfigError",
    "LidarInfo",
    "PipelineError",
    "RecordingInfo",
    "Stop",
    "__version__",
]
