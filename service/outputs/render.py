"""A flattened region in the forms besides JSON: the GLB (:mod:`.glb`) and the picture of its
map as SVG or PNG (:mod:`.picture`, :mod:`.draw`). What they carry of the answer (params,
validation, metrics) comes from the same response models as the JSON answer."""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from transforms import Layout
from transforms.arrays import triangle_areas
from transforms.region import region_face_distortion
from transforms.traces import grid_offsets, plane_traces

from ..encoding import plain
from ..jobs import charge, picture_bytes
from ..params import FlattenParams, PictureParams, SitesParams, TransferParams
from ..problems import Problem
from ..schemas import Metrics, ResolvedParams, Validation
from . import Output
from .colours import ColourBy, colouring, vertex_colours
from .draw import to_png, to_svg
from .glb import layout_uv, region_glb
from .lookup import grey_alpha_png16, lookup_bytes
from .picture import Drawn, describe

if TYPE_CHECKING:
    from ..operations import Measured, MeshRegion, Placed, Registered, Transferred

#: Vertex ids travel in the GLB as float32 (glTF allows no 32-bit integer attributes).
FLOAT32_EXACT = 2**24


def glb(region: MeshRegion, params: FlattenParams, sites=None) -> bytes:
    """The region as a GLB with ``TEXCOORD_0`` from the layout (and ``sites``, points and
    normals, as a POINTS primitive: :func:`.glb.region_glb`).

    Raises
    ------
    Problem
        422 when a vertex id is beyond float32's exact integers.
    """
    flat = region.flat
    largest = int(flat.vertex_ids[-1])
    if largest >= FLOAT32_EXACT:
        raise Problem(
            422,
            f"params.output: a GLB carries vertex ids as float32, exact below "
            f"{FLOAT32_EXACT:,}; this region uses vertex {largest:,}. Ask for JSON instead.",
            "invalid-request",
            "params.output",
            [largest],
        )
    s_sign = 1.0 if flat.layout is Layout.THETA_PHI else -1.0  # s grows with theta
    x, y = region.layout  # repaired when untangled
    uv, affine = layout_uv(x, s_sign * y)
    validation = plain(Validation.of(region))
    summary = {
        key: value if not isinstance(value, np.ndarray) else len(value)
        for key, value in validation.items()
    }
    extras = {
        "params": plain(ResolvedParams.of_region(region)),
        "validation": summary,
        "metrics": plain(Metrics.of(region)),
        "uv": affine | {"s_sign": s_sign, "layout": flat.layout.value},
    }
    if region.untangled is not None:
        u = region.untangled
        extras["untangle"] = {
            "moved_vertices": len(u.moved),
            "folded_after": len(u.flipped_after),
        }
    positions = region.mesh.vertices[flat.vertex_ids]
    colours = None
    coloured = face_colouring(region, getattr(params, "colour_by", ColourBy.FLAGS))
    if coloured is not None:
        areas = triangle_areas(positions, flat.faces)
        colours = vertex_colours(flat.faces, coloured[0], areas, len(positions))
        bar = coloured[1]
        extras["colour_by"] = {
            "measure": bar.measure.value,
            "low": bar.low,
            "high": bar.high,
            "p50": bar.p50,
            "p95": bar.p95,
        }
    return region_glb(
        positions, uv, flat.vertex_ids, flat.faces, region.faces, extras, sites, colours
    )


def _picture(region: MeshRegion, params: PictureParams, drawn: tuple[Drawn, ...] = (), sites=None):
    resolved = plain(ResolvedParams.of_region(region))
    x, y = region.layout  # repaired when untangled
    flat = replace(region.flat, x=x, y=y)
    size = (params.image_width, params.image_height)
    coloured = face_colouring(region, params.colour_by)
    grid = reference_grid(region, params.grid_lines)
    return describe(flat, resolved, len(region.faces), *size, drawn, sites, coloured, grid)


def reference_grid(region: MeshRegion, count: int) -> np.ndarray | None:
    """(s, 2, 2) layout segments: where ``count`` planes square to the frame's local X axis
    and ``count`` square to its local Z axis, evenly spaced, cut the region (None: none)."""
    if count == 0:
        return None
    flat = region.flat
    points = region.mesh.vertices[flat.vertex_ids]
    x, y = region.layout
    on_map = np.column_stack([x, y])
    # Not through triangles that wrap round the map (across the seam, over a singular point).
    faces = flat.faces[flat.validation.drawn_faces(len(flat.faces))]
    rotation = region.frame.rotation  # rows: the local axes in the world
    return np.concatenate(
        [
            plane_traces(points, faces, on_map, axis, grid_offsets(points, axis, count))
            for axis in (rotation[0], rotation[2])
        ]
    )


def face_colouring(region: MeshRegion, measure: ColourBy):
    """The region's faces coloured by ``measure`` (their colours and the bar), None for the
    flags: the measures of section 7, face by face, of the layout as flattened."""
    if measure is ColourBy.FLAGS:
        return None
    found = region_face_distortion(region.mesh.vertices, region.flat, region.frame, region.chart)
    return colouring(found, measure, len(region.flat.faces))


def _drawn(measured: Measured) -> tuple[Drawn, ...]:
    scale, area = measured.mm_per_unit, measured.triangles.surface_area
    zones = tuple(
        Drawn(outline.rings, True, outline.name, _area_text(cover.total(area), scale))
        for outline, cover in measured.zones
    )
    curves = tuple(
        Drawn((line.map_points,), False, name, _length_text(line.length, scale))
        for name, line in measured.curves
    )
    return zones + curves


