"""``POST /v1/locate``: the surface points of directions on the map, by the ray from the
centre or by the map's own triangles (docs/math.md, sections 10 and 12)."""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import Annotated

import numpy as np
from pydantic import ConfigDict, Field, model_validator

from transforms import Chart, Frame, Hits, Layout, LocateIndex, layout_xy, locate
from transforms.viewpoint import check_center_sees_area

from ..encoding import Answer
from ..errors import check_count
from ..meshio import Mesh
from .context import Context
from .fields import Number, choice
from .region.answers import ResolvedParams
from .region.params import MESH_PARAMS_EXAMPLE, MeshParams
from .region.resolve import (
    MeshInput,
    Resolved,
    Selection,
    facing_of,
    flatten,
    map_triangles,
    region_faces,
    resolved_region,
)
from .rows import MeshCapability
from .warnings import WarnedAnswer


class LocateVia(StrEnum):
    """How /v1/locate finds the surface point of a query (docs/math.md, section 12)."""

    RAY = "ray"
    MAP = "map"


class LocateParams(MeshParams):
    """The JSON of the ``params`` field of /v1/locate: a region and its frame as for
    /v1/flatten (``"auto"`` allowed), and the query directions."""

    theta: Annotated[list[Number], Field(min_length=1, fail_fast=True)] = Field(
        description="Polar angles of the query directions, radians, in [0, pi], in the frame "
        "the other params resolve to."
    )
    phi: Annotated[list[Number], Field(min_length=1, fail_fast=True)] = Field(
        description="Azimuths, radians, in [-pi, pi]; one per theta."
    )
    via: choice(LocateVia) = Field(
        LocateVia.RAY,
        description="ray: the point the ray from the centre in direction (theta, phi) meets "
        "first. map: the point the map shows at (theta, phi): the layout's (x, y) of those "
        "angles (the answered layout, untangled when untangle is set) in the region triangle "
        "that holds it, lifted with the same barycentric weights (the map is linear inside "
        "each triangle, as the GLB's UVs and the pictures draw it).",
    )

    model_config = ConfigDict(
        json_schema_extra={
            "examples": [{**MESH_PARAMS_EXAMPLE, "theta": [1.5, 1.7], "phi": [-1.6, -1.4]}]
        }
    )

    @model_validator(mode="after")
    def _one_phi_per_theta(self) -> LocateParams:
        if len(self.phi) != len(self.theta):
            raise ValueError(
                f"theta, phi: one phi per theta; got {len(self.theta)} theta and "
                f"{len(self.phi)} phi"
            )
        return self


@dataclass(frozen=True)
class Located:
    """Where the query directions meet the region.

    Attributes
    ----------
    chart, frame : what the directions were read in
    selection : Selection, the region's file face ids and the region as answers repeat it
    hits : Hits, face positions in ``selection.faces``, points in the local frame
    layout : Layout, of the params (for the answer's params)
    format : str, the format the mesh was read as
    untangle : bool, whether the map was untangled (``via`` map) or the params asked for it
    facing : (3,) float or None, where the face looks (for the answer's params)
    """

    chart: Chart
    frame: Frame
    selection: Selection
    hits: Hits
    layout: Layout
    format: str
    untangle: bool
    facing: np.ndarray | None = None

    @property
    def found(self) -> np.ndarray:
        """(k,) bool: the queries whose ray meets the region."""
        return self.hits.faces >= 0


def locate_directions(given: MeshInput[LocateParams], ctx: Context) -> Located:
    """For each ``(theta, phi)`` of ``params``, the region triangle the ray from the centre
    meets first (:func:`transforms.locate`)."""
    mesh, params = given.mesh, given.params
    check_count(len(params.theta), ctx.settings.max_points, "theta")
    if params.via is LocateVia.MAP:
        return _locate_on_map(given, ctx)
    resolved = resolved_region(given, ctx)
    selection, chart, frame, _ = resolved
    directions = chart.inverse(params.theta, params.phi, 1.0)
    # A rotation keeps the triangle a ray meets, the weights and the depth: the rays turn to
    # the world's axes instead of every vertex to the frame's, and the few hit points back.
    rotation = frame.rotation
    if ctx.holds(resolved):  # a held mesh keeps the region's index for the next click
        index = ctx.remembered(resolved, "locate_index", lambda _: _index(mesh, resolved))
        hits = index.query(directions @ rotation)
    else:
        faces = _seen_faces(mesh, resolved)
        hits = locate(mesh.vertices - frame.center, faces, directions @ rotation)
    hits = Hits(hits.faces, hits.barycentric, hits.points @ rotation.T)
    facing = facing_of(params)
    return Located(
        chart, frame, selection, hits, params.layout, mesh.format, params.untangle, facing
    )


