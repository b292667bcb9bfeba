"""What the service can do, one row each: route, parameter model, operation, response model
and the forms of the answer. The routes (:mod:`service.routes`), the OpenAPI document
(:mod:`service.document`), its examples and the command line are all derived from these rows,
so a new capability is a row here, an operation, a params model and a response model.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import ClassVar

from pydantic import BaseModel

from . import operations
from .encoding import Timings, encode
from .jobs import JSON_BYTES_PER_BYTE, READER_BYTES_PER_BYTE
from .meshio import Mesh
from .outputs import Output
from .outputs.render import (
    MEASURE_RENDERERS,
    REGISTER_RENDERERS,
    RENDERERS,
    SITES_RENDERERS,
    TRANSFER_RENDERERS,
)
from .params import (
    FitParams,
    FlattenParams,
    InverseRequest,
    LocateParams,
    MeasureParams,
    MeshParams,
    PointsRequest,
    RegisterParams,
    SitesParams,
    TransferParams,
)
from .problems import ErrorPlaces
from .schemas import (
    FitResponse,
    FlattenResponse,
    InverseResponse,
    LocateResponse,
    MeasureResponse,
    PointsResponse,
    RegisterResponse,
    SitesResponse,
    TransferResponse,
    ValidateResponse,
)
from .settings import Settings


@dataclass(frozen=True)
class Capability:
    """What every route of the table has.

    Attributes
    ----------
    name : the route's name (its OpenAPI operation id starts with it)
    path, summary, description : the route and its documentation
    operation : the use-case (:mod:`service.operations`), ``result`` from parsed input
    response : the JSON answer's model; ``response.of(result)`` builds it
    """

    name: str
    path: str
    summary: str
    description: str
    operation: Callable
    response: type[BaseModel]
    parse_bytes_per_byte: ClassVar[int]

    def encoded(self, result, timings: Timings) -> bytes:
        """The JSON answer to ``result`` (timed as ``encode``)."""
        with timings.measure("encode"):
            return encode(self.response.of(result))


@dataclass(frozen=True)
class MeshCapability(Capability):
    """A multipart route: a ``mesh`` file and a ``params`` JSON field; its operation is
    ``(mesh, params, settings) -> result``.

    Attributes
    ----------
    params : the model of the ``params`` field
    renderers : the other forms of the answer, ``(result, params) -> bytes`` by Output
    """

    params: type[MeshParams]
    renderers: Mapping[Output, Callable] = field(default_factory=dict)
    #: What parsing the body may take per byte, beside the mesh (charged by service.jobs).
    parse_bytes_per_byte: ClassVar[int] = READER_BYTES_PER_BYTE

    @property
    def command(self) -> str:
        """The command line's command: the path's last part."""
        return self.path.rsplit("/", 1)[-1]

    @property
    def outputs(self) -> tuple[Output, ...]:
        """The forms of the answer, JSON first."""
        return (Output.JSON, *self.renderers)

    def answer(
        self, mesh: Mesh, params: MeshParams, settings: Settings, output: Output, timings: Timings
    ) -> bytes:
        """The answer's bytes in ``output`` (one of :attr:`outputs`); the operation sees it as
        ``params.output`` (chosen by the Accept header, or the command line's file name)."""
        if "output" in type(params).model_fields and params.output is not output:
            params = params.model_copy(update={"output": output})
        with timings.measure("compute"):
            result = self.operation(mesh, params, settings)
        return self.render(result, params, output, timings)

    def render(self, result, params: MeshParams, output: Output, timings: Timings) -> bytes:
        """The bytes of ``result`` in ``output``: one computation can be answered in several
        forms (``meshflat batch`` writes each output a manifest line names)."""
        if output is Output.JSON:
            return self.encoded(result, timings)
        with timings.measure("encode"):
            return self.renderers[output](result, params)


@dataclass(frozen=True)
class JsonCapability(Capability):
    """A route whose body is one JSON model; its operation is ``(request, settings) ->
    result``.

    Attributes
    ----------
    request : the body's model
    """

    request: type[BaseModel]
    #: What parsing the body may take per byte (charged by service.jobs).
    parse_bytes_per_byte: ClassVar[int] = JSON_BYTES_PER_BYTE

    def answer(self, request: BaseModel, settings: Settings, timings: Timings) -> bytes:
        with timings.measure("compute"):
            result = self.operation(request, settings)
        return self.encoded(result, timings)


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

MESH_CAPABILITIES = (
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
        operation=operations.flatten,
        response=FlattenResponse,
        renderers=RENDERERS,
    ),
    MeshCapability(
        name="validate",
        path="/v1/validate",
        summary="Validate a region of a mesh",
        description="The same input as /v1/flatten; answers only the resolved parameters, the "
        "validation report and the distortion metrics.",
        params=MeshParams,
        operation=operations.flatten,
        response=ValidateResponse,
    ),
    MeshCapability(
        name="fit",
        path="/v1/fit",
        summary="Choose the centre, rotation and sigma for a region",
        description="The same input as /v1/flatten, but centre, rotation and sigma not given "
        'are chosen ("auto"); any of them may be fixed. They are chosen together to minimise '
        "the region's area-weighted isometric energy, keeping the centre inside the region's "
        "kernel at a depth of at least min_kernel_depth of its inscribed radius and the margin "
        "to the seam and the singular points at least min_margin_deg. The search starts from "
        "the kernel's deepest point (a linear program), the middle of the largest cap free of "
        "region directions as the pole, the roll along the region's widest spread about the "
        "pole (or the up hint), and the best sigma with that cap; then refines the free ones "
        "together on an area-weighted sample of the triangles. Answers the resolved "
        "parameters, the validation and metrics they give on every triangle, and `explain`.",
        params=FitParams,
        operation=operations.flatten,
        response=FitResponse,
    ),
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
        operation=operations.locate_directions,
        response=LocateResponse,
    ),
    MeshCapability(
        name="measure",
        path="/v1/measure",
        summary="Measure zones and curves drawn on the map",
        description="Multipart like /v1/flatten; `params` also holds `zones` (an outer ring "
        "and holes each, in the layout's coordinates: the vertices.x and vertices.y of a "
        "flatten answer, straight edges in that plane), `curves` (polylines in the same plane) "
        "and `units`. The map is linear inside each region triangle, as the GLB's UVs and the "
        "pictures draw it: a map point in a triangle's image stands for the surface point "
        "with the same barycentric weights (docs/math.md, section 12). Answers, per zone, its "
        "surface area (in cm² too with units), the part on flagged triangles, the map area no "
        "triangle covers, the surface perimeter, the triangles wholly inside and the cut ones "
        "with the share of each inside, and the outline lifted onto the surface; per curve, "
        "the lifted polyline (its points and every crossing of a triangle edge, with face "
        "ids) and its surface length; and the area each pair of overlapping zones shares. "
        "Exact: a zone covering the whole map has the region's area, zones tiling the map sum "
        "to it. Or, by the Accept header or params.output, the map with the zones filled, "
        "named and labelled with their areas, and the curves (SVG or PNG).",
        params=MeasureParams,
        operation=operations.measure,
        response=MeasureResponse,
        renderers=MEASURE_RENDERERS,
    ),
    MeshCapability(
        name="sites",
        path="/v1/sites",
        summary="Place sites (grafts) on the region at a density",
        description="Multipart like /v1/measure; `params` also holds the density, "
        "`density_per_cm2` for the whole region or `zones` (as /v1/measure's, not "
        "overlapping) each with its own, and `units` (required: densities are per cm²). "
        "Sites are Poisson-disk samples of the surface (random sequential adsorption, "
        "docs/math.md section 13): each zone gets its area times its density, rounded (or, "
        "with `count`, its share of that exact total), no two sites closer than "
        "`min_spacing_mm` or the default rule's 0.7 / sqrt(density), across triangle and zone "
        "borders; none on flagged triangles unless `allow_flagged`; the same `seed`, the same "
        "sites, in any pose of the mesh. Answers the sites (position, unit normal, face id, "
        "barycentric weights, theta and phi, and the layout's x and y), the count, per zone "
        "its area, sites and achieved density, and the smallest distance between two sites, "
        "measured. Or, by the Accept header or params.output: a PLY point cloud with normals "
        "and face ids, the region's GLB with the sites as a POINTS primitive, or the map with "
        "the sites and zones (SVG or PNG).",
        params=SitesParams,
        operation=operations.place,
        response=SitesResponse,
        renderers=SITES_RENDERERS,
    ),
    MeshCapability(
        name="register",
        path="/v1/register",
        summary="Register a follow-up scan to the baseline",
        description="Multipart: the `baseline` and `follow_up` meshes and a `params` JSON "
        "field: the baseline's region (the part to align on: the scalp changes over time, the "
        "face and ears less) and frame as for /v1/flatten, `landmarks` of either scan, `mode` "
        "(rigid or similarity) and `units`. Seeded by the landmarks of both scans when given, "
        "else by the scans' moments (their principal axes in 24 turns, centroids or ends "
        "matched, and in similarity mode also scaled to the scans' spreads; refused when two "
        "distinct alignments fit about as well); refined by small_gicp's point-to-plane ICP "
        "over area-weighted samples, trimmed so that a cropped follow-up still aligns "
        "(docs/math.md, section 15). In rigid mode a follow-up more than "
        f"{operations.OTHER_UNITS:g} times the baseline's size, or less than "
        f"1/{operations.OTHER_UNITS:g} of it, is refused at once as in other units. Answers "
        "the 4x4 transform onto the baseline, the RMS "
        "and 95th percentile of the residuals over the overlap (mm), the overlap, and the "
        "baseline's frame expressed for the follow-up, so that the follow-up's map lands on "
        f"the baseline's; refuses (422) when after the best alignment less than "
        f"{operations.MIN_OVERLAP:.0%} of the follow-up lies within {operations.OVERLAP_MM:g} "
        "mm of the baseline. Or, by the Accept header or "
        "params.output, the overlay: the baseline's map with both regions' boundaries and "
        "the zones (SVG or PNG).",
        params=RegisterParams,
        operation=operations.register_scans,
        response=RegisterResponse,
        renderers=REGISTER_RENDERERS,
    ),
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
        operation=operations.transfer,
        response=TransferResponse,
        renderers=TRANSFER_RENDERERS,
    ),
)