def _area_text(area: float, mm_per_unit: float | None) -> str:
    if mm_per_unit is None:
        return f"{area:.4g} units²"
    return f"{area * mm_per_unit**2 / 100.0:.2f} cm²"


def _length_text(length: float, mm_per_unit: float | None) -> str:
    if mm_per_unit is None:
        return f"{length:.4g} units"
    return f"{length * mm_per_unit:.1f} mm"


def map_renderers(region_of, drawn_of, sites_of=lambda result: None) -> dict:
    """The SVG and PNG renderers, ``(result, params) -> bytes``, of a result's region's map
    (``region_of(result)``) with ``drawn_of(result)`` (zones, curves) and ``sites_of(result)``
    ((n, 2) layout points or None) over it; the PNG's raster charged first, as for
    /v1/flatten."""

    def as_svg(result, params: PictureParams) -> bytes:
        picture = _picture(region_of(result), params, drawn_of(result), sites_of(result))
        return to_svg(picture)

    def as_png(result, params: PictureParams) -> bytes:
        region = region_of(result)
        charge(picture_bytes(params.image_width, params.image_height, len(region.mesh.faces)))
        return to_png(_picture(region, params, drawn_of(result), sites_of(result)))

    return {Output.SVG: as_svg, Output.PNG: as_png}


#: The forms of a flattened region besides JSON, by :class:`Output`: the GLB, and the picture
#: of its map, ``params.image_width`` by ``image_height``.
RENDERERS = {Output.GLB: glb, **map_renderers(lambda region: region, lambda region: ())}


#: The forms of measured zones besides JSON, by :class:`Output`: the map with the zones
#: filled, named and labelled with their areas, and the curves with their lengths.
MEASURE_RENDERERS = map_renderers(lambda measured: measured.region, _drawn)


# -- sites ---------------------------------------------------------------------------------


def sites_ply(placed: Placed, params: SitesParams) -> bytes:
    """The sites as a binary PLY point cloud: ``x y z`` (double), ``nx ny nz`` (float, unit
    normals) and ``face`` (int, the file's triangle id) per vertex."""
    sites = placed.sites
    row = np.dtype(
        [("x", "<f8"), ("y", "<f8"), ("z", "<f8"), ("nx", "<f4"), ("ny", "<f4"),
         ("nz", "<f4"), ("face", "<i4")]
    )  # fmt: skip
    table = np.empty(len(sites.triangles), dtype=row)
    for k, axis in enumerate("xyz"):
        table[axis] = sites.points[:, k]
        table[f"n{axis}"] = placed.normals[:, k]
    table["face"] = placed.region.faces[sites.triangles]
    header = (
        "ply\nformat binary_little_endian 1.0\ncomment meshflat sites\n"
        f"element vertex {len(table)}\n"
        "property double x\nproperty double y\nproperty double z\n"
        "property float nx\nproperty float ny\nproperty float nz\n"
        "property int face\nend_header\n"
    )
    return header.encode("ascii") + table.tobytes()


def sites_glb(placed: Placed, params: SitesParams) -> bytes:
    """The region as /v1/flatten's GLB, with the sites as a POINTS primitive (none when no
    site was placed: glTF has no empty accessors)."""
    sites = (placed.sites.points, placed.normals) if len(placed.sites.points) else None
    return glb(placed.region, params, sites)


def _site_zones(placed: Placed) -> tuple[Drawn, ...]:
    return tuple(
        Drawn(zone.outline.rings, True, zone.name, f"{zone.quota:,} sites")
        for zone in placed.zones
        if zone.outline is not None
    )


#: The forms of placed sites besides JSON, by :class:`Output`.
SITES_RENDERERS = {
    Output.PLY: sites_ply,
    Output.GLB: sites_glb,
    # The map with the zones and the sites (an SVG draws up to SVG_SITES of them).
    **map_renderers(lambda placed: placed.region, _site_zones, lambda placed: placed.map_points),
}


# -- a follow-up registered ------------------------------------------------------------------


def _overlay(registered: Registered) -> tuple[Drawn, ...]:
    edges = registered.follow_boundary
    follow = Drawn(tuple(edges), False, "follow-up", f"boundary, {len(edges):,} edges")
    zones = tuple(Drawn(zone.rings, True, zone.name, "zone") for zone in registered.zones)
    return (follow, *zones)


#: The forms of a registration besides JSON, by :class:`Output`: the baseline's map with its
#: region's boundary, the follow-up's (mapped with the frame the answer gives it) and the
#: zones.
REGISTER_RENDERERS = map_renderers(lambda registered: registered.region, _overlay)


# -- values between the map and the mesh -------------------------------------------------------


def _drawn_png(transferred: Transferred, params: TransferParams) -> bytes:
    """The values drawn (the operation refuses output png without them), coverage as alpha."""
    return grey_alpha_png16(transferred.image, transferred.ids >= 0)


def _lookup(transferred: Transferred, params: TransferParams) -> bytes:
    return lookup_bytes(transferred.ids, transferred.weights)


TRANSFER_RENDERERS = {
    Output.PNG: _drawn_png,
    Output.FACE_IDS: _lookup,
    Output.BARYCENTRIC: _lookup,
}
