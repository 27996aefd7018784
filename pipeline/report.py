"""Report images of a calibration: the accumulated map from above and from the side, before and
after calibration, each LiDAR in its own colour, and the error per optimisation iteration (PNG).

Both maps are drawn in W, the base frame at the first stop: before with the odometry's stop poses
and the initial extrinsics, after with the refined poses and the calibrated extrinsics. The same
points enter both (the floor is hidden from above, where it would only cover the objects). The
view is where the robot was: around its path, as far as its LiDARs reach, so that a calibration
that diverged (points thrown tens of metres away) cannot shrink the robot's surroundings to a dot;
the after panel then says how many points fell outside.

What the images show is here; how they are drawn (a matplotlib figure laid out in pixels: frames,
ticks, labels, legends, pasted images, PNG) is `pipeline.report_canvas`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from pipeline.problem import CalibrationProblem
from pipeline.report_canvas import (
    FONT_PT,
    PX_PER_PT,
    Drawing,
    Extent,
    LegendKey,
    Panel,
    Tick,
    integer_ticks,
    log_ticks,
    rgb,
)
from pipeline.transforms import Matrix4, Points, invert

if TYPE_CHECKING:
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
        maps = []
        for row, T_row in zip(self.clouds, poses, strict=True):
            # Written in place, stop by stop: no temporaries per stop, no copy to join them.
            placed = np.empty((sum(len(c) for c in row), 3))
            start = 0
            for cloud, T in zip(row, T_row, strict=True):
                part = placed[start : start + len(cloud)]
                np.matmul(cloud, T[:3, :3].T, out=part)
                part += T[:3, 3]
                start += len(cloud)
            maps.append(placed)
        return maps


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
                # `take`: the rows `cloud[rows]` selects, a third of its time on these clouds.
                cloud = np.take(cloud, rng.choice(len(cloud), per_cloud, replace=False), axis=0)
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
    return {name: drawing.png() for name, drawing in drawings(data, names).items()}


def drawings(data: ReportInput, names: Sequence[str] = REPORT_IMAGES) -> dict[str, Drawing]:
    """The images of `render` before encoding, by name, in `REPORT_IMAGES` order."""
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


def load_renderer() -> None:
    """Import the matplotlib modules `render` draws with, once per process.

    They cost more CPU than drawing set 1's three images (about 0.4 s of import on an idle
    core, twice that on a loaded one). A process that renders many reports (the service's
    pool children, forked from a server that preloads the job module) calls this once up
    front instead of paying it inside its first run. Idempotent; `render` works without it.
    """
    import matplotlib.backends.backend_agg
    import matplotlib.collections
    import matplotlib.figure
    import matplotlib.lines
    import matplotlib.patches
    import matplotlib.ticker  # noqa: F401


@dataclass(frozen=True)
class _Maps:
    """Both maps' points in W (per LiDAR), the x, y of those that are objects (one
    classification, from the calibrated map, so both show the same points), the floor height,
    the robot's surroundings and the top view."""

    before: list[Points]
    after: list[Points]
    objects_before: list[NDArray[np.float64]]
    objects_after: list[NDArray[np.float64]]
    floor_z: float
    surroundings: Extent
    extent: Extent

    @classmethod
    def of(cls, data: ReportInput) -> _Maps:
        before, after = data.placed(after=False), data.placed(after=True)
        floor_z = floor_height(np.concatenate(after)) if any(len(p) for p in after) else 0.0
        objects = [p[:, 2] > floor_z + _OBJECT_MIN_HEIGHT_M for p in after]
        objects_before, objects_after = (
            [_rows(p[:, :2], mask) for p, mask in zip(placed, objects, strict=True)]
            for placed in (before, after)
        )
        window = robot_surroundings(data)
        extent = _map_extent(window, [*objects_before, *objects_after])
        return cls(before, after, objects_before, objects_after, floor_z, window, extent)


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


def _map_extent(window: Extent, objects_xy: Sequence[NDArray[np.float64]]) -> Extent:
    shown = [_rows(xy, _inside(xy, window)) for xy in objects_xy]
    x0, x1, y0, y1 = _top_extent(shown)
    return _square(max(x0, window[0]), min(x1, window[1]), max(y0, window[2]), min(y1, window[3]))


