"""The report images' drawing layer: a matplotlib figure without Axes, laid out in pixels.

A `Drawing` is one image: `Panel`s framed at pixel boxes, with ticks, a grid, labels, titles and
legends placed as matplotlib would place them (sizes in points at 100 dpi), RGB images pasted
pixel for pixel (`Drawing.paste`) and curves added in pixels (`Drawing.add`); `Drawing.png`
encodes it. What the images show is `pipeline.report`'s. Importing this module imports no
matplotlib: each drawing call imports what it draws with (`pipeline.report.load_renderer`
preloads them).
"""

from __future__ import annotations

import functools
import io
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import NDArray

from pipeline.report_text import text_caching_canvas

if TYPE_CHECKING:
    from matplotlib.artist import Artist
    from matplotlib.backend_bases import RendererBase
    from matplotlib.text import Text

Extent = tuple[float, float, float, float]
"""(x0, x1, y0, y1): the data range a panel spans (metres in the report's maps)."""

# Sizes in points, as matplotlib's, on images of 100 pixels an inch.
_DPI = 100
FONT_PT = 10
_TITLE_PT = 12
PX_PER_PT = _DPI / 72
_LINE_PT = 0.8
# matplotlib's defaults: ticks 3.5 pt long, their labels 3.5 pt beyond, axis labels 4 pt further.
_TICK_PX = 3.5 * PX_PER_PT
_TICK_LABEL_PX = _TICK_PX + 3.5 * PX_PER_PT
_AXIS_LABEL_PAD_PX = 4 * PX_PER_PT
_GRID_COLOUR = "#b0b0b0"


