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
#: The colour map of a difference, about 0: Crameri's vik (blue below, red above, light at
#: 0; perceptually uniform and read by colour-blind eyes).
DIVERGING_MAP = "crameri:vik"
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
    ``p50`` and ``p95`` over the region's area, marked on the bar; on a log scale in
    ``colour_map``'s colours, or, for a difference (``measure`` None, ``label`` its title),
    on a linear one."""

    measure: ColourBy | None
    low: float
    high: float
    p50: float
    p95: float
    label: str | None = None
    colour_map: str = COLOUR_MAP

    @property
    def title(self) -> str:
        """The bar's title: the measure's, or its label."""
        return self.label if self.measure is None else self.measure.title

    def position(self, values: np.ndarray) -> np.ndarray:
        """(n,) float in [0, 1]: where ``values`` sit on the bar (log scale for a measure)."""
        values = np.asarray(values, dtype=np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            if self.measure is None:
                t = (values - self.low) / (self.high - self.low)
            else:
                span = np.log(self.high) - np.log(self.low)
                t = (np.log(values) - np.log(self.low)) / span if span > 0 else 0.0 * values
        return np.clip(np.nan_to_num(t, nan=0.0), 0.0, 1.0)

    def steps(self, values: np.ndarray) -> np.ndarray:
        """(n,) int in [0, STEPS): the colour map's step of each value."""
        return np.minimum((self.position(values) * STEPS).astype(np.int64), STEPS - 1)


@cache
def palette(name: str = COLOUR_MAP) -> np.ndarray:
    """(STEPS, 3) uint8: the colour map's colours."""
    table = Colormap(name).lut(STEPS)[:, :3]
    return np.rint(table * 255).astype(np.uint8)


def hex_of(rgb) -> str:
    """``#rrggbb`` of three 0-255 channels."""
    red, green, blue = (int(channel) for channel in rgb)
    return f"#{red:02x}{green:02x}{blue:02x}"


def hex_colour(step: int, name: str = COLOUR_MAP) -> str:
    """The colour map ``name``'s colour at ``step``, as ``#rrggbb``."""
    return hex_of(palette(name)[step])


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


#: The share of the region's faces (by count) beyond a difference map's ends: the bar runs
#: over the 99th percentile of the differences' size, so one outlier does not wash it out.
DIFFERENCE_QUANTILE = 0.99


def difference_colouring(values: np.ndarray, label: str = "follow-up minus baseline"):
    """((m, 3) uint8 colours, the bar) of faces by a signed difference ((m,) float, NaN
    where there is none: light grey), on a linear scale symmetric about 0."""
    values = np.asarray(values, dtype=np.float64)
    known = np.isfinite(values)
    colours = np.full((len(values), 3), 220, dtype=np.uint8)
    found = values[known]
    reach = float(np.quantile(np.abs(found), DIFFERENCE_QUANTILE)) if len(found) else 0.0
    reach = reach if reach > 0 else 1.0
    p50, p95 = (float(np.quantile(found, q)) if len(found) else 0.0 for q in (0.5, 0.95))
    bar = ColourBar(None, -reach, reach, p50, p95, label, DIVERGING_MAP)
    colours[known] = palette(DIVERGING_MAP)[bar.steps(found)]
    return colours, bar
