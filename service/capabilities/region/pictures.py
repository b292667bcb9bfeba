"""A flattened region in the forms besides JSON: the GLB (:mod:`service.outputs.glb`) and
the picture of its map as SVG or PNG (:mod:`service.outputs.picture`,
:mod:`service.outputs.draw`), with what a route draws over it. What they carry of the answer
(params, validation, metrics) comes from the same response models as the JSON answer."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from transforms.arrays import triangle_areas
from transforms.region import region_face_distortion
from transforms.traces import grid_offsets, plane_traces

from ...encoding import plain
from ...errors import InvalidInput
from ...outputs import Output
from ...outputs.colours import ColourBy, colouring, vertex_colours
from ...outputs.draw import to_png, to_svg
from ...outputs.glb import layout_uv, region_glb
from ...outputs.picture import Drawn, describe
from ..context import Context, picture_bytes
from ..fields import PictureParams
from .answers import Metrics, ResolvedParams, Validation
from .params import MeshParams
from .resolve import MeshRegion

#: Vertex ids travel in the GLB as float32 (glTF allows no 32-bit integer attributes).
FLOAT32_EXACT = 2**24


def glb(
    region: MeshRegion,
    params: MeshParams,
    sites: tuple[np.ndarray, np.ndarray] | None = None,
    lines: tuple[np.ndarray, np.ndarray] | None = None,
    lines_name: str = "growth",
) -> bytes:
    """The region as a GLB with ``TEXCOORD_0`` from the layout (and ``sites``, (n, 3) points
    and normals, as a POINTS primitive, ``lines``, segments' ends and colours, as a LINES
    one of a node named ``lines_name``: :func:`service.outputs.glb.region_glb`).

    Raises
    ------
    InvalidInput
        ``output``: a vertex id at or beyond :data:`FLOAT32_EXACT`.
    """
    flat = region.flat
    largest = int(flat.vertex_ids[-1])
    if largest >= FLOAT32_EXACT:
        raise InvalidInput(
            "output",
            f"a GLB carries vertex ids as float32, exact below {FLOAT32_EXACT:,}; this region "
            f"uses vertex {largest:,}. Ask for JSON instead.",
            indices=[largest],
        )
    s_sign = float(flat.layout.s_sign)  # s grows with theta
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
        positions,
        uv,
        flat.vertex_ids,
        flat.faces,
        region.faces,
        extras,
        sites,
        colours,
        lines,
        lines_name,
    )


def _picture(region: MeshRegion, params: PictureParams, drawn: tuple[Drawn, ...] = (), sites=None,
             directions=None, headline=None, coloured=None, dots="sites"):  # fmt: skip
    resolved = plain(ResolvedParams.of_region(region))
    x, y = region.layout  # repaired when untangled
    flat = replace(region.flat, x=x, y=y)
    size = (params.image_width, params.image_height)
    if coloured is None:
        coloured = face_colouring(region, params.colour_by)
    grid = reference_grid(region, params.grid_lines)
    return describe(flat, resolved, len(region.faces), *size, drawn, sites, coloured, grid,
                    directions, headline, dots)  # fmt: skip


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


#: A renderer: the bytes of a use-case's result in one form besides JSON, ``(result, params,
#: ctx) -> bytes``, charging what it draws to ``ctx``.
Renderer = Callable[..., bytes]


def map_renderers(
    region_of,
    drawn_of,
    sites_of=lambda result: None,
    directions_of=lambda result: None,
    headline_of=lambda result: None,
    colouring_of=lambda result: None,
    dots: str = "sites",
) -> dict[Output, Renderer]:
    """The SVG and PNG renderers of a result's region's map (``region_of(result)``) with
    ``drawn_of(result)`` (zones, curves: :class:`~service.outputs.picture.Drawn`),
    ``sites_of(result)`` ((n, 2) layout points or None) and ``directions_of(result)`` ((n, 2)
    unit layout directions at them, or None) over it, ``headline_of(result)`` (None, or the
    caption's first line) and ``colouring_of(result)`` (None, or the faces' colours and
    their bar in place of params.colour_by's), the legend calling the sites ``dots``; the
    PNG's raster charged first."""

    def drawn(result, params: PictureParams):
        return _picture(region_of(result), params, drawn_of(result), sites_of(result),
                        directions_of(result), headline_of(result),
                        colouring_of(result), dots)  # fmt: skip

    def as_svg(result, params: PictureParams, ctx: Context) -> bytes:
        return to_svg(drawn(result, params))

    def as_png(result, params: PictureParams, ctx: Context) -> bytes:
        region = region_of(result)
        ctx.charge(picture_bytes(params.image_width, params.image_height, len(region.mesh.faces)))
        return to_png(drawn(result, params))

    return {Output.SVG: as_svg, Output.PNG: as_png}


def as_glb(region: MeshRegion, params: MeshParams, ctx: Context) -> bytes:
    """The GLB renderer of a flattened region (:func:`glb`)."""
    return glb(region, params)


#: The forms of a flattened region besides JSON, by :class:`Output`: the GLB, and the picture
#: of its map, ``params.image_width`` by ``image_height``.
RENDERERS = {Output.GLB: as_glb, **map_renderers(lambda region: region, lambda region: ())}
