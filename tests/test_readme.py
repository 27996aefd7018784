"""The README's examples stay true."""

import re
from pathlib import Path

from pipeline.config import config_from_mapping
from pipeline.problem import ScanPattern

README = Path(__file__).resolve().parents[1] / "README.md"


def test_the_readme_config_example_is_a_valid_pipeline_config() -> None:
    import yaml

    blocks = re.findall(r"```yaml\n(.*?)```", README.read_text(encoding="utf-8"), re.DOTALL)
    assert len(blocks) == 1
    config = config_from_mapping(yaml.safe_load(blocks[0]))
    assert config.frames.reference_frame == "lidar_front"
    assert config.denoise.scan_patterns == {"lidar_top": ScanPattern.REPETITIVE}
    assert config.denoise.optical_axes == {"lidar_side": (0.0, 1.0, 0.0)}
