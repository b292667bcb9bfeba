"""``POST /v1/strands``: guide hairs grown from the plan's sites along the growth field, kept
out of the head (:mod:`transforms.strands`, docs/math.md, section 20)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated

import numpy as np
from pydantic import ConfigDict, Field, model_validator

from transforms import Framing
from transforms.sites import outward_sign, vertex_normals
from transforms.strands import Curl, Roots, StrandShape, SurfaceGuard, grow_strands

from ..errors import InvalidInput
from ..outputs import Output
from ..outputs.glb import layout_uv
from ..outputs.usd import strands_usda
from .context import Context
from .fields import Strict, output_choice
from .inputs import PngFile, PngPart
from .region.answers import ResolvedParams
from .region.params import MESH_PARAMS_EXAMPLE
from .region.pictures import glb, map_renderers
from .rows import MeshCapability
from .sites import (
    DENSITY_MAP,
    Placed,
    SitesInput,
    SitesParams,
    SiteZone,
    place,
)
from .units import Units
from .warnings import WarnedAnswer

#: A strand's length, millimetres: a tenth of a millimetre to a metre.
LengthMm = Annotated[float, Field(allow_inf_nan=False, gt=0.1, le=1000.0)]
#: The arc length from the root within which a strand may lie nearer the scalp than half
#: its clearance (it leaves the skin there), millimetres.
FREE_MM = 2.0
#: What a strand point takes beside the mesh and the sites: its coordinates, the march's and
#: the guard's temporaries, its answer. `make bench-strands` measured the peak of a whole
#: request of 100,000 strands at 93 to 283 bytes a point, by form (mesh and fit included).
STRAND_POINT_BYTES = 400
#: What a curled strand point takes besides: the search for its helix's length (its path,
#: tangents, frames and a round's temporaries); the same benchmark measured the growth of
#: 100,000 curled strands of 32 points at 472 bytes a point in all.
CURL_POINT_BYTES = 800


#: Points a turn of curl at least: fewer draw a zigzag, not a helix.
POINTS_A_TURN = 4


class CurlParams(Strict):
    """A helix about the strand's path (docs/math.md, section 20)."""

    radius_mm: float = Field(
        gt=0, le=50, allow_inf_nan=False, description="The helix's radius, mm."
    )
    period_mm: float = Field(
        gt=0,
        le=1000,
        allow_inf_nan=False,
        description="The length of path a turn takes, mm.",
    )


class StrandZone(SiteZone):
    """A zone drawn on the map, its density of sites, and the length of their strands."""

    length_mm: LengthMm | None = Field(
        None, description="The length of this zone's strands (default: params.length_mm)."
    )


