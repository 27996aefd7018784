"""Existing scenarios render as they did before the world options (room, walkers, uneven floor,
dust) existed: the benchmarks' tables stay reproducible for their seeds.

The digests were taken on the code before those options were added. Coordinates are rounded to
1 um and intensities to 1e-3 before hashing, so a last-bit difference in a maths library cannot
fail the test, while any real change of a scan (a point moved, a label changed) does.
"""

from __future__ import annotations

import hashlib

import numpy as np
import pytest

from pipeline.synth import LabelledScan, make_world

# (scenario, seed, rate_scale, scans per LiDAR: every `step`-th scan of the recording) -> digest
DIGESTS = {
    ("set1-box", 0, 0.02, 3): "e17a97e04bb997467747a27c9f16dcaed891b335109c344d74c6874871d7b855",
    ("driven", 1, 0.02, 7): "d8043e0b56a3be4787b89f734695ed7f88ba44470600ac085360da116024190b",
    ("spinning", 2, 0.02, 9): "bc763439b11c36f937ab8093d13c69d9e3e7713262d37efd25c46496802a04ad",
    ("set2-capsule", 3, 0.02, 11): (
        "caa541a150ae9b062efef6ef3364bb851fada62e376e9e3ece73dad602bdffe7"
    ),
}


def _digest(scans: list[LabelledScan]) -> str:
    sha = hashlib.sha256()
    for labelled in scans:
        sha.update(np.int64(labelled.stamp_ns).tobytes())
        sha.update(np.round(labelled.points * 1e6).astype(np.int64).tobytes())
        sha.update(np.round(labelled.times * 1e9).astype(np.int64).tobytes())
        sha.update(np.round(labelled.intensity.astype(np.float64) * 1e3).astype(np.int64).tobytes())
        sha.update(labelled.is_bleeding.tobytes())
        sha.update(labelled.object_index.tobytes())
    return sha.hexdigest()


def _scans(name: str, seed: int, rate_scale: float, step: int) -> list[LabelledScan]:
    world = make_world(name, seed, rate_scale)
    return [
        world.simulate_scan(i, k)
        for i in range(len(world.spec.lidars))
        for k in range(0, world.scan_count(i), step)
    ]


@pytest.mark.parametrize(("key", "expected"), DIGESTS.items(), ids=[k[0] for k in DIGESTS])
def test_existing_scenarios_render_as_before(
    key: tuple[str, int, float, int], expected: str
) -> None:
    assert _digest(_scans(*key)) == expected
