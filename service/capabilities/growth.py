"""``growth`` of ``/v1/sites``: which way the hair grows at each site. A field drawn on the
map (flow curves, whorls), pushed onto the surface and tilted off it by an exit angle
(:mod:`transforms.growth`, docs/math.md, section 19)."""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import Annotated

import numpy as np
import shapely
from pydantic import Field
from scipy.spatial import cKDTree

from transforms import MapTriangles, lift_curve, world_to_angles
from transforms.growth import FlowsDisagree, GrowthField, growth_field, pushed_forward
from transforms.layouts import layout_xy
from transforms.sites import Sites

from ..encoding import Answer
from ..errors import InvalidInput
from ..outputs.colours import STEPS, palette
from ..outputs.picture import Drawn
from .context import Context
from .drawn import Curve, charge_crossings, check_drawn, check_names, checked_curve
from .fields import Coordinate, Strict, choice
from .region.heads import checked_landmarks
from .region.resolve import MeshRegion

#: A site's stroke in the GLB, millimetres: long enough to see, short of its neighbours at
#: the densities of a plan (1 to 2 mm apart).
STROKE_MM = 3.0
#: A whorl's mark on the map: a circle of this share of the map's larger side.
WHORL_MARK = 0.015

#: The exit angle when none is given, degrees: the low end of the hairline's 10-20 degrees
#: in the transplant literature, where a plan is most often drawn.
DEFAULT_EXIT_ANGLE_DEG = 20.0
ExitAngle = Annotated[float, Field(ge=0, le=90, allow_inf_nan=False)]


class WhorlTurn(StrEnum):
    CLOCKWISE = "clockwise"
    COUNTERCLOCKWISE = "counterclockwise"


class Whorl(Strict):
    """A point where the hair turns round (the crown), on the map."""

    x: Coordinate = Field(description="The layout's x.")
    y: Coordinate = Field(description="The layout's y.")
    turn: choice(WhorlTurn) = Field(
        description="The sense the hair turns in about it, as seen from outside the head."
    )


class Growth(Strict):
    """Which way the hair grows: flow curves and whorls drawn on the map, and the angle
    between the hair and the scalp."""

    flow: Annotated[list[Curve], Field(max_length=256)] = Field(
        [],
        description="Polylines in the layout's coordinates (as /v1/measure's curves): the "
        "hair grows along each, from its first point to its last.",
    )
    whorls: Annotated[list[Whorl], Field(max_length=64)] = Field(
        [],
        description="Points where the hair turns round: the field spirals about each, once "
        "(index +1), in the sense given.",
    )
    exit_angle_deg: ExitAngle = Field(
        DEFAULT_EXIT_ANGLE_DEG,
        description="The angle between the hair and the scalp's tangent plane, degrees (0-90; "
        "default 20, the hairline's range in the literature being 10-20); a zone's own "
        "exit_angle_deg takes its place there.",
    )


@dataclass(frozen=True)
class Grown:
    """The growth at each site, and per zone.

    Attributes
    ----------
    direction : (n, 3) float, unit: ``cos(a) t + sin(a) n``
    tangent : (n, 3) float, unit, orthogonal to the site's normal
    exit_angle : (n,) float, degrees
    map_direction : (n, 2) float, unit
    zone_exit_angle : (z,) float, degrees, each zone's mean
    zone_turn : (z,) float or NaN, degrees: each zone's largest turn of direction between
        sites within two spacings (NaN for fewer than two sites)
    field : GrowthField
    whorls : (k, 2) float and turns (k,) str: the whorls used (the default one included)
    flows : tuple of (n_i, 2) float, the flows' points
    """

    direction: np.ndarray
    tangent: np.ndarray
    exit_angle: np.ndarray
    map_direction: np.ndarray
    zone_exit_angle: np.ndarray
    zone_turn: np.ndarray
    field: GrowthField
    whorls: np.ndarray
    turns: tuple[str, ...]
    flows: tuple[np.ndarray, ...]
    exit_angle_default: float


@dataclass(frozen=True)
class SitesAt:
    """What :func:`grow` reads of placed sites: the sites, their normals and map points,
    each zone's exit angle and spacing (None: no site)."""

    sites: Sites
    normals: np.ndarray
    map_points: np.ndarray
    exit_angles: list[float]
    spacings: list[float | None]


def check_growth(ctx: Context, growth: Growth, zones) -> list[np.ndarray]:
    """The flows' points, checked before the region is flattened; their points count with
    the zones' against MESHFLAT_MAX_DRAWN_POINTS."""
    check_names("growth.flow", growth.flow)
    check_drawn(ctx, zones, growth.flow, cover=False, curves_field="growth.flow")
    return [checked_curve(flow, k, "growth.flow") for k, flow in enumerate(growth.flow)]


