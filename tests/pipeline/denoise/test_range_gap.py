"""The range-gap filter: removes ranges between those of the neighbouring beams, keeps surfaces,
and takes its range noise and scan pattern from the cloud when the config does not give them."""

from __future__ import annotations

import numpy as np

from pipeline.denoise import DenoiseConfig, DenoiseMethod, denoise
from pipeline.denoise.range_gap import range_gap_keep
from pipeline.problem import ScanPattern
from tests.pipeline.denoise.clouds import AXIS, f_score, floor_in_lidar_frame, veil


def _floor_and_veil(noise: float = 0.01) -> tuple[np.ndarray, np.ndarray]:
    floor = floor_in_lidar_frame(40_000, noise=noise)
    sheet = veil(300)
    labels = np.r_[np.zeros(len(floor), bool), np.ones(len(sheet), bool)]
    return np.vstack([floor, sheet]), labels


def test_the_veil_goes_and_the_floor_stays() -> None:
    cloud, is_bleeding = _floor_and_veil()
    keep, report = range_gap_keep(cloud)
    assert f_score(keep, is_bleeding) > 0.8
    assert np.count_nonzero(~keep[~is_bleeding]) < 0.002 * np.count_nonzero(~is_bleeding)
    assert report.pattern is ScanPattern.NON_REPETITIVE
    assert report.noise_estimated and report.pattern_estimated


def test_the_range_noise_is_estimated_from_the_cloud() -> None:
    for sigma in (0.005, 0.02):
        _, report = range_gap_keep(_floor_and_veil(sigma)[0])
        assert 0.8 * sigma < report.range_noise_m < 1.5 * sigma


def test_a_known_lidar_is_not_estimated() -> None:
    cloud, _ = _floor_and_veil()
    _, report = range_gap_keep(cloud, range_noise_m=0.01, pattern=ScanPattern.NON_REPETITIVE)
    assert report.range_noise_m == 0.01 and not report.noise_estimated
    assert not report.pattern_estimated


def test_repeated_directions_are_taken_for_a_repetitive_scan() -> None:
    rng = np.random.default_rng(0)
    floor = floor_in_lidar_frame(5_000, noise=0.0)
    ranges = np.linalg.norm(floor, axis=1)
    scans = [floor / ranges[:, None] * (ranges + rng.normal(0, 0.02, len(floor)))[:, None]]
    scans += [floor / ranges[:, None] * (ranges + rng.normal(0, 0.02, len(floor)))[:, None]]
    _, report = range_gap_keep(np.vstack(scans * 3))
    assert report.pattern is ScanPattern.REPETITIVE


def test_the_stage_reports_what_the_filter_used() -> None:
    cloud, is_bleeding = _floor_and_veil()
    config = DenoiseConfig(method=DenoiseMethod.RANGE_GAP)
    result = denoise(cloud, config, AXIS, range_noise_m=0.01)
    assert result.parameters["range_noise_m"] == 0.01
    assert result.parameters["scan_pattern"] == "non_repetitive"
    judged = denoise(cloud, config, AXIS, judge=is_bleeding)
    assert judged.keep[~is_bleeding].all()
    assert np.count_nonzero(~judged.keep[is_bleeding]) > 0.7 * is_bleeding.sum()


def test_a_drawn_beam_outside_the_benchmark_draws() -> None:
    """Draw 100 of the randomised bleeding models (the benchmark judges by 0-19 and holds out
    20-39): a Mid-70 rosette on boxes, 0.08 x 0.03 deg beam, uniform mixing. The filter gets the
    LiDAR model's range noise and scan pattern. Before the false-alarm tau, the well-supported
    neighbour and the floor's margin the pooled F here was 0.59 (0.65 with the tau alone, 0.76
    with the neighbour, 0.78 with the floor); now 0.81."""
    from pipeline.synth.bleeding import draw_bleeding_case
    from tests.pipeline.denoise.clouds import bleeding_stop_clouds

    beams = list(bleeding_stop_clouds(draw_bleeding_case(100), (0,)))
    keep = [
        range_gap_keep(b.cloud.points, range_noise_m=b.range_noise_m, pattern=b.scan_pattern)[0]
        for b in beams
    ]
    is_bleeding = np.concatenate([b.cloud.is_bleeding for b in beams])
    assert f_score(np.concatenate(keep), is_bleeding) > 0.75
    # The label's rule applied to the measured points (what the benchmark prints beside the
    # filters) agrees with the labels only in part: 2 cm of range noise carries points across
    # the three-sigma line both ways. Here it scores 0.67, below the filter, which pools returns.
    by_rule = np.concatenate([b.surface_distance_m <= 3.0 * b.range_noise_m for b in beams])
    assert 0.5 < f_score(by_rule, is_bleeding) < f_score(np.concatenate(keep), is_bleeding)