class StrandsParams(SitesParams):
    """The JSON of the ``params`` field of /v1/strands: everything /v1/sites takes (growth
    required), the strands' length, points, clearance and width."""

    zones: Annotated[list[StrandZone], Field(max_length=256)] = Field(
        [],
        description="Zones drawn on the map (as for /v1/sites), each with its density and "
        "optionally its strands' length_mm.",
    )
    length_mm: LengthMm | None = Field(
        None,
        description="The strands' length (arc length), mm; or per zone, or a length_map.",
    )
    length_range: Annotated[list[LengthMm], Field(min_length=2, max_length=2)] | None = Field(
        None,
        description="With a length_map part: the lengths, mm, its grey values 0 and 255 stand "
        "for, [lo, hi] (linear between).",
    )
    points: int = Field(16, ge=2, le=256, description="Points a strand (2 to 256).")
    clearance_mm: float = Field(
        1.0,
        gt=0,
        le=100,
        allow_inf_nan=False,
        description="How far above the scalp a strand lies once it has bent over, mm.",
    )
    width_mm: float = Field(
        0.08, gt=0, le=10, allow_inf_nan=False, description="A strand's width, mm."
    )
    curl: CurlParams | None = Field(
        None,
        description="A helix about each strand's path, which then runs radius_mm higher so "
        "that the curls keep the clearance; the arc length stays length_mm. At least "
        f"{POINTS_A_TURN} points a turn.",
    )
    output: output_choice(
        (Output.JSON, Output.USD, Output.PLY, Output.GLB, Output.SVG, Output.PNG),
        "json (application/json); usd (model/vnd.usda: a USD text stage, the region as a Mesh "
        "with its map as primvars:st and the strands as one linear BasisCurves with widths, "
        "each root's st and face id); ply (application/ply: the strands' points and their "
        "segments as edges); glb (model/gltf-binary: the region mesh with its UVs and a "
        "strands node, a LINES primitive); svg (image/svg+xml) or png (image/png): the map "
        "with the roots and their directions.",
    ) = None

    model_config = ConfigDict(
        json_schema_extra={
            "examples": [
                {
                    **MESH_PARAMS_EXAMPLE,
                    "density_per_cm2": 3,
                    "units": "cm",
                    "seed": 7,
                    "growth": {"whorls": [{"x": -1.55, "y": 1.55, "turn": "clockwise"}]},
                    "length_mm": 40,
                    "points": 8,
                }
            ]
        }
    )

    @model_validator(mode="after")
    def _a_length_for_each(self) -> StrandsParams:
        if self.length_range is not None:
            low, high = self.length_range
            if low > high or self.length_mm is not None:
                raise ValueError(
                    "length_range: [lo, hi] with lo <= hi, for a length_map part, without length_mm"
                )
            return self
        if self.length_mm is not None:
            return self
        missing = [i for i, zone in enumerate(self.zones) if zone.length_mm is None]
        if not self.zones or missing:
            where = f"zones.{missing[0]} gives none: " if missing else ""
            raise ValueError(
                f"length_mm: the strands' length, mm ({where}give length_mm, or each zone's, "
                "or with a length_map part length_range)"
            )
        return self


@dataclass(frozen=True)
class StrandsInput(SitesInput):
    """A strands request: the sites' inputs and the ``length_map`` part."""

    length_map: PngFile | None = None


@dataclass(frozen=True)
class Strands:
    """Strands grown from placed sites: ``points`` (n, m, 3), each strand's ``length``
    (n,), mesh units; the ``placed`` sites their roots; their ``width_mm``."""

    placed: Placed
    points: np.ndarray
    length: np.ndarray
    width_mm: float


def strands(given: StrandsInput, ctx: Context) -> Strands:
    """The sites of ``params`` (:func:`service.capabilities.sites.place`, their growth
    required) and a strand from each (:func:`transforms.strands.grow_strands`)."""
    params = given.params
    if params.growth is None:
        raise InvalidInput("growth", "strands grow along the hair's direction: give growth "
                           "(flow, whorls, or the head's landmarks)")  # fmt: skip
    if (params.length_range is None) != (given.length_map is None):
        raise InvalidInput("length_map", "a length map and params.length_range go together")
    placed = place(given, ctx)
    scale = placed.mm_per_unit
    count = len(placed.sites.triangles)
    per_point = STRAND_POINT_BYTES + (CURL_POINT_BYTES if params.curl is not None else 0)
    ctx.charge(per_point * count * params.points)
    lengths_mm = _lengths(params, given.length_map, placed, ctx)
    curl = _curl(params, lengths_mm, scale)
    lengths = lengths_mm / scale
    grown = placed.grown
    triangles = placed.triangles
    normals = vertex_normals(triangles.surface_points, triangles.faces)
    outward = outward_sign(triangles.surface_points, triangles.faces, placed.region.frame.center)
    mesh = placed.region.mesh
    roots = Roots(placed.sites.points, grown.direction, placed.normals, placed.sites.triangles,
                  placed.map_points)  # fmt: skip
    clearance = params.clearance_mm / scale
    shape = StrandShape(params.points, clearance, 2.0 * clearance, FREE_MM / scale, curl)
    guard = SurfaceGuard(mesh.vertices, mesh.faces, outward)
    points = grow_strands(triangles, grown.field, outward * normals, roots, lengths, shape, guard)
    return Strands(placed, points, lengths, params.width_mm)


