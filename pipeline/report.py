"""Report images of a calibration: the accumulated map from above and from the side, before and
after calibration, each LiDAR in its own colour, and the error per optimisation iteration (PNG).

Both maps are drawn in W, the base frame at the first stop: before with the odometry's stop poses
and the initial extrinsics, after with the refined poses and the calibrated extrinsics. The same
points enter both (the floor is hidden from above, where it would only cover the objects).
"""

from __future__ import annotations

import io
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from pipeline.problem import CalibrationProblem
from pipeline.transforms import Matrix4, Points, invert

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from pipeline.calibrate import CalibrationResult

REPORT_IMAGES: tuple[str, ...] = ("map-top", "map-side", "error")
"""The images `render_report` makes, by name (each a PNG)."""

LIDAR_COLOURS: tuple[str, ...] = (
    "#0072B2",  # blue
    "#D55E00",  # vermillion
    "#009E73",  # bluish green
    "#CC79A7",  # reddish purple
    "#E69F00",  # orange
    "#56B4E9",  # sky blue
    "#000000",  # black
    "#F0E442",  # yellow
)
"""Okabe-Ito colours, distinguishable with every common colour-vision deficiency; LiDAR i (the
reference first) gets colour i, in these images and on the dashboard."""

_OBJECT_MIN_HEIGHT_M = 0.05
_DPI = 100


def lidar_colour(index: int) -> str:
    return LIDAR_COLOURS[index % len(LIDAR_COLOURS)]


@dataclass(frozen=True)
class ReportInput:
    """What the images show. `frames`: the LiDARs, the reference first. `clouds[i][j]`: (N, 3)
    points of LiDAR i at stop j in its own frame. `T_W_lidar_before` / `_after`: (L, J, 4, 4)
    poses of each LiDAR at each stop in W. Errors in metres (NaN when unknown)."""

    frames: tuple[str, ...]
    clouds: tuple[tuple[Points, ...], ...]
    T_W_lidar_before: NDArray[np.float64]
    T_W_lidar_after: NDArray[np.float64]
    error_per_iteration: tuple[float, ...] = ()
    metric_error_initial: float = float("nan")
    metric_error_final: float = float("nan")
    passed: bool | None = None
    converged: bool | None = None

    def placed(self, after: bool) -> list[Points]:
        """Each LiDAR's points of every stop in W, (sum N_j, 3) per LiDAR."""
        poses = self.T_W_lidar_after if after else self.T_W_lidar_before
        return [
            np.concatenate(
                [c @ T[:3, :3].T + T[:3, 3] for c, T in zip(row, poses[i], strict=True)]
                or [np.zeros((0, 3))]
            )
            for i, row in enumerate(self.clouds)
        ]


def map_poses(
    T_odom_base: NDArray[np.float64], T_base_lidar: Sequence[Matrix4]
) -> NDArray[np.float64]:
    """(L, J, 4, 4) `T_W_lidar` from stop poses `T_odom_base` (J, 4, 4) and one extrinsic per
    LiDAR, with W the base at stop 0: `inv(T_odom_base[0]) @ T_odom_base[j] @ T_base_lidar[i]`."""
    T_W_base = invert(T_odom_base[0]) @ np.asarray(T_odom_base)
    return np.stack([T_W_base @ np.asarray(T) for T in T_base_lidar])


def report_input(
    problem: CalibrationProblem,
    result: CalibrationResult,
    *,
    max_points: int = 150_000,
    seed: int = 0,
) -> ReportInput:
    """The images' data for `result`, calibrated from `problem`; at most about `max_points`
    points in each map (a random subset of each stop cloud, the same one before and after)."""
    frames = tuple(lidar.frame for lidar in result.lidars)
    initial = [problem.lidar(frame).T_base_lidar for frame in frames]
    odometry = np.stack([stop.T_odom_base for stop in problem.stops])
    calibrated = [lidar.T_base_lidar_calibrated for lidar in result.lidars]
    # The refined stop poses are the reference's (`T_G_ref`); W is then the calibrated base frame
    # at stop 0 whatever gauge G the optimisation fixed.
    T_G_base = result.optimisation.T_G_ref @ invert(calibrated[0])
    return ReportInput(
        frames=frames,
        clouds=_subsample(problem, frames, max_points, seed),
        T_W_lidar_before=map_poses(odometry, initial),
        T_W_lidar_after=map_poses(T_G_base, calibrated),
        error_per_iteration=tuple(result.error_per_iteration),
        metric_error_initial=result.metric_error_initial,
        metric_error_final=result.metric_error_final,
        passed=result.passed,
        converged=result.converged,
    )