def points_outside(points: Sequence[Points], extent: Extent) -> tuple[float, float]:
    """The share of the (N, 3) `points` whose x, y fall outside `extent` (a box), and how far
    the farthest of them lies from it (m)."""
    total = sum(len(p) for p in points)
    if not total:
        return 0.0, 0.0
    # Distances of the points outside only: usually a few of hundreds of thousands (selected
    # from each array, not from a copy of them all).
    outside = np.concatenate([_rows(p[:, :2], ~_inside(p, extent)) for p in points if len(p)])
    if not len(outside):
        return 0.0, 0.0
    low = np.array([extent[0], extent[2]])
    high = np.array([extent[1], extent[3]])
    distance = np.linalg.norm(np.maximum(0.0, np.maximum(low - outside, outside - high)), axis=1)
    return len(outside) / total, float(distance.max())


def _inside(xy: NDArray[np.float64], extent: Extent) -> NDArray[np.bool_]:
    x0, x1, y0, y1 = extent
    inside: NDArray[np.bool_] = (
        (xy[:, 0] >= x0) & (xy[:, 0] <= x1) & (xy[:, 1] >= y0) & (xy[:, 1] <= y1)
    )
    return inside


def _rows(array: NDArray[np.float64], mask: NDArray[np.bool_]) -> NDArray[np.float64]:
    """The rows of a 2-D `array` where `mask` holds: `array[mask]`, in half its time on these
    hundreds of thousands of points (`np.compress`)."""
    return np.compress(mask, array, axis=0)


def floor_height(points: Points, bin_m: float = 0.01) -> float:
    """The most populated height (m) of (N, 3) points in a frame whose z is up: the floor."""
    z = points[:, 2]
    low, high = np.percentile(z, [0.5, 99.5])
    bins = max(1, int(np.ceil((high - low) / bin_m)))
    counts, edges = np.histogram(z, bins=bins, range=(low, high + 1e-9))
    k = int(np.argmax(counts))
    return float((edges[k] + edges[k + 1]) / 2)


# -- the images ------------------------------------------------------------------------------------


def _lidar_keys(frames: Sequence[str]) -> list[LegendKey]:
    keys = [
        LegendKey(frame + (" (reference)" if i == 0 else ""), lidar_colour(i))
        for i, frame in enumerate(frames)
    ]
    if len(frames) > 1:
        both = np.prod([rgb(lidar_colour(i)) for i in range(len(frames))], axis=0)
        keys.append(LegendKey("LiDARs overlapping", _hex(both)))
    return keys


def _hex(channels: NDArray[np.float64]) -> str:
    return "#" + "".join(f"{round(float(c) * 255):02x}" for c in channels)


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
        # What a pixel of each count lets through, looked up: the same values as computing it
        # per pixel, for a few thousand counts instead of every pixel (most of them empty).
        alpha = np.clip(np.log1p(np.arange(int(occupied.max()) + 1)) / full, 0.0, 1.0)
        ink = 1.0 - np.asarray(rgb(lidar_colour(i)))
        # `take`: `table[counts]`, in a third of its time.
        image *= np.take(1.0 - alpha[:, None] * ink, counts, axis=0)
    return image


def grid_counts(
    points: NDArray[np.float64], extent: Extent, cols: int, rows: int
) -> NDArray[np.int64]:
    """(cols, rows) how many of the (N, 2) points fall in each cell of `extent` cut into
    `cols` x `rows` equal cells (points on the far edges count in the last cells, points
    outside in none): `np.histogram2d`'s counts, by one `bincount` instead of its sorted
    search, which took most of the report's numpy time on a million points. The cell numbers
    stay floats (whole numbers) until the points inside are chosen: fewer passes over them."""
    x0, x1, y0, y1 = extent
    ix = _cell_numbers(points[:, 0], x0, x1, cols)
    iy = _cell_numbers(points[:, 1], y0, y1, rows)
    inside = (ix >= 0) & (ix < cols) & (iy >= 0) & (iy < rows)
    ix *= rows
    ix += iy  # the cell's number in the (cols, rows) grid, row-major
    cells = np.bincount(np.compress(inside, ix).astype(np.int64), minlength=cols * rows)
    return cells.reshape(cols, rows)


def _cell_numbers(
    values: NDArray[np.float64], low: float, high: float, count: int
) -> NDArray[np.float64]:
    """Which of `count` equal cells of [`low`, `high`] each value falls in, as a float: whole
    numbers, `high` in the last cell, values outside below 0 or from `count` up (NaN for NaN)."""
    cells = values - low
    cells *= count / (high - low)
    np.floor(cells, out=cells)
    cells[values == high] = count - 1
    return cells


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