def _seen_faces(mesh: Mesh, resolved: Resolved) -> np.ndarray:
    """(m, 3) int: the region's faces, checked to be seen from the centre."""
    faces = region_faces(mesh, resolved.selection)
    # Seen edge-on from the centre, the region has nothing to hit (the flatten routes refuse
    # such a centre in the core; a fixed frame and sigma reach locate without it).
    check_center_sees_area(mesh.vertices, faces, resolved.frame.center)
    return faces


def _index(mesh: Mesh, resolved: Resolved) -> LocateIndex:
    """The locate index of the region's triangles about its centre (every vertex given, so
    that an error names the file's vertex ids)."""
    faces = _seen_faces(mesh, resolved)
    return LocateIndex.build(mesh.vertices - resolved.frame.center, faces)


def _locate_on_map(given: MeshInput[LocateParams], ctx: Context) -> Located:
    """For each ``(theta, phi)`` of ``params``, the point the map shows there: the layout's
    point of those angles in the region triangle that holds it, lifted with the same
    barycentric weights (:meth:`transforms.MapTriangles.locate`)."""
    params = given.params
    region = flatten(given, ctx)
    triangles = map_triangles(region, ctx)
    x, y = layout_xy(np.asarray(params.theta), np.asarray(params.phi), params.layout)
    faces, weights = triangles.locate(np.column_stack([x, y]))
    found = faces >= 0
    points = np.full((len(faces), 3), np.nan)
    points[found] = triangles.lift(faces[found], weights[found])
    local = region.frame.to_local(points[found])
    hits = Hits(faces, weights, np.full((len(faces), 3), np.nan))
    hits.points[found] = local
    untangled = region.untangled is not None
    return Located(
        region.chart,
        region.frame,
        region.selection,
        hits,
        params.layout,
        given.mesh.format,
        untangled,
        region.facing,
    )


class Hit(Answer):
    face: int = Field(description="The region triangle's id in the file.")
    barycentric: list[float] = Field(
        description="Weights of the triangle's three vertices (file order) at the hit."
    )
    point: list[float] = Field(description="The hit point, world coordinates.")


class LocateResponse(WarnedAnswer):
    params: ResolvedParams
    hits: list[Hit | None] = Field(description="Per query; null where the ray misses.")

    @classmethod
    def of(cls, located: Located) -> LocateResponse:
        hits, found = located.hits, located.found
        world = located.frame.to_world(np.where(found[:, None], hits.points, 0.0))
        ids = np.where(found, located.selection.faces[np.maximum(hits.faces, 0)], -1).tolist()
        weights = np.where(found[:, None], hits.barycentric, 0.0).tolist()
        answers = Hit.rows(found.tolist(), face=ids, barycentric=weights, point=world.tolist())
        params = ResolvedParams.of(
            located.chart,
            located.frame,
            located.layout,
            located.selection,
            format=located.format,
            untangle=located.untangle,
            facing=None if located.facing is None else located.facing.tolist(),
        )
        return cls.build(params=params, hits=answers)


ROWS = (
    MeshCapability(
        name="locate_points",
        path="/v1/locate",
        summary="Find the surface points of directions on the map",
        description="Multipart like /v1/flatten; `params` also holds the queries, `theta` and "
        "`phi` (radians, in the frame the other params resolve to). Answers, per query, the "
        "region triangle the ray from the centre in that direction meets first (`via: ray`, "
        "the default) or the region triangle whose image on the map holds the layout's point "
        "of those angles (`via: map`: the point a picture or the GLB's UVs show there), the "
        "barycentric weights of the hit (of the triangle's vertices in file order) and the hit "
        "point (world coordinates), or null where the ray misses the region or no triangle "
        "holds the map point.",
        params=LocateParams,
        operation=locate_directions,
        response=LocateResponse,
    ),
)
