"""Zones and curves drawn on the map, in the layout's coordinates (/v1/measure, /v1/sites,
/v1/register): their params, and as the core takes them: rings checked with GEOS (through
shapely: simple, at least three distinct points, holes inside the outer ring and apart), the
zones' pairwise overlaps as polygons of their own.

A bad ring is refused naming the zone (its position and name) and the ring; one wholly
outside the region's map is answered with a warning that gives the map's extent (and says
when the numbers look like degrees: the layout is in radians).
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Annotated

import numpy as np
import shapely
from pydantic import Field, model_validator
from scipy import sparse

from transforms import Layout, MapTriangles, ZoneCover, curve_crossings

from ..errors import InvalidInput, check_count
from .context import CURVE_BYTES_PER_CROSSING, ZONE_BYTES_PER_POINT, Context
from .fields import MapCoordinates, Name, Strict
from .warnings import WarningCode


class _MapPoints(Strict):
    """Points on the map: as many ``y`` as ``x``."""

    x: MapCoordinates
    y: MapCoordinates

    @model_validator(mode="after")
    def _one_y_per_x(self) -> _MapPoints:
        if len(self.x) != len(self.y):
            raise ValueError(f"x, y: one y per x; got {len(self.x)} x and {len(self.y)} y")
        return self


class Ring(_MapPoints):
    """A closed ring on the map, in the layout's coordinates (``vertices.x`` and
    ``vertices.y`` of a flatten answer): straight edges from each point to the next and from
    the last back to the first (which need not be repeated)."""

    x: MapCoordinates = Field(min_length=3)
    y: MapCoordinates = Field(min_length=3)


class Zone(Strict):
    """An area drawn on the map: an outer ring and the holes cut out of it."""

    name: Name
    outer: Ring
    holes: Annotated[list[Ring], Field(max_length=256)] = Field(
        [], description="Rings inside the outer one, apart from each other."
    )


class Curve(_MapPoints):
    """A polyline drawn on the map (a hairline, an incision), in the layout's coordinates."""

    name: Name
    x: MapCoordinates = Field(min_length=2)
    y: MapCoordinates = Field(min_length=2)


def check_names(kind: str, drawn: list) -> None:
    """Refuse two of ``drawn`` (zones or curves, ``kind``) of one name: answers, overlaps
    and the picture's legend name them."""
    seen: dict[str, int] = {}
    for i, item in enumerate(drawn):
        if item.name in seen:
            raise ValueError(
                f"{kind}.{i}: the name {item.name!r} is that of {kind}.{seen[item.name]}; "
                "each needs its own"
            )
        seen[item.name] = i


def zone_points(zones: Sequence[Zone]) -> int:
    """The points of all the rings of ``zones``."""
    return sum(len(zone.outer.x) + sum(len(hole.x) for hole in zone.holes) for zone in zones)


def check_drawn(
    ctx: Context,
    zones: Sequence[Zone],
    curves: Sequence[Curve] = (),
    cover: bool = True,
    curves_field: str = "curves",
    zones_field: str = "zones",
) -> None:
    """Refuse more points in ``zones`` and ``curves`` than MESHFLAT_MAX_DRAWN_POINTS (named
    ``zones_field``, or ``curves_field`` when the zones alone are within it), and, for zones
    that will be covered (``cover``), charge their points' cost before a ring is checked.

    Raises
    ------
    OverLimit
        Too many points.
    """
    zoned = zone_points(zones)
    drawn = zoned + sum(len(curve.x) for curve in curves)
    within = zoned <= ctx.settings.max_drawn_points and curves
    field = curves_field if within else zones_field
    check_count(drawn, ctx.settings.max_drawn_points, field, "MESHFLAT_MAX_DRAWN_POINTS")
    if cover:
        ctx.charge(ZONE_BYTES_PER_POINT * zoned)