def _curl(params: StrandsParams, lengths_mm: np.ndarray, scale: float) -> Curl | None:
    """The curl in mesh units (``scale`` mm each), refused when the longest strand's points
    past its first segment are fewer than ``POINTS_A_TURN`` a turn of its helix."""
    curl = params.curl
    if curl is None or not len(lengths_mm):
        return None
    longest = float(lengths_mm.max())
    # A helix of length L winds about L / sqrt(1 + (2 pi r / p)^2) of its axis.
    turns = longest / math.hypot(1.0, 2.0 * math.pi * curl.radius_mm / curl.period_mm)
    turns /= curl.period_mm
    if params.points - 2 < POINTS_A_TURN * turns:
        needed = math.ceil(POINTS_A_TURN * turns) + 2
        raise InvalidInput(
            "curl.period_mm",
            f"a strand of {longest:g} mm winds {turns:.3g} times about its path at "
            f"{curl.period_mm:g} mm a turn: {params.points} points draw fewer than "
            f"{POINTS_A_TURN} a turn; give points >= {needed} (at most 256) or a longer period",
        )
    return Curl(curl.radius_mm / scale, curl.period_mm / scale)


def _lengths(params: StrandsParams, length_map: PngFile | None, placed: Placed, ctx) -> np.ndarray:
    """(n,) float, mm: each site's strand length: its zone's, the top-level one, or the
    length map's pixel under its map point."""
    part = placed.sites.part
    if params.length_range is not None:
        image = length_map.read(params, ctx).values
        height, width = image.shape
        x, y = placed.region.layout
        framing = Framing.of(x, y, placed.region.flat.layout, width, height)
        column, row = np.floor(framing.pixels(placed.map_points)).astype(np.int64).T
        values = image[np.clip(row, 0, height - 1), np.clip(column, 0, width - 1)]
        low, high = params.length_range
        return low + (high - low) * values
    if not params.zones:
        return np.full(len(part), params.length_mm, dtype=np.float64)
    by_zone = [params.length_mm if z.length_mm is None else z.length_mm for z in params.zones]
    return np.asarray(by_zone, dtype=np.float64)[part]


class StrandsResponse(WarnedAnswer):
    params: ResolvedParams
    units: Units = Field(description="The scale used.")
    count: int = Field(description="Strands (one a site).")
    points: list[list[list[float]]] = Field(
        description="Each strand's points [x, y, z], root first: shape (count, "
        "params.points, 3), mesh units."
    )
    root_site: list[int] = Field(
        description="Each strand's site: its position in /v1/sites' answer for the same params "
        "and seed (the strands' order)."
    )
    length: list[float] = Field(description="Each strand's arc length, mesh units.")
    length_mm: list[float] = Field(description="The same in mm.")
    width_mm: float = Field(description="The strands' width, mm.")

    @classmethod
    def of(cls, grown: Strands) -> StrandsResponse:
        placed = grown.placed
        return cls.build(
            params=ResolvedParams.of_region(placed.region),
            units=Units.build(mm_per_unit=placed.mm_per_unit),
            count=len(grown.points),
            points=grown.points,
            root_site=np.arange(len(grown.points)),
            length=grown.length,
            length_mm=grown.length * placed.mm_per_unit,
            width_mm=grown.width_mm,
        )


def strands_ply(grown: Strands, params: StrandsParams, ctx: Context) -> bytes:
    """The strands as a binary PLY: every point (``x y z``, double) and every segment as an
    edge (``vertex1 vertex2``, int), strand after strand."""
    n, m, _ = grown.points.shape
    vertices = np.ascontiguousarray(grown.points.reshape(-1, 3), dtype="<f8")
    first = (np.arange(n)[:, None] * m + np.arange(m - 1)[None, :]).ravel()
    edges = np.column_stack([first, first + 1]).astype("<i4")
    header = (
        "ply\nformat binary_little_endian 1.0\ncomment meshflat strands\n"
        f"element vertex {len(vertices)}\nproperty double x\nproperty double y\n"
        f"property double z\nelement edge {len(edges)}\nproperty int vertex1\n"
        "property int vertex2\nend_header\n"
    )
    return header.encode("ascii") + vertices.tobytes() + edges.tobytes()


