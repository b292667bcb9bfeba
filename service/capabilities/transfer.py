"""``POST /v1/transfer``: values carried between the map and the mesh on the PNG answer's
pixel grid: an image painted over the map onto the vertices and faces, values a vertex drawn
on the map, and the look-up images of face ids and barycentric weights (docs/math.md,
section 16)."""

from __future__ import annotations

import base64
import io
from dataclasses import dataclass, replace
from typing import Annotated

import numpy as np
from PIL import Image
from pydantic import ConfigDict, Field

from transforms import Framing, TransformInputError, pixels

from ..encoding import Answer
from ..errors import InvalidInput
from ..images import Png
from ..meshio import Mesh
from ..outputs import Output
from ..outputs.lookup import grey_alpha_png16, lookup_bytes
from .context import Context
from .fields import MAX_COORDINATE, Coordinate, FramingParams, ValueRange, output_choice
from .inputs import PngFile, PngPart
from .region.answers import ResolvedParams
from .region.params import MESH_PARAMS_EXAMPLE, MeshParams
from .region.resolve import MeshInput, MeshRegion, flatten, lacking
from .rows import MeshCapability
from .warnings import WarnedAnswer


class TransferParams(MeshParams, FramingParams):
    """The JSON of the ``params`` field of /v1/transfer: as for /v1/flatten, and what crosses
    between the map and the mesh (docs/math.md, section 16)."""

    values: Annotated[list[Coordinate], Field(min_length=1, fail_fast=True)] | str | None = Field(
        None,
        description="Values a vertex to draw on the map: one a vertex of the file (in its "
        "order), or the name of a per-vertex property of the file (a PLY property, a glTF "
        "custom attribute such as _FEATURE_ID_0); each within +-1e15.",
    )
    value_range: ValueRange | None = Field(
        None,
        description="With an image part: the values its black and white stand for (default "
        "[0, 1]). With values: the values drawn as 0 and 65535 (default: their least and "
        "largest over the region; when all are v, a range of 1 from v towards 0). Within "
        "+-1e15, as values.",
    )
    output: output_choice(
        (Output.JSON, Output.PNG, Output.FACE_IDS, Output.BARYCENTRIC),
        "json (application/json): the values carried; png (image/png): with values, the "
        "16-bit grey and alpha PNG of them (the alpha 65535 where a triangle holds the pixel); "
        "face_ids or barycentric (application/octet-stream): the look-up images, a "
        "little-endian array behind a 16-byte header (docs/api.md says how to read it).",
    ) = None

    model_config = ConfigDict(
        json_schema_extra={
            "examples": [
                # A value a vertex of the 12-vertex icosahedron of the examples, drawn.
                {
                    **MESH_PARAMS_EXAMPLE,
                    "values": [float(k) for k in range(12)],
                    "image_width": 480,
                    "image_height": 360,
                },
                {**MESH_PARAMS_EXAMPLE, "output": "face_ids"},
            ]
        }
    )


#: Bytes a pixel of a transfer's grid may cost: ids, weights, values and their encoding.
TRANSFER_BYTES_PER_PIXEL = 48
#: The farthest a value drawn may lie from value_range's low end, in the range's widths:
#: beyond, the drawing is 0 or 65535 but for slivers thinner than its rounding, and the
#: planes through the triangles' values could overflow (a range of 1e-300 for values of 1).
MAX_RANGES = 1e12


@dataclass(frozen=True)
class Transferred:
    """Values carried between the region's map and its mesh (docs/math.md, section 16), on
    the PNG answer's grid (``framing``, ``width`` x ``height``).

    Attributes
    ----------
    region : MeshRegion
    value_range : (low, high) or None
    vertex_values : (k,) float or None, a value a region vertex (``flat.vertex_ids``), NaN
        where the image reaches neither it nor its faces: an image carried onto the mesh
    face_values, coverage : (m,) float or None, a value (NaN with no coverage) and the share
        covered a region face
    image : (h, w) float or None, the values drawn, 0 to 1 of the range
    ids : (h, w) int or None, the file's face id at each pixel, -1 where none
    weights : (h, w, 3) float32 or None, the pixel centre's weights in that face's corners
    """

    region: MeshRegion
    width: int
    height: int
    value_range: tuple[float, float] | None = None
    vertex_values: np.ndarray | None = None
    face_values: np.ndarray | None = None
    coverage: np.ndarray | None = None
    image: np.ndarray | None = None
    ids: np.ndarray | None = None
    weights: np.ndarray | None = None