def charge_crossings(
    ctx: Context, triangles: MapTriangles, curves: list[np.ndarray], field: str = "curves"
) -> None:
    """Refuse curves that cross more triangle edges than MESHFLAT_MAX_CURVE_CROSSINGS (as
    :func:`transforms.curve_crossings` counts them, before any is built), and charge the
    others' crossings."""
    crossings = sum(curve_crossings(triangles, points) for points in curves)
    check_count(
        crossings,
        ctx.settings.max_curve_crossings,
        field,
        "MESHFLAT_MAX_CURVE_CROSSINGS",
        "the items are the triangle edges the curves cross on the map, counted from their "
        "lengths over the triangles' size: draw them shorter, with fewer back-and-forths",
    )
    ctx.charge(CURVE_BYTES_PER_CROSSING * crossings)


#: Where GEOS says a polygon is invalid: "Self-intersection[x y]".
_WHERE = re.compile(r"\[(?P<x>\S+) (?P<y>\S+)\]")


@dataclass(frozen=True)
class Outline:
    """A zone checked: its rings as (n, 2) float arrays, the outer one first, none closed
    by repeating its first point; and the polygon they bound."""

    name: str
    rings: tuple[np.ndarray, ...]
    polygon: shapely.Polygon


def checked_zone(zone: Zone, number: int, kind: str = "zones") -> Outline:
    """The zone's rings, checked; ``kind``, the list of params it is in.

    Raises
    ------
    InvalidInput
        A ring of fewer than three distinct points, a ring that crosses or touches itself, a
        hole outside the outer ring, holes that cross or nest (named ``{kind}.{number}...``).
    """
    field = f"{kind}.{number}"
    rings = [_ring(zone.outer, f"{field}.outer", (field, zone.name, ", outer ring"))]
    rings += [
        _ring(hole, f"{field}.holes.{k}", (field, zone.name, f", hole {k}"))
        for k, hole in enumerate(zone.holes)
    ]
    polygon = shapely.Polygon(rings[0], rings[1:])
    if not polygon.is_valid:
        hole = next(
            (
                k
                for k, ring in enumerate(rings[1:])
                if not shapely.Polygon(rings[0]).contains(shapely.Polygon(ring))
            ),
            None,
        )
        where = _where(shapely.is_valid_reason(polygon))
        if hole is not None:
            raise InvalidInput(
                f"{field}.holes.{hole}",
                f"a hole must lie inside the outer ring{where}",
                name=zone.name,
                item=field,
                about=f", hole {hole}",
            )
        raise InvalidInput(
            f"{field}.holes",
            f"its holes must lie apart from each other and from the outer ring{where}",
            name=zone.name,
            item=field,
        )
    return Outline(zone.name, tuple(rings), polygon)


def _ring(ring: Ring, field: str, label: tuple[str, str, str]) -> np.ndarray:
    """(n, 2) float: the ring's points, checked; ``label``, the zone's field and name and
    which ring it is, for the refusal."""
    item, zone, which = label
    points = _distinct_in_turn(ring.x, ring.y)
    if len(points) > 1 and (points[0] == points[-1]).all():
        points = points[:-1]  # closed by repeating the first point
    distinct = len(np.unique(points, axis=0))
    if distinct < 3:
        raise InvalidInput(
            field,
            f"a ring needs at least three distinct points; it has {distinct}",
            name=zone,
            item=item,
            about=which,
        )
    if not shapely.LinearRing(points).is_simple:
        where = _where(shapely.is_valid_reason(shapely.Polygon(points)))
        raise InvalidInput(
            field,
            f"the ring crosses or touches itself{where}; draw it without crossings",
            name=zone,
            item=item,
            about=which,
        )
    return points


def checked_curve(curve: Curve, number: int, field: str = "curves") -> np.ndarray:
    """(n, 2) float: the curve's points, repeated ones dropped.

    Raises
    ------
    InvalidInput
        Fewer than two distinct points (named ``{field}.{number}``).
    """
    points = _distinct_in_turn(curve.x, curve.y)
    if len(points) < 2:
        raise InvalidInput(
            f"{field}.{number}", "a curve needs at least two distinct points", name=curve.name
        )
    return points


