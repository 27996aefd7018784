"""Report images: the maps are placed with the right poses (the truth makes the LiDARs agree, the
initial extrinsics do not), the adapter reads a calibration result consistently, and the PNGs show
each LiDAR in its own colour in both panels."""

from __future__ import annotations

import io
import os
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from pykdtree.kdtree import KDTree

from pipeline.calibrate import calibrate
from pipeline.config import config_from_mapping
from pipeline.problem import CalibrationProblem
from pipeline.report import (
    LAST_ERROR,
    OUTSIDE_NOTE,
    REPORT_IMAGES,
    ReportInput,
    convergence_note,
    drawings,
    floor_height,
    grid_counts,
    lidar_colour,
    map_extent,
    map_poses,
    points_outside,
    render,
    report_input,
    robot_surroundings,
)
from pipeline.synth import Truth, simulate_problem
from pipeline.transforms import from_xyz_rpy, invert


@pytest.fixture(scope="module")
def tiny() -> tuple[CalibrationProblem, Truth]:
    return simulate_problem("tiny", seed=0)


def truth_report_input(problem: CalibrationProblem, truth: Truth) -> ReportInput:
    """Before: the odometry and tf_static as recorded; after: the synthesiser's truth."""
    frames = problem.frames
    return ReportInput(
        frames=frames,
        clouds=tuple(tuple(stop.clouds[f] for stop in problem.stops) for f in frames),
        T_W_lidar_before=map_poses(
            np.stack([stop.T_odom_base for stop in problem.stops]),
            [problem.lidar(f).T_base_lidar for f in frames],
        ),
        T_W_lidar_after=map_poses(
            np.stack([stop.T_odom_base_true for stop in truth.stops]),
            [truth.lidar(f).T_base_lidar_true for f in frames],
        ),
        error_per_iteration=(0.091, 0.043, 0.012, 0.0031, 0.0016, 0.0015),
        metric_error_initial=0.0912,
        metric_error_final=0.0015,
        passed=True,
        converged=True,
    )


@pytest.fixture(scope="module")
def truth_input(tiny: tuple[CalibrationProblem, Truth]) -> ReportInput:
    return truth_report_input(*tiny)


def object_distance_to_reference(data: ReportInput, after: bool) -> float:
    """Median distance of the other LiDAR's object points to the reference's map, in metres."""
    placed = data.placed(after=after)
    floor = floor_height(np.concatenate(data.placed(after=True)))
    objects = [p[p[:, 2] > floor + 0.05] for p in placed]
    distance, _ = KDTree(objects[0]).query(objects[1], k=1)
    return float(np.median(distance))


def test_the_true_poses_make_the_lidars_agree_and_the_initial_ones_do_not(
    truth_input: ReportInput,
) -> None:
    # After: about the point spacing of these sparse clouds (15 mm); before: a quarter metre.
    assert object_distance_to_reference(truth_input, after=True) < 0.03
    assert object_distance_to_reference(truth_input, after=False) > 0.1


def test_the_map_frame_is_the_base_at_the_first_stop(
    tiny: tuple[CalibrationProblem, Truth], truth_input: ReportInput
) -> None:
    problem, _ = tiny
    for i, frame in enumerate(truth_input.frames):
        np.testing.assert_allclose(
            truth_input.T_W_lidar_before[i, 0], problem.lidar(frame).T_base_lidar, atol=1e-12
        )
    # The floor (z = 0 in the synthesiser's base_link) is where the truth puts it.
    assert abs(floor_height(np.concatenate(truth_input.placed(after=True)))) < 0.01