@dataclass(frozen=True)
class TransferInput(MeshInput[TransferParams]):
    """A transfer: the mesh, the params, the mask and the ``image`` part."""

    image: PngFile | None = None


def transfer(given: TransferInput, ctx: Context) -> Transferred:
    """An image painted over the map carried onto the mesh (the ``image`` part), values a
    vertex drawn on the map (``values``), or, for ``output`` face_ids or barycentric, the
    look-up images; on the grid of the PNG answer."""
    mesh, params, sent = given.mesh, given.params, given.image
    lookup = params.output in (Output.FACE_IDS, Output.BARYCENTRIC)
    if sent is not None and params.values is not None:
        raise InvalidInput("image", "send an image part or params.values, not both")
    if sent is not None and lookup:
        raise InvalidInput("image", f"output {params.output.value} answers the look-up image alone")
    if params.output is Output.PNG and params.values is None:
        raise TransformInputError(
            "values", "output png draws params.values: send them (an image part answers JSON)"
        )
    if sent is None and params.values is None and not lookup:
        raise InvalidInput(
            "image",
            "nothing to carry: send an image part (the map painted over), params.values (to "
            "draw), or ask for params.output face_ids or barycentric (the look-up images)",
        )
    width, height = params.image_width, params.image_height
    values = None if params.values is None else vertex_values(mesh, params.values)
    image = None if sent is None else sent.read(params, ctx)
    region = flatten(given, ctx)
    ctx.charge(TRANSFER_BYTES_PER_PIXEL * width * height)
    x, y = region.layout
    at = Framing.of(x, y, region.flat.layout, width, height).pixels(np.column_stack([x, y]))
    # A face that wraps round the map has no triangle of its own there: no pixel is its.
    drawn = region.flat.validation.drawn_faces(len(region.flat.faces))
    faces = region.flat.faces[drawn]
    found = Transferred(region, width, height)
    if image is not None:
        found = _image_to_mesh(region, image, at, drawn, faces, params, ctx)
    elif values is not None:
        on_region = values[region.flat.vertex_ids]
        found = _values_to_image(region, on_region, drawn, faces, at, params, ctx)
    if lookup:
        corners = at[faces]
        ids = pixels.face_ids(corners, height, width, ctx.threads)
        weights = pixels.barycentric(corners, ids) if params.output is Output.BARYCENTRIC else None
        found = replace(found, ids=_file_ids(region, drawn, ids), weights=weights)
    return found


def _values_to_image(region: MeshRegion, values, drawn, faces, at, params, ctx: Context):
    """The region vertices' ``values`` drawn linear inside each of the ``drawn`` faces
    (``faces``, their corners; ``at``, the vertices' pixels), 0 to 1 of the range
    (``value_range``, or the values' least and largest; for values all equal to ``v``, a
    range of 1 from ``v`` towards 0, which the values' bound admits when sent back)."""
    low, high = params.value_range or (float(values.min()), float(values.max()))
    if high <= low:
        low, high = (low, low + 1.0) if low < 0 else (low - 1.0, low)
    reach = float(np.abs(values - low).max())  # within 2e15: the values' bound
    if reach > MAX_RANGES * (high - low):
        raise InvalidInput(
            "value_range",
            f"[{low:.6g}, {high:.6g}] is too narrow for the values, which lie up to {reach:.6g} "
            f"from its low end: at most {MAX_RANGES:.0e} times its width",
        )
    scaled = (values - low) / (high - low)
    width, height = params.image_width, params.image_height
    image, ids = pixels.vertex_image(at[faces], scaled[faces], height, width, ctx.threads)
    ids = _file_ids(region, drawn, ids)
    return Transferred(region, width, height, (low, high), image=np.clip(image, 0, 1), ids=ids)


def _image_to_mesh(region: MeshRegion, image: Png, at, drawn, faces, params, ctx: Context):
    """The image's values at the region's vertices and over its ``drawn`` faces (``faces``,
    their corners; the others uncovered; :func:`transforms.pixels.onto_mesh`), mapped to
    ``value_range``."""
    low, high = params.value_range or (0.0, 1.0)
    height, width = image.values.shape
    vertex, found_means, found_coverage = pixels.onto_mesh(
        at, faces, image.values, image.alpha, ctx.threads
    )
    means, coverage = np.full(len(region.flat.faces), np.nan), np.zeros(len(region.flat.faces))
    means[drawn], coverage[drawn] = found_means, found_coverage
    vertex_values = low + (high - low) * vertex  # NaN where nothing reaches the vertex
    face_values = low + (high - low) * means  # NaN stays NaN: no coverage
    return Transferred(region, width, height, (low, high), vertex_values, face_values, coverage)