def _outside_note(
    drawing: Drawing, panel: Panel, placed: Sequence[Points], surroundings: Extent
) -> None:
    """Say so when more points than the LiDARs' stray far returns (1 %) lie beyond the robot's
    surroundings: the poses threw them there, and the view does not follow them."""
    share, farthest = points_outside(placed, surroundings)
    if share > 0.01:
        drawing.text(
            panel.left + 0.02 * panel.width,
            panel.bottom + 0.02 * panel.height,
            f"{share:.0%} of the points lie beyond the robot's surroundings, up to "
            f"{farthest:.0f} m: not in this view",
            color=_WARNING_COLOUR,
            bbox={"facecolor": "white", "alpha": 0.85, "edgecolor": _WARNING_COLOUR},
            gid=OUTSIDE_NOTE,
            zorder=6,
        )


OUTSIDE_NOTE = "outside-note"
"""The `gid` of a map panel's note on the points out of view."""


def _top_view(data: ReportInput, maps: _Maps) -> Drawing:
    # Two square panels side by side under the titles, as tall as the image allows.
    drawing = Drawing(1400, 780)
    size, bottom = 616, 55
    extent = maps.extent
    # Cells of 2 cm at least (the segmentation's voxel): sparse clouds still show surfaces.
    cells = int(min(_TOP_PIXELS, (extent[1] - extent[0]) / _MIN_CELL_M))
    for left, layers, placed, title in zip(
        (80, 1386 - size),
        (maps.objects_before, maps.objects_after),
        (maps.before, maps.after),
        _panel_titles(data),
        strict=True,
    ):
        first = left == 80
        panel = drawing.panel(
            (left, bottom, size, size),
            extent,
            xlabel="x (m)",
            ylabel="y (m)" if first else None,
            ytick_labels=first,
        )
        drawing.paste(panel, _density_image(layers, extent, cells, cells))
        _outside_note(drawing, panel, placed, maps.surroundings)
        drawing.title(panel, title)
    drawing.legend(drawing.panels[1], _lidar_keys(data.frames))
    drawing.suptitle(
        "Top view: points above the floor from every stop, in the base frame of the first stop\n"
        "A mismatch shows each object twice, once per colour; agreement darkens them together"
    )
    return drawing


def _side_view(data: ReportInput, maps: _Maps) -> Drawing:
    # Two wide panels, before above after.
    drawing = Drawing(1400, 640)
    left, width, height = 70, 1316, 210
    x0, x1, _, _ = maps.extent
    floor_z = maps.floor_z
    # Heights of both maps' points in the top view's box: a tilted failed map must not
    # stretch the panel either.
    # x and z of every point: views (every other column), copied only where selected.
    xz_before, xz_after = [p[:, ::2] for p in maps.before], [p[:, ::2] for p in maps.after]
    inside = [
        _rows(xz, _inside(p, maps.extent))
        for xz, p in zip((*xz_before, *xz_after), (*maps.before, *maps.after), strict=True)
    ]
    heights = np.concatenate([xz for xz in inside if len(xz)] or [np.zeros((0, 2))])
    top = _dense_extent(
        heights, cell_m=0.05, margin_m=0.15, fallback=(x0, x1, floor_z, floor_z + 1)
    )[3]
    extent = (x0, x1, floor_z - 0.35, max(top, floor_z + 0.5))
    cols = int(min(_SIDE_COLS, (x1 - x0) / _MIN_CELL_M))
    # Heights are stretched on screen: finer cells in z keep the floor a thin line.
    rows = int(min(_SIDE_ROWS, (extent[3] - extent[2]) / (_MIN_CELL_M / 2)))
    for bottom, placed, title in zip(
        (321, 58), (xz_before, xz_after), _panel_titles(data), strict=True
    ):
        after = bottom == 58
        panel = drawing.panel(
            (left, bottom, width, height),
            extent,
            xlabel="x (m)" if after else None,
            ylabel="z (m)",
            xtick_labels=after,
        )
        drawing.paste(panel, _density_image(placed, extent, cols, rows))
        drawing.title(panel, title)
    drawing.legend(drawing.panels[1], _lidar_keys(data.frames))
    drawing.suptitle(
        "Side view: all points of every stop, height stretched\n"
        "A mismatch shows the floor and the objects at several heights and tilts"
    )
    return drawing


def convergence_note(data: ReportInput) -> str | None:
    """Why the error curve's last value is not the reported metric error (None when both read
    the same). They measure different things: the curve is stage 4's own error (eq. 11), the
    reported metric error eq. 12 (`pipeline.metric`)."""
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


