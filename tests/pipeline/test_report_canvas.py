"""The report's drawing layer: a pasted image lies where the panel's ticks say, and the ticks
are matplotlib's, labelled with the decimals their step needs."""

from __future__ import annotations

import io

import numpy as np
from PIL import Image

from pipeline.report_canvas import Drawing, linear_ticks


def decoded(data: bytes) -> np.ndarray:
    image = Image.open(io.BytesIO(data))
    assert image.format == "PNG"
    return np.asarray(image.convert("RGB"), dtype=np.int16)


def test_a_pasted_map_lies_where_its_ticks_say() -> None:
    drawing = Drawing(400, 300)
    panel = drawing.panel((60, 50, 300, 200), (-2.0, 4.0, 10.0, 12.0), xlabel="x (m)")
    # 30 x 20 cells of 0.2 x 0.1 m; one red, at x -1.0 to -0.8 m and y 11.5 to 11.6 m.
    image = np.ones((20, 30, 3))
    image[15, 5] = (1.0, 0.0, 0.0)
    drawing.paste(panel, image)

    rgb = decoded(drawing.png())
    rows, cols = np.nonzero((rgb[..., 0] > 200) & (rgb[..., 1] < 60) & (rgb[..., 2] < 60))
    (x0, y0), (x1, y1) = panel.point(-1.0, 11.5), panel.point(-0.8, 11.6)
    assert 0.8 * (x1 - x0) * (y1 - y0) <= len(rows) <= 1.3 * (x1 - x0) * (y1 - y0)
    assert abs(cols.mean() + 0.5 - (x0 + x1) / 2) < 1
    # The PNG's rows count from the top, the drawing's pixels from the bottom.
    assert abs(300 - rows.mean() - 0.5 - (y0 + y1) / 2) < 1
    labels = {t.get_text(): t.get_position() for t in drawing.figure.texts}
    assert labels["\u22122"][0] == panel.left and labels["4"][0] == panel.right
    assert labels["10.0"][1] == panel.bottom and labels["12.0"][1] == panel.top


def test_ticks_are_matplotlibs_with_the_decimals_their_step_needs() -> None:
    ticks = linear_ticks(-2.93, 4.21, 9)
    assert [value for value, _ in ticks] == list(range(-2, 5))
    assert [label for _, label in ticks] == ["\u22122", "\u22121", "0", "1", "2", "3", "4"]
    assert [label for _, label in linear_ticks(-0.38, 0.49, 7)] == [
        "\u22120.2",
        "0.0",
        "0.2",
        "0.4",
    ]
    assert [label for _, label in linear_ticks(0.0, 1.0, 4)] == [
        "0.00",
        "0.25",
        "0.50",
        "0.75",
        "1.00",
    ]
