"""README.md and docs/ stand alone: every link resolves inside the repository, and the config
examples in docs/ are valid pipeline configs."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml

from pipeline.config import config_from_mapping

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
_LINK = re.compile(r"(?<!!)\[[^\]]*\]\(([^)\s]+)\)")
_CODE = re.compile(r"```.*?```|`[^`\n]*`", re.DOTALL)


def links(page: Path) -> list[str]:
    return _LINK.findall(_CODE.sub("", page.read_text(encoding="utf-8")))


def anchors(page: Path) -> set[str]:
    """GitHub's heading anchors: lower case, punctuation dropped, spaces as hyphens."""
    headings = re.findall(r"^#+ (.+)$", page.read_text(encoding="utf-8"), re.MULTILINE)
    return {re.sub(r"[^\w\- ]", "", h).strip().lower().replace(" ", "-") for h in headings}


def test_the_documentation_pages_exist() -> None:
    names = {page.name for page in PAGES}
    assert {"design.md", "method.md", "configuration.md", "api.md"} <= names


@pytest.mark.parametrize("page", PAGES, ids=lambda page: page.relative_to(ROOT).as_posix())
def test_every_link_resolves_inside_the_repository(page: Path) -> None:
    found = links(page)
    assert found or page.name != "README.md", "the README links its docs"
    for link in found:
        assert not re.match(r"^[a-z][a-z0-9+.-]*:", link), f"{link}: links outside the repository"
        assert not link.startswith("/"), f"{link}: an absolute path"
        path, _, anchor = link.partition("#")
        target = (page.parent / path).resolve() if path else page
        assert target.is_relative_to(ROOT), f"{link}: leaves the repository"
        assert target.exists(), f"{link}: no such file"
        if anchor:
            assert anchor in anchors(target), f"{link}: no such heading in {target.name}"


def test_no_page_refers_to_files_outside_the_repository() -> None:
    for page in PAGES:
        text = page.read_text(encoding="utf-8")
        assert "../shared" not in text and "/work/" not in text, page.name


def test_the_link_check_catches_a_link_out_of_the_repository(tmp_path: Path) -> None:
    page = tmp_path / "page.md"
    page.write_text("[design](../shared/DESIGN.md), [`x`](docs/x.md) and `[not](a-link)`")
    assert links(page) == ["../shared/DESIGN.md", "docs/x.md"]


def test_the_config_examples_in_docs_are_valid_pipeline_configs() -> None:
    text = (ROOT / "docs" / "configuration.md").read_text(encoding="utf-8")
    (block,) = re.findall(r"```yaml\n(.*?)```", text, re.DOTALL)
    config = config_from_mapping(yaml.safe_load(block))
    assert config.frames.base_height_above_floor_m == 0.0
    assert config.reader.stops.min_dwell_s == 0.5