def _distinct_in_turn(x, y) -> np.ndarray:
    """(n, 2) float: the points, each one that repeats the one before it dropped."""
    points = np.column_stack([np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)])
    return points[np.r_[True, np.any(points[1:] != points[:-1], axis=1)]]


def _where(reason: str) -> str:
    """`` near (x, y)`` from GEOS's reason, or nothing."""
    found = _WHERE.search(reason)
    return f" near ({float(found['x']):.6g}, {float(found['y']):.6g})" if found else ""


@dataclass(frozen=True)
class ZonePair:
    """Two zones (positions ``i < j``) whose areas overlap, and their common part: ``within``,
    the one of them that lies wholly in the other (the common part is that zone itself), or
    else ``parts``, the common part as zones of their own (rings as :class:`Outline` holds
    them)."""

    i: int
    j: int
    within: int | None
    parts: tuple[tuple[np.ndarray, ...], ...] = ()
    common: shapely.Geometry | None = None


def overlaps(outlines: list[Outline]) -> list[ZonePair]:
    """The pairs of zones whose areas overlap, in order of ``(i, j)``.

    Only the pairs whose boxes meet (found by GEOS's STRtree, in ``O(n log n + pairs)``) are
    tested exactly, all at once in GEOS: a pair where one zone covers the other takes that
    zone as its common part, with no intersection computed (so nested zones cost one
    predicate a pair); the others are intersected."""
    if len(outlines) < 2:
        return []
    polygons = np.array([outline.polygon for outline in outlines], dtype=object)
    left, right = shapely.STRtree(polygons).query(polygons)
    pairs = left < right
    order = np.lexsort((right[pairs], left[pairs]))
    left, right = left[pairs][order], right[pairs][order]
    first, second = polygons[left], polygons[right]
    within = np.where(
        shapely.covers(first, second), right, np.where(shapely.covers(second, first), left, -1)
    )
    crossed = np.flatnonzero(within < 0)
    commons = shapely.intersection(first[crossed], second[crossed])
    common = dict(zip(crossed.tolist(), commons, strict=True))
    found = []
    for k, (i, j) in enumerate(zip(left.tolist(), right.tolist(), strict=True)):
        if within[k] >= 0:
            found.append(ZonePair(i, j, int(within[k])))
        elif parts := _parts(common[k]):
            found.append(ZonePair(i, j, None, parts, common[k]))
    return found


def shared_areas(triangles: MapTriangles, covers: list[ZoneCover], pairs: list[ZonePair]):
    """(p,) float: the surface area each pair of zones shares (docs/math.md, section 12).

    A zone inside the other shares its own area. Two that partly overlap share, on each
    triangle, the other's share where one holds it wholly; only on the triangles both
    outlines cut is their common part clipped to the triangle (GEOS, all such triangles of
    all pairs in one call). So the cost is in proportion to the zones' triangles, with no
    zone measured again a pair."""
    area = triangles.surface_area
    shared = np.array(
        [covers[p.within].total(area) if p.within is not None else 0.0 for p in pairs]
    )
    crossed = [k for k, pair in enumerate(pairs) if pair.within is None]
    if not crossed:
        return shared
    whole, cut = _cover_matrices(covers, len(triangles))
    first = np.array([pairs[k].i for k in crossed])
    second = np.array([pairs[k].j for k in crossed])
    held = sparse.csr_matrix(whole.multiply(area))
    shared[crossed] = _row_dots(held[first], whole[second] + cut[second])
    shared[crossed] += _row_dots(whole[first] + cut[first], held[second])
    shared[crossed] -= _row_dots(held[first], whole[second])
    both = cut[first].multiply(cut[second] > 0).tocoo()
    if both.nnz:
        corners = triangles.corners(both.col)
        inside = shapely.area(
            shapely.intersection(
                shapely.polygons(corners),
                np.array([pairs[crossed[r]].common for r in both.row], dtype=object),
            )
        )
        ratio = inside / np.abs(triangles.signed_map_area[both.col])
        shared[crossed] += np.bincount(both.row, ratio * area[both.col], len(crossed))
    return shared