def test_the_adapter_places_the_result_consistently(
    tiny: tuple[CalibrationProblem, Truth],
) -> None:
    """Whatever the calibration found: within each stop the LiDARs sit at the calibrated
    extrinsics, and the reference moves between stops as the optimisation says."""
    problem, _ = tiny
    config = config_from_mapping(
        {"optimisation": {"max_iterations": 3}, "denoise": {"enabled": False}}
    )
    result = calibrate(problem, config)
    data = report_input(problem, result, max_points=4000)

    assert data.frames == tuple(lidar.frame for lidar in result.lidars)
    assert data.error_per_iteration == tuple(result.error_per_iteration)
    T_base_ref = result.lidars[0].T_base_lidar_calibrated
    after = data.T_W_lidar_after
    np.testing.assert_allclose(after[0, 0], T_base_ref, atol=1e-9)
    T_G_ref = result.optimisation.T_G_ref
    for j in range(len(problem.stops)):
        for i, lidar in enumerate(result.lidars):
            np.testing.assert_allclose(
                invert(after[0, j]) @ after[i, j],
                invert(T_base_ref) @ lidar.T_base_lidar_calibrated,
                atol=1e-9,
            )
            np.testing.assert_allclose(
                data.T_W_lidar_before[i, j],
                invert(problem.stops[0].T_odom_base)
                @ problem.stops[j].T_odom_base
                @ lidar.T_base_lidar_initial,
                atol=1e-9,
            )
        np.testing.assert_allclose(
            invert(after[0, 0]) @ after[0, j], invert(T_G_ref[0]) @ T_G_ref[j], atol=1e-9
        )
    # The same subset of each stop cloud for both maps, about max_points in all.
    total = sum(len(cloud) for row in data.clouds for cloud in row)
    assert 3000 <= total <= 4000

    assert list(render(data, names=["error"])) == ["error"]


@pytest.fixture(scope="module")
def images(truth_input: ReportInput) -> dict[str, bytes]:
    return render(truth_input)


def decoded(data: bytes) -> np.ndarray:
    image = Image.open(io.BytesIO(data))
    assert image.format == "PNG"
    return np.asarray(image.convert("RGB"), dtype=np.int16)


def pixels_of(rgb: np.ndarray, colour: str) -> int:
    """Pixels of `colour` blended over white (points are drawn translucent)."""
    white = np.array([255.0, 255.0, 255.0])
    direction = np.array([int(colour[k : k + 2], 16) for k in (1, 3, 5)]) - white
    offset = rgb - white
    alpha = offset @ direction / (direction @ direction)
    residual = np.linalg.norm(offset - alpha[..., None] * direction, axis=2)
    return int(((alpha > 0.3) & (alpha < 1.1) & (residual < 20)).sum())


def test_every_image_is_a_png_of_a_readable_size(images: dict[str, bytes]) -> None:
    assert list(images) == list(REPORT_IMAGES) == ["map-top", "map-side", "error"]
    for name, data in images.items():
        height, width, _ = decoded(data).shape
        assert width >= 800 and height >= 400, name


