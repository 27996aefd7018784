"""Stage 4: stop poses and extrinsics refined together on object points, like ICP.

Unknowns: `T_G_ref` per stop (stop 0 fixed: the gauge) and `T_ref_lidar` per non-reference LiDAR.
Each iteration places every object cloud in G, associates each point with its nearest neighbour
in the reference LiDAR's object map (kd-tree), and takes one Levenberg-Marquardt step on the
robust cost below, with the normal equations assembled in numpy:

- cross terms: points of LiDAR i at stop j against the reference map (eq. 11 of the paper);
- reference self-consistency: reference points at stop j against the reference map of the other
  stops, so the map the others are aligned to cannot bend;
- floor terms: every (LiDAR, stop) floor plane against the floor in G from stage 3, so the objects
  cannot trade roll, pitch or height for a slightly better fit.

Twists are `[rho (3), phi (3)]` applied on the left: `T_G_ref <- exp(d) T_G_ref` in G, and
`T_ref_lidar <- exp(e) T_ref_lidar` in the reference frame.

Modules, in the order the data flow through them: `config`; `objective` (the clouds and floor
planes, `JointObjective`, placed in G for given poses); `association` (nearest-neighbour pairs);
`pair_noise` (each pair's residual sigma, where `pair_weights` measures it); `residuals`
(point and floor residuals, their Jacobians, the robust cost); `assembly` (the
normal equations); `solver` (`optimise`: phases of Levenberg-Marquardt steps); `layout` and
`result` (what it returns).
"""

from pipeline.optimisation.config import OptimisationConfig, ResidualKind, RobustLoss
from pipeline.optimisation.layout import ParameterLayout
from pipeline.optimisation.result import OptimisationResult
from pipeline.optimisation.solver import optimise

__all__ = [
    "OptimisationConfig",
    "OptimisationResult",
    "ParameterLayout",
    "ResidualKind",
    "RobustLoss",
    "optimise",
]
