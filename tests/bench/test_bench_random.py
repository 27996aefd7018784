"""bench_random's bookkeeping on fake results: seeds, success, the verdict's confusion, sigma."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.bench.bench_random import (
    SeedResult,
    grouped_table,
    parse_seeds,
    report,
    result_path,
    run_seed,
    summary_row,
)


def _record(seed: int, mm: float, deg: float, passed: bool, **kw: object) -> SeedResult:
    return SeedResult(
        seed=seed,
        method=str(kw.get("method", "proposed")),
        scenario_class=str(kw.get("scenario_class", "loop/mixed/small")),
        clock=str(kw.get("clock", "synced")),
        translation=[mm / 1000, mm / 2000],
        rotation=[deg, deg / 2],
        sigma_translation=[mm / 1000, mm / 1000],
        sigma_rotation=[deg / 2, deg / 2],
        passed=passed,
        seconds=2.0,
    )


def _cells(row: str) -> list[str]:
    return [cell.strip() for cell in row.strip("|").split("|")]


def test_seed_ranges_parse_and_bad_ones_say_how() -> None:
    assert parse_seeds("1000-1003") == [1000, 1001, 1002, 1003]
    assert parse_seeds("7") == [7] and parse_seeds("1,5,9-11") == [1, 5, 9, 10, 11]
    with pytest.raises(SystemExit, match="write seeds as 1000-1099"):
        parse_seeds("a-b")
    with pytest.raises(SystemExit, match="from low to high"):
        parse_seeds("9-3")


def test_summary_counts_success_and_every_cell_of_the_confusion_table() -> None:
    records = [
        _record(1, 3.0, 0.05, True),  # success, passed within 10 mm / 0.3 deg
        _record(2, 8.0, 0.05, True),  # passed within 10 mm: right, but no success
        _record(3, 12.0, 0.05, True),  # passed beyond 10 mm: a false pass
        _record(4, 4.0, 0.08, False),  # failed within 5 mm / 0.1 deg: a false fail
        _record(5, 4.0, 0.2, False),  # failed and worse (rotation)
        SeedResult(6, "proposed", "loop/mixed/small", "simulated", refused="NoStopsError: x"),
    ]
    cells = _cells(summary_row("loop/mixed/small", records))
    assert cells[0] == "loop/mixed/small" and cells[1] == "6"
    assert cells[2] == "2/6 (33 %)"  # records 1 and 4: success whatever the verdict said
    # Errors pool the calibrated recordings' LiDARs: 10 values, the largest 12 mm.
    assert cells[6] == "12.00" and cells[10] == "0.200"
    assert cells[11:16] == ["2", "**1**", "1", "1", "1"]
    # error / sigma: translation [1, 0.5] per record, rotation [2, 1].
    assert cells[16] == f"{(0.625) ** 0.5:.2f} / {(2.5) ** 0.5:.2f}"
    assert cells[17] == f"{(5 * 2.0) / 6:.1f}"


def test_grouped_tables_have_a_row_per_group_and_one_over_all() -> None:
    records = [
        _record(1, 3.0, 0.05, True, scenario_class="rotate/rosette/small"),
        _record(2, 3.0, 0.05, True, scenario_class="lane/spinning/large"),
        _record(3, 30.0, 0.5, False, scenario_class="lane/spinning/large"),
    ]
    table = grouped_table(records, lambda r: r.scenario_class, "class").splitlines()
    assert table[0].startswith("| class | recordings | success")
    assert [_cells(row)[0] for row in table[2:]] == [
        "lane/spinning/large",
        "rotate/rosette/small",
        "**all**",
    ]
    assert _cells(table[-1])[2] == "2/3 (67 %)"
    text = report(
        [*records, _record(1, 5.0, 0.05, True, method="without_stage1")],
        ["proposed", "without_stage1"],
    )
    for heading in (
        "per scenario class",
        "per routine",
        "per sensors",
        "per errors",
        "per header clock",
    ):
        assert f"## proposed: {heading}" in text
    assert "## without_stage1: per scenario class" in text


def test_cached_results_are_read_back_not_recomputed(tmp_path: Path) -> None:
    record = _record(42, 3.0, 0.05, True)
    path = result_path(tmp_path, 0.1, "proposed", 42)
    path.parent.mkdir(parents=True)
    path.write_text(__import__("json").dumps(record.__dict__))
    # No recording is cached: were the result not reused, the seed would be synthesised.
    assert run_seed(tmp_path, 0.1, 42, ["proposed"]) == [record]
    assert not (tmp_path / "recordings").exists()