@pytest.mark.parametrize("name", ["map-top", "map-side"])
def test_both_panels_show_each_lidar_in_its_own_colour(
    images: dict[str, bytes], truth_input: ReportInput, name: str
) -> None:
    rgb = decoded(images[name])
    height, width, _ = rgb.shape
    # map-top: before | after side by side; map-side: before above after.
    halves = (
        (rgb[:, : width // 2], rgb[:, width // 2 :])
        if name == "map-top"
        else (rgb[: height // 2], rgb[height // 2 :])
    )
    for panel in halves:
        for i in range(len(truth_input.frames)):
            assert pixels_of(panel, lidar_colour(i)) > 200, (name, i)


def test_the_images_keep_their_labels_legends_and_titles(truth_input: ReportInput) -> None:
    drawn = drawings(truth_input)
    texts = {name: [t.get_text() for t in d.figure.texts] for name, d in drawn.items()}
    front, rear = truth_input.frames
    for name, axis_labels in (("map-top", ["x (m)", "y (m)"]), ("map-side", ["x (m)", "z (m)"])):
        assert set(axis_labels) <= set(texts[name]), name
        assert {f"{front} (reference)", rear, "LiDARs overlapping"} <= set(texts[name]), name
        assert "Before calibration: metric error 91.2 mm" in texts[name], name
        assert "After calibration: metric error 1.50 mm, PASSED" in texts[name], name
        # Tick labels in metres on every panel's axes, a true minus sign below zero.
        assert "0" in texts[name] or "0.0" in texts[name], name
    assert "optimiser's error (eq. 11)" in texts["error"]
    # No matplotlib Axes (their ticks and layout were most of the drawing time): pixel layout.
    assert all(not d.figure.axes for d in drawn.values())
    assert [len(d.panels) for d in drawn.values()] == [2, 2, 1]


def test_no_iterations_still_renders(truth_input: ReportInput) -> None:
    unknown = replace(truth_input, error_per_iteration=(), passed=None, converged=None)
    assert decoded(render(unknown, names=["error"])["error"]).shape[1] >= 800


def test_an_unknown_image_name_is_refused(truth_input: ReportInput) -> None:
    with pytest.raises(ValueError, match=r"no report image \['map-3d'\]"):
        render(truth_input, names=["map-3d"])


# -- a failed calibration -------------------------------------------------------------------------


@pytest.fixture(scope="module")
def diverged_input(truth_input: ReportInput) -> ReportInput:
    """A calibration that diverged: the rear LiDAR's map thrown 55 m away and turned, as a
    failed run's result can place it."""
    T_W_lidar_after = truth_input.T_W_lidar_after.copy()
    T_W_lidar_after[1] = from_xyz_rpy([48.0, -27.0, 0.0], [0.0, 0.0, 1.0]) @ T_W_lidar_after[1]
    return replace(
        truth_input, T_W_lidar_after=T_W_lidar_after, metric_error_final=0.1, passed=False
    )


def width(extent: tuple[float, float, float, float]) -> float:
    return extent[1] - extent[0]


def test_a_failed_calibration_keeps_the_robots_surroundings_in_view(
    truth_input: ReportInput, diverged_input: ReportInput
) -> None:
    good, failed = map_extent(truth_input), map_extent(diverged_input)
    # The tiny scene is about 5 m across; the diverged map made the view 60 m wide.
    assert 3 < width(good) < 8
    assert width(failed) < 1.5 * width(good), failed
    path = diverged_input.T_W_lidar_before[:, :, :2, 3].reshape(-1, 2)
    x0, x1, y0, y1 = failed
    assert np.all((path >= [x0, y0]) & (path <= [x1, y1]))
    window = robot_surroundings(diverged_input)
    assert window[0] < x0 and x1 < window[1]


def test_a_failed_calibrations_before_map_is_drawn_at_full_scale(
    images: dict[str, bytes], diverged_input: ReportInput
) -> None:
    def before_panel(data: bytes) -> np.ndarray:
        rgb = decoded(data)
        return rgb[:, : rgb.shape[1] // 2]

    good = before_panel(images["map-top"])
    failed = before_panel(render(diverged_input, names=["map-top"])["map-top"])
    for i in range(len(diverged_input.frames)):
        assert pixels_of(failed, lidar_colour(i)) > 0.5 * pixels_of(good, lidar_colour(i)), i


def test_the_after_panel_counts_the_points_thrown_out_of_view(
    truth_input: ReportInput, diverged_input: ReportInput
) -> None:
    def notes(data: ReportInput) -> list[str]:
        top = drawings(data, names=["map-top"])["map-top"]
        return [text.get_text() for text in top.figure.texts if text.get_gid() == OUTSIDE_NOTE]

    assert notes(truth_input) == []
    (note,) = notes(diverged_input)
    # The rear LiDAR's half of the points, about 55 m away from the robot's surroundings.
    assert "% of the points lie beyond the robot's surroundings" in note
    assert note.startswith("50% of") and "up to 53 m" in note


# -- the convergence plot -----------------------------------------------------------------------


def test_the_error_curve_ends_at_the_reported_metric_or_says_why_not(
    truth_input: ReportInput,
) -> None:
    # The fixture's curve ends at 1.50 mm, its metric error is 1.50 mm: nothing to explain.
    assert convergence_note(truth_input) is None
    differs = replace(truth_input, metric_error_final=0.0021)
    note = convergence_note(differs)
    assert note is not None
    assert note.startswith("The curve ends at 1.50 mm, the reported metric error is 2.10 mm")
    assert "eq. 11" in note and "eq. 12" in note
    figure = drawings(differs, names=["error"])["error"].figure
    texts = [text.get_text() for text in figure.texts]
    assert any(text.startswith("iteration\nThe curve ends at 1.50 mm") for text in texts)
    labels = [artist.get_label() for artist in figure.artists]
    assert "reported metric error (eq. 12): 2.10 mm" in labels
    assert [text.get_text() for text in figure.texts if text.get_gid() == LAST_ERROR] == ["1.50 mm"]
    unmeasured = replace(truth_input, metric_error_final=float("nan"))
    assert "no metric error was measured" in (convergence_note(unmeasured) or "")
    assert convergence_note(replace(truth_input, error_per_iteration=())) is None


def error_axis_labels(data: ReportInput) -> dict[str, float]:
    """The error curve's y tick labels and their heights (pixels from the bottom)."""
    drawing = drawings(data, names=["error"])["error"]
    (panel,) = drawing.panels
    return {
        t.get_text(): t.get_position()[1]
        for t in drawing.figure.texts
        if t.get_position()[0] < panel.left and t.get_rotation() == 0
    }


def test_the_error_axis_is_logarithmic_past_a_factor_20_and_labelled_in_mm(
    truth_input: ReportInput,
) -> None:
    # 91.2 -> 1.5 mm: a log axis, ticks at 1, 2 and 5 x 10^k, a decade the same height anywhere.
    log = error_axis_labels(truth_input)
    assert list(log) == ["2", "5", "10", "20", "50", "100"]
    assert log["20"] - log["2"] == pytest.approx(log["100"] - log["10"], abs=0.5)
    # 12.4 -> 10.1 mm: linear, evenly spaced.
    narrow = replace(truth_input, error_per_iteration=(0.0124, 0.0113, 0.0105))
    linear = error_axis_labels(replace(narrow, metric_error_final=0.0101))
    assert list(linear) == ["10.0", "10.5", "11.0", "11.5", "12.0", "12.5"]
    steps = np.diff(list(linear.values()))
    np.testing.assert_allclose(steps, steps[0], atol=0.5)


def test_grid_counts_are_histogram2d_counts_edges_and_outside_included() -> None:
    rng = np.random.default_rng(3)
    extent = (-1.0, 2.0, 0.5, 1.5)
    inside = rng.uniform((-1.0, 0.5), (2.0, 1.5), size=(5000, 2))
    edges = np.array([[-1.0, 0.5], [2.0, 1.5], [2.0, 0.5], [-1.0, 1.5]])
    outside = np.array([[-1.01, 1.0], [2.01, 1.0], [0.0, 0.49], [0.0, 1.51]])
    points = np.concatenate([inside, edges, outside])

    expected, _, _ = np.histogram2d(
        points[:, 0], points[:, 1], bins=(30, 7), range=((-1.0, 2.0), (0.5, 1.5))
    )
    counts = grid_counts(points, extent, cols=30, rows=7)

    assert counts.shape == (30, 7)
    assert counts.sum() == len(inside) + len(edges)
    np.testing.assert_array_equal(counts, expected)


def test_points_outside_counts_only_beyond_the_box_edges_included() -> None:
    box = (0.0, 10.0, 0.0, 10.0)
    inside = np.array([[0.0, 0.0, 1.0], [10.0, 10.0, 1.0], [5.0, 5.0, 1.0]])  # edges count in
    beyond = np.array([[13.0, 14.0, 0.0], [-1.0, 5.0, 0.0]])

    assert points_outside([inside], box) == (0.0, 0.0)
    assert points_outside([inside, beyond, np.zeros((0, 3))], box) == (2 / 5, 5.0)
    assert points_outside([np.zeros((0, 3))], box) == (0.0, 0.0)


def test_importing_the_report_leaves_matplotlib_to_load_renderer() -> None:
    # `pipeline.map_export` and the service import this module for its colours and names; the
    # service's pool children preload matplotlib on purpose, through `load_renderer`.
    probe = (
        "import sys\n"
        "import pipeline.report as report\n"
        "before = 'matplotlib' in sys.modules\n"
        "report.load_renderer()\n"
        "print(before, all(m in sys.modules for m in "
        "('matplotlib.figure', 'matplotlib.backends.backend_agg')))\n"
    )
    repo = Path(__file__).resolve().parents[2]
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(repo), os.environ.get("PYTHONPATH", "")]),
    }
    done = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, env=env, timeout=120
    )

    assert done.stdout.split() == ["False", "True"], done.stderr