def grow(
    ctx: Context,
    params,
    flows: list[np.ndarray],
    region: MeshRegion,
    triangles: MapTriangles,
    at: SitesAt,
) -> Grown:
    """The growth at the sites ``at``: the field of ``params.growth``'s flows and whorls on
    the map (:func:`transforms.growth.growth_field`; with neither, a whorl at the vertex of
    the params' landmarks), pushed forward onto the surface and tilted by the exit angle.

    Raises
    ------
    InvalidInput
        Flows that cross, point against each other or lie wholly off the region; a whorl
        off the region; neither flows, whorls nor landmarks.
    """
    growth = params.growth
    _check_crossing(growth.flow, flows)
    charge_crossings(ctx, triangles, flows, "growth.flow")
    lifted = [lift_curve(triangles, points) for points in flows]
    for k, line in enumerate(lifted):
        if not (line.faces >= 0).any():
            raise InvalidInput(f"growth.flow.{k}", "lies wholly off the region's map",
                               name=growth.flow[k].name)  # fmt: skip
    whorls, turns = _whorls(params, region, triangles)
    on_map = np.array([1 if turn == WhorlTurn.COUNTERCLOCKWISE else -1 for turn in turns])
    try:
        field = growth_field(triangles, lifted, whorls, on_map * triangles.front)
    except FlowsDisagree as error:
        raise _disagreeing(growth, error) from None
    sites = at.sites
    map_direction = field.map_directions(at.map_points, sites.triangles)
    tangent, map_direction = pushed_forward(triangles, sites.triangles, map_direction, at.normals)
    angle = np.asarray(at.exit_angles, dtype=np.float64)[sites.part] if len(sites.part) else (
        np.empty(0))  # fmt: skip
    rad = np.radians(angle)[:, None]
    direction = np.cos(rad) * tangent + np.sin(rad) * at.normals
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    zone_angle = np.asarray(at.exit_angles, dtype=np.float64)
    turn = np.array([
        _largest_turn(sites.points[sites.part == k], direction[sites.part == k], spacing)
        for k, spacing in enumerate(at.spacings)
    ])  # fmt: skip
    return Grown(direction, tangent, angle, map_direction, zone_angle, turn, field, whorls,
                 turns, tuple(flows), growth.exit_angle_deg)  # fmt: skip


def _check_crossing(given: list[Curve], flows: list[np.ndarray]) -> None:
    lines = [shapely.LineString(points) for points in flows]
    if len(lines) < 2:
        return
    tree = shapely.STRtree(lines)
    left, right = tree.query(lines, predicate="crosses")
    pairs = sorted((int(i), int(j)) for i, j in zip(left, right, strict=True) if i < j)
    if pairs:
        i, j = pairs[0]
        meet = shapely.get_coordinates(lines[i].intersection(lines[j]))[0]
        raise InvalidInput(
            f"growth.flow.{j}",
            "flow curves may not cross (the hair would grow two ways there)",
            name=given[j].name,
            about=f" crosses growth.flow.{i} ({given[i].name!r}) near "
            f"({meet[0]:.6g}, {meet[1]:.6g})",
        )


def _disagreeing(growth: Growth, error: FlowsDisagree) -> InvalidInput:
    first, second = growth.flow[error.first], growth.flow[error.second]
    near = f" near ({error.where[0]:.6g}, {error.where[1]:.6g})"
    if error.first == error.second:
        return InvalidInput(f"growth.flow.{error.first}", "points against itself",
                            name=first.name, about=near)  # fmt: skip
    return InvalidInput(
        f"growth.flow.{error.second}",
        "flow curves that point against each other leave the hair no direction between them",
        name=second.name,
        about=f" points against growth.flow.{error.first} ({first.name!r}){near}",
    )


def _whorls(params, region: MeshRegion, triangles: MapTriangles):
    """(k, 2) map points and turns of the whorls, each checked on the region's map; with
    neither flows nor whorls, the default: one turning clockwise at the vertex landmark (or
    straight up from the landmarks' centre)."""
    growth = params.growth
    if growth.whorls:
        points = np.array([[w.x, w.y] for w in growth.whorls], dtype=np.float64)
        found, _ = triangles.locate(points)
        for k in np.flatnonzero(found < 0):
            raise InvalidInput(f"growth.whorls.{k}", "lies off the region's map: "
                               f"({points[k, 0]:.6g}, {points[k, 1]:.6g})")  # fmt: skip
        return points, tuple(WhorlTurn(w.turn) for w in growth.whorls)
    if growth.flow:
        return np.empty((0, 2)), ()
    top = _vertex_point(params, region)
    if top is None:
        raise InvalidInput(
            "growth.flow",
            "give the flow (curves along which the hair grows) or whorls; or the head's "
            "landmarks (params.frame or region.scalp), for the default pattern",
        )
    theta, phi, _ = world_to_angles(top[None, :], region.frame, region.chart)
    x, y = layout_xy(theta, phi, region.flat.layout)
    return np.array([[float(x[0]), float(y[0])]]), (WhorlTurn.CLOCKWISE,)


