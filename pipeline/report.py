"""Report images of a calibration: the accumulated map from above and from the side, before and
after calibration, each LiDAR in its own colour, and the error per optimisation iteration (PNG).

Both maps are drawn in W, the base frame at the first stop: before with the odometry's stop poses
and the initial extrinsics, after with the refined poses and the calibrated extrinsics. The same
points enter both (the floor is hidden from above, where it would only cover the objects). The
view is where the robot was: around its path, as far as its LiDARs reach, so that a calibration
that diverged (points thrown tens of metres away) cannot shrink the robot's surroundings to a dot;
the after panel then says how many points fell outside.
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
# Density pixels per panel: about one per screen pixel of the 14-inch-wide figures at 100 dpi.
_TOP_PIXELS = 560
_SIDE_COLS, _SIDE_ROWS = 1200, 220
_MIN_CELL_M = 0.02
_WARNING_COLOUR = "#B23A00"


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
    passed: bool | None = None,
    max_points: int = 400_000,
    seed: int = 0,
) -> ReportInput:
    """The images' data for `result`, calibrated from `problem`; at most about `max_points`
    points in each map (a random subset of each stop cloud, the same one before and after).
    `passed`: the run's final verdict when checks beyond the pipeline's (drift) decide it."""
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
        passed=result.passed if passed is None else passed,
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


def render_report(
    problem: CalibrationProblem, result: CalibrationResult, *, passed: bool | None = None
) -> dict[str, bytes]:
    """The PNG images of `REPORT_IMAGES` for a calibration of `problem`, by name (`passed`: the
    run's final verdict, if not the pipeline's)."""
    return render(report_input(problem, result, passed=passed))


def render(data: ReportInput, names: Sequence[str] = REPORT_IMAGES) -> dict[str, bytes]:
    """The PNG images `names` (of `REPORT_IMAGES`) for `data`, by name."""
    return {name: _png(figure) for name, figure in figures(data, names).items()}


def figures(data: ReportInput, names: Sequence[str] = REPORT_IMAGES) -> dict[str, Figure]:
    """The matplotlib figures of `render`, by name, in `REPORT_IMAGES` order."""
    unknown = sorted(set(names) - set(REPORT_IMAGES))
    if unknown:
        raise ValueError(f"no report image {unknown}; the images are {list(REPORT_IMAGES)}")
    maps = _Maps.of(data)
    make = {
        "map-top": lambda: _top_view(data, maps),
        "map-side": lambda: _side_view(data, maps),
        "error": lambda: _error_curve(data),
    }
    return {name: make[name]() for name in REPORT_IMAGES if name in names}


@dataclass(frozen=True)
class _Maps:
    """Both maps' points in W (per LiDAR), which of them are objects (one classification, from
    the calibrated map, so both show the same points), the floor height, the robot's
    surroundings and the top view."""

    before: list[Points]
    after: list[Points]
    objects: list[NDArray[np.bool_]]
    floor_z: float
    surroundings: Extent
    extent: Extent

    @classmethod
    def of(cls, data: ReportInput) -> _Maps:
        before, after = data.placed(after=False), data.placed(after=True)
        floor_z = floor_height(np.concatenate(after)) if any(len(p) for p in after) else 0.0
        objects = [p[:, 2] > floor_z + _OBJECT_MIN_HEIGHT_M for p in after]
        window = robot_surroundings(data)
        extent = _map_extent(window, before, after, objects)
        return cls(before, after, objects, floor_z, window, extent)


def robot_surroundings(data: ReportInput) -> Extent:
    """Where the maps can hold anything real: the box around the robot's path (each LiDAR's
    origin at each stop, placed by the odometry and the initial extrinsics, never far off) grown
    by the LiDARs' reach (the 99th percentile of the points' range in their own frames, which no
    pose can change)."""
    origins = data.T_W_lidar_before[:, :, :2, 3].reshape(-1, 2)
    ranges = [np.linalg.norm(cloud, axis=1) for row in data.clouds for cloud in row if len(cloud)]
    reach = float(np.percentile(np.concatenate(ranges), 99)) if ranges else 5.0
    low, high = origins.min(axis=0) - reach, origins.max(axis=0) + reach
    return (float(low[0]), float(high[0]), float(low[1]), float(high[1]))


def map_extent(data: ReportInput) -> Extent:
    """The top view's square (x0, x1, y0, y1), metres in W: around the dense objects of both
    maps within `robot_surroundings`. Points a failed calibration threw further away are left
    out, not allowed to widen the view (the panel counts those outside the surroundings)."""
    return _Maps.of(data).extent


def _map_extent(
    window: Extent,
    before: list[Points],
    after: list[Points],
    objects: list[NDArray[np.bool_]],
) -> Extent:
    shown = [
        placed[mask, :2][_inside(placed[mask, :2], window)]
        for maps in (before, after)
        for placed, mask in zip(maps, objects, strict=True)
    ]
    x0, x1, y0, y1 = _top_extent(shown)
    return _square(max(x0, window[0]), min(x1, window[1]), max(y0, window[2]), min(y1, window[3]))


def points_outside(points: Sequence[Points], extent: Extent) -> tuple[float, float]:
    """The share of the (N, 3) `points` whose x, y fall outside `extent` (a box), and how far
    the farthest of them lies from it (m)."""
    xy = np.concatenate([p[:, :2] for p in points if len(p)] or [np.zeros((0, 2))])
    if not len(xy):
        return 0.0, 0.0
    # Distances of the points outside only: usually a few of hundreds of thousands.
    outside = xy[~_inside(xy, extent)]
    if not len(outside):
        return 0.0, 0.0
    low = np.array([extent[0], extent[2]])
    high = np.array([extent[1], extent[3]])
    distance = np.linalg.norm(np.maximum(0.0, np.maximum(low - outside, outside - high)), axis=1)
    return len(outside) / len(xy), float(distance.max())


def _inside(xy: NDArray[np.float64], extent: Extent) -> NDArray[np.bool_]:
    x0, x1, y0, y1 = extent
    inside: NDArray[np.bool_] = (
        (xy[:, 0] >= x0) & (xy[:, 0] <= x1) & (xy[:, 1] >= y0) & (xy[:, 1] <= y1)
    )
    return inside


def floor_height(points: Points, bin_m: float = 0.01) -> float:
    """The most populated height (m) of (N, 3) points in a frame whose z is up: the floor."""
    z = points[:, 2]
    low, high = np.percentile(z, [0.5, 99.5])
    bins = max(1, int(np.ceil((high - low) / bin_m)))
    counts, edges = np.histogram(z, bins=bins, range=(low, high + 1e-9))
    k = int(np.argmax(counts))
    return float((edges[k] + edges[k + 1]) / 2)


# -- figures ---------------------------------------------------------------------------------------


def load_renderer() -> None:
    """Import matplotlib's figure and Agg modules, once per process.

    They cost more CPU than drawing set 1's three images (about 0.4 s of import on an idle
    core, twice that on a loaded one). A process that renders many reports (the service's
    pool children, forked from a server that preloads the job module) calls this once up
    front instead of paying it inside its first run. Idempotent; `render` works without it.
    """
    import matplotlib.backends.backend_agg
    import matplotlib.figure
    import matplotlib.patches
    import matplotlib.ticker  # noqa: F401


def _figure(width_in: float, height_in: float, **margins: float) -> Figure:
    """A figure whose panels sit within fixed `margins` (`Figure.subplots_adjust`'s fractions).

    Fixed, not "constrained": the constrained layout measured every tick label of every panel
    and took most of the drawing time (about 1 s of 1.5 s for set 1's three images)."""
    from matplotlib.figure import Figure

    # No pyplot: no global figure registry, safe in worker threads and processes.
    figure = Figure(figsize=(width_in, height_in), dpi=_DPI)
    figure.subplots_adjust(**margins)
    return figure


def _png(figure: Figure) -> bytes:
    buffer = io.BytesIO()
    # zlib level 1: these images are mostly flat colour, and level 6 (the default) spent a third
    # of the drawing time compressing them for a few per cent of size.
    figure.savefig(buffer, format="png", pil_kwargs={"compress_level": 1})
    return buffer.getvalue()


Extent = tuple[float, float, float, float]
"""(x0, x1, y0, y1) of a panel, metres."""


def _density_image(
    layers: Sequence[NDArray[np.float64]], extent: Extent, cols: int, rows: int
) -> NDArray[np.float64]:
    """(rows, cols, 3) RGB in [0, 1]: each LiDAR's (N, 2) points as a density in its colour.

    Opacity grows with the log of the points per pixel, so dense surfaces show strongly and
    stray points faintly. LiDARs mix like inks (multiplied), order-free: where they agree the
    colours darken together; where they disagree each stands apart in its own colour.
    """
    image = np.ones((rows, cols, 3))
    for i, points in enumerate(layers):
        if not len(points):
            continue
        counts = grid_counts(points, extent, cols, rows).T
        occupied = counts[counts > 0]
        if not len(occupied):
            continue
        # Relative to the well-filled pixels: a lone point is faint in a dense map, and still
        # visible in a sparse one.
        full = np.log1p(max(float(np.percentile(occupied, 95)), 2.0))
        alpha = np.clip(np.log1p(counts) / full, 0.0, 1.0)
        ink = 1.0 - np.asarray(_rgb(lidar_colour(i)))
        image *= 1.0 - alpha[..., None] * ink
    return image


def grid_counts(
    points: NDArray[np.float64], extent: Extent, cols: int, rows: int
) -> NDArray[np.int64]:
    """(cols, rows) how many of the (N, 2) points fall in each cell of `extent` cut into
    `cols` x `rows` equal cells (points on the far edges count in the last cells, points
    outside in none): `np.histogram2d`'s counts, by one `bincount` instead of its sorted
    search, which took most of the report's numpy time on a million points."""
    x0, x1, y0, y1 = extent
    ix = np.floor((points[:, 0] - x0) * (cols / (x1 - x0))).astype(np.int64)
    iy = np.floor((points[:, 1] - y0) * (rows / (y1 - y0))).astype(np.int64)
    ix[points[:, 0] == x1] = cols - 1
    iy[points[:, 1] == y1] = rows - 1
    inside = (ix >= 0) & (ix < cols) & (iy >= 0) & (iy < rows)
    cells = np.bincount(ix[inside] * rows + iy[inside], minlength=cols * rows)
    return cells.reshape(cols, rows)


def _rgb(colour: str) -> tuple[float, float, float]:
    return (
        int(colour[1:3], 16) / 255,
        int(colour[3:5], 16) / 255,
        int(colour[5:7], 16) / 255,
    )


def _draw(
    axes: Axes, layers: Sequence[NDArray[np.float64]], extent: Extent, cols: int, rows: int
) -> None:
    axes.imshow(
        _density_image(layers, extent, cols, rows),
        extent=extent,
        origin="lower",
        interpolation="nearest",
        aspect="auto",
    )
    axes.set_xlim(extent[0], extent[1])
    axes.set_ylim(extent[2], extent[3])


def _legend(axes: Axes, frames: Sequence[str]) -> None:
    from matplotlib.patches import Patch

    handles = [
        Patch(color=lidar_colour(i), label=frame + (" (reference)" if i == 0 else ""))
        for i, frame in enumerate(frames)
    ]
    if len(frames) > 1:
        both = np.prod([_rgb(lidar_colour(i)) for i in range(len(frames))], axis=0)
        handles.append(Patch(color=tuple(both), label="LiDARs overlapping"))
    axes.legend(handles=handles, loc="upper right", framealpha=0.9)


def _dense_extent(
    points: NDArray[np.float64], cell_m: float, margin_m: float, fallback: Extent
) -> Extent:
    """The box around where (N, 2) points are dense (cells holding at least 2 % of the fullest
    cell), plus a margin: stray far returns must not shrink the structure to a dot."""
    if len(points) < 10:
        return fallback
    low, high = np.percentile(points, [0.1, 99.9], axis=0)  # one partition for both
    bins = np.maximum(1, np.ceil((high - low) / cell_m)).astype(int)
    cols, rows = int(bins[0]), int(bins[1])
    box = (float(low[0]), float(high[0]), float(low[1]), float(high[1]))
    counts = grid_counts(points, box, cols, rows)
    xs, ys = np.linspace(box[0], box[1], cols + 1), np.linspace(box[2], box[3], rows + 1)
    ix, iy = np.nonzero(counts >= max(2.0, 0.02 * counts.max()))
    if not len(ix):
        return fallback
    return (
        float(xs[ix.min()]) - margin_m,
        float(xs[ix.max() + 1]) + margin_m,
        float(ys[iy.min()]) - margin_m,
        float(ys[iy.max() + 1]) + margin_m,
    )


def _panel_titles(data: ReportInput) -> tuple[str, str]:
    return (
        f"Before calibration: metric error {_mm(data.metric_error_initial)}",
        f"After calibration: metric error {_mm(data.metric_error_final)}"
        + ("" if data.passed is None else (", PASSED" if data.passed else ", FAILED")),
    )


def _top_extent(objects_xy: Sequence[NDArray[np.float64]]) -> Extent:
    """The box around where (N, 2) object points are dense."""
    points = np.concatenate([p for p in objects_xy if len(p)] or [np.zeros((0, 2))])
    return _dense_extent(points, cell_m=0.1, margin_m=0.5, fallback=(-5, 5, -5, 5))


def _square(x0: float, x1: float, y0: float, y1: float) -> Extent:
    half = max(x1 - x0, y1 - y0) / 2
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    return (cx - half, cx + half, cy - half, cy + half)


def _outside_note(axes: Axes, placed: Sequence[Points], surroundings: Extent) -> None:
    """Say so when more points than the LiDARs' stray far returns (1 %) lie beyond the robot's
    surroundings: the poses threw them there, and the view does not follow them."""
    share, farthest = points_outside(placed, surroundings)
    if share > 0.01:
        axes.text(
            0.02,
            0.02,
            f"{share:.0%} of the points lie beyond the robot's surroundings, up to "
            f"{farthest:.0f} m: not in this view",
            transform=axes.transAxes,
            fontsize=10,
            color=_WARNING_COLOUR,
            bbox={"facecolor": "white", "alpha": 0.85, "edgecolor": _WARNING_COLOUR},
        )


def _top_view(data: ReportInput, maps: _Maps) -> Figure:
    figure = _figure(14, 7.8, left=0.05, right=0.99, bottom=0.07, top=0.86, wspace=0.06)
    panels = figure.subplots(1, 2, sharex=True, sharey=True)
    shown_after = [p[m, :2] for p, m in zip(maps.after, maps.objects, strict=True)]
    shown_before = [p[m, :2] for p, m in zip(maps.before, maps.objects, strict=True)]
    extent = maps.extent
    # Cells of 2 cm at least (the segmentation's voxel): sparse clouds still show surfaces.
    cells = int(min(_TOP_PIXELS, (extent[1] - extent[0]) / _MIN_CELL_M))
    for axes, layers, placed, title in zip(
        panels,
        (shown_before, shown_after),
        (maps.before, maps.after),
        _panel_titles(data),
        strict=True,
    ):
        _draw(axes, layers, extent, cols=cells, rows=cells)
        _outside_note(axes, placed, maps.surroundings)
        axes.set_title(title, y=1.0)
        axes.set_aspect("equal", adjustable="box")
        axes.set_xlabel("x (m)")
        axes.grid(True, alpha=0.25)
    panels[0].set_ylabel("y (m)")
    _legend(panels[1], data.frames)
    figure.suptitle(
        "Top view: points above the floor from every stop, in the base frame of the first stop\n"
        "A mismatch shows each object twice, once per colour; agreement darkens them together"
    )
    return figure


def _side_view(data: ReportInput, maps: _Maps) -> Figure:
    figure = _figure(14, 6.4, left=0.05, right=0.99, bottom=0.09, top=0.83, hspace=0.25)
    panels = figure.subplots(2, 1, sharex=True, sharey=True)
    x0, x1, _, _ = maps.extent
    floor_z = maps.floor_z
    # Heights of both maps' points in the top view's box: a tilted failed map must not
    # stretch the panel either.
    inside = [p[_inside(p[:, :2], maps.extent)] for p in (*maps.before, *maps.after)]
    heights = np.concatenate([p[:, [0, 2]] for p in inside if len(p)] or [np.zeros((0, 2))])
    top = _dense_extent(
        heights, cell_m=0.05, margin_m=0.15, fallback=(x0, x1, floor_z, floor_z + 1)
    )[3]
    extent = (x0, x1, floor_z - 0.35, max(top, floor_z + 0.5))
    cols = int(min(_SIDE_COLS, (x1 - x0) / _MIN_CELL_M))
    # Heights are stretched on screen: finer cells in z keep the floor a thin line.
    rows = int(min(_SIDE_ROWS, (extent[3] - extent[2]) / (_MIN_CELL_M / 2)))
    for axes, placed, title in zip(
        panels, (maps.before, maps.after), _panel_titles(data), strict=True
    ):
        _draw(axes, [p[:, [0, 2]] for p in placed], extent, cols=cols, rows=rows)
        axes.set_title(title, y=1.0)
        axes.set_ylabel("z (m)")
        axes.grid(True, alpha=0.25)
    panels[1].set_xlabel("x (m)")
    _legend(panels[1], data.frames)
    figure.suptitle(
        "Side view: all points of every stop, height stretched\n"
        "A mismatch shows the floor and the objects at several heights and tilts"
    )
    return figure


def convergence_note(data: ReportInput) -> str | None:
    """Why the error curve's last value is not the reported metric error (None when both read
    the same). They measure different things: the curve is stage 4's own error (eq. 11), the
    metric the verdict judges is eq. 12 (`pipeline.metric`)."""
    if not data.error_per_iteration:
        return None
    last, final = _mm(data.error_per_iteration[-1]), _mm(data.metric_error_final)
    if last == final:
        return None
    if not np.isfinite(data.metric_error_final):
        return (
            f"The curve ends at {last}; no metric error was measured (no object points of a "
            "LiDAR other than the reference to compare)."
        )
    return (
        f"The curve ends at {last}, the reported metric error is {final}: the curve is the "
        "optimiser's own error (eq. 11: every nearest-neighbour distance as it is, on the points "
        "it optimises), the metric (eq. 12) caps each distance and takes every object point."
    )


def _error_curve(data: ReportInput) -> Figure:
    import textwrap

    from matplotlib.ticker import MaxNLocator, ScalarFormatter

    note = convergence_note(data)
    label = "iteration" + ("\n" + textwrap.fill(note, 90) if note else "")
    # Room below the axes for the x label's lines (about 0.18 in each at 10 pt, of 4.8 in).
    bottom = 0.07 + 0.038 * (label.count("\n") + 1) + 0.03
    figure = _figure(8, 4.8, left=0.1, right=0.97, bottom=bottom, top=0.87)
    axes = figure.subplots()
    errors = np.asarray(data.error_per_iteration, dtype=np.float64) * 1000
    final_mm = data.metric_error_final * 1000
    if len(errors):
        axes.plot(
            np.arange(len(errors)),
            errors,
            marker="o",
            markersize=3,
            color=LIDAR_COLOURS[0],
            label="optimiser's error (eq. 11)",
        )
        if np.isfinite(final_mm):
            axes.axhline(
                final_mm,
                color=LIDAR_COLOURS[1],
                linestyle="--",
                linewidth=1.2,
                label=f"reported metric error (eq. 12): {_mm(data.metric_error_final)}",
            )
        finite = np.concatenate([errors, [final_mm]])
        finite = finite[np.isfinite(finite) & (finite > 0)]
        if len(finite) and finite.max() / finite.min() > 20:
            axes.set_yscale("log")
            axes.yaxis.set_major_formatter(ScalarFormatter())
        axes.annotate(
            _mm(data.error_per_iteration[-1]),
            (len(errors) - 1, errors[-1]),
            textcoords="offset points",
            xytext=(-10, 10),
            ha="right",
        )
        axes.legend(loc="upper right", framealpha=0.9)
    else:
        axes.text(0.5, 0.5, "no iterations recorded", ha="center", transform=axes.transAxes)
    axes.xaxis.set_major_locator(MaxNLocator(integer=True))
    axes.set_xlabel(label)
    axes.set_ylabel("mean point distance to the reference map (mm)", fontsize=9)
    axes.grid(True, alpha=0.3, which="both")
    state = (
        "" if data.converged is None else (", converged" if data.converged else ", not converged")
    )
    axes.set_title(
        f"Joint optimisation: error per iteration{state}\nmetric error "
        f"{_mm(data.metric_error_initial)} before, {_mm(data.metric_error_final)} after",
        y=1.0,
    )
    return figure


def _mm(value: float) -> str:
    """Millimetres: two decimals below 10 mm, one above."""
    if not np.isfinite(value):
        return "n/a"
    size = abs(value) * 1000
    return f"{value * 1000:.{2 if size < 10 else 1}f} mm"
