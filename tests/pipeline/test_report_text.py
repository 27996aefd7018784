"""The report's text: each line rasterised once and reused, measured as matplotlib measures it,
and drawn where matplotlib draws it."""

from __future__ import annotations

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg, RendererAgg, get_hinting_flag
from matplotlib.figure import Figure
from matplotlib.font_manager import FontProperties, findfont

from pipeline.report_text import LineBitmap, line_bitmap, text_caching_canvas


def bitmap_of(text: str, size_pt: float) -> LineBitmap:
    """`text` in matplotlib's default font at `size_pt`, as the report's renderer asks for it."""
    hinting = get_hinting_flag()  # type: ignore[no-untyped-call]
    return line_bitmap(text, findfont(FontProperties()), size_pt, 100, hinting, True)


def test_a_line_is_rasterised_once_and_each_size_on_its_own() -> None:
    first, again = bitmap_of("x (m) \u22122.5", 10), bitmap_of("x (m) \u22122.5", 10)
    assert again is first  # the cache's: the same pixels, not rasterised again
    larger = bitmap_of("x (m) \u22122.5", 12)
    assert larger.width > first.width and larger.coverage.shape[0] > first.coverage.shape[0]
    assert first.coverage.dtype == np.uint8 and first.coverage.max() == 255


def test_lines_measure_as_matplotlib_measures_them() -> None:
    """The same metrics, so every text is laid out where matplotlib would put it."""
    renderer = RendererAgg(200, 100, 100)  # type: ignore[no-untyped-call]
    for text, size in (("Before calibration: 65.0 mm", 12), ("y (m)", 10), ("Tq,", 9)):
        prop = FontProperties(size=size)
        line = bitmap_of(text, size)
        expected = renderer.get_text_width_height_descent(text, prop, ismath=False)  # type: ignore[no-untyped-call]
        assert (line.width, line.height, line.descent) == expected, text


def ink(canvas: FigureCanvasAgg) -> np.ndarray:
    """The dark pixels' rows and columns of the drawn canvas."""
    canvas.draw()  # type: ignore[no-untyped-call]
    grey = np.asarray(canvas.buffer_rgba())[..., :3].mean(axis=2)  # type: ignore[no-untyped-call]
    return np.argwhere(grey < 128)


def test_text_lands_where_matplotlib_draws_it() -> None:
    def drawn(canvas_class: type[FigureCanvasAgg]) -> FigureCanvasAgg:
        figure = Figure(figsize=(3, 2), dpi=100)
        canvas = canvas_class(figure)
        figure.text(0.1, 0.6, "metric error 5.68 mm\nPASSED", ha="left", va="top", fontsize=10)
        figure.text(0.9, 0.5, "z (m)", rotation=90, ha="right", va="center", fontsize=10)
        figure.text(0.5, 0.1, "$x^2$", ha="center", fontsize=10)  # math text: matplotlib's own
        return canvas

    cached, plain = ink(drawn(text_caching_canvas())), ink(drawn(FigureCanvasAgg))
    # The same letters within a pixel: the cached lines sit at whole pixels, matplotlib 3.11's
    # glyphs at 1/64 pixel.
    np.testing.assert_allclose(cached.min(axis=0), plain.min(axis=0), atol=1)
    np.testing.assert_allclose(cached.max(axis=0), plain.max(axis=0), atol=1)
    assert abs(len(cached) - len(plain)) < 0.1 * len(plain)
