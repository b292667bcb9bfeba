"""``POST /v1/flatten``: a region of a mesh flattened into distorted-pole spherical
coordinates, answered as JSON (the angles and the layout of every vertex, the triangles, the
validation report, the metrics), as a GLB whose UVs are the layout, or as a picture of the
map (docs/math.md, sections 1 to 7)."""

from __future__ import annotations

from pydantic import ConfigDict, Field

from ..encoding import Answer
from ..outputs import Output
from .fields import PictureParams, output_choice
from .region.answers import Metrics, ResolvedParams, UntangleReport, ValidateResponse, Validation
from .region.params import MESH_PARAMS_EXAMPLE, MeshParams
from .region.pictures import RENDERERS
from .region.resolve import MeshRegion, flatten
from .rows import MeshCapability
from .warnings import WarnedAnswer


class FlattenParams(MeshParams, PictureParams):
    """The JSON of the ``params`` field of /v1/flatten: as for /v1/validate, and the form of
    the answer."""

    output: output_choice(
        (Output.JSON, Output.GLB, Output.SVG, Output.PNG),
        "json (application/json), glb (model/gltf-binary: the region with TEXCOORD_0 from the "
        "layout), svg (image/svg+xml) or png (image/png): a picture of the map.",
    ) = None

    model_config = ConfigDict(json_schema_extra={"examples": [MESH_PARAMS_EXAMPLE]})


class FlatVertices(Answer):
    ids: list[int] = Field(description="The file's vertex ids used by the region, ascending.")
    theta: list[float] = Field(description="Polar angle from local +Z, radians, per id.")
    phi: list[float] = Field(description="Azimuth from +X towards +Y, radians, per id.")
    r: list[float] = Field(description="Distance from the centre, per id.")
    x: list[float] = Field(
        description="Layout x per id: phi (both layouts); with untangle, the repaired layout."
    )
    y: list[float] = Field(
        description="Layout y per id: theta (theta_phi) or ln tan((pi - theta) / 2) (mercator); "
        "with untangle, the repaired layout."
    )


class FlatFaces(Answer):
    ids: list[int] = Field(description="The region's triangle ids, in file order.")
    vertices: list[list[int]] = Field(description="Each triangle's three vertex ids.")


class FlattenResponse(WarnedAnswer):
    params: ResolvedParams
    vertices: FlatVertices
    faces: FlatFaces
    validation: Validation
    metrics: Metrics
    untangle: UntangleReport | None = Field(
        None, description="With params.untangle: what untangling moved and what it could not."
    )

    @classmethod
    def of(cls, region: MeshRegion) -> FlattenResponse:
        flat = region.flat
        x, y = region.layout
        vertices = {"ids": flat.vertex_ids, "theta": flat.theta, "phi": flat.phi, "r": flat.r}
        vertices |= {"x": x, "y": y}
        # The small blocks first, so that a client reading the stream meets them early.
        return cls.build(
            **ValidateResponse.report(region),
            vertices=FlatVertices.build(**vertices),
            faces=FlatFaces.build(ids=region.faces, vertices=region.mesh.faces[region.faces]),
        )


GLB_RULES = """
The GLB holds one triangle mesh: `POSITION`, the file's coordinates of the region's vertices
in the order of `vertices.ids`; `TEXCOORD_0`, the layout scaled into [0, 1] by one factor
(`u = (x - x_min) * scale`, `v = (s - s_min) * scale`, with `s = s_sign * y` growing with
theta: +1 for theta_phi, -1 for mercator; the numbers are in `asset.extras.meshflat.uv`);
`_VERTEX_ID`, each vertex's file id (float32, exact below 2^24); and a material that shows a
checker through the UVs. Triangle `k` (indices `3k .. 3k+2`) is file face `faces.ids[k]`;
the ids are also the accessor named by `asset.extras.meshflat.face_ids_accessor`.
`asset.extras.meshflat` also holds the resolved `params`, the validation summary (counts of
flagged faces) and the metrics.
"""

ROWS = (
    MeshCapability(
        name="flatten",
        path="/v1/flatten",
        summary="Flatten a region of a mesh",
        description="Multipart: a `mesh` file and a `params` JSON field (FlattenParams). "
        "Answers the resolved parameters, (theta, phi, r) of every vertex the region uses, the "
        "region's triangles, the validation report and the distortion metrics; or, by the "
        "Accept header or params.output, the region as a GLB (model/gltf-binary) whose "
        "TEXCOORD_0 is the layout, or a picture of the map (image/svg+xml, image/png).\n"
        + GLB_RULES,
        params=FlattenParams,
        operation=flatten,
        response=FlattenResponse,
        renderers=RENDERERS,
    ),
)
