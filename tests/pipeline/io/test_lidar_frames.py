from pathlib import Path

import pytest

from pipeline.io.errors import RecordingError
from pipeline.io.lidar_frames import lidar_frames
from pipeline.io.writer import WriterFormat
from tests.pipeline.io.recordings import Spec, write_recording


@pytest.mark.parametrize("fmt", list(WriterFormat))
def test_each_topics_frame_comes_from_its_first_scan(tmp_path: Path, fmt: WriterFormat) -> None:
    path = tmp_path / "rec"
    write_recording(path, fmt, Spec(stops=2, points=40, frame_prefix="/"))
    assert lidar_frames(path) == {
        "/lidar_front/points": "lidar_front",
        "/lidar_rear/points": "lidar_rear",
    }


def test_a_file_that_is_no_recording_is_a_recording_error(tmp_path: Path) -> None:
    path = tmp_path / "notes.mcap"
    path.write_text("not a bag" * 20)
    with pytest.raises(RecordingError, match="not a recording we can read"):
        lidar_frames(path)