def image_at_vertices(flat, layout, image: Png, value_range, ctx: Context) -> np.ndarray:
    """(k,) float: a picture on the grid of a region's PNG answer read at the region's
    vertices (``flat``, its layout ``(x, y)``), bilinear as an image part of /v1/transfer is
    (:func:`transforms.pixels.onto_mesh`), mapped to ``value_range`` (default [0, 1]); NaN
    where the picture reaches neither the vertex nor its faces."""
    x, y = layout
    height, width = image.values.shape
    at = Framing.of(x, y, flat.layout, width, height).pixels(np.column_stack([x, y]))
    faces = flat.faces[flat.validation.drawn_faces(len(flat.faces))]
    vertex, _, _ = pixels.onto_mesh(at, faces, image.values, image.alpha, ctx.threads)
    low, high = value_range or (0.0, 1.0)
    return low + (high - low) * vertex


def _file_ids(region: MeshRegion, drawn: np.ndarray, ids: np.ndarray) -> np.ndarray:
    """The grid of positions in the ``drawn`` faces as the file's face ids (-1 stays)."""
    file_ids = region.faces[drawn].astype(np.int32)
    return np.where(ids >= 0, file_ids[np.maximum(ids, 0)], -1).astype(np.int32, copy=False)


def vertex_values(mesh: Mesh, values, field: str = "values") -> np.ndarray:
    """(n,) float: values listed in params (the params' ``field``), one a vertex of the
    file, or the file's per-vertex property of that name.

    Raises
    ------
    TransformInputError
        Not one a vertex, a property the file lacks, a NaN among them, or (a property's) a
        value beyond +-1e15, the bound of listed values: the range drawn must be finite and
        wider than its ends' rounding.
    """
    if isinstance(values, str):
        found = mesh.attributes.vertex.get(values)
        if found is None:
            raise lacking(mesh, field, f"per-vertex property {values!r}")
        array = np.asarray(found, dtype=np.float64)
    else:
        array = np.asarray(values, dtype=np.float64)
        if len(array) != len(mesh.vertices):
            raise TransformInputError(
                field,
                f"{len(array):,} values; the file has {len(mesh.vertices):,} vertices (one "
                "value a vertex, in the file's order)",
            )
    bad = np.flatnonzero(~np.isfinite(array))
    if bad.size:
        raise TransformInputError(
            field, f"vertex {int(bad[0])}'s value is not a number", indices=bad
        )
    bad = np.flatnonzero(np.abs(array) > MAX_COORDINATE)
    if bad.size:
        raise TransformInputError(
            field,
            f"vertex {int(bad[0])}'s value is {array[bad[0]]:.4g}; values must lie within "
            "+-1e15, as listed values",
            indices=bad,
        )
    return array


def _nullable(values: np.ndarray) -> list:
    """Floats with None where NaN (an answer carries no NaN)."""
    return np.where(np.isnan(values), None, values).tolist()


def _data_url(png: bytes) -> str:
    return "data:image/png;base64," + base64.b64encode(png).decode("ascii")


class TransferredVertices(Answer):
    ids: list[int] = Field(description="The file's ids of the region's vertices.")
    values: list[float | None] = Field(
        description="The image at each vertex's map position, read bilinearly between the "
        "four nearest pixel centres and mapped to value_range; null off the image."
    )


class TransferredFaces(Answer):
    ids: list[int] = Field(description="The file's ids of the region's faces.")
    values: list[float | None] = Field(
        description="The image's mean over each face's triangle on the map (the pixels whose "
        "centres it holds; a triangle holding fewer than 4, 10 samples between them), weighed "
        "by the alpha, mapped to value_range; null where coverage is 0."
    )
    coverage: list[float] = Field(
        description="The share of each face's map triangle on the image, times the alpha's "
        "mean over it (docs/math.md, eq. 16.2)."
    )


