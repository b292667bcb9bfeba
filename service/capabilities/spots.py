"""The spots of ``POST /v1/compare``: points on the baseline's map where values were
measured (a trichoscope's pictures), each lifted to the baseline's surface and found again
on the follow-up's, where to put the trichoscope next time (docs/math.md, section 22,
eq. 22.3); their values as measured, or read from the scans' values."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydantic import Field

from transforms import MapTriangles
from transforms.arrays import as_points
from transforms.compare import moved, nearest_on_surface, relative_change, values_at
from transforms.layouts import layout_xy

from ..encoding import Answer
from .context import Context
from .fields import Coordinate, Name, Strict
from .register import Registered, RegisterInput
from .warnings import WarningCode

#: A spot is found again on the follow-up when the follow-up's surface passes within this
#: distance of where the registration puts it (mm): as far as /v1/register's overlap.
SPOT_REACH_MM = 2.0


class Spot(Strict):
    """A point on the baseline's map where values were measured (a trichoscope's picture)."""

    name: Name
    x: Coordinate = Field(description="Its x on the baseline's map (the layout's coordinates).")
    y: Coordinate = Field(description="Its y on the baseline's map.")
    baseline: Coordinate | None = Field(None, description="The value measured there at baseline.")
    follow_up: Coordinate | None = Field(None, description="The value measured there at follow-up.")


@dataclass(frozen=True)
class ScanMap:
    """A scan's region on the baseline's map and its values.

    Attributes
    ----------
    triangles : MapTriangles, the region on the map and on its surface
    values : (k,) float or None, a value at each of the region's vertices (NaN: none);
        None when the scan has no values
    """

    triangles: MapTriangles
    values: np.ndarray | None


@dataclass(frozen=True)
class SpotFound:
    """A spot on both scans.

    Attributes
    ----------
    spot : Spot, as sent
    baseline_position : (3,) float or None, on the baseline's surface (None: off its map)
    follow_up_position : (3,) float or None, the follow-up's nearest surface point to where
        the registration puts it (None: none within SPOT_REACH_MM)
    follow_up_xy : (2,) float or None, that point on the follow-up's map
    distance : float or None, from where the registration puts the spot to that point, mm
        (None beyond SPOT_REACH_MM)
    baseline_value, follow_up_value : float or None, as sent, else read from the values
    """

    spot: Spot
    baseline_position: np.ndarray | None
    follow_up_position: np.ndarray | None
    follow_up_xy: np.ndarray | None
    distance: float | None
    baseline_value: float | None
    follow_up_value: float | None


def find_spots(ctx: Context, given: RegisterInput, registered: Registered, base: ScanMap,
           follow: ScanMap, scale: float) -> tuple[SpotFound, ...]:  # fmt: skip
    """Each spot on the baseline's surface (by its map point), found again on the
    follow-up's (the nearest point to where the registration puts it), with its values."""
    spots = given.params.spots
    if not spots:
        return ()
    points = np.array([[spot.x, spot.y] for spot in spots], dtype=np.float64)
    triangle, weights = base.triangles.locate(points)
    held = np.flatnonzero(triangle >= 0)
    positions = np.full((len(spots), 3), np.nan)
    positions[held] = base.triangles.lift(triangle[held], weights[held])
    found = registered.on.found
    mesh = given.follow_up
    there = moved(np.linalg.inv(found.matrix), positions[held])
    to_mm = found.scale * scale  # follow-up units to the baseline's, to mm
    near = nearest_on_surface(mesh.vertices, mesh.faces, there, SPOT_REACH_MM / to_mm)
    distance = np.full(len(spots), np.nan)
    distance[held] = near.distance * to_mm
    feet = np.full((len(spots), 3), np.nan)
    feet[held] = near.points
    reached = np.flatnonzero(distance <= SPOT_REACH_MM)
    distance[distance > SPOT_REACH_MM] = np.nan  # beyond reach, not measured
    on_map = np.full((len(spots), 2), np.nan)
    if len(reached):
        region = registered.region
        naming = ("spots", "spot", reached)
        points_there = as_points(feet[reached], "spots")
        theta, phi, _ = region.chart.forward_checked(
            points_there, registered.frame, ctx.threads, naming
        )
        on_map[reached] = np.column_stack(layout_xy(theta, phi, region.flat.layout))
    read = {
        "baseline": _read(base, points),
        "follow_up": _read(follow, on_map),
    }
    reach = np.zeros(len(spots), dtype=bool)
    reach[reached] = True
    answers = []
    for k, spot in enumerate(spots):
        answers.append(
            SpotFound(
                spot,
                positions[k] if np.isfinite(positions[k, 0]) else None,
                feet[k] if reach[k] else None,
                on_map[k] if reach[k] else None,
                None if np.isnan(distance[k]) else float(distance[k]),
                _given_or(spot.baseline, read["baseline"][k]),
                _given_or(spot.follow_up, read["follow_up"][k]),
            )
        )
        _warn_of_spot(ctx, answers[-1], k)
    return tuple(answers)


