"""Calibration recordings in and out: the only package that touches rosbags (and mcap).

`read_recording(path, config)` turns a bag directory, `.mcap`, `.db3`, ROS 1 `.bag` or an archive
of a bag directory into a `CalibrationProblem`; `summarize_recording` is its lenient half that
`fleetcal inspect` uses; `write_calibrated_recording` copies a recording with its `/tf_static`
replaced by a calibration; `detect_format_from_head` recognises an upload by its first bytes.
`__all__` is the public API that `service`, `workers` and `client` use (`.importlinter` checks it).
"""

from typing import TYPE_CHECKING

from pipeline.lazy import lazy_attributes

if TYPE_CHECKING:
    from pipeline.io.config import ReaderConfig
    from pipeline.io.formats import HEAD_BYTES, RecordingFormat, detect_format_from_head
    from pipeline.io.reader import read_recording, summarize_recording
    from pipeline.io.retag import write_calibrated_recording
    from pipeline.io.summary import RecordingSummary

__all__ = [
    "HEAD_BYTES",
    "ReaderConfig",
    "RecordingFormat",
    "RecordingSummary",
    "detect_format_from_head",
    "read_recording",
    "summarize_recording",
    "write_calibrated_recording",
]

# Loaded when first used: the reader and the copier load numpy and rosbags, which the service's
# upload path (format detection only) and `fleetcal --help` do without.
_LAZY = {
    "ReaderConfig": "pipeline.io.config",
    "HEAD_BYTES": "pipeline.io.formats",
    "RecordingFormat": "pipeline.io.formats",
    "detect_format_from_head": "pipeline.io.formats",
    "read_recording": "pipeline.io.reader",
    "summarize_recording": "pipeline.io.reader",
    "write_calibrated_recording": "pipeline.io.retag",
    "RecordingSummary": "pipeline.io.summary",
}

__getattr__ = lazy_attributes(__name__, _LAZY)