def _cover_matrices(covers: list[ZoneCover], count: int):
    """Sparse (z, m) matrices of the zones' triangles: 1 where wholly inside, and the share
    where cut."""
    rows = [np.full(len(c.inside), k) for k, c in enumerate(covers)]
    whole = sparse.csr_matrix(
        (
            np.ones(sum(map(len, rows))),
            (np.concatenate(rows), np.concatenate([c.inside for c in covers])),
        ),
        shape=(len(covers), count),
    )
    rows = [np.full(len(c.partial), k) for k, c in enumerate(covers)]
    cut = sparse.csr_matrix(
        (
            np.concatenate([c.share for c in covers]),
            (np.concatenate(rows), np.concatenate([c.partial for c in covers])),
        ),
        shape=(len(covers), count),
    )
    return whole, cut


def _row_dots(a, b) -> np.ndarray:
    """(p,) float: the dot products of the rows of two sparse (p, m) matrices."""
    return np.asarray(a.multiply(b).sum(axis=1)).ravel()


def _parts(common) -> tuple[tuple[np.ndarray, ...], ...]:
    """The polygons of positive area of a GEOS intersection, as rings."""
    return tuple(
        (_open(part.exterior), *(_open(hole) for hole in part.interiors))
        for part in shapely.get_parts(common)
        if isinstance(part, shapely.Polygon) and part.area > 0
    )


def _open(ring) -> np.ndarray:
    """(n, 2) float: a shapely ring's points without the repeated first one."""
    return np.asarray(ring.coords)[:-1, :2]


def beside_map(points: np.ndarray, x: np.ndarray, y: np.ndarray) -> bool:
    """Whether ``points`` ((n, 2) float) lie wholly beside the box of the map's ``x`` and
    ``y`` ((k,) float each): then they miss the map, whatever its shape."""
    low, high = points.min(axis=0), points.max(axis=0)
    return bool(low[0] > x.max() or high[0] < x.min() or low[1] > y.max() or high[1] < y.min())


def warn_outside(ctx: Context, region, field: str, name: str, points: np.ndarray) -> None:
    """Warn (``drawn_outside_map``) that the zone or curve ``field`` (``zones.2``, named
    ``name``), of ``points`` ((n, 2) float), lies wholly outside the map of ``region`` (a
    :class:`~.region.resolve.MeshRegion`): the map's extent in its layout's coordinates, the
    points', and whether they look like degrees (beyond the map, within 360, while the map
    is within 2 pi)."""
    (x, y), layout = region.layout, region.flat.layout
    x0, x1, y0, y1 = float(x.min()), float(x.max()), float(y.min()), float(y.max())
    low, high = points.min(axis=0), points.max(axis=0)
    kind = field.partition(".")[0].removesuffix("s")  # zone, curve
    words = (
        f"the {kind} {name!r} lies wholly outside the region's map, which spans x {x0:.4g} to "
        f"{x1:.4g} and y {y0:.4g} to {y1:.4g} (the {Layout(layout).value} layout's "
        f"coordinates); its points span x {low[0]:.4g} to {high[0]:.4g} and y "
        f"{low[1]:.4g} to {high[1]:.4g}"
    )
    reach, drawn = max(abs(x0), abs(x1), abs(y0), abs(y1)), float(np.abs(points).max())
    if reach <= 2 * np.pi and reach < drawn <= 360:
        words += (
            ": its numbers look like degrees, but the map's are radians (phi, and theta or "
            "its Mercator function): multiply degrees by pi/180"
        )
    ctx.warn(WarningCode.DRAWN_OUTSIDE_MAP, field, words)
