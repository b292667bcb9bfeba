"""A picture of a flattened region's map, described once and drawn as SVG or PNG.

The map shows the region's triangles in the returned layout, the triangles the validation
flags in their own colours with a legend, the region's boundary, the seam and the singular
points where they fall in view, axes in the layout's own coordinates (the ``x``, ``y`` that
zones, curves and the flatten answer's vertices use) and a caption. Up to ``VECTOR_TRIANGLES``
triangles are drawn one by one; beyond that, where triangles are too small to see, the fill
is decimated (a raster of the triangles, painted by :mod:`transforms.raster`) and flagged
triangles are marked at their centroids.

A triangle that crosses the seam or holds a singular point wraps around the map: its corners
lie on both sides of the cut, and the triangle between them in the plane is not where it is
on the surface. Such triangles are not filled; their corners are marked instead.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from transforms import STRETCHED_ENERGY, FlatRegion, Framing, Layout
from transforms.pixels import face_ids
from transforms.raster import paint_points, paint_segments, paint_triangles

from .colours import STEPS, ColourBar, hex_colour

#: Triangles drawn one by one (with outlines) up to this many.
VECTOR_TRIANGLES = 20_000
#: Flagged triangles marked one by one up to this many; the legend says when more were left.
MARKED_TRIANGLES = 20_000

#: Labels of the raster, in drawing priority (a larger label wins a pixel).
EMPTY, FILL, OUTLINE = 0, 1, 2
#: (label, colour, legend text, validation field) of each flag, in priority order.
#: Stretched is the least serious: its map is one to one, only drawn too long or too large.
FLAGS = (
    (3, "#8c6d31", f"stretched (isometric > {STRETCHED_ENERGY:g})", "stretched_faces"),
    (4, "#f0e442", "degenerate", "degenerate_faces"),
    (5, "#e69f00", "back-facing", "backfacing_faces"),
    (6, "#d55e00", "folded", "folded_faces"),
    (7, "#cc79a7", "crosses the seam", "seam_faces"),
    (8, "#000000", "contains a singular point", "singular_point_faces"),
)
BOUNDARY = 9
COLOURS = {
    EMPTY: "#ffffff",
    FILL: "#cfe3f2",
    OUTLINE: "#7fa7c9",
    **{label: colour for label, colour, _, _ in FLAGS},
    BOUNDARY: "#1f3b57",
}
SEAM_COLOUR, SINGULAR_COLOUR = "#cc79a7", "#000000"
#: Colours of the zones and curves drawn over the map, in turn (a palette that stays apart
#: from the flags' and reads for colour-blind eyes).
OVERLAY_COLOURS = ("#0072b2", "#009e73", "#56b4e9", "#e41a1c", "#6a3d9a", "#b15928")


@dataclass(frozen=True)
class Drawn:
    """A zone or a curve to draw over the map, in the layout's coordinates.

    Attributes
    ----------
    rings : tuple of (n, 2) float: a zone's outer ring then its holes, or a curve's points
    closed : bool, a zone (filled) rather than a curve
    name : str, written on it
    measure : str, its area or length, for the legend
    colour : str or None, its colour (``#rrggbb``); None: the next of ``OVERLAY_COLOURS``
    label : str or None, a line written on it under its name (a plan's grafts, a change)
    """

    rings: tuple[np.ndarray, ...]
    closed: bool
    name: str
    measure: str
    colour: str | None = None
    label: str | None = None


@dataclass(frozen=True)
class Overlay:
    """A :class:`Drawn` in canvas pixels, with its colour and where its name goes (the
    outer ring's mean point or the curve's first, kept inside the plot)."""

    rings: tuple[np.ndarray, ...]
    closed: bool
    name: str
    colour: str
    anchor: tuple[float, float]
    label: str | None = None


#: Legend keys of the zones (a filled swatch), the curves (a line), the sites (a dot) and
#: the reference grid (a thin line).
ZONE_KEY, CURVE_KEY, SITES_KEY, GRID_KEY = 100, -3, -4, -5
#: The reference grid's colour over the flags' fill, and over a measure's colours.
GRID_COLOUR, GRID_ON_COLOURS = "#4d4d4d", "#ffffff"


def grid_colour(coloured: bool) -> str:
    """The reference grid's colour: light over a measure's colours, dark over the flags'."""
    return GRID_ON_COLOURS if coloured else GRID_COLOUR


SITES_COLOUR = "#222222"
#: The colour of the strokes that show which way the hair grows at each site.
STROKES_COLOUR = "#b2182b"
#: A stroke's length on the canvas, pixels.
STROKE_PX = 9.0
#: Sites an SVG draws at the most (each a little square); a PNG draws them all.
SVG_SITES = 50_000


@dataclass(frozen=True)
class Picture:
    """Everything a drawing of the map needs, in pixels of a ``width`` x ``height`` canvas
    (``(column, row)``, rows growing downwards; the layout's theta grows downwards too).

    Attributes
    ----------
    width, height : int
    plot : (left, top, right, bottom), the plotting box
    corners : (m, 3, 2) float, the triangles
    labels : (m,) uint8, FILL or the label of the triangle's most serious flag
    wrapping : (m,) bool, triangles that cross the seam or hold a singular point (their
        corners are marked, they are not filled)
    vector : bool, whether the triangles are few enough to draw one by one
    boundary : (k, 2, 2) float, the region's boundary edges
    seam_columns : columns where the seam (phi = +-180 degrees) falls in view
    singular_rows : (row, name) where a singular point (theta 0 or 180) falls in view
    x_ticks, y_ticks : (pixel, text) for the axes
    x_title, y_title : str
    legend : (label, colour, text) rows
    caption : lines of text
    overlays : zones and curves drawn over the map
    sites : (n, 2) float, sites drawn over the map as dots
    face_colours : (m, 3) uint8 or None, the triangles' colours by a measure (flagged ones
        keep the flags' colours)
    colour_bar : ColourBar or None, that measure's scale, drawn under the legend
    grid : (s, 2, 2) float, the reference grid's segments
    strokes : (n, 2, 2) float, a short segment from each site along its direction on the map
    """

    width: int
    height: int
    plot: tuple[int, int, int, int]
    corners: np.ndarray
    labels: np.ndarray
    wrapping: np.ndarray
    vector: bool
    boundary: np.ndarray
    seam_columns: tuple[float, ...]
    singular_rows: tuple[tuple[float, str], ...]
    x_ticks: tuple[tuple[float, str], ...]
    y_ticks: tuple[tuple[float, str], ...]
    x_title: str
    y_title: str
    legend: tuple[tuple[int, str, str], ...]
    caption: tuple[str, ...]
    overlays: tuple[Overlay, ...] = ()
    sites: np.ndarray = field(default_factory=lambda: np.empty((0, 2)))
    face_colours: np.ndarray | None = None
    colour_bar: ColourBar | None = None
    grid: np.ndarray = field(default_factory=lambda: np.empty((0, 2, 2)))
    strokes: np.ndarray = field(default_factory=lambda: np.empty((0, 2, 2)))

    @property
    def grid_colour(self) -> str:
        return grid_colour(self.face_colours is not None)

    def face_ids(self, scale: float = 1.0) -> np.ndarray:
        """(h, w) int: the triangle holding each pixel's centre in the plotting box at
        ``scale`` pixels per canvas pixel (exactly, :func:`transforms.pixels.face_ids`;
        wrapping triangles are not filled), -1 where none does."""
        left, top, right, bottom = self.plot
        shape = (max(round((bottom - top) * scale), 1), max(round((right - left) * scale), 1))
        filled = np.flatnonzero(~self.wrapping)
        if not len(filled):
            return np.full(shape, -1)
        corners = (self.corners[filled] - np.array([left, top], dtype=np.float64)) * scale
        ids = face_ids(corners, *shape)
        return np.where(ids >= 0, filled[np.maximum(ids, 0)], -1)

    def raster(self, scale: float = 1.0, include_boundary: bool = True) -> np.ndarray:
        """(h, w) uint8 labels of the plotting box at ``scale`` pixels per canvas pixel:
        the triangles (with outlines when drawn one by one and not coloured by a measure),
        flagged triangles marked, and the boundary on top (unless it is drawn otherwise)."""
        left, top, right, bottom = self.plot
        shape = (max(round((bottom - top) * scale), 1), max(round((right - left) * scale), 1))
        image = np.zeros(shape, dtype=np.uint8)
        origin = np.array([left, top], dtype=np.float64)
        corners = (self.corners - origin) * scale
        filled = ~self.wrapping
        if self.face_colours is not None:  # the fill comes from :meth:`face_ids`; flags here
            filled &= self.labels > FILL
        paint_triangles(image, corners[filled], self.labels[filled])
        if self.vector and self.face_colours is None:
            edges = corners[filled][:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2, 2)
            paint_segments(image, edges, OUTLINE)
        marks, labels = self.marks(corners)
        if len(marks):  # 3 x 3 pixels, so that a flag on a tiny triangle stays visible
            offsets = np.array([[dx, dy] for dx in (-1, 0, 1) for dy in (-1, 0, 1)], float)
            spots = (marks[:, None, :] + offsets[None]).reshape(-1, 2)
            paint_points(image, spots, np.repeat(labels, len(offsets)))
        if include_boundary:
            paint_segments(image, (self.boundary - origin) * scale, BOUNDARY)
        return image

    def marks(self, corners: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Where flagged triangles are marked: (k, 2) points and (k,) labels, at most
        ``MARKED_TRIANGLES`` triangles: the centroid of a filled one, the corners of a
        wrapping one. ``corners`` defaults to the canvas's."""
        corners = self.corners if corners is None else corners
        flagged = np.flatnonzero(self.labels > FILL)[:MARKED_TRIANGLES]
        wraps = self.wrapping[flagged]
        points = np.concatenate(
            [corners[flagged[~wraps]].mean(axis=1), corners[flagged[wraps]].reshape(-1, 2)]
        )
        labels = np.concatenate(
            [self.labels[flagged[~wraps]], np.repeat(self.labels[flagged[wraps]], 3)]
        )
        return points, labels


def describe(
    flat: FlatRegion,
    params: dict,
    face_count: int,
    width: int,
    height: int,
    drawn: tuple[Drawn, ...] = (),
    sites: np.ndarray | None = None,
    colouring: tuple[np.ndarray, ColourBar] | None = None,
    grid: np.ndarray | None = None,
    directions: np.ndarray | None = None,
    headline: str | None = None,
    dots: str = "sites",
) -> Picture:
    """The picture of a flattened region, with zones, curves and sites over it (and, with
    ``directions``, a stroke from each site along its direction; with ``headline``, that
    first in the caption, in place of the method's line).

    Parameters
    ----------
    flat : FlatRegion, from :func:`transforms.flatten_region`
    params : dict, the resolved parameters (method, sigma, pole_angle_deg, layout)
    face_count : int, the region's triangles
    width, height : int, the canvas in pixels
    drawn : zones and curves to draw over the map
    sites : (n, 2) float or None, points of the layout to draw as dots
    colouring : ((m, 3) uint8 colours, their bar) or None: the triangles coloured by a
        measure
    grid : (s, 2, 2) float or None, segments of the layout: a reference grid
    directions : (n, 2) float or None, unit layout directions at the ``sites``
    headline : str or None, the caption's first line (the picture's title) instead of the
        method (which the JSON answer's params give), the layout and the triangles (which
        the axes and the legend give)
    dots : what the legend calls the ``sites`` ("spots" for /v1/compare's)
    """
    framing = Framing.of(flat.x, flat.y, flat.layout, width, height)
    x, s, plot = flat.x, framing.s_sign * flat.y, framing.plot
    x_low, x_high, s_low, s_high = framing.view
    column, row = framing.column, framing.row
    y_row = lambda y: row(framing.s_sign * y)  # noqa: E731
    points = np.stack([column(x), row(s)], axis=1)
    corners = points[flat.faces]
    labels = np.full(len(flat.faces), FILL, dtype=np.uint8)
    validation = flat.validation
    wrapping = np.zeros(len(flat.faces), dtype=bool)
    wrapping[validation.wrapping_faces] = True
    # Coloured by a measure, the region's swatch is in its colours (the bar's middle).
    swatch = COLOURS[FILL] if colouring is None else hex_colour(STEPS // 2, colouring[1].colour_map)
    legend = [(FILL, swatch, f"region: {face_count:,} triangles")]
    # A triangle with several flags is drawn in the colour of the last (the most serious);
    # the legend counts it under each and says where the colours hide one.
    both = np.intersect1d(validation.backfacing_faces, validation.folded_faces).size
    for label, colour, text, attribute in FLAGS:
        flagged = getattr(validation, attribute)
        labels[flagged] = label
        if len(flagged):
            shown = "" if len(flagged) <= MARKED_TRIANGLES else f", {MARKED_TRIANGLES:,} marked"
            if attribute == "backfacing_faces" and both:
                shown += f" ({both:,} drawn as folded)"
            legend.append((label, colour, f"{text}: {len(flagged):,}{shown}"))
    if len(validation.boundary_edges):
        legend.append((BOUNDARY, COLOURS[BOUNDARY], "boundary"))

    in_x = lambda value: x_low <= value <= x_high  # noqa: E731
    in_s = lambda value: s_low <= value <= s_high  # noqa: E731
    seam = tuple(float(column(v)) for v in (-math.pi, math.pi) if in_x(v))
    singular = tuple(
        (float(row(value)), name)
        for theta, name in ((0.0, "north"), (math.pi, "south"))
        if math.isfinite(value := _second_of(theta, flat.layout)) and in_s(value)
    )

    overlays, dots = _overlays(drawn, sites, framing.pixels, plot, legend, dots)
    lines = np.empty((0, 2, 2))
    if grid is not None and len(grid):
        lines = framing.pixels(grid.reshape(-1, 2)).reshape(-1, 2, 2)
        legend.append(
            (GRID_KEY, grid_colour(colouring is not None), "grid: planes across local X and Z")
        )
    strokes = np.empty((0, 2, 2))
    if directions is not None and len(dots):
        on_canvas = directions * [1.0, framing.s_sign]  # rows grow with s
        strokes = np.stack([dots, dots + STROKE_PX * on_canvas], axis=1)
        legend.append((CURVE_KEY, STROKES_COLOUR, "growth: the hair's direction"))
    if seam:
        legend.append((-1, SEAM_COLOUR, "seam (phi +-180 deg)"))
    if singular:
        legend.append((-2, SINGULAR_COLOUR, "singular points (theta 0, 180 deg)"))
    return Picture(
        width=width,
        height=height,
        plot=plot,
        corners=corners,
        labels=labels,
        wrapping=wrapping,
        vector=len(flat.faces) <= VECTOR_TRIANGLES,
        boundary=points[validation.boundary_edges],
        seam_columns=seam,
        singular_rows=singular,
        x_ticks=_ticks(x_low, x_high, column),
        y_ticks=_ticks(*sorted((framing.s_sign * s_low, framing.s_sign * s_high)), y_row),
        x_title=AXIS_TITLES[flat.layout][0],
        y_title=AXIS_TITLES[flat.layout][1],
        legend=tuple(legend),
        caption=_caption(flat, params, face_count, headline),
        overlays=tuple(overlays),
        sites=dots,
        face_colours=None if colouring is None else colouring[0],
        colour_bar=None if colouring is None else colouring[1],
        grid=lines,
        strokes=strokes,
    )


def _overlays(drawn: tuple[Drawn, ...], sites, canvas, plot, legend: list, dots: str = "sites"):
    """The zones and curves in pixels (``canvas`` maps layout points), each in its colour
    with its name kept inside the ``plot``, and the sites' dots ((n, 2) float; ``dots``,
    what the legend calls them); their legend rows are added to ``legend``."""
    overlays = []
    for k, item in enumerate(drawn):
        rings = tuple(canvas(ring) for ring in item.rings)
        colour = item.colour or OVERLAY_COLOURS[k % len(OVERLAY_COLOURS)]
        anchor = rings[0].mean(axis=0) if item.closed else rings[0][0]
        anchor = np.clip(anchor, [plot[0] + 30, plot[1] + 10], [plot[2] - 30, plot[3] - 10])
        overlays.append(
            Overlay(rings, item.closed, item.name, colour, tuple(anchor.tolist()), item.label)
        )
        key = ZONE_KEY if item.closed else CURVE_KEY
        legend.append((key, colour, f"{item.name}: {item.measure}"))
    if sites is None:
        return tuple(overlays), np.empty((0, 2))
    legend.append((SITES_KEY, SITES_COLOUR, f"{dots}: {len(sites):,}"))
    return tuple(overlays), canvas(sites)


#: The axes' titles by layout: which coordinate of the layout each axis is, in what units.
AXIS_TITLES = {
    Layout.THETA_PHI: ("x = phi (layout units, rad)", "y = theta (layout units, rad)"),
    Layout.MERCATOR: ("x = phi (layout units, rad)", "y = ln tan((pi - theta) / 2) (layout units)"),
}


def _second_of(theta: float, layout: Layout) -> float:
    """The layout's downward coordinate of a polar angle (infinite at Mercator's poles)."""
    if layout is Layout.THETA_PHI:
        return theta
    with np.errstate(divide="ignore"):
        return float(np.log(np.tan(0.5 * theta)))


def _nice_step(span: float, count: int = 6) -> float:
    raw = span / count
    power = 10 ** math.floor(math.log10(raw))
    return next(k * power for k in (1, 2, 2.5, 5, 10) if k * power >= raw)


def _ticks(low: float, high: float, to_pixel) -> tuple[tuple[float, str], ...]:
    """Ticks at round values of a linear axis from ``low`` to ``high``, labelled in the
    axis's own units (the layout's): a value read off the picture is one to send back."""
    step = _nice_step(high - low)
    values = np.arange(math.ceil(low / step), math.floor(high / step) + 1) * step
    return tuple((float(to_pixel(v)), f"{round(float(v), 12) + 0.0:g}") for v in values)


def _caption(flat: FlatRegion, params: dict, face_count: int, headline=None) -> tuple[str, ...]:
    v = flat.validation
    method = params["method"]
    if params.get("sigma") is not None:
        method += f", sigma {params['sigma']:.4g} (cap {params['pole_angle_deg']:.1f} deg)"
    status = [
        "seam-free" if v.seam_free else "NOT seam-free",
        "star-shaped" if v.star_shaped else "NOT star-shaped",
    ]
    margins = (
        f"margins: seam {v.margin_deg_seam:.1f} deg, north {v.margin_deg_north:.1f} deg, "
        f"south {v.margin_deg_south:.1f} deg"
    )
    return (
        headline or f"meshflat: {method}; layout {flat.layout.value}; {face_count:,} triangles",
        f"{', '.join(status)}; {margins}",
        energy_text(flat),
    )


def energy_text(flat: FlatRegion) -> str:
    """The isometric energy as a caption says it: its median and 95th percentile over the
    trusted faces (a mean is dominated by a few slivers), and how many faces are flagged,
    the stretched among them."""
    flagged = flat.flagged_faces
    stretched = len(flat.validation.stretched_faces)
    of_them = f", {stretched:,} of them stretched" if stretched else ""
    if flat.trusted is None:
        return f"isometric energy: no trusted face ({flagged:,} flagged{of_them})"
    energy = flat.trusted.isometric
    return (
        f"isometric energy p50 {energy.p50:.3f}, p95 {energy.p95:.3f} on the trusted faces "
        f"({flagged:,} flagged{of_them})"
    )
