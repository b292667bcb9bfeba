"""The zones and curves of a /v1/measure request as the core takes them: rings checked with
GEOS (through shapely: simple, at least three distinct points, holes inside the outer ring
and apart), and the zones' pairwise overlaps as polygons of their own.

A bad ring is a 422 naming the zone (its position and name) and the ring.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np
import shapely

from .params import Curve, Ring, Zone
from .problems import Problem

#: Where GEOS says a polygon is invalid: "Self-intersection[x y]".
_WHERE = re.compile(r"\[(?P<x>\S+) (?P<y>\S+)\]")


@dataclass(frozen=True)
class Outline:
    """A zone checked: its rings as (n, 2) float arrays, the outer one first, none closed
    by repeating its first point; and the polygon they bound."""

    name: str
    rings: tuple[np.ndarray, ...]
    polygon: shapely.Polygon


def checked_zone(zone: Zone, number: int) -> Outline:
    """The zone's rings, checked.

    Raises
    ------
    Problem
        422: a ring of fewer than three distinct points, a ring that crosses or touches
        itself, a hole outside the outer ring, holes that cross or nest.
    """
    field = f"params.zones.{number}"
    label = f"{field} ({zone.name!r})"
    rings = [_ring(zone.outer, f"{field}.outer", f"{label}, outer ring")]
    rings += [
        _ring(hole, f"{field}.holes.{k}", f"{label}, hole {k}") for k, hole in enumerate(zone.holes)
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
            raise Problem(
                422,
                f"{label}, hole {hole}: a hole must lie inside the outer ring{where}",
                "invalid-request",
                f"{field}.holes.{hole}",
            )
        raise Problem(
            422,
            f"{label}: its holes must lie apart from each other and from the outer ring{where}",
            "invalid-request",
            f"{field}.holes",
        )
    return Outline(zone.name, tuple(rings), polygon)


def _ring(ring: Ring, field: str, label: str) -> np.ndarray:
    points = _distinct_in_turn(ring.x, ring.y)
    if len(points) > 1 and (points[0] == points[-1]).all():
        points = points[:-1]  # closed by repeating the first point
    distinct = len(np.unique(points, axis=0))
    if distinct < 3:
        raise Problem(
            422,
            f"{label}: a ring needs at least three distinct points; it has {distinct}",
            "invalid-request",
            field,
        )
    if not shapely.LinearRing(points).is_simple:
        where = _where(shapely.is_valid_reason(shapely.Polygon(points)))
        raise Problem(
            422,
            f"{label}: the ring crosses or touches itself{where}; draw it without crossings",
            "invalid-request",
            field,
        )
    return points


def checked_curve(curve: Curve, number: int) -> np.ndarray:
    """(n, 2) float: the curve's points, repeated ones dropped.

    Raises
    ------
    Problem
        422: fewer than two distinct points.
    """
    points = _distinct_in_turn(curve.x, curve.y)
    if len(points) < 2:
        field = f"params.curves.{number}"
        raise Problem(
            422,
            f"{field} ({curve.name!r}): a curve needs at least two distinct points",
            "invalid-request",
            field,
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


def overlaps(outlines: list[Outline]) -> list[tuple[int, int, list[tuple[np.ndarray, ...]]]]:
    """The pairs of zones whose areas overlap, with their common part as zones of their own
    (rings as :class:`Outline` holds them): ``(i, j, parts)`` for ``i < j``."""
    if len(outlines) < 2:
        return []
    polygons = [outline.polygon for outline in outlines]
    tree = shapely.STRtree(polygons)
    found = []
    left, right = tree.query(polygons, predicate="intersects")
    for i, j in zip(left.tolist(), right.tolist(), strict=True):
        if i >= j:
            continue
        common = shapely.intersection(polygons[i], polygons[j])
        parts = [
            (_open(part.exterior), *(_open(hole) for hole in part.interiors))
            for part in shapely.get_parts(common)
            if isinstance(part, shapely.Polygon) and part.area > 0
        ]
        if parts:
            found.append((i, j, parts))
    return sorted(found, key=lambda item: item[:2])


def _open(ring) -> np.ndarray:
    """(n, 2) float: a shapely ring's points without the repeated first one."""
    return np.asarray(ring.coords)[:-1, :2]
