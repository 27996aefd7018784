"""The joint optimisation's settings."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

_FROZEN = ConfigDict(frozen=True, extra="forbid")

ResidualKind = Literal["point_to_point", "point_to_plane"]
RobustLoss = Literal["cauchy", "geman_mcclure", "huber", "none"]


EVERY_LIDAR_FROM = 3
"""`cross_pairs: auto` pairs every LiDAR with every other's map on rigs of this many LiDARs or
more: with two, the reference and the other already share their one tie."""

FALLBACK_FLOOR_SIGMA = (0.02, 0.001)
"""Floor terms' tilt (deg) and offset (m) standard deviations where they are to be measured and
stage 3 leaves nothing to measure them by."""


class OptimisationConfig(BaseModel):
    """The joint optimisation; lengths in metres, angles in degrees."""

    model_config = _FROZEN

    residual: ResidualKind = "point_to_plane"
    max_iterations: int = Field(default=200, ge=1, description="the paper's 200")
    robust_loss: RobustLoss = Field(
        default="cauchy",
        description="the robust loss of the coarse phase: Cauchy's still pulls from afar, so it "
        "gets close from a distant start",
    )
    fine_robust_loss: RobustLoss | None = Field(
        default="geman_mcclure",
        description="the robust loss of the final phase (None: `robust_loss`). Points on a "
        "surface the reference never saw pair with some other surface; under Cauchy's loss "
        "each still pulls like a few-millimetre inlier, and many of them move the minimum "
        "(tens of millimetres on a lane where the LiDARs face apart). Geman-McClure's pull "
        "vanishes beyond a few kernel scales",
    )
    kernel_scale_initial_m: float = Field(
        default=0.1, gt=0, description="the robust kernel's scale at the first iteration"
    )
    kernel_scale_decay: float = Field(
        default=0.8, gt=0, le=1, description="the scale shrinks by this factor every iteration..."
    )
    kernel_scale_min_m: float = Field(default=0.015, gt=0, description="...down to this")
    kernel_scale_min_sigmas: float | None = Field(
        default=None,
        gt=0,
        description="...and not below this many robust standard deviations of the current "
        "residuals (1.4826 x their median absolute value; None: `kernel_scale_min_m` alone). "
        "Opt-in: a kernel narrower than the surfaces' own scatter down-weights one side of it "
        "wherever that scatter is skewed. On the driven routine under 2 cm of range noise "
        "(residual sigma 6-7 mm) Geman-McClure at 15 mm turns the rear LiDAR's yaw by "
        "0.05-0.16 deg, started from the truth as from stage 3, and without range noise ends "
        "within 1 mm / 0.04 deg; 3.8 sigmas (Geman-McClure's 95 % efficiency on Gaussian "
        "residuals) takes stage 4 on driven seeds 0-4 from 3.99 mm / 0.098 deg to 3.20 mm / "
        "0.036 deg mean, the paper protocol's seven other cases unchanged within 0.13 mm. But "
        "on bench_random, where spinning LiDARs scatter 10 mm and more, the "
        "wider kernel lets the surfaces the reference never saw pull again: seeds 1000-1005 "
        "are all worse (1000 3.1 -> 8.0 mm, 1001 1.2 -> 3.2 mm)",
    )
    max_normal_angle_deg: float | None = Field(
        default=45.0,
        gt=0,
        le=180,
        description="coarse phase: pairs whose surface normals (facing their sensors) differ more "
        "are dropped: the front and the back of an object seen from opposite sides are not the "
        "same surface, and far from the solution such pairs pull the wrong way",
    )
    fine_max_normal_angle_deg: float | None = Field(
        default=None,
        gt=0,
        le=180,
        description="the same gate in the final phase (None: no gate). Close to the solution the "
        "gate itself biases: it drops the pairs on one side of every edge and curved patch, and "
        "on a driven loop that turned the rear LiDAR's yaw by 0.1-0.25 deg",
    )
    max_correspondence_m: float = Field(
        default=0.5, gt=0, description="pairs further apart than this are ignored"
    )
    pair_weights: Literal["uniform", "lidar_pairs"] = Field(
        default="uniform",
        description="uniform: every point pair weighs 1/point_sigma_m^2; lidar_pairs: each pair "
        "by the robust sigma of its pair of LiDARs' inlier residuals, measured at "
        "every association (`pipeline/optimisation/pair_noise.py`), so that a noisy "
        "LiDAR's map pulls the others less; the points' mean weight stays that of "
        "uniform. Opt-in: over the whole bench_random it ties uniform (93/100 within "
        "5 mm / 0.1 deg; seed 1013 7.2 -> 4.4 mm, seed 1086 within -> 12.5 mm) and "
        "moves the paper protocol's two spinning heads 3.0 -> 3.9 mm (docs/method.md)",
    )
    point_sigma_m: float = Field(
        default=0.01, gt=0, description="standard deviation of a point residual"
    )
    reference_self_consistency: bool = True
    lidar_self_consistency: bool = Field(
        default=False,
        description="every LiDAR's object map kept self-consistent across stops, not only the "
        "reference's: more constraints on the stop poses",
    )
    cross_pairs: Literal["reference", "every_lidar", "auto"] = Field(
        default="auto",
        description="reference: the other LiDARs' points pair with the reference LiDAR's map "
        "(eq. 11); every_lidar: every LiDAR's points also pair with every other LiDAR's map, "
        "the reference's included, and each LiDAR's map is kept self-consistent "
        "(lidar_self_consistency): LiDARs that overlap each other more than the reference tie "
        "each other directly. auto (the default): every_lidar on rigs of "
        f"{EVERY_LIDAR_FROM} LiDARs or more, reference on two, where every_lidar only counts "
        "the one tie twice. Over bench_random seeds 1000-1099 auto takes 92 of 100 recordings "
        "within 5 mm / 0.1 deg against 89 (lanes 16 -> 19 of 21), 0 false passes either way, "
        "false fails 8 -> 9, 0.95 mm (standard error 0.33) nearer per LiDAR, for about half "
        "as many seconds again on rigs of three or more; every_lidar on two LiDARs fails "
        "seed 1001 at 0.2 mm (docs/method.md)",
    )
    floor_terms: bool = True
    floor_normal_sigma_deg: float | None = Field(
        default=0.02,
        gt=0,
        description="standard deviation of a floor term's tilt, per axis; None: measured, the "
        "spread of stage 3's floor residuals (`rough_refinement.floor_noise`: how far one "
        "LiDAR's floor at one stop lies from the common floor), or "
        f"{FALLBACK_FLOOR_SIGMA[0]} deg where stage 3 leaves nothing to measure it by",
    )
    floor_offset_sigma_m: float | None = Field(
        default=0.001,
        gt=0,
        description="standard deviation of a floor term's offset; None: measured, as the tilt's "
        f"(or {FALLBACK_FLOOR_SIGMA[1]} m)",
    )
    stop_prior_sigma_m: float | None = Field(
        default=None,
        gt=0,
        description="each stop's position held, softly, where stage 4 started it (odometry, "
        "levelled on the floor by stage 3), with this standard deviation; None: no prior (the "
        "default). 1 m is a weak belief (odometry over a calibration routine is within a metre "
        "of the truth, the start's error from the reference's initial mount included) that "
        "holds only what the data leave free: a stop without object pairs, whose x, y and yaw "
        "the solve otherwise throws by tenths of a metre a step on rounding noise. Against the "
        "information the objects give a paired stop (1e3-1e7 per m^2) it weighs nothing "
        "(`pipeline/optimisation/stop_prior.py`). Opt-in, with `converge_on: extrinsics` "
        "(measured together: docs/method.md)",
    )
    stop_prior_sigma_deg: float = Field(
        default=30.0,
        gt=0,
        description="...and its rotation with this one, where `stop_prior_sigma_m` is set",
    )
    self_neighbours: int = Field(
        default=4,
        ge=1,
        description="neighbours searched for a reference point's match from another stop",
    )
    normal_neighbours: int = Field(
        default=30, ge=3, description="neighbours of a reference point whose plane gives its normal"
    )
    smooth_clouds: bool = Field(
        default=True,
        description="project every object point onto its local plane (removes range noise)",
    )
    max_points_per_cloud: int | None = Field(
        default=1000,
        ge=10,
        description="random subset of each (LiDAR, stop) object cloud in the final phase; None "
        "keeps all (at full rate ~2.5k: about 1.5 mm better, three times slower)",
    )
    coarse_points_per_cloud: int | None = Field(
        default=300,
        ge=10,
        description="a first phase on this many points per cloud gets close cheaply; None: no "
        "coarse phase",
    )
    converge_on: Literal["extrinsics", "all_poses"] = Field(
        default="all_poses",
        description="whose motion in a step says the optimisation has converged: every pose, "
        "the stops' included (the default), or the extrinsics alone (the calibration; opt-in, "
        "then with tolerances ten times tighter: re-pairing after every step makes the "
        "convergence linear, and at 0.1 mm a step the extrinsics stopped up to 0.7 mm short "
        "of the solution in `tests/pipeline/optimisation/test_solver.py`'s range-bias test). "
        "A stop the objects hold weakly moves as its few pairs change, millimetres to tenths "
        "of a metre a step, long after the extrinsics have settled: bench_random seed 1028 "
        "runs to the iteration limit with 'all_poses' and fails on it. Over bench_random "
        "1000-1099, 'extrinsics' with `stop_prior_sigma_m: 1.0` and 0.01 mm / 0.0001 deg "
        "gains 1028 and 1044 and loses 1084 and 1048, 16 % slower (docs/method.md). With one "
        "LiDAR: every pose",
    )
    translation_tolerance_m: float = Field(
        default=1e-4,
        gt=0,
        description="converged when no pose (`converge_on`) moves more than this in one step",
    )
    rotation_tolerance_deg: float = Field(default=1e-3, gt=0, description="...and this")
    coarse_translation_tolerance_m: float = Field(
        default=1e-3, gt=0, description="the coarse phase only has to get close: it stops here"
    )
    coarse_rotation_tolerance_deg: float = Field(default=1e-2, gt=0, description="...and here")
    acceleration: Literal["none", "anderson"] = Field(
        default="anderson",
        description="anderson: once the robust kernel is at its floor in the final phase, each "
        "step's poses are extrapolated from the last `anderson_depth` steps (Anderson "
        "acceleration of the pair-then-step iteration), kept only where their cost with fresh "
        "pairs is lower than the plain step's (`pipeline/optimisation/acceleration.py`); the "
        "plain iteration creeps along weakly held directions and can end on its iteration limit "
        "short of the minimum (bench_random seed 1060: 14.6 -> 4.4 mm). none: the plain "
        "iteration. Measured over bench_random and its worlds, docs/method.md",
    )
    anderson_depth: int = Field(default=5, ge=1, le=20, description="steps extrapolated from")
    initial_damping: float = Field(
        default=1e-4, ge=0, description="Levenberg-Marquardt lambda at start"
    )
    uncertainty_block_m: float = Field(
        default=0.5,
        gt=0,
        description="edge of the cubic blocks of space (in G) that the leave-one-block-out "
        "jackknife leaves out in turn: larger than a surface fit's patch (the correlation length "
        "of the residuals), about the size of an object",
    )
    seed: int = 0

    def pairs_every_lidar(self, n_lidars: int) -> bool:
        """Whether the points of a rig of `n_lidars` LiDARs pair with every LiDAR's map
        (`cross_pairs`), not the reference's alone."""
        if self.cross_pairs == "auto":
            return n_lidars >= EVERY_LIDAR_FROM
        return self.cross_pairs == "every_lidar"