@dataclass(frozen=True)
class Panel:
    """A plot on a `Drawing`: its box in pixels from the image's lower left (matplotlib's display
    coordinates) and the data range `extent` it spans."""

    left: int
    bottom: int
    width: int
    height: int
    extent: Extent

    @property
    def right(self) -> int:
        return self.left + self.width

    @property
    def top(self) -> int:
        return self.bottom + self.height

    def pixels(
        self, x: NDArray[np.float64], y: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Where data coordinates `x`, `y` lie on the image, pixels from its lower left."""
        x0, x1, y0, y1 = self.extent
        return (
            self.left + (np.asarray(x, dtype=np.float64) - x0) * (self.width / (x1 - x0)),
            self.bottom + (np.asarray(y, dtype=np.float64) - y0) * (self.height / (y1 - y0)),
        )

    def point(self, x: float, y: float) -> tuple[float, float]:
        px, py = self.pixels(np.array([x]), np.array([y]))
        return float(px[0]), float(py[0])


@dataclass(frozen=True)
class LegendKey:
    """One legend entry: a filled swatch of `colour`, or a line of `linestyle` (and `marker`)."""

    label: str
    colour: str
    linestyle: Literal["-", "--"] | None = None
    marker: str = ""


Tick = tuple[float, str]
"""A tick's value (data units) and its label."""


class Drawing:
    """One report image, `width` x `height` pixels: a matplotlib figure without Axes, laid out
    in pixels, whose maps are RGB images composed in numpy (`paste`) under lines and text
    (frames, ticks, grids, labels, legends, curves).

    No matplotlib Axes: building and drawing their ticks and labels took most of the report's
    time (0.15-0.35 s per image for set 1), and their images are resampled onto the screen
    (~0.1 s a map image) where `paste` copies pixels. The tick values still come from
    matplotlib's locators, every line from its Agg renderer and every line of text from
    FreeType once per process (`pipeline.report_text`)."""

    def __init__(self, width: int, height: int) -> None:
        from matplotlib.figure import Figure

        # No pyplot: no global figure registry, safe in worker threads and processes.
        self.figure = Figure(figsize=(width / _DPI, height / _DPI), dpi=_DPI)
        # Agg's, its text from a cache of rasterised lines: texts measure themselves with its
        # renderer (`widest`) and draw with it.
        self._canvas = text_caching_canvas()(self.figure)
        self.panels: list[Panel] = []

    def png(self) -> bytes:
        """The image, drawn by Agg, as an RGB PNG (Pillow's encoder, as `savefig`'s).

        RGB: the figure is opaque (white underneath everything), so its alpha is 255 everywhere
        and a quarter of the bytes need not be filtered and compressed (about a quarter less
        encoding time, the three images of set 1 551 -> 479 kB). zlib level 1: these images are
        mostly flat colour, and level 6 (the default) spent a third of the drawing time
        compressing them for a few per cent of size.
        """
        from PIL import Image

        self._canvas.draw()  # type: ignore[no-untyped-call]
        size = self._canvas.get_width_height(physical=True)
        buffer_rgba = self._canvas.buffer_rgba()  # type: ignore[no-untyped-call]
        rgba = Image.frombuffer("RGBA", size, buffer_rgba, "raw", "RGBA", 0, 1)
        buffer = io.BytesIO()
        rgba.convert("RGB").save(buffer, format="png", compress_level=1)
        return buffer.getvalue()

    def add(self, artist: Artist) -> None:
        """Add `artist`, whose coordinates are pixels from the image's lower left."""
        from matplotlib.transforms import IdentityTransform

        artist.set_transform(IdentityTransform())
        self.figure.add_artist(artist)

    def text(self, x: float, y: float, text: str, **style: Any) -> Text:
        """`text` at pixel `x`, `y` (from the lower left); `style`: `Text`'s properties."""
        from matplotlib.transforms import IdentityTransform

        style.setdefault("fontsize", FONT_PT)
        return self.figure.text(x, y, text, transform=IdentityTransform(), **style)

    def widest(self, texts: Sequence[Text]) -> float:
        """The widest of `texts` on the image, pixels."""
        return max((t.get_window_extent().width for t in texts), default=0.0)

    def panel(
        self,
        box: tuple[int, int, int, int],
        extent: Extent,
        *,
        xlabel: str | None = None,
        ylabel: str | None = None,
        xticks: Sequence[Tick] | None = None,
        yticks: Sequence[Tick] | None = None,
        xtick_labels: bool = True,
        ytick_labels: bool = True,
        grid_alpha: float = 0.25,
        ylabel_pt: float = FONT_PT,
    ) -> Panel:
        """A framed panel at `box` (left, bottom, width, height in pixels) spanning `extent`,
        with a grid at its ticks (`xticks`, `yticks`: matplotlib's choice when None)."""
        from matplotlib.collections import LineCollection

        panel = Panel(*box, extent=extent)
        self.panels.append(panel)
        x0, x1, y0, y1 = extent
        if xticks is None:
            xticks = linear_ticks(x0, x1, panel.width / PX_PER_PT / (3 * FONT_PT))
        if yticks is None:
            yticks = linear_ticks(y0, y1, panel.height / PX_PER_PT / (2 * FONT_PT))
        xs, _ = panel.pixels(np.array([v for v, _ in xticks]), np.zeros(len(xticks)))
        _, ys = panel.pixels(np.zeros(len(yticks)), np.array([v for v, _ in yticks]))
        left, right, bottom, top = panel.left, panel.right, panel.bottom, panel.top
        grid = [((x, bottom), (x, top)) for x in xs] + [((left, y), (right, y)) for y in ys]
        ticks = [((x, bottom), (x, bottom - _TICK_PX)) for x in xs] + [
            ((left, y), (left - _TICK_PX, y)) for y in ys
        ]
        frame = [((left, bottom), (right, bottom)), ((right, bottom), (right, top))]
        frame += [((right, top), (left, top)), ((left, top), (left, bottom))]
        # One collection, the grid translucent under the black ticks and frame.
        self.add(
            LineCollection(
                grid + ticks + frame,
                colors=[(*rgb(_GRID_COLOUR), grid_alpha)] * len(grid)
                + [(0.0, 0.0, 0.0, 1.0)] * (len(ticks) + len(frame)),
                linewidths=_LINE_PT,
            )
        )
        if xtick_labels:
            for x, (_, label) in zip(xs, xticks, strict=True):
                self.text(x, bottom - _TICK_LABEL_PX, label, ha="center", va="top")
        labels = (
            [
                self.text(left - _TICK_LABEL_PX, y, label, ha="right", va="center_baseline")
                for y, (_, label) in zip(ys, yticks, strict=True)
            ]
            if ytick_labels
            else []
        )
        if xlabel is not None:
            # Below the tick labels (about 1.2 lines of the font).
            below = _TICK_LABEL_PX + 1.2 * FONT_PT * PX_PER_PT + _AXIS_LABEL_PAD_PX
            self.text((left + right) / 2, bottom - below, xlabel, ha="center", va="top")
        if ylabel is not None:
            beside = _TICK_LABEL_PX + self.widest(labels) + _AXIS_LABEL_PAD_PX
            self.text(
                left - beside,
                (bottom + top) / 2,
                ylabel,
                ha="right",
                va="center",
                rotation=90,
                fontsize=ylabel_pt,
            )
        return panel

    def paste(self, panel: Panel, image: NDArray[np.float64]) -> None:
        """Fill `panel` with the (rows, cols, 3) RGB `image` in [0, 1] (row 0 at the bottom of
        its extent): each screen pixel takes the cell under its centre (nearest neighbour)."""
        rows, cols, _ = image.shape
        levels = image * 255
        np.round(levels, out=levels)
        cells = np.empty((rows, cols, 4), dtype=np.uint8)
        cells[..., :3] = levels
        cells[..., 3] = 255
        up = ((np.arange(panel.height) + 0.5) * (rows / panel.height)).astype(int)
        across = ((np.arange(panel.width) + 0.5) * (cols / panel.width)).astype(int)
        # `take`, once per axis: `cells[up][:, across]`, in half its time.
        screen = np.take(np.take(cells, up, axis=0), across, axis=1)
        self.figure.add_artist(_pixels()(panel.left, panel.bottom, screen))

    def title(self, panel: Panel, title: str, fontsize: float = _TITLE_PT) -> None:
        """`title` centred above `panel` (6 pt above it, as matplotlib's axes titles)."""
        top = panel.top + 6 * PX_PER_PT
        self.text((panel.left + panel.right) / 2, top, title, ha="center", fontsize=fontsize)

    def suptitle(self, title: str) -> None:
        """`title` centred at the top of the image."""
        width, height = self.figure.bbox.width, self.figure.bbox.height
        self.text(width / 2, 0.98 * height, title, ha="center", va="top", fontsize=_TITLE_PT)

    def legend(self, panel: Panel, keys: Sequence[LegendKey]) -> None:
        """`keys` in a box at `panel`'s upper right (matplotlib's legend, its sizes in ems)."""
        from matplotlib.lines import Line2D
        from matplotlib.patches import Rectangle

        em = FONT_PT * PX_PER_PT
        pad, handle, gap, row = 0.4 * em, 2.0 * em, 0.8 * em, 1.5 * em
        labels = [self.text(0, 0, key.label, va="center_baseline", zorder=6) for key in keys]
        width = 2 * pad + handle + gap + self.widest(labels)
        height = 2 * pad + len(keys) * row - 0.5 * em
        right, top = panel.right - 0.5 * em, panel.top - 0.5 * em
        left = right - width
        self.add(
            Rectangle(
                (left, top - height),
                width,
                height,
                facecolor=(1.0, 1.0, 1.0, 0.9),
                edgecolor="0.8",
                linewidth=_LINE_PT,
                zorder=5,
            )
        )
        for k, (key, label) in enumerate(zip(keys, labels, strict=True)):
            y = top - pad - 0.5 * em - k * row
            x = left + pad
            if key.linestyle is None:
                swatch: Artist = Rectangle(
                    (x, y - 0.35 * em), handle, 0.7 * em, color=key.colour, zorder=6
                )
            else:
                swatch = Line2D(
                    [x, x + handle / 2, x + handle],
                    [y, y, y],
                    color=key.colour,
                    linestyle=key.linestyle,
                    marker=key.marker,
                    markevery=[1],
                    markersize=3,
                    zorder=6,
                )
            self.add(swatch)
            label.set_position((x + handle + gap, y))


@functools.cache
def _pixels() -> Callable[[int, int, NDArray[np.uint8]], Artist]:
    """The class of an artist that puts a (rows, cols, 4) RGBA image (first row at the bottom)
    on the canvas pixel for pixel, its lower left corner at a pixel (left, bottom). Made on
    first use: matplotlib is imported only to draw, and subclassing `Artist` costs milliseconds
    each time."""
    from matplotlib.artist import Artist

    class Pixels(Artist):
        def __init__(self, left: int, bottom: int, rgba: NDArray[np.uint8]) -> None:
            super().__init__()
            self._at, self._rgba = (left, bottom), rgba

        def draw(self, renderer: RendererBase) -> None:
            if self.get_visible():
                gc = renderer.new_gc()
                renderer.draw_image(gc, *self._at, self._rgba)
                gc.restore()

    return Pixels


def linear_ticks(low: float, high: float, bins: float) -> list[Tick]:
    """Ticks within [low, high] at matplotlib's "nice" steps (at most `bins` + 1 of them, never
    more than 10, as its automatic locator), labelled with as many decimals as the step needs
    and a true minus sign."""
    from matplotlib.ticker import MaxNLocator

    locator = MaxNLocator(nbins=max(1, min(9, int(bins))), steps=[1, 2, 2.5, 5, 10])
    values = np.asarray(locator.tick_values(low, high), dtype=np.float64)
    step = float(values[1] - values[0]) if len(values) > 1 else 1.0
    slack = 1e-9 * step
    values = values[(values >= low - slack) & (values <= high + slack)]
    values = np.where(np.abs(values) < slack, 0.0, values)  # no "-0"
    decimals = next(d for d in range(12) if np.allclose(np.round(values, d), values, atol=slack))
    return [(float(v), f"{v:.{decimals}f}".replace("-", "\u2212")) for v in values]


def integer_ticks(low: float, high: float, bins: float) -> list[Tick]:
    """Ticks at whole numbers within [low, high] (at most `bins` + 1, never more than 10), a true
    minus sign below zero."""
    from matplotlib.ticker import MaxNLocator

    locator = MaxNLocator(nbins=max(1, min(9, int(bins))), integer=True)
    values = locator.tick_values(low, high)
    return [(float(v), f"{v:.0f}".replace("-", "\u2212")) for v in values if low <= v <= high]


def log_ticks(low: float, high: float) -> list[Tick]:
    """Ticks at 1, 2 and 5 x 10^k between 10^`low` and 10^`high`, at their log10 positions."""
    from matplotlib.ticker import LogLocator

    values = LogLocator(subs=(1.0, 2.0, 5.0)).tick_values(10**low, 10**high)
    return [(float(np.log10(v)), f"{v:g}") for v in values if low <= np.log10(v) <= high]


def rgb(colour: str) -> tuple[float, float, float]:
    """The red, green and blue in [0, 1] of a colour written "#rrggbb"."""
    return (
        int(colour[1:3], 16) / 255,
        int(colour[3:5], 16) / 255,
        int(colour[5:7], 16) / 255,
    )
