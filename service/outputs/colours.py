"""Triangles coloured by a distortion measure: the vocabulary (:class:`ColourBy`), the scale
and its colour bar, and the colour of each triangle and each vertex.

The colours are viridis's (``cmap``'s copy of matplotlib's data, perceptually uniform, read
alike in grey and by colour-blind eyes), on a log scale: a measure ``v`` sits at ``log v``.
Each measure is a factor of at least 1 (1: kept): the conformal ``s1 / s2``, the isometric
energy, and for areas ``exp |log(s1 s2)|``, the factor by which the map grows or shrinks the
triangle's area; the bar runs from 1 (its dark end) to the measure's 99th percentile.
Percentiles are over the faces' 3D area (as the metrics').
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from functools import cache

import numpy as np
from cmap import Colormap

from transforms.metrics import FaceDistortion, weighted_quantile

#: The colour map, by its name in ``cmap``'s catalogue.
COLOUR_MAP = "viridis"
#: Steps of the colour map: the picture's colours come from this many.
STEPS = 256


class ColourBy(StrEnum):
    """What colours a picture's triangles: the validation's flags (the default) or a
    distortion measure (docs/math.md, section 7)."""

    FLAGS = "flags"
    ISOMETRIC = "isometric"
    CONFORMAL = "conformal"
    AREA = "area"

    @property
    def title(self) -> str:
        return {
            ColourBy.ISOMETRIC: "isometric distortion",
            ColourBy.CONFORMAL: "conformal distortion",
            ColourBy.AREA: "area distortion (factor)",
        }.get(self, "flags")


@dataclass(frozen=True)
class ColourBar:
    """A measure's scale: ``low`` and ``high`` (the measure at the bar's ends), and its
    ``p50`` and ``p95`` over the region's area, marked on the bar."""

    measure: ColourBy
    low: float
    high: float
    p50: float
    p95: float

    def position(self, values: np.ndarray) -> np.ndarray:
        """(n,) float in [0, 1]: where ``values`` sit on the bar (log scale)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            logs = np.log(np.asarray(values, dtype=np.float64))
        span = np.log(self.high) - np.log(self.low)
        t = (logs - np.log(self.low)) / span if span > 0 else np.zeros_like(logs)
        return np.clip(np.nan_to_num(t, nan=0.0), 0.0, 1.0)

    def steps(self, values: np.ndarray) -> np.ndarray:
        """(n,) int in [0, STEPS): the colour map's step of each value."""
        return np.minimum((self.position(values) * STEPS).astype(np.int64), STEPS - 1)


@cache
def palette() -> np.ndarray:
    """(STEPS, 3) uint8: the colour map's colours."""
    table = Colormap(COLOUR_MAP).lut(STEPS)[:, :3]
    return np.rint(table * 255).astype(np.uint8)


def hex_of(rgb) -> str:
    """``#rrggbb`` of three 0-255 channels."""
    red, green, blue = (int(channel) for channel in rgb)
    return f"#{red:02x}{green:02x}{blue:02x}"


def hex_colour(step: int) -> str:
    """The colour map's colour at ``step``, as ``#rrggbb``."""
    return hex_of(palette()[step])


def factors(found: FaceDistortion, measure: ColourBy) -> np.ndarray:
    """(j,) float: the measured faces' factor of ``measure``, at least 1."""
    values = getattr(found, measure.value)
    return np.exp(values) if measure is ColourBy.AREA else values


def colour_bar(values: np.ndarray, weights: np.ndarray, measure: ColourBy) -> ColourBar:
    """The bar of ``measure`` from the measured faces' factors (:func:`factors`) and 3D areas
    (see the module docstring)."""
    p50 = weighted_quantile(values, weights, 0.5)
    p95 = weighted_quantile(values, weights, 0.95)
    top = weighted_quantile(values, weights, 0.99)
    return ColourBar(measure, 1.0, float(max(top, 1.01)), p50, p95)


def vertex_colours(faces: np.ndarray, face_rgb: np.ndarray, areas: np.ndarray, count: int):
    """(count, 3) float32 in [0, 1]: each vertex's colour, its faces' weighed by their area
    (a vertex of degenerate faces only: white), linear as glTF's ``COLOR_0`` is (the
    colour map's sRGB values decoded)."""
    weight = np.repeat(areas, 3)
    corners = faces.ravel()
    total = np.bincount(corners, weights=weight, minlength=count)
    colours = np.ones((count, 3), dtype=np.float32)
    held = total > 0
    for channel in range(3):
        summed = np.bincount(
            corners, weights=weight * np.repeat(face_rgb[:, channel], 3), minlength=count
        )
        colours[held, channel] = summed[held] / total[held] / 255.0
    return np.where(colours <= 0.04045, colours / 12.92, ((colours + 0.055) / 1.055) ** 2.4).astype(
        np.float32
    )


def colouring(found: FaceDistortion, measure: ColourBy, count: int):
    """((count, 3) uint8 colours, the bar) of the region's faces by ``measure``; a
    degenerate face (no measure) in light grey."""
    measured = factors(found, measure)
    bar = colour_bar(measured, found.weights, measure)
    colours = np.full((count, 3), 220, dtype=np.uint8)
    colours[found.faces] = palette()[bar.steps(measured)]
    return colours, bar