def strands_glb(grown: Strands, params: StrandsParams, ctx: Context) -> bytes:
    """The region as /v1/flatten's GLB, with a node of the strands: their segments as a LINES
    primitive, coloured from root (dark) to tip (light)."""
    n, m, _ = grown.points.shape
    if n == 0:
        return glb(grown.placed.region, params)
    ends = np.stack([grown.points[:, :-1], grown.points[:, 1:]], axis=2).reshape(-1, 3)
    shade = np.linspace(0.25, 0.85, m)
    along = np.stack([shade[:-1], shade[1:]], axis=1)
    tint = np.broadcast_to(along[None], (n, m - 1, 2)).reshape(-1)
    colours = np.column_stack([tint, 0.6 * tint, 0.3 * tint])
    return glb(grown.placed.region, params, None, (ends, colours), lines_name="strands")


def strands_usd(grown: Strands, params: StrandsParams, ctx: Context) -> bytes:
    """A USD text stage (:func:`service.outputs.usd.strands_usda`): the region as a Mesh,
    its map as ``st`` (the GLB's UVs), and the strands as one linear BasisCurves with each
    root's ``st`` and face id."""
    placed = grown.placed
    region, scale = placed.region, placed.mm_per_unit
    flat = region.flat
    x, y = region.layout  # repaired when untangled
    s_sign = float(flat.layout.s_sign)
    st, affine = layout_uv(x, s_sign * y)
    roots = placed.map_points
    root_st = np.column_stack(
        [roots[:, 0] - affine["x_min"], s_sign * roots[:, 1] - affine["s_min"]]
    )
    root_st = np.clip(root_st * affine["scale"], 0.0, 1.0)
    return strands_usda(
        region.mesh.vertices[flat.vertex_ids], flat.faces, st, region.faces, grown.points,
        root_st, region.faces[placed.sites.triangles], params.width_mm / scale, scale / 1000.0,
    )  # fmt: skip


LENGTH_MAP = PngPart(
    "length_map",
    "A grey PNG (8 bits) in the framing of the PNG answer: each strand takes the length of "
    "the pixel under its root on the map, params.length_range mapping grey 0-255 to mm.",
    framed=True,
    grey_only=True,
)

#: The forms of strands besides JSON, by :class:`Output`.
RENDERERS = {
    Output.USD: strands_usd,
    Output.PLY: strands_ply,
    Output.GLB: strands_glb,
    # The map with the roots and their directions (as /v1/sites' picture with growth).
    **map_renderers(
        lambda grown: grown.placed.region,
        lambda grown: (),
        lambda grown: grown.placed.map_points,
        lambda grown: grown.placed.grown.map_direction,
    ),
}

ROWS = (
    MeshCapability(
        name="strands",
        path="/v1/strands",
        summary="Grow strands (guide hairs) from the plan's sites",
        description="Multipart like /v1/sites, whose params it takes (growth required), with "
        "the strands' `length_mm` (one, per zone, or a `length_map` part with "
        "`length_range`), `points` a strand (2-256, default 16), `clearance_mm` (default 1) "
        "and `width_mm` (default 0.08), and an optional `curl` (a helix about the path: "
        "`radius_mm`, `period_mm`). A strand starts at its site, leaves along the site's "
        "direction (the exit angle), bends over towards the field's tangent and runs on at "
        "the clearance above the scalp, following the field, until its arc length is the "
        "length; no point of it lies inside the head (docs/math.md, section 20). Answers "
        "each strand's points, its site and its length; or, by the Accept header or "
        "params.output, a USD text stage, a PLY of points and edges, the region's GLB with a "
        "strands node of LINES, or the map with the roots and their directions (SVG or PNG).",
        params=StrandsParams,
        extra_parts=(DENSITY_MAP, LENGTH_MAP),
        input=StrandsInput,
        operation=strands,
        response=StrandsResponse,
        renderers=RENDERERS,
    ),
)
