import dataclasses

import numpy as np

from pipeline.config import PipelineConfig
from pipeline.stages import joint_optimise, observe
from pipeline.stages.runner import Listeners
from pipeline.transforms import make_transform
from tests.pipeline.stages.test_global_align import _after_stage_3, _pushed_far


def test_a_second_solution_the_data_fit_alike_is_inside_the_reported_stddev() -> None:
    near = _after_stage_3()
    far = _pushed_far(near)
    config = PipelineConfig()
    two_starts = dataclasses.replace(near, second_start=(far.T_G_ref, far.T_ref_lidar))
    optimised = joint_optimise.run(two_starts, config, Listeners()).state
    compared = optimised.start_comparison
    assert compared is not None
    # Both starts ended as one: nothing to widen.
    plain = observe.run(optimised, config, Listeners()).state.uncertainties
    # The same, had the other solution ended 0.4 m to the side and the maps not told them apart.
    other = optimised.T_ref_lidar.copy()
    other[1] = make_transform(np.eye(3), [0.0, 0.4, 0.0]) @ other[1]
    alike = dataclasses.replace(
        compared, apart_translation_m=0.4, difference_m=0.0, other_T_ref_lidar=other
    )
    wider = observe.run(
        dataclasses.replace(optimised, start_comparison=alike), config, Listeners()
    ).state.uncertainties
    assert plain is not None and wider is not None
    assert max(plain[1].stddev_translation_m) < 0.01
    assert np.linalg.norm(wider[1].stddev_translation_m) >= 0.4
    # Preferred decisively (the verdict's rule), the other solution widens nothing.
    preferred = dataclasses.replace(alike, difference_m=1.0, stderr_m=0.01)
    kept = observe.run(
        dataclasses.replace(optimised, start_comparison=preferred), config, Listeners()
    ).state.uncertainties
    assert kept is not None
    np.testing.assert_allclose(kept[1].stddev_translation_m, plain[1].stddev_translation_m)
