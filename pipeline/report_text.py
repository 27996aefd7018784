"""Text of the report images, laid out and rasterised by FreeType once per line and font.

matplotlib's Agg renderer (3.11) loads, hints and rasterises every glyph of a text each time it
measures the text and again each time it draws it, about 50 us a glyph with its autohinter: a
third of the report's time for set 1 (issue 17), where the same tick labels, titles and legend
entries recur in every image. `text_caching_canvas` is an Agg canvas whose renderer measures and
draws each line of plain text from `line_bitmap`, a process-wide LRU cache of its FreeType bitmap:
matplotlib's font, size, hinting and layout (kerning), the line's bitmap placed at a whole pixel
as matplotlib drew text up to 3.10 (3.11 places each glyph at a 1/64 pixel). Text positions,
sizes and metrics are matplotlib's own. Math text falls back to matplotlib's renderer.

Importing this module imports no matplotlib (as `pipeline.report_canvas`).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from matplotlib.backend_bases import GraphicsContextBase
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.ft2font import LoadFlags
    from matplotlib.text import Text

# Distinct lines of text kept: a report has about 40; their bitmaps take a few kB each.
_CACHED_LINES = 4096


@dataclass(frozen=True)
class LineBitmap:
    """One line of text rasterised: its coverage (rows, cols; 0-255, shared by every drawing of
    the line: never to be written), the line's width, height and descent as matplotlib measures
    them, and the bitmap's offset from the pen (FreeType's), all in pixels."""

    coverage: NDArray[np.uint8]
    width: float
    height: float
    descent: float
    offset: tuple[float, float]


@functools.lru_cache(maxsize=_CACHED_LINES)
def line_bitmap(
    text: str, font_path: str, size_pt: float, dpi: float, hinting: LoadFlags, antialiased: bool
) -> LineBitmap:
    """`text` (one line) in the font at `font_path`, `size_pt` points at `dpi`, rasterised with
    FreeType's `hinting` as matplotlib's Agg renderer does; cached, since a report draws the
    same lines many times (and a service process many reports)."""
    from matplotlib.font_manager import get_font

    font = get_font(font_path)  # matplotlib's FT2Font of this path, shared: reset it first
    font.clear()
    font.set_size(size_pt, dpi)
    font.set_text(text, 0.0, flags=hinting)
    font.draw_glyphs_to_bitmap(antialiased=antialiased)
    # A copy: the font reuses its buffer. Writeable, as Agg's `draw_text_image` takes it (it only
    # reads it).
    coverage = np.array(font.get_image(), dtype=np.uint8)
    width, height = font.get_width_height()
    x, y = font.get_bitmap_offset()
    # FreeType's sizes are in 1/64 pixel.
    return LineBitmap(coverage, width / 64, height / 64, font.get_descent() / 64, (x / 64, y / 64))


@functools.cache
def text_caching_canvas() -> type[FigureCanvasAgg]:
    """The class of an Agg canvas (`FigureCanvasAgg`) whose renderer measures and draws plain
    text from `line_bitmap` (math text as matplotlib does). Made on first use: matplotlib is
    imported only to draw, and subclassing its classes costs milliseconds each time."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg, RendererAgg, get_hinting_flag
    from matplotlib.font_manager import FontProperties, findfont

    class TextCachingRenderer(RendererAgg):
        def _line(self, text: str, prop: FontProperties, antialiased: bool) -> LineBitmap:
            hinting = get_hinting_flag()  # type: ignore[no-untyped-call]
            size = prop.get_size_in_points()
            return line_bitmap(text, findfont(prop), size, self.dpi, hinting, antialiased)

        def get_text_width_height_descent(
            self, s: str, prop: FontProperties, ismath: bool | str
        ) -> tuple[float, float, float]:
            if ismath or not s:
                measured: tuple[float, float, float]
                measured = super().get_text_width_height_descent(s, prop, ismath)  # type: ignore[no-untyped-call]
                return measured
            line = self._line(s, prop, antialiased=True)
            return line.width, line.height, line.descent

        def draw_text(
            self,
            gc: GraphicsContextBase,
            x: float,
            y: float,
            s: str,
            prop: FontProperties,
            angle: float,
            ismath: bool | str = False,
            mtext: Text | None = None,
        ) -> None:
            if ismath or not s:
                super().draw_text(gc, x, y, s, prop, angle, ismath, mtext)  # type: ignore[no-untyped-call]
                return
            line = self._line(s, prop, bool(gc.get_antialiased()))
            # matplotlib 3.10's placement: the bitmap at the whole pixel nearest its offset from
            # the pen, the descent turned with the text; y counts downwards.
            xo, yo = line.offset
            turn = math.radians(angle)
            left = round(x + xo + line.descent * math.sin(turn))
            bottom = round(y + yo + line.descent * math.cos(turn))
            self._renderer.draw_text_image(line.coverage, left, bottom + 1, angle, gc)

    class TextCachingCanvas(FigureCanvasAgg):
        _renderer_key: tuple[float, ...] | None = None

        def get_renderer(self) -> TextCachingRenderer:
            # As `FigureCanvasAgg.get_renderer`: one renderer while the size and dpi hold.
            width, height = self.get_width_height(physical=True)
            key = (width, height, self.figure.dpi)
            if key != self._renderer_key:
                self.renderer = TextCachingRenderer(width, height, self.figure.dpi)  # type: ignore[no-untyped-call]
                self._renderer_key = key
            renderer: TextCachingRenderer = self.renderer
            return renderer

    return TextCachingCanvas
