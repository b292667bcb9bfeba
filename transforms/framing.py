"""The pixel grid of a picture of the map (docs/math.md, section 16): where the layout's
points fall on a ``width`` x ``height`` canvas, its theta growing down the rows.

The PNG answer draws the map on this grid, and every image exchanged with the map uses the
same one: a density map's pixel under a triangle, an image carried onto the mesh, the look-up
images of face ids and barycentric weights.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .layouts import Layout


@dataclass(frozen=True)
class Framing:
    """Where the map's layout points fall on a ``width`` x ``height`` canvas: its box
    padded by 4 % (``view``: x and s ranges, ``s = s_sign * y`` growing with theta,
    downwards), scaled alike in both directions into the box inside the margins and centred
    there (``plot``: left, top, right, bottom pixels). Pixel ``(column, row)`` covers
    ``[column, column + 1) x [row, row + 1)``: its centre is at half-integers."""

    s_sign: float
    view: tuple[float, float, float, float]
    scale: float
    plot: tuple[int, int, int, int]

    #: Margins (left, top, right, bottom) for the axes, the legend and the caption.
    MARGINS = (70, 48, 270, 96)

    @classmethod
    def of(cls, x: np.ndarray, y: np.ndarray, layout: Layout, width: int, height: int) -> Framing:
        """The framing of the layout ``x``, ``y`` ((k,) float each) on the canvas."""
        s_sign = float(Layout(layout).s_sign)
        margin_left, margin_top, margin_right, margin_bottom = cls.MARGINS
        box = (margin_left, margin_top, width - margin_right, height - margin_bottom)
        x_low, x_high, s_low, s_high = view = _view(np.asarray(x), s_sign * np.asarray(y))
        scale = min((box[2] - box[0]) / (x_high - x_low), (box[3] - box[1]) / (s_high - s_low))
        # Centre the view in the box; the plot is the part the view fills.
        used_w, used_h = (x_high - x_low) * scale, (s_high - s_low) * scale
        left = box[0] + ((box[2] - box[0]) - used_w) / 2
        top = box[1] + ((box[3] - box[1]) - used_h) / 2
        plot = (round(left), round(top), round(left + used_w), round(top + used_h))
        return cls(s_sign, view, scale, plot)

    def column(self, x) -> np.ndarray:
        """The canvas column of layout ``x`` values."""
        return self.plot[0] + (np.asarray(x) - self.view[0]) * self.scale

    def row(self, s) -> np.ndarray:
        """The canvas row of ``s`` values (``s_sign * y``)."""
        return self.plot[1] + (np.asarray(s) - self.view[2]) * self.scale

    def pixels(self, points: np.ndarray) -> np.ndarray:
        """(n, 2) float: the canvas ``(column, row)`` of layout points ((n, 2): x, y)."""
        return np.stack([self.column(points[:, 0]), self.row(self.s_sign * points[:, 1])], axis=1)


def _view(x: np.ndarray, s: np.ndarray) -> tuple[float, float, float, float]:
    """The layout's box with a margin of 4 % (and a least size, for a single point)."""
    x_low, x_high, s_low, s_high = float(x.min()), float(x.max()), float(s.min()), float(s.max())
    pad = 0.04 * max(x_high - x_low, s_high - s_low, 1e-6)
    return x_low - pad, x_high + pad, s_low - pad, s_high + pad
