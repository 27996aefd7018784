"""Bleeding models: draws within the declared table, reproducible per seed, balanced patterns."""

from __future__ import annotations

import pytest

from pipeline.synth.bleeding import (
    BLEEDING_RANGES,
    BleedingModel,
    draw_bleeding_case,
)


def test_draws_lie_in_the_declared_ranges() -> None:
    ranges = BLEEDING_RANGES
    cases = [draw_bleeding_case(seed) for seed in range(200)]
    for case in cases:
        model = case.bleeding
        major, minor = model.divergence_deg
        low, high = ranges.divergence_major_deg
        assert low <= major <= high
        assert ranges.divergence_minor_min_deg <= minor <= major
        assert ranges.sub_rays[0] <= model.sub_rays <= ranges.sub_rays[1]
        assert ranges.mixed_probability[0] <= model.mixed_probability <= ranges.mixed_probability[1]
        expected = ranges.rosette_scenes if case.pattern == "rosette" else (ranges.spinning_scene,)
        assert case.scenario in expected
    # Every option is drawn, both ends of the divergence range are reached (log-uniform).
    assert {c.bleeding.range_rule for c in cases} == set(ranges.range_rules)
    assert {c.scenario for c in cases} == {*ranges.rosette_scenes, ranges.spinning_scene}
    majors = sorted(c.bleeding.divergence_deg[0] for c in cases)
    assert majors[10] < 0.06 and majors[-10] > 0.6


def test_a_seed_draws_the_same_case_and_patterns_alternate() -> None:
    assert draw_bleeding_case(5) == draw_bleeding_case(5)
    assert draw_bleeding_case(5) != draw_bleeding_case(7)
    patterns = [draw_bleeding_case(seed).pattern for seed in range(10)]
    assert patterns.count("rosette") == patterns.count("spinning") == 5


def test_an_impossible_ellipse_is_refused() -> None:
    with pytest.raises(ValueError, match="major, minor"):
        BleedingModel(divergence_deg=(0.03, 0.28))
