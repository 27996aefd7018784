"""bench_random's bookkeeping on fake results: seeds, success, the verdict's confusion, sigma."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace
from typing import Any, cast

import numpy as np
import pytest

from tests.bench.bench_random import (
    DETERMINED,
    UNDETERMINED,
    SeedResult,
    along_reference_axis,
    axis_bias_table,
    comparisons,
    determination,
    grouped_table,
    mixed_code,
    parse_limits,
    parse_seeds,
    parse_worlds,
    recording_dir,
    report,
    result_path,
    run_seed,
    summary_row,
    with_limits,
    without_checks,
    world_pairs,
    world_pairs_table,
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
        world=str(kw.get("world", "")),
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


def _check(name: str, passed: bool) -> dict[str, object]:
    return {"name": name, "value": 0.05, "limit": 0.04, "passed": passed}


def test_verdicts_are_judged_again_without_the_named_kinds_of_check() -> None:
    failed_on_metric = _record(1, 3.0, 0.05, False)
    failed_on_metric.checks = [_check("metric_error", False), _check("convergence", True)]
    failed_on_two = _record(2, 3.0, 0.05, False)
    failed_on_two.checks = [
        _check("metric_error", False),
        _check("uncertainty_translation:lidar_1", False),
        _check("uncertainty_rotation:lidar_1", True),
    ]
    again = without_checks(failed_on_metric, {"metric_error"})
    assert again.passed and again.failed_checks == [] and not failed_on_metric.passed
    still = without_checks(failed_on_two, {"metric_error"})
    assert not still.passed and still.failed_checks == ["uncertainty_translation:lidar_1"]
    assert without_checks(failed_on_two, {"uncertainty_translation"}).failed_checks == [
        "metric_error"
    ]
    assert without_checks(failed_on_two, set()) is failed_on_two
    refused = SeedResult(3, "proposed", "loop/mixed/small", "synced", refused="NoStopsError: x")
    assert without_checks(refused, {"metric_error"}) is refused
    with pytest.raises(SystemExit, match="keeps no checks"):
        without_checks(_record(4, 3.0, 0.05, True), {"metric_error"})


def test_verdicts_are_judged_again_with_other_limits() -> None:
    record = _record(1, 3.0, 0.05, False)
    record.metric_error_m = 0.05
    record.checks = [
        {"name": "seen_metric_error:lidar_1", "value": 0.012, "limit": 0.01, "passed": False},
        {"name": "seen_metric_error:lidar_2", "value": None, "limit": 0.01, "passed": False},
        _check("convergence", True),
    ]
    looser = with_limits(record, {"seen_metric_error": 0.015})
    assert looser.failed_checks == ["seen_metric_error:lidar_2"]  # no value never passes
    assert looser.checks[0]["limit"] == 0.015 and record.checks[0]["limit"] == 0.01
    with_eq12 = without_checks(with_limits(record, {"metric_error": 0.04}), {"seen_metric_error"})
    assert with_eq12.failed_checks == ["metric_error"]  # added from the recording's eq. 12
    assert without_checks(with_limits(record, {"metric_error": 0.06}), {"seen_metric_error"}).passed
    assert with_limits(record, {}) is record
    assert parse_limits("seen_metric_error=0.015, metric_error=0.04") == {
        "seen_metric_error": 0.015,
        "metric_error": 0.04,
    }
    with pytest.raises(SystemExit, match="kind=number"):
        parse_limits("seen_metric_error")


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
        "by what the data determines (the reported 1-sigma)",
        "error along the reference's optical axis, by its model",
    ):
        assert f"## proposed: {heading}" in text
    assert "## without_stage1: per scenario class" in text


def test_recordings_are_told_apart_by_whether_every_reported_sigma_is_within_the_bar() -> None:
    def with_stddev(mm: float, deg: float) -> SeedResult:
        record = _record(1, 3.0, 0.05, True)
        record.stddev = [[0.001, 0.001, 0.001, 0.01, 0.01, 0.01], [mm / 1000, 0, 0, 0, 0, deg]]
        return record

    assert determination(with_stddev(5.0, 0.1)) == DETERMINED
    assert determination(with_stddev(5.1, 0.01)) == UNDETERMINED
    assert determination(with_stddev(1.0, 0.11)) == UNDETERMINED
    refused = _record(2, 0.0, 0.0, False)
    refused.refused = "NoStopsError: no stops"
    assert determination(refused) == "refused"


def _pose(x: float, y: float, yaw_deg: float) -> np.ndarray[Any, np.dtype[np.float64]]:
    yaw = np.radians(yaw_deg)
    pose = np.eye(4)
    pose[:2, :2] = [[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]]
    pose[:2, 3] = [x, y]
    return pose


def test_the_error_along_the_reference_s_axis_is_signed_and_in_its_frame() -> None:
    # The reference looks along base +y (yaw 90 deg, optical axis +x in its frame); the other
    # LiDAR is calibrated 3 mm too far along base +y and 2 mm off along base x.
    reference = _pose(0.0, 0.0, 90.0)
    true_other = _pose(0.5, 0.0, 0.0)
    calibrated_other = _pose(0.502, 0.003, 0.0)
    lidar = SimpleNamespace
    truth = lidar(
        lidars=[
            lidar(frame="front", T_base_lidar_true=reference, optical_axis=np.array([2.0, 0, 0])),
            lidar(frame="side", T_base_lidar_true=true_other, optical_axis=np.array([1.0, 0, 0])),
        ]
    )
    result = lidar(
        lidars=[
            lidar(frame="front", T_base_lidar_calibrated=reference),
            lidar(frame="side", T_base_lidar_calibrated=calibrated_other),
        ]
    )
    (along,) = along_reference_axis(cast(Any, result), cast(Any, truth))
    assert along == pytest.approx(0.003)


def test_the_axis_table_averages_recordings_per_reference_without_wrong_basins() -> None:
    records = []
    for seed, along, model in (
        (1, [0.002, 0.004], "livox-mid70"),
        (2, [0.001], "livox-mid70"),
        (3, [-0.001], "spinning"),
    ):
        record = _record(seed, 3.0, 0.05, True)
        record.along_reference_axis, record.reference_model = along, model
        records.append(record)
    old = _record(4, 3.0, 0.05, True)  # cached before the error along the axis was recorded
    lost = _record(5, 2000.0, 0.05, False)  # a wrong basin, 2 m off
    lost.along_reference_axis, lost.reference_model = [2.0], "livox-mid70"
    lines = axis_bias_table([*records, old, lost]).splitlines()
    mid70, spinning, everything = (_cells(line) for line in lines[2:])
    # Recording means 3 and 1 mm: mean 2, standard error 1 (sample std sqrt(2) over sqrt(2)).
    assert mid70 == ["livox-mid70", "2", "3", "+2.00", "1.00", "+2.00", "2/2"]
    assert spinning == ["spinning", "1", "1", "-1.00", "n/a", "-1.00", "0/1"]
    assert everything[:3] == ["**all**", "3", "4"]


def test_results_of_one_method_from_several_code_versions_are_named() -> None:
    records = [_record(seed, 1.0, 0.01, True) for seed in (1, 2, 3)]
    records[0].code, records[1].code = "14a0a70", "14a0a70"
    assert mixed_code(records) == [
        "proposed's results come from 2 code versions: 14a0a70 (2), unknown (1); delete the "
        "cache's results/proposed to calibrate them again with this code"
    ]
    records[2].code = "14a0a70"
    other = _record(1, 1.0, 0.01, True, method="pair_weights")
    assert mixed_code([*records, other]) == []


def test_cached_results_are_read_back_not_recomputed(tmp_path: Path) -> None:
    record = _record(42, 3.0, 0.05, True)
    path = result_path(tmp_path, 0.1, "proposed", 42)
    path.parent.mkdir(parents=True)
    path.write_text(__import__("json").dumps(record.__dict__))
    # No recording is cached: were the result not reused, the seed would be synthesised.
    assert run_seed(tmp_path, 0.1, 42, ["proposed"]) == [record]
    assert not (tmp_path / "recordings").exists()


@pytest.mark.parametrize(
    ("discard", "keep_free_bytes", "kept"),
    [
        (True, 0, False),  # asked for
        (False, 2**62, False),  # the disk has less free than asked to keep: the cache stops growing
        (False, 0, True),
    ],
)
def test_a_recording_is_discarded_when_asked_or_when_the_disk_runs_short(
    tmp_path: Path, discard: bool, keep_free_bytes: int, kept: bool
) -> None:
    record = _record(42, 3.0, 0.05, True)
    path = result_path(tmp_path, 0.1, "proposed", 42)
    path.parent.mkdir(parents=True)
    path.write_text(__import__("json").dumps(record.__dict__))
    recording = recording_dir(tmp_path, 0.1, 42)
    recording.mkdir(parents=True)
    (recording / "left-from-an-earlier-run").write_text("x")
    results = run_seed(
        tmp_path,
        0.1,
        42,
        ["proposed"],
        discard_recording=discard,
        keep_free_bytes=keep_free_bytes,
    )
    assert results == [record]
    assert recording.exists() == kept


def _in_world(seed: int, world: str, mm: float, deg: float, **kw: object) -> SeedResult:
    return _record(
        seed, mm, deg, True, world=world, scenario_class=f"loop/mixed/small/{world}", **kw
    )


def test_worlds_parse_and_bad_ones_say_how() -> None:
    assert parse_worlds(None) == [None]
    assert parse_worlds("open, room,random") == ["open", "room", "random"]
    for bad in ("open,warehouse", "open,open", ","):
        with pytest.raises(SystemExit, match="name each world once"):
            parse_worlds(bad)


def test_each_world_has_its_own_cache_and_a_run_without_worlds_keeps_the_old_one() -> None:
    cache = Path("/cache")
    assert result_path(cache, 0.1, "proposed", 7) == cache / "results/rate-0.1/proposed/seed-7.json"
    assert recording_dir(cache, 1.0, 7) == cache / "recordings/rate-1/seed-7"
    assert result_path(cache, 0.1, "proposed", 7, "room") == (
        cache / "results/rate-0.1/world-room/proposed/seed-7.json"
    )
    assert recording_dir(cache, 1.0, 7, "open") == cache / "recordings/rate-1/world-open/seed-7"


def test_worlds_pair_with_the_open_floor_seed_by_seed_and_method_by_method() -> None:
    records = [
        _in_world(1, "open", 3.0, 0.05),
        _in_world(1, "room", 1.0, 0.05),
        _in_world(2, "open", 2.0, 0.04),
        _in_world(2, "room", 4.0, 0.12),
        _in_world(3, "room", 1.0, 0.01),  # no open run of seed 3: no pair
        _in_world(1, "dust", 3.2, 0.05),
        _in_world(1, "open", 9.0, 0.9, method="without_stage1"),
    ]
    pairs = world_pairs([r for r in records if r.method == "proposed"])
    assert list(pairs) == ["dust", "room"]
    assert [(p.world.seed, p.open.seed, p.open.world) for p in pairs["room"]] == [
        (1, 1, "open"),
        (2, 2, "open"),
    ]
    rows = world_pairs_table([r for r in records if r.method == "proposed"]).splitlines()
    assert [_cells(row)[0] for row in rows[2:]] == ["dust", "room", "**all**"]
    room = _cells(rows[3])
    # Errors of a recording: its largest LiDAR's (3, 1, 2, 4 mm): differences -2 and +2 mm.
    assert room[1:4] == ["2", "1/2", "2/2"]  # seed 2 in the room: 0.12 deg, no success
    assert room[4:7] == ["+0.00", "+0.00", "+2.00"]
    assert room[7:10] == ["+0.040", "+0.040", "+0.080"]
    assert room[10:13] == ["1 / 0 / 1", "0 / 1 / 1", "0 / 0"]
    assert _cells(rows[2])[10] == "0 / 1 / 0"  # dust: 0.2 mm worse is a tie
    assert _cells(rows[4])[1] == "3"


def test_a_refused_side_counts_as_no_success_and_leaves_the_differences() -> None:
    refused = SeedResult(
        1, "proposed", "loop/mixed/small/room", "synced", refused="X", world="room"
    )
    rows = world_pairs_table([_in_world(1, "open", 3.0, 0.05), refused]).splitlines()
    cells = _cells(rows[2])
    assert cells[1:4] == ["1", "0/1", "1/1"]
    assert cells[4] == "n/a" and cells[-1] == "1 / 0"


def test_a_report_with_worlds_has_a_table_per_world_and_the_pairs_and_without_none() -> None:
    records = [_in_world(1, "open", 3.0, 0.05), _in_world(1, "room", 1.0, 0.05)]
    text = report(records, ["proposed"])
    assert "## proposed: per world" in text
    assert "## proposed: each world against the open floor, on the same seeds" in text
    assert "| loop/mixed/small/room | 1 |" in text
    plain = report([_record(1, 3.0, 0.05, True)], ["proposed"])
    assert "per world" not in plain and "open floor" not in plain


def test_cached_results_of_a_world_are_read_back_not_recomputed(tmp_path: Path) -> None:
    record = _in_world(42, "room", 3.0, 0.05)
    path = result_path(tmp_path, 0.1, "proposed", 42, "room")
    path.parent.mkdir(parents=True)
    path.write_text(__import__("json").dumps(record.__dict__))
    assert run_seed(tmp_path, 0.1, 42, ["proposed"], "room") == [record]
    assert not (tmp_path / "recordings").exists()


def test_every_method_is_compared_with_the_default_and_the_fixed_pairs_keep_their_order() -> None:
    assert comparisons(["proposed", "surface_passes4", "beam_fit"]) == [
        ("surface_passes4", "proposed"),
        ("beam_fit", "proposed"),
    ]
    assert comparisons(["proposed", "point_to_point"]) == [("proposed", "point_to_point")]
    assert comparisons(["with_stage1", "without_stage1"]) == [("with_stage1", "without_stage1")]
    records = [
        _record(1, 3.0, 0.05, True),
        _record(1, 2.0, 0.04, True, method="surface_passes4"),
    ]
    text = report(records, ["proposed", "surface_passes4"])
    assert "## surface_passes4 against proposed, recording by recording" in text
