"""Calibration recordings in and out: the only package that touches rosbags.

`read_recording(path, config)` turns a bag directory, `.mcap`, `.db3`, ROS 1 `.bag` or an archive
of a bag directory into a `CalibrationProblem`; `summarize_recording` is its lenient half that
`fleetcal inspect` uses; `RecordingWriter` writes recordings (synthesiser, tests).
"""

from pipeline.io.config import ReaderConfig
from pipeline.io.reader import read_recording, summarize_recording
from pipeline.io.summary import RecordingSummary

__all__ = ["ReaderConfig", "RecordingSummary", "read_recording", "summarize_recording"]