def _read(scan: ScanMap, points: np.ndarray) -> np.ndarray:
    """(s,) float: the scan's values at map ``points`` ((s, 2); NaN rows: none), NaN
    where it has none."""
    found = np.full(len(points), np.nan)
    known = np.isfinite(points).all(axis=1)
    if scan.values is not None and known.any():
        found[known] = values_at(scan.triangles, points[known], scan.values)
    return found


def _given_or(given: float | None, read: float) -> float | None:
    """A spot's value as sent, else as read from the scan's values (None: neither)."""
    if given is not None:
        return given
    return None if np.isnan(read) else float(read)


def _warn_of_spot(ctx: Context, found: SpotFound, k: int) -> None:
    """The ``spot_off_scan`` warning: a spot off the baseline's map, or with no follow-up
    surface within reach of where the registration puts it."""
    name = found.spot.name
    if found.baseline_position is None:
        why = (
            f"the spot {name!r} at ({found.spot.x:.4g}, {found.spot.y:.4g}) is on no "
            "triangle of the baseline's map: it has no place on either scan"
        )
    elif found.follow_up_position is None:
        why = (
            f"the spot {name!r} has no follow-up surface within {SPOT_REACH_MM:g} mm of "
            "where the registration puts it: the follow-up does not show that part of the head"
        )
    else:
        return
    ctx.warn(WarningCode.SPOT_OFF_SCAN, f"spots.{k}", why)


def number_or_none(value: float) -> float | None:
    """A float, None for NaN (an answer carries no NaN)."""
    return None if value is None or np.isnan(value) else float(value)


class SpotCompared(Answer):
    name: str
    x: float = Field(description="As sent: the spot on the baseline's map.")
    y: float
    baseline_position: list[float] | None = Field(
        description="The spot on the baseline's surface, in its file's coordinates; null "
        "when no triangle of the baseline's map holds it."
    )
    follow_up_position: list[float] | None = Field(
        description="The same spot on the follow-up's surface, in its file's coordinates: "
        "the follow-up's nearest point to where the registration puts the baseline's; null "
        f"when none is within {SPOT_REACH_MM:g} mm."
    )
    follow_up_x: float | None = Field(
        description="follow_up_position on the follow-up's map (the registration's frame): "
        "where to put the trichoscope next time."
    )
    follow_up_y: float | None
    distance_mm: float | None = Field(
        description="From where the registration puts the spot to follow_up_position, mm."
    )
    baseline: float | None = Field(
        description="The baseline's value there: as sent, else read from the baseline's "
        "values (linear inside the triangle), else null."
    )
    follow_up: float | None = Field(description="The follow-up's, likewise.")
    change: float | None = Field(description="follow_up - baseline.")
    change_percent: float | None = Field(description="100 x change / |baseline|.")

    @classmethod
    def of(cls, found: SpotFound) -> SpotCompared:
        both = found.baseline_value is not None and found.follow_up_value is not None
        change, percent = (
            relative_change(found.baseline_value, found.follow_up_value)
            if both
            else (np.nan, np.nan)
        )
        xy = found.follow_up_xy
        return cls.build(
            name=found.spot.name,
            x=found.spot.x,
            y=found.spot.y,
            baseline_position=found.baseline_position,
            follow_up_position=found.follow_up_position,
            follow_up_x=None if xy is None else float(xy[0]),
            follow_up_y=None if xy is None else float(xy[1]),
            distance_mm=found.distance,
            baseline=found.baseline_value,
            follow_up=found.follow_up_value,
            change=number_or_none(change),
            change_percent=number_or_none(percent),
        )