def _vertex_point(params, region: MeshRegion) -> np.ndarray | None:
    """The vertex landmark of the params, or a point straight up from the landmark frame's
    centre (against its pole, local +Y, which points down the neck); None without them."""
    given = params.frame.landmarks if params.frame is not None else None
    field = "frame.landmarks"
    if given is None and params.region is not None and params.region.scalp is not None:
        given, field = params.region.scalp.landmarks, "region.scalp.landmarks"
    if given is None:
        return None
    landmarks = checked_landmarks(region.mesh, given, field)
    named = landmarks.named()
    if "vertex" in named:
        return np.asarray(named["vertex"], dtype=np.float64)
    frame = landmarks.frame()
    return frame.center - frame.rotation[1]


def _largest_turn(points: np.ndarray, directions: np.ndarray, spacing: float | None) -> float:
    """Degrees: the largest angle between the directions of two sites within two spacings;
    NaN for fewer than two sites."""
    if len(points) < 2 or spacing is None:
        return float("nan")
    pairs = cKDTree(points).query_pairs(2.0 * spacing, output_type="ndarray")
    if len(pairs) == 0:
        return 0.0
    cosine = np.einsum("pd,pd->p", directions[pairs[:, 0]], directions[pairs[:, 1]])
    return float(np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0))).max())


class GrowthAnswer(Answer):
    whorls: list[Whorl] = Field(
        description="The whorls the field turns about: those given, or the default one."
    )
    exit_angle_deg: float = Field(description="The exit angle of sites outside any zone's own.")


def growth_answer(grown: Grown) -> GrowthAnswer:
    return GrowthAnswer.build(
        whorls=[
            Whorl.model_construct(x=float(x), y=float(y), turn=turn.value)
            for (x, y), turn in zip(grown.whorls, grown.turns, strict=True)
        ],
        exit_angle_deg=grown.exit_angle_default,
    )


def site_growth(grown: Grown | None) -> dict:
    """The growth fields of the sites' answer (none without growth)."""
    if grown is None:
        return {}
    return {
        "direction": grown.direction,
        "tangent": grown.tangent,
        "exit_angle_deg": grown.exit_angle,
        "map_direction": grown.map_direction,
    }


def zone_growth(grown: Grown | None, k: int) -> dict:
    """The growth fields of zone ``k``'s answer (none without growth)."""
    if grown is None:
        return {}
    turn = float(grown.zone_turn[k])
    return {
        "exit_angle_deg": float(grown.zone_exit_angle[k]),
        "largest_turn_deg": turn if np.isfinite(turn) else None,
    }


def growth_lines(grown: Grown, points: np.ndarray, mm_per_unit: float):
    """The GLB's strokes: from each site ``STROKE_MM`` along its direction ((2 n, 3) ends),
    coloured by its exit angle on the colour map, 0 to 90 degrees ((2 n, 3) in [0, 1])."""
    ends = np.empty((2 * len(points), 3))
    ends[0::2] = points
    ends[1::2] = points + (STROKE_MM / mm_per_unit) * grown.direction
    steps = np.minimum((grown.exit_angle / 90.0 * STEPS).astype(np.int64), STEPS - 1)
    colours = np.repeat(palette()[steps] / 255.0, 2, axis=0)
    return ends, colours


def growth_drawn(grown: Grown, triangles: MapTriangles) -> tuple[Drawn, ...]:
    """The flows and whorls to draw over the map: each flow as a curve, each whorl as a small
    circle."""
    flows = tuple(
        Drawn((points,), False, f"flow {k}", "flow") for k, points in enumerate(grown.flows)
    )
    size = float(np.ptp(triangles.map_points, axis=0).max())
    turn = np.linspace(0.0, 2.0 * np.pi, 25)
    circle = WHORL_MARK * size * np.column_stack([np.cos(turn), np.sin(turn)])
    whorls = tuple(
        Drawn((point + circle,), False, f"whorl {k}", f"{how.value}")
        for k, (point, how) in enumerate(zip(grown.whorls, grown.turns, strict=True))
    )
    return flows + whorls