def _error_curve(data: ReportInput) -> Drawing:
    import textwrap

    from matplotlib.lines import Line2D

    note = convergence_note(data)
    label = "iteration" + ("\n" + textwrap.fill(note, 90) if note else "")
    # Room below the panel for the x label's lines (about 0.18 in each at 10 pt, of 4.8 in).
    width, height = 800, 480
    bottom = round(height * (0.07 + 0.038 * (label.count("\n") + 1) + 0.03))
    box = (80, bottom, 776 - 80, round(0.87 * height) - bottom)
    drawing = Drawing(width, height)
    errors = np.asarray(data.error_per_iteration, dtype=np.float64) * 1000
    final_mm = data.metric_error_final * 1000
    values = np.concatenate([errors, [final_mm]])
    values = values[np.isfinite(values)]
    log = bool(len(values[values > 0])) and _spans(values[values > 0]) > 20
    if log:
        # A log axis: its positions are log10 of the millimetres, its ticks at 1, 2 and 5 x 10^k.
        with np.errstate(divide="ignore", invalid="ignore"):
            axis = np.where(errors > 0, np.log10(errors), np.nan)
            final_axis = np.log10(final_mm) if final_mm > 0 else np.nan
        low, high = _with_margins(np.log10(values[values > 0]))
        yticks: list[Tick] | None = log_ticks(low, high)
    else:
        axis, final_axis = errors, final_mm
        low, high = _with_margins(values) if len(values) else (0.0, 1.0)
        yticks = None
    n = len(errors)
    x0, x1 = _with_margins(np.arange(n, dtype=np.float64)) if n else (0.0, 1.0)
    xticks = integer_ticks(x0, x1, box[2] / PX_PER_PT / (3 * FONT_PT))
    panel = drawing.panel(
        box,
        (x0, x1, low, high),
        xlabel=label,
        ylabel="mean point distance to the reference map (mm)",
        ylabel_pt=9,
        xticks=xticks,
        yticks=yticks,
        grid_alpha=0.3,
    )
    if n:
        keys = [LegendKey("optimiser's error (eq. 11)", LIDAR_COLOURS[0], "-", "o")]
        xs, ys = panel.pixels(np.arange(n, dtype=np.float64), axis)
        drawing.add(
            Line2D(xs, ys, marker="o", markersize=3, color=LIDAR_COLOURS[0], label=keys[0].label)
        )
        if np.isfinite(final_axis):
            keys.append(
                LegendKey(
                    f"reported metric error (eq. 12): {_mm(data.metric_error_final)}",
                    LIDAR_COLOURS[1],
                    "--",
                )
            )
            _, y = panel.point(x0, final_axis)
            drawing.add(
                Line2D(
                    [panel.left, panel.right],
                    [y, y],
                    color=LIDAR_COLOURS[1],
                    linestyle="--",
                    linewidth=1.2,
                    label=keys[1].label,
                )
            )
        if np.isfinite(ys[-1]):
            # 10 pt to the upper left of the last point, as an annotation offset in points.
            offset = 10 * PX_PER_PT
            drawing.text(
                xs[-1] - offset,
                ys[-1] + offset,
                _mm(data.error_per_iteration[-1]),
                ha="right",
                gid=LAST_ERROR,
            )
        drawing.legend(panel, keys)
    else:
        drawing.text(
            (panel.left + panel.right) / 2,
            (panel.bottom + panel.top) / 2,
            "no iterations recorded",
            ha="center",
        )
    state = (
        "" if data.converged is None else (", converged" if data.converged else ", not converged")
    )
    drawing.title(
        panel,
        f"Joint optimisation: error per iteration{state}\nmetric error "
        f"{_mm(data.metric_error_initial)} before, {_mm(data.metric_error_final)} after",
    )
    return drawing


LAST_ERROR = "last-error"
"""The `gid` of the error curve's label of its last value."""


def _spans(positive: NDArray[np.float64]) -> float:
    return float(positive.max() / positive.min())


def _with_margins(values: NDArray[np.float64], margin: float = 0.05) -> tuple[float, float]:
    """The range of `values` grown by `margin` of it on each side (matplotlib's autoscale); one
    unit on each side of a single value (or 5 % of it)."""
    low, high = float(values.min()), float(values.max())
    if high == low:
        grow = 0.05 * abs(low) or 1.0
        return low - grow, high + grow
    grow = margin * (high - low)
    return low - grow, high + grow


def _mm(value: float) -> str:
    """Millimetres: two decimals below 10 mm, one above."""
    if not np.isfinite(value):
        return "n/a"
    size = abs(value) * 1000
    return f"{value * 1000:.{2 if size < 10 else 1}f} mm"