JSON_CAPABILITIES = (
    JsonCapability(
        name="points",
        path="/v1/points",
        summary="Points to (theta, phi, r)",
        description="World points to distorted-pole (or standard, or separable) coordinates, "
        "radians:\n``theta`` the polar angle from local +Z, ``phi`` the azimuth from +X "
        "towards +Y.\nBody: JSON, as the PointsRequest schema.",
        request=PointsRequest,
        operation=operations.points_to_angles,
        response=PointsResponse,
    ),
    JsonCapability(
        name="points_inverse",
        path="/v1/points/inverse",
        summary="(theta, phi, r) to points",
        description="Coordinates back to world points, with the same parameters as "
        "/v1/points.\nBody: JSON, as the InverseRequest schema.",
        request=InverseRequest,
        operation=operations.angles_to_points,
        response=InverseResponse,
    ),
)

#: Where a mesh route's fields lie: the parameters of every mesh route in the ``params``
#: part; whatever else the core names (vertices, faces, points it derived from them) is the
#: uploaded mesh's.
MESH_FORM = ErrorPlaces(
    "params.", frozenset(name for c in MESH_CAPABILITIES for name in c.params.model_fields), "mesh"
)

#: The mesh routes by command-line command.
MESH_COMMANDS = {capability.command: capability for capability in MESH_CAPABILITIES}