class TransferResponse(WarnedAnswer):
    params: ResolvedParams
    image_width: int = Field(description="The grid's width, pixels (the PNG answer's).")
    image_height: int = Field(description="The grid's height, pixels.")
    value_range: list[float] | None = Field(
        description="The values black and white stand for (an image carried onto the mesh), "
        "or the values drawn as 0 and 65535 (values drawn on the map); null for look-ups."
    )
    vertices: TransferredVertices | None = Field(
        None, description="An image part carried onto the region's vertices."
    )
    faces: TransferredFaces | None = Field(
        None, description="An image part carried onto the region's faces."
    )
    image: str | None = Field(
        None,
        description="params.values drawn on the map, linear inside each triangle: a 16-bit "
        "grey PNG as a data: URL (0 and 65535 the ends of value_range).",
    )
    mask: str | None = Field(
        None,
        description="Where the drawing holds a triangle: an 8-bit grey PNG as a data: URL (255 "
        "where a triangle holds the pixel's centre, 0 elsewhere).",
    )

    @classmethod
    def of(cls, transferred: Transferred) -> TransferResponse:
        region = transferred.region
        found = {}
        if transferred.vertex_values is not None:
            found["vertices"] = TransferredVertices.build(
                ids=region.flat.vertex_ids, values=_nullable(transferred.vertex_values)
            )
            found["faces"] = TransferredFaces.build(
                ids=region.faces,
                values=_nullable(transferred.face_values),
                coverage=transferred.coverage,
            )
        if transferred.image is not None:
            found["image"] = _data_url(_png(np.rint(transferred.image * 65535), "I;16"))
            found["mask"] = _data_url(_png((transferred.ids >= 0) * 255, "L"))
        value_range = transferred.value_range
        return cls.build(
            params=ResolvedParams.of_region(region),
            image_width=transferred.width,
            image_height=transferred.height,
            value_range=None if value_range is None else list(value_range),
            **found,
        )


def _png(pixels: np.ndarray, mode: str) -> bytes:
    """A PNG of ``pixels`` in Pillow's ``mode`` (``I;16``: 16-bit grey, ``L``: 8-bit)."""
    dtype = np.uint16 if mode == "I;16" else np.uint8
    out = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(pixels, dtype=dtype)).save(out, format="PNG")
    return out.getvalue()


def _drawn_png(transferred: Transferred, params: TransferParams, ctx: Context) -> bytes:
    """The values drawn (the operation refuses output png without them), coverage as alpha."""
    return grey_alpha_png16(transferred.image, transferred.ids >= 0)


def _lookup(transferred: Transferred, params: TransferParams, ctx: Context) -> bytes:
    return lookup_bytes(transferred.ids, transferred.weights)


RENDERERS = {
    Output.PNG: _drawn_png,
    Output.FACE_IDS: _lookup,
    Output.BARYCENTRIC: _lookup,
}


#: The image painted over the map, on the PNG answer's grid.
IMAGE = PngPart(
    "image",
    "A PNG in the framing of the PNG answer (image_width by image_height pixels, the map "
    "where the PNG answer draws it; 8- or 16-bit grey, grey and alpha, RGB or RGBA, a colour "
    "read as its luminance, the alpha as the coverage; 16 bits kept for grey and for colour, "
    "grey and alpha read at 8): its values carried onto the mesh's vertices and faces.",
    framed=True,
)

ROWS = (
    MeshCapability(
        name="transfer",
        path="/v1/transfer",
        summary="Carry values between the map and the mesh",
        description="Multipart like /v1/flatten, on the grid of the PNG answer (params."
        "image_width by image_height; pixel centres at half-integers, rows down with theta; "
        "docs/math.md section 16). Image to mesh: an `image` part (a PNG of that size, "
        "painted over the map) and `value_range`; answers a value a region vertex (bilinear "
        "at its map position) and a face (the mean over its map triangle, with the share "
        "covered). Mesh to image: `values` (one a vertex of the file, or the name of a "
        "per-vertex property of the file), drawn linear inside each triangle; answers them "
        "as a 16-bit grey PNG and the coverage mask (data: URLs in the JSON, or one 16-bit "
        "grey and alpha PNG with params.output png). Look-ups: params.output face_ids or "
        "barycentric answers the file's face id a pixel (-1 outside) and the centre's "
        "weights in its corners, little-endian behind a 16-byte header (docs/api.md says "
        "how to read it).",
        params=TransferParams,
        extra_parts=(IMAGE,),
        input=TransferInput,
        operation=transfer,
        response=TransferResponse,
        renderers=RENDERERS,
    ),
)