def _subsample(
    problem: CalibrationProblem, frames: Sequence[str], max_points: int, seed: int
) -> tuple[tuple[Points, ...], ...]:
    rng = np.random.default_rng(seed)
    per_cloud = max(500, max_points // max(1, len(frames) * len(problem.stops)))
    rows = []
    for frame in frames:
        row = []
        for stop in problem.stops:
            cloud = np.asarray(stop.clouds.get(frame, np.zeros((0, 3))), dtype=np.float64)
            if len(cloud) > per_cloud:
                cloud = cloud[rng.choice(len(cloud), per_cloud, replace=False)]
            row.append(cloud)
        rows.append(tuple(row))
    return tuple(rows)


def render_report(problem: CalibrationProblem, result: CalibrationResult) -> dict[str, bytes]:
    """The PNG images of `REPORT_IMAGES` for a calibration of `problem`, by name."""
    return render(report_input(problem, result))


def render(data: ReportInput, names: Sequence[str] = REPORT_IMAGES) -> dict[str, bytes]:
    """The PNG images `names` (of `REPORT_IMAGES`) for `data`, by name."""
    unknown = sorted(set(names) - set(REPORT_IMAGES))
    if unknown:
        raise ValueError(f"no report image {unknown}; the images are {list(REPORT_IMAGES)}")
    before, after = data.placed(after=False), data.placed(after=True)
    floor_z = floor_height(np.concatenate(after)) if any(len(p) for p in after) else 0.0
    # One classification for both maps (from the calibrated one), so both show the same points.
    objects = [p[:, 2] > floor_z + _OBJECT_MIN_HEIGHT_M for p in after]
    figures = {
        "map-top": lambda: _top_view(data, before, after, objects),
        "map-side": lambda: _side_view(data, before, after),
        "error": lambda: _error_curve(data),
    }
    return {name: _png(figures[name]()) for name in REPORT_IMAGES if name in names}


def floor_height(points: Points, bin_m: float = 0.01) -> float:
    """The most populated height (m) of (N, 3) points in a frame whose z is up: the floor."""
    z = points[:, 2]
    low, high = np.percentile(z, [0.5, 99.5])
    bins = max(1, int(np.ceil((high - low) / bin_m)))
    counts, edges = np.histogram(z, bins=bins, range=(low, high + 1e-9))
    k = int(np.argmax(counts))
    return float((edges[k] + edges[k + 1]) / 2)


# -- figures ---------------------------------------------------------------------------------------


def _figure(width_in: float, height_in: float) -> Figure:
    from matplotlib.figure import Figure

    # No pyplot: no global figure registry, safe in worker threads and processes.
    return Figure(figsize=(width_in, height_in), dpi=_DPI, layout="constrained")


def _png(figure: Figure) -> bytes:
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png")
    return buffer.getvalue()


def _scatter(
    axes: Axes, frames: Sequence[str], layers: Sequence[NDArray[np.float64]], size: float
) -> None:
    """Every LiDAR's (N, 2) points in its colour, drawn interleaved so none hides another."""
    points = np.concatenate([p for p in layers if len(p)] or [np.zeros((0, 2))])
    colours = np.concatenate(
        [np.full(len(p), i) for i, p in enumerate(layers)] or [np.zeros(0)]
    ).astype(int)
    order = np.random.default_rng(1).permutation(len(points))
    palette = np.array([lidar_colour(i) for i in range(len(frames))])
    axes.scatter(
        points[order, 0],
        points[order, 1],
        s=size,
        c=palette[colours[order]] if len(points) else [],
        marker=".",
        linewidths=0,
        alpha=0.8,
        rasterized=True,
    )
    for i, frame in enumerate(frames):
        axes.scatter([], [], s=40, c=lidar_colour(i), label=frame + (" (reference)" * (i == 0)))


def _panel_titles(data: ReportInput) -> tuple[str, str]:
    return (
        f"Before calibration: metric error {_mm(data.metric_error_initial)}",
        f"After calibration: metric error {_mm(data.metric_error_final)}"
        + ("" if data.passed is None else (", PASSED" if data.passed else ", FAILED")),
    )


def _top_view(
    data: ReportInput, before: list[Points], after: list[Points], objects: list[NDArray[np.bool_]]
) -> Figure:
    figure = _figure(14, 7)
    panels = figure.subplots(1, 2, sharex=True, sharey=True)
    shown_after = [p[m, :2] for p, m in zip(after, objects, strict=True)]
    shown_before = [p[m, :2] for p, m in zip(before, objects, strict=True)]
    for axes, layers, title in zip(
        panels, (shown_before, shown_after), _panel_titles(data), strict=True
    ):
        _scatter(axes, data.frames, layers, size=4.0)
        axes.set_title(title)
        axes.set_aspect("equal", adjustable="box")
        axes.set_xlabel("x (m)")
        axes.grid(True, alpha=0.3)
    panels[0].set_ylabel("y (m)")
    _limits(panels[1], np.concatenate(shown_after or [np.zeros((0, 2))]), margin=0.3)
    panels[1].legend(loc="upper right", markerscale=1, framealpha=0.9)
    figure.suptitle(
        "Top view: object points of every stop (floor hidden), in the base frame of the first "
        "stop. A mismatch shows each object twice."
    )
    return figure


def _side_view(data: ReportInput, before: list[Points], after: list[Points]) -> Figure:
    figure = _figure(14, 6)
    panels = figure.subplots(2, 1, sharex=True, sharey=True)
    for axes, placed, title in zip(panels, (before, after), _panel_titles(data), strict=True):
        _scatter(axes, data.frames, [p[:, [0, 2]] for p in placed], size=1.5)
        axes.set_title(title)
        axes.set_ylabel("z (m)")
        axes.grid(True, alpha=0.3)
    panels[1].set_xlabel("x (m)")
    # Limits from both maps: a badly tilted floor before calibration must stay in the picture.
    everything = np.concatenate([p[:, [0, 2]] for p in (*before, *after)] or [np.zeros((0, 2))])
    _limits(panels[1], everything, margin=0.2)
    panels[1].legend(loc="upper right", framealpha=0.9)
    figure.suptitle(
        "Side view: all points of every stop, z stretched. A mismatch shows the floor at several "
        "heights and tilts."
    )
    return figure


def _error_curve(data: ReportInput) -> Figure:
    figure = _figure(8, 4.5)
    axes = figure.subplots()
    errors = np.asarray(data.error_per_iteration, dtype=np.float64) * 1000
    if len(errors):
        axes.plot(np.arange(len(errors)), errors, marker="o", markersize=3, color=LIDAR_COLOURS[0])
        finite = errors[np.isfinite(errors) & (errors > 0)]
        if len(finite) and finite.max() / finite.min() > 20:
            from matplotlib.ticker import ScalarFormatter

            axes.set_yscale("log")
            axes.yaxis.set_major_formatter(ScalarFormatter())
        axes.annotate(
            f"{errors[-1]:.2f} mm",
            (len(errors) - 1, errors[-1]),
            textcoords="offset points",
            xytext=(-10, 10),
            ha="right",
        )
    else:
        axes.text(0.5, 0.5, "no iterations recorded", ha="center", transform=axes.transAxes)
    from matplotlib.ticker import MaxNLocator

    axes.xaxis.set_major_locator(MaxNLocator(integer=True))
    axes.set_xlabel("iteration")
    axes.set_ylabel("mean point distance to the reference map (mm)")
    axes.grid(True, alpha=0.3, which="both")
    state = (
        "" if data.converged is None else (", converged" if data.converged else ", not converged")
    )
    axes.set_title(
        f"Joint optimisation: error per iteration{state}\nmetric error "
        f"{_mm(data.metric_error_initial)} before, {_mm(data.metric_error_final)} after"
    )
    return figure


def _limits(axes: Axes, points: NDArray[np.float64], margin: float) -> None:
    """Axis limits holding 99 % of the points (a few far returns must not shrink the map)."""
    if len(points) < 10:
        return
    low = np.percentile(points, 0.5, axis=0) - margin
    high = np.percentile(points, 99.5, axis=0) + margin
    axes.set_xlim(float(low[0]), float(high[0]))
    axes.set_ylim(float(low[1]), float(high[1]))


def _mm(value: float) -> str:
    return "n/a" if not np.isfinite(value) else f"{value * 1000:.1f} mm"
