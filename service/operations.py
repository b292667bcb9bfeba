"""The use-cases: plain functions over parsed parameter models and a :class:`Mesh`, shared by
the API (:mod:`service.routes`), the command line (:mod:`service.cli`) and the OpenAPI
examples (:mod:`service.examples`).

They know nothing of HTTP. Bad input surfaces as the core's
:class:`~transforms.TransformInputError` (placed in the request by
:func:`service.problems.core_errors_as_problems`) or, for the service's own limits, a
:class:`~service.problems.Problem`. Each returns a result that a response model of
:mod:`service.schemas` presents (``Model.of(result)``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cache

import numpy as np

from transforms import (
    LAYOUT_ORIENTATION,
    Chart,
    Fit,
    FitBounds,
    FitFixed,
    FlatRegion,
    Frame,
    Hits,
    Landmarks,
    Layout,
    MapTriangles,
    Method,
    PoleCap,
    Polyline,
    TransformInputError,
    Untangled,
    ZoneCover,
    angles_to_world,
    cover_zone,
    default_choice,
    fit_region,
    flatten_region,
    layout_xy,
    lift_curve,
    locate,
    pixels,
    untangle,
    world_to_angles,
)
from transforms import selection as select
from transforms.region import flagged_mask
from transforms.registration import (
    Registration,
    RegistrationAmbiguous,
    Surface,
    apply,
    on_surface_distance,
    register,
)
from transforms.sites import (
    SPACING_RULE,
    SitePart,
    Sites,
    SitesDoNotFit,
    minimum_distance,
    place_sites,
    site_normals,
)
from transforms.viewpoint import check_center_sees_area

from .images import read_png, refusal
from .inputs import load_other_mesh
from .jobs import MAP_BYTES_PER_FACE, SITE_BYTES, charge
from .meshio import Mesh, format_of, read_mesh
from .outlines import Outline, checked_curve, checked_zone, overlaps
from .outputs import Output
from .outputs.picture import Framing
from .params import (
    DEFAULT_SIGMA,
    AutoPole,
    ChartParams,
    InverseRequest,
    KnownDistance,
    LengthUnit,
    LocateParams,
    LocateVia,
    MeasureParams,
    MeshParams,
    PointsRequest,
    PoleUp,
    RegisterMode,
    RegisterParams,
    SitesParams,
    TextureMask,
    TransferParams,
)
from .problems import Problem
from .samples import SAMPLES
from .schemas import SampleInfo
from .settings import Settings

# -- parameters into the core's objects ---------------------------------------------------


def chart_of(params: ChartParams) -> Chart:
    """The chart the parameters name (sigma 0.3 when neither sigma nor a pole angle is set)."""
    if params.method is Method.STANDARD:
        return Chart.standard()
    if params.pole_angle_deg is not None and params.sigma is None:
        cap = PoleCap.from_rho_deg(params.pole_angle_deg)
    else:
        cap = PoleCap.from_sigma(DEFAULT_SIGMA if params.sigma is None else params.sigma)
    return Chart.from_method(params.method, cap)


def frame_of(params: ChartParams, center: np.ndarray) -> Frame:
    """The frame at ``center`` with the parameters' rotation (identity when none: a mesh
    request without one has it chosen by :func:`resolve` instead)."""
    if params.rotation is None or params.rotation == "identity":
        return Frame.identity(center)
    if isinstance(params.rotation, PoleUp):
        return Frame.from_pole_up(params.rotation.pole, params.rotation.up, center)
    return Frame.from_matrix(params.rotation, center)


@dataclass(frozen=True)
class Selection:
    """The region a request names: its file face ids (ascending), the centre the
    parameters ask for (before any fit), and the region as answers repeat it (a cone with
    its apex resolved; None for the whole mesh), so that sent back it selects these faces."""

    faces: np.ndarray
    center: np.ndarray
    region: dict | None


def select_region(mesh: Mesh, params: MeshParams) -> Selection:
    """The faces and the centre of ``params.region`` and ``params.center``
    (:mod:`transforms.selection`); a cone is taken around the centre of the whole mesh.

    Raises
    ------
    TransformInputError
        Ids out of range or repeated, unknown groups, a zero cone axis, a centroid of no
        area; :class:`~transforms.EmptyRegionError` when nothing is selected.
    """
    region = params.region
    if params.part("mask") is not None and (region is None or region.texture_mask is None):
        raise refusal(
            "mask", "a mask part is read for a region.texture_mask only, and the region is another"
        )
    if region is not None and region.cone is not None:
        return _cone_selection(mesh, params)
    faces = select.nonempty(_region_faces(mesh, params))
    resolved = None if region is None else region.model_dump(exclude_none=True)
    return Selection(faces, _center(mesh, faces, params.center), resolved)


def _cone_selection(mesh: Mesh, params: MeshParams) -> Selection:
    """A cone's faces, its apex resolved (by default the whole mesh's box centre)."""
    cone = params.region.cone
    center = _center(mesh, None, params.center)
    if cone.apex is not None:
        apex = np.asarray(cone.apex, dtype=np.float64)
    elif params.center in ("bbox_center", "auto"):
        apex = center  # the same box centre, of the whole mesh: found once
    else:
        apex = select.bbox_center(mesh.vertices, mesh.faces)
    faces = select.cone_faces(mesh.vertices, mesh.faces, apex, cone.axis, cone.half_angle_deg)
    resolved = {"cone": {**cone.model_dump(), "apex": apex.tolist()}}
    return Selection(select.nonempty(faces), center, resolved)


def _region_faces(mesh: Mesh, params: MeshParams) -> np.ndarray:
    """The file face ids of any region but a cone (all of them for none)."""
    region, n_faces = params.region, len(mesh.faces)
    if region is None:
        return np.arange(n_faces)
    if region.scalp is not None:
        scalp = region.scalp
        landmarks = checked_landmarks(mesh, scalp.landmarks, "region.scalp.landmarks")
        offset = scalp.offset_mm / _mm_per_unit(scalp.units, "params.region.scalp.units")
        return landmarks.scalp_faces(mesh.vertices, mesh.faces, offset)
    if region.vertex_color is not None or region.feature_id is not None:
        return _painted_faces(mesh, region)
    if region.texture_mask is not None:
        return _masked_faces(mesh, region.texture_mask, params.part("mask"))
    if region.faces is not None:
        return select.faces_listed(region.faces, n_faces)
    if region.vertices is not None:
        return select.faces_of_vertices(mesh.faces, region.vertices, len(mesh.vertices))
    return mesh.group_faces(region.groups)


def _painted_faces(mesh: Mesh, region) -> np.ndarray:
    """The faces of a region painted in the file's vertex colours or ids.

    Raises
    ------
    TransformInputError
        The file has no such colours or attribute (naming what it has), or no face is in.
    """
    attributes = mesh.attributes
    if region.vertex_color is not None:
        paint = region.vertex_color
        if attributes.colors is None:
            raise _lacking(mesh, "region.vertex_color", "vertex colours")
        return select.faces_by_color(
            mesh.faces, attributes.colors, paint.channel, paint.min, paint.rule
        )
    wanted = region.feature_id
    for per_face, values in ((False, attributes.vertex), (True, attributes.face)):
        if wanted.attribute in values:
            return select.faces_by_ids(
                mesh.faces, values[wanted.attribute], wanted.values, per_face, wanted.rule
            )
    raise _lacking(mesh, "region.feature_id.attribute", f"attribute {wanted.attribute!r}")


def _masked_faces(mesh: Mesh, mask: TextureMask, data: bytes | None) -> np.ndarray:
    """The faces under the form's ``mask`` PNG, read through the mesh's texture coordinates.

    Raises
    ------
    Problem
        422: no mask part, or not a readable PNG.
    TransformInputError
        The file has no texture coordinates (naming what it has), or no face is in.
    """
    if data is None:
        raise refusal(
            "mask",
            "region.texture_mask needs the mask: a multipart part 'mask', a PNG (--mask on "
            "the command line)",
        )
    attributes = mesh.attributes
    if attributes.uv is None:
        raise _lacking(
            mesh, "region.texture_mask", "texture coordinates (glTF TEXCOORD_0, OBJ vt, PLY u v)"
        )
    image = read_png(data, "mask")
    shade = image.values if image.alpha is None else image.values * image.alpha
    return select.faces_by_mask(attributes.uv, attributes.uv_faces, shade, mask.min)


def _lacking(mesh: Mesh, field: str, what: str) -> TransformInputError:
    """The refusal of a request for ``what`` the file lacks, naming what it has."""
    return TransformInputError(
        field,
        f"the {mesh.format.upper()} file has no {what}; it has {mesh.attributes.described()}",
    )


def region_faces(mesh: Mesh, selection: Selection) -> np.ndarray:
    """(m, 3) int: the region's faces, the mesh's own array (no copy) for the whole mesh."""
    if len(selection.faces) == len(mesh.faces):  # ascending and distinct: every face, in order
        return mesh.faces
    return mesh.faces[selection.faces]


def _center(mesh: Mesh, face_ids: np.ndarray | None, center) -> np.ndarray:
    """A world point, or the centre named (``auto`` starts from the bounding-box centre) of
    the faces ``face_ids`` (None: all), which are copied out only then."""
    if not isinstance(center, str):
        return np.asarray(center, dtype=np.float64)
    name = "bbox_center" if center == "auto" else center
    faces = mesh.faces if face_ids is None else mesh.faces[face_ids]
    return select.named_center(mesh.vertices, faces, name)


def fixed_choices(params: MeshParams, center: np.ndarray, head: Frame | None = None) -> FitFixed:
    """What the caller fixed for :func:`transforms.fit_region` and
    :func:`transforms.default_choice` (None: choose it; no rotation or no cap given counts
    as chosen); the ``head``'s frame (from landmarks) fixes the centre and the rotation."""
    rotation, up = params.rotation, None
    if head is not None:
        center, rotation = head.center, Frame.from_matrix(head.rotation)
    elif rotation is None or rotation == "auto":
        rotation = None
    elif isinstance(rotation, AutoPole):
        rotation, up = None, rotation.up
    else:
        rotation = frame_of(params, np.zeros(3))
    sigma = None
    given = params.sigma is not None or params.pole_angle_deg is not None
    if given and params.sigma != "auto" and params.method is not Method.STANDARD:
        sigma = chart_of(params).cap.sigma
    return FitFixed(
        center=None if params.center == "auto" and head is None else center,
        rotation=rotation,
        up=None if up is None else np.asarray(up, dtype=np.float64),
        sigma=sigma,
    )


def fit_bounds(params: MeshParams) -> FitBounds:
    return FitBounds(params.min_kernel_depth, params.min_margin_deg)


# -- meshes ------------------------------------------------------------------------------


@dataclass(frozen=True)
class MeshRegion:
    """A request's region flattened: its file face ids, the chart and frame used, the
    flattened region, and the fit when any parameter was chosen.

    Attributes
    ----------
    mesh : Mesh, as read
    selection : Selection, the region's file face ids and the region as answers repeat it
    chart, frame : what the region was flattened with
    flat : FlatRegion, positions in ``faces`` and ``flat.vertex_ids``
    fit : Fit or None
    untangled : Untangled or None, the layout made fold-free (``params.untangle``)
    """

    mesh: Mesh
    selection: Selection
    chart: Chart
    frame: Frame
    flat: FlatRegion
    fit: Fit | None
    untangled: Untangled | None = None

    @property
    def layout(self) -> tuple[np.ndarray, np.ndarray]:
        """(k,) float each: the layout answered, repaired when untangled."""
        if self.untangled is None:
            return self.flat.x, self.flat.y
        return self.untangled.x, self.untangled.y

    @property
    def faces(self) -> np.ndarray:
        """(m,) int: the region's file face ids, ascending."""
        return self.selection.faces


def resolve(
    mesh: Mesh, selection: Selection, params: MeshParams, settings: Settings
) -> tuple[Chart, Frame, Fit | None]:
    """The chart and frame the parameters name; fitted (with the fit) where any is ``"auto"``
    (and always for /v1/fit's :class:`~service.params.FitParams`); the rotation and sigma not
    given chosen by :func:`transforms.default_choice` (no search) otherwise."""
    head = head_frame(mesh, params)
    fixed = fixed_choices(params, selection.center, head)
    if not params.auto:
        warped = params.method is not Method.STANDARD
        if fixed.rotation is not None and (fixed.sigma is not None or not warped):
            frame = head if head is not None else frame_of(params, selection.center)
            return chart_of(params), frame, None
        chosen = default_choice(
            mesh.vertices,
            region_faces(mesh, selection),
            fixed,
            fit_bounds(params),
            method=params.method,
            layout=params.layout,
            threads=settings.threads,
        )
        return chosen.chart, chosen.frame, chosen
    fit = fit_region(
        mesh.vertices,
        region_faces(mesh, selection),
        fixed,
        fit_bounds(params),
        method=params.method,
        layout=params.layout,
        threads=settings.threads,
    )
    return fit.chart, fit.frame, fit


def head_frame(mesh: Mesh, params: MeshParams) -> Frame | None:
    """The frame of ``params.frame``'s landmarks (:meth:`transforms.Landmarks.frame`), each
    checked on the mesh's surface; None without landmarks."""
    if params.frame is None:
        return None
    landmarks = checked_landmarks(mesh, params.frame.landmarks, "frame.landmarks")
    return landmarks.frame()


def checked_landmarks(mesh: Mesh, given, field: str) -> Landmarks:
    """The landmarks of ``given`` (the params' model), checked as a head's and on the
    mesh's surface; errors name ``field``'s landmark."""
    landmarks = Landmarks.of(given.model_dump(exclude_none=True), field=field)
    landmarks.check_on_surface(mesh.vertices, mesh.faces)
    return landmarks


def flatten(mesh: Mesh, params: MeshParams, settings: Settings) -> MeshRegion:
    """The region flattened with the chart and frame :func:`resolve` gives."""
    selection = select_region(mesh, params)
    chart, frame, fit = resolve(mesh, selection, params, settings)
    if fit is not None:
        flat = fit.region
    else:
        faces = region_faces(mesh, selection)
        flat = flatten_region(
            mesh.vertices, faces, frame, chart, threads=settings.threads, layout=params.layout
        )
    untangled = untangle_layout(mesh, flat) if params.untangle else None
    return MeshRegion(mesh, selection, chart, frame, flat, fit, untangled)


def untangle_layout(mesh: Mesh, flat: FlatRegion) -> Untangled:
    """The region's layout made fold-free (:func:`transforms.untangle`)."""
    shapes = mesh.vertices[flat.vertex_ids]
    return untangle(flat.x, flat.y, flat.faces, shapes, front_orientation(flat))


def front_orientation(flat: FlatRegion) -> int:
    """The sign of a front-facing triangle's signed area in the returned ``(x, y)`` plane,
    whose second axis runs against theta for Mercator."""
    s_sign = 1 if flat.layout is Layout.THETA_PHI else -1
    return LAYOUT_ORIENTATION * flat.validation.winding * s_sign


def map_triangles(region: MeshRegion) -> MapTriangles:
    """The region's triangles on its answered map (untangled when asked) and on the
    surface: the correspondence of docs/math.md, section 12."""
    flat = region.flat
    charge(MAP_BYTES_PER_FACE * len(flat.faces))
    x, y = region.layout
    surface = region.mesh.vertices[flat.vertex_ids]
    return MapTriangles.of(x, y, surface, flat.faces, front_orientation(flat))


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
    """

    chart: Chart
    frame: Frame
    selection: Selection
    hits: Hits
    layout: Layout
    format: str
    untangle: bool

    @property
    def found(self) -> np.ndarray:
        """(k,) bool: the queries whose ray meets the region."""
        return self.hits.faces >= 0


def locate_directions(mesh: Mesh, params: LocateParams, settings: Settings) -> Located:
    """For each ``(theta, phi)`` of ``params``, the region triangle the ray from the centre
    meets first (:func:`transforms.locate`)."""
    check_count(len(params.theta), settings.max_points, "params.theta")
    if params.via is LocateVia.MAP:
        return _locate_on_map(mesh, params, settings)
    selection = select_region(mesh, params)
    chart, frame, _ = resolve(mesh, selection, params, settings)
    directions = chart.inverse(params.theta, params.phi, 1.0)
    faces = region_faces(mesh, selection)
    # Seen edge-on from the centre, the region has nothing to hit (the flatten routes refuse
    # such a centre in the core; a fixed frame and sigma reach locate without it).
    check_center_sees_area(mesh.vertices, faces, frame.center)
    # Every vertex given, so that an error names the file's vertex ids. A rotation keeps the
    # triangle a ray meets, the weights and the depth: the rays turn to the world's axes
    # instead of every vertex to the frame's, and the few hit points back.
    rotation = frame.rotation
    hits = locate(mesh.vertices - frame.center, faces, directions @ rotation)
    hits = Hits(hits.faces, hits.barycentric, hits.points @ rotation.T)
    return Located(chart, frame, selection, hits, params.layout, mesh.format, params.untangle)


def _locate_on_map(mesh: Mesh, params: LocateParams, settings: Settings) -> Located:
    """For each ``(theta, phi)`` of ``params``, the point the map shows there: the layout's
    point of those angles in the region triangle that holds it, lifted with the same
    barycentric weights (:meth:`transforms.MapTriangles.locate`)."""
    region = flatten(mesh, params, settings)
    triangles = map_triangles(region)
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
        region.chart, region.frame, region.selection, hits, params.layout, mesh.format, untangled
    )


# -- zones and curves ------------------------------------------------------------------------


@dataclass(frozen=True)
class Measured:
    """What was drawn on a region's map, measured on its surface.

    Attributes
    ----------
    region : MeshRegion, the region flattened
    triangles : MapTriangles, its map and surface
    flagged : (m,) bool, the region's faces the validation flags
    zones : tuple of (Outline, ZoneCover)
    curves : tuple of (name, Polyline)
    overlaps : tuple of (i, j, area): the surface area zones i and j share
    mm_per_unit : float or None, from params.units
    """

    region: MeshRegion
    triangles: MapTriangles
    flagged: np.ndarray
    zones: tuple[tuple[Outline, ZoneCover], ...]
    curves: tuple[tuple[str, Polyline], ...]
    overlaps: tuple[tuple[int, int, float], ...]
    mm_per_unit: float | None


def measure(mesh: Mesh, params: MeasureParams, settings: Settings) -> Measured:
    """The zones and curves of ``params``, drawn on the map of the region it names, measured
    on the surface (:func:`transforms.cover_zone`, :func:`transforms.lift_curve`)."""
    drawn = sum(len(z.outer.x) + sum(len(h.x) for h in z.holes) for z in params.zones)
    drawn += sum(len(curve.x) for curve in params.curves)
    check_count(drawn, settings.max_drawn_points, "params.zones", "MESHFLAT_MAX_DRAWN_POINTS")
    outlines = [checked_zone(zone, k) for k, zone in enumerate(params.zones)]
    curves = [checked_curve(curve, k) for k, curve in enumerate(params.curves)]
    mm_per_unit = _mm_per_unit(params.units)
    region = flatten(mesh, params, settings)
    triangles = map_triangles(region)
    covers = [cover_zone(triangles, outline.rings) for outline in outlines]
    shared = tuple(
        (i, j, sum(cover_zone(triangles, rings).total(triangles.surface_area) for rings in parts))
        for i, j, parts in overlaps(outlines)
    )
    return Measured(
        region,
        triangles,
        flagged_mask(region.flat.validation, len(triangles)),
        tuple(zip(outlines, covers, strict=True)),
        tuple(
            (curve.name, lift_curve(triangles, points))
            for curve, points in zip(params.curves, curves, strict=True)
        ),
        shared,
        mm_per_unit,
    )


def _mm_per_unit(
    units: LengthUnit | KnownDistance | None, field: str = "params.units"
) -> float | None:
    """Millimetres per mesh unit, from ``units`` (the params' ``field``).

    Raises
    ------
    Problem
        422 when the two points of a known distance coincide, or give a scale beyond
        ``MM_PER_UNIT``.
    """
    if units is None:
        return None
    if isinstance(units, KnownDistance):
        start, end = (np.asarray(point, dtype=np.float64) for point in units.between)
        distance = float(np.linalg.norm(end - start))
        if not distance > 0:
            raise Problem(
                422,
                f"{field}.between: the two points coincide; give two points the known "
                "distance apart",
                "invalid-request",
                f"{field}.between",
            )
        scale = units.mm / distance
        if not MM_PER_UNIT[0] <= scale <= MM_PER_UNIT[1]:
            low, high = MM_PER_UNIT
            raise Problem(
                422,
                f"{field}: {units.mm:g} mm over a distance of {distance:g} mesh units is "
                f"{scale:.3g} mm per unit; the scale must be within {low:g} to {high:g} mm per "
                "unit (a micron to a kilometre)",
                "invalid-request",
                field,
            )
        return scale
    return LengthUnit(units).mm


#: Millimetres per mesh unit a known distance may give (areas in cm² stay finite).
MM_PER_UNIT = (1e-3, 1e6)


# -- sites ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class SiteZoneResult:
    """One part that got sites: a zone, or the whole region (``outline`` None).

    Attributes
    ----------
    name : str
    outline : Outline or None
    area : float, its surface area, mesh units²
    open_area : float, the part of it sites may go on (flagged triangles left out unless
        allowed), mesh units²
    density_per_cm2 : float, the density asked for
    quota : int, its sites
    spacing : float or None, the least distance between its sites and any other, mesh units
        (None without sites)
    achieved : float, its sites per cm² of ``open_area``
    """

    name: str
    outline: Outline | None
    area: float
    open_area: float
    density_per_cm2: float
    quota: int
    spacing: float | None
    achieved: float


@dataclass(frozen=True)
class Placed:
    """Sites placed on a region (docs/math.md, section 13).

    Attributes
    ----------
    region : MeshRegion
    triangles : MapTriangles
    sites : Sites, positions in the region's faces, barycentric weights, points, parts
    normals : (n, 3) float, unit: the region's vertex normals interpolated
    map_points : (n, 2) float, the layout's x, y (the correspondence of section 12)
    theta, phi : (n,) float, the transform of the points
    zones : tuple of SiteZoneResult, in the order of ``sites.part``
    min_distance : float, the smallest distance between two sites, measured
    mm_per_unit : float
    """

    region: MeshRegion
    triangles: MapTriangles
    sites: Sites
    normals: np.ndarray
    map_points: np.ndarray
    theta: np.ndarray
    phi: np.ndarray
    zones: tuple[SiteZoneResult, ...]
    min_distance: float
    mm_per_unit: float


def place(mesh: Mesh, params: SitesParams, settings: Settings) -> Placed:
    """Sites on the region of ``params`` at its densities (:func:`transforms.sites.place_sites`):
    the count of each zone its area times its density (or shares of ``count``), spaced at
    least ``min_spacing_mm`` and the default rule's spacing apart."""
    mm_per_unit = _mm_per_unit(params.units)
    if mm_per_unit is None:
        raise Problem(
            422,
            "params.units: sites per cm² need the mesh's length unit (mm, cm or m) or a known "
            "distance",
            "invalid-request",
            "params.units",
        )
    outlines = _apart([checked_zone(zone, k) for k, zone in enumerate(params.zones)])
    image = _density_image(params)
    region = flatten(mesh, params, settings)
    triangles = map_triangles(region)
    open_faces = ~flagged_mask(region.flat.validation, len(triangles)) | params.allow_flagged
    if image is not None:
        found = [_density_map_part(region, triangles, image, open_faces)]
    else:
        found = list(_zone_parts(triangles, params, outlines, open_faces))
    unit_area = mm_per_unit**2 / 100.0  # cm² per mesh unit²
    expected = [float(np.dot(part.core.area, part.core.density)) * unit_area for part in found]
    total = params.count if params.count is not None else sum(expected)
    check_count(round(total), settings.max_sites, "sites", "MESHFLAT_MAX_SITES")
    quotas = _quotas(expected, params.count)
    charge(SITE_BYTES * sum(quotas))
    asked = None if params.min_spacing_mm is None else params.min_spacing_mm / mm_per_unit
    parts, results = [], []
    for part, quota, count in zip(found, quotas, expected, strict=True):
        # The density placed: as asked, scaled to the quota (a count, or rounding).
        placed = part.core.density * unit_area * (quota / count if count > 0 else 0.0)
        if asked is None:  # the default rule (13.1) at the density placed
            with np.errstate(divide="ignore"):
                spacing = SPACING_RULE / np.sqrt(placed)
            spacing[placed == 0] = 1.0  # no site goes there
        else:
            spacing = np.full_like(placed, asked)
        parts.append(part.sites(quota, spacing))
        least = float(spacing[placed > 0].min()) if quota and (placed > 0).any() else None
        results.append(part.result(quota, least, unit_area))
    sites = _placed(triangles, parts, params, mm_per_unit)
    normals = site_normals(triangles.surface_points, triangles.faces, sites, region.frame.center)
    map_points = triangles.on_map(sites.triangles, sites.weights)
    theta, phi, _ = world_to_angles(sites.points, region.frame, region.chart)
    return Placed(
        region, triangles, sites, normals, map_points, theta, phi, tuple(results),
        minimum_distance(sites.points), mm_per_unit,
    )  # fmt: skip


def _apart(outlines: list[Outline]) -> list[Outline]:
    """The zones, refused when two overlap (a site's density would be ambiguous there)."""
    for i, j, _ in overlaps(outlines):
        raise Problem(
            422,
            f"params.zones.{j} ({outlines[j].name!r}) overlaps params.zones.{i} "
            f"({outlines[i].name!r}): a site's density would be ambiguous there",
            "invalid-request",
            f"params.zones.{j}",
        )
    return outlines


def _placed(triangles: MapTriangles, parts: list[SitePart], params: SitesParams, mm_per_unit):
    """:func:`transforms.sites.place_sites` with the seed; a part too full is a 422."""
    try:
        return place_sites(
            triangles.surface_points, triangles.faces, parts, np.random.default_rng(params.seed)
        )
    except SitesDoNotFit as error:
        if params.min_spacing_mm is not None:
            field = "params.min_spacing_mm"
        elif params.density_range is not None:
            field = "params.density_range"
        elif params.zones:
            field = f"params.zones.{error.part}"
        else:
            field = "params.density_per_cm2"
        raise Problem(
            422,
            f"{field} ({error.name!r}): {error.words}, at a spacing of "
            f"{error.spacing * mm_per_unit:.4g} mm; ask for fewer sites (count, density) or a "
            "smaller min_spacing_mm",
            "invalid-request",
            field,
        ) from None


@dataclass(frozen=True)
class _Part:
    """A zone's (or the region's) triangles open to sites, as the core's part before its
    quota and spacing (known once every part's expected count is), with what the answer says
    of the zone: its outline, its whole surface area and the one density asked for (None for
    a density map). ``core.density`` is the density asked for on each triangle, per cm²."""

    core: SitePart
    outline: Outline | None
    area: float
    asked: float | None

    def sites(self, quota: int, spacing: np.ndarray) -> SitePart:
        """The core's part: ``quota`` sites at ``spacing`` ((j,) float) on these triangles."""
        return replace(self.core, quota=quota, spacing=spacing)

    def result(self, quota: int, spacing: float | None, unit_area: float) -> SiteZoneResult:
        weight, density = self.core.area, self.core.density
        open_area = float(weight[density > 0].sum())
        mean = self.asked
        if mean is None:  # a density map: its mean over the area it puts sites on
            mean = float(np.dot(weight, density) / open_area) if open_area else 0.0
        open_cm2 = open_area * unit_area
        achieved = quota / open_cm2 if open_cm2 > 0 else 0.0
        return SiteZoneResult(
            self.core.name, self.outline, self.area, open_area, mean, quota, spacing, achieved
        )


def _zone_parts(triangles: MapTriangles, params: SitesParams, outlines, open_faces):
    """A part for each zone (its own density, or params.density_per_cm2), or the region's."""
    area = triangles.surface_area
    if not outlines:
        faces = np.flatnonzero(open_faces)
        asked = float(params.density_per_cm2)
        density = np.full(len(faces), asked)
        core = SitePart(faces, area[faces], 0, 0.0, density, name="region")
        yield _Part(core, None, float(area.sum()), asked)
        return
    for outline, zone in zip(outlines, params.zones, strict=True):
        cover = cover_zone(triangles, outline.rings)
        faces = np.concatenate([cover.inside, cover.partial])
        weight = np.concatenate([area[cover.inside], area[cover.partial] * cover.share])
        partial = np.r_[np.zeros(len(cover.inside), bool), np.ones(len(cover.partial), bool)]
        keep = open_faces[faces]
        asked = float(zone.density_per_cm2 or params.density_per_cm2)
        density = np.full(int(keep.sum()), asked)

        def inside(faces, weights, cover=cover):
            return cover.winding(triangles.on_map(faces, weights)) != 0

        core = SitePart(
            faces[keep], weight[keep], 0, 0.0, density, partial[keep], inside,
            area[faces[keep]], outline.name,
        )  # fmt: skip
        yield _Part(core, outline, cover.total(area), asked)


def _density_image(params: SitesParams) -> np.ndarray | None:
    """(h, w) float: the density_map part's sites per cm² (grey 0-255 to density_range), or
    None without density_range.

    Raises
    ------
    Problem
        422: no part, not a PNG, another size than the PNG answer's, not 8-bit grey.
    """
    data = params.part("density_map")

    def refuse(words: str) -> Problem:
        return refusal("density_map", words)

    if params.density_range is None:
        if data is not None:
            raise refuse("a density map needs params.density_range, and no zones or density")
        return None
    if data is None:
        raise refuse("density_range needs the map: a multipart part 'density_map', a grey PNG")
    size = (params.image_width, params.image_height)
    grey = read_png(data, "density_map", size, grey_only=True).values
    low, high = params.density_range
    return low + (high - low) * grey


def _density_map_part(region: MeshRegion, triangles: MapTriangles, image, open_faces) -> _Part:
    """The region's open triangles, each at the density of the pixel under its centroid on
    the map, in the framing of the PNG answer (:class:`service.outputs.picture.Framing`)."""
    height, width = image.shape
    x, y = region.layout
    framing = Framing.of(x, y, region.flat.layout, width, height)
    centroids = np.column_stack([triangles.corner_x.mean(axis=0), triangles.corner_y.mean(axis=0)])
    column, row = np.floor(framing.pixels(centroids)).astype(np.int64).T
    shown = (column >= 0) & (column < width) & (row >= 0) & (row < height)
    density = np.zeros(len(centroids))
    density[shown] = image[row[shown], column[shown]]
    faces = np.flatnonzero(open_faces)
    area = triangles.surface_area
    core = SitePart(faces, area[faces], 0, 0.0, density[faces], name="density map")
    return _Part(core, None, float(area.sum()), None)


def _quotas(expected: list[float], count: int | None) -> list[int]:
    """Each part's sites: its expected number rounded, or, with ``count``, its share of
    ``count`` by the largest remainders (the total exact, the ratios kept)."""
    expected = np.asarray(expected, dtype=np.float64)
    if count is None:
        return np.rint(expected).astype(int).tolist()
    if not expected.sum() > 0:
        raise Problem(
            422,
            "params.count: no part of the region is open to sites at a density above 0",
            "invalid-request",
            "params.count",
        )
    share = expected / expected.sum() * count
    quotas = np.floor(share).astype(int)
    order = np.argsort(-(share - quotas), kind="stable")
    quotas[order[: count - quotas.sum()]] += 1
    return quotas.tolist()


# -- a follow-up registered to the baseline -----------------------------------------------

#: A follow-up point lies on the baseline when within this distance of it (mm).
OVERLAP_MM = 2.0
#: The least share of the follow-up's area on the baseline for a registration to be given:
#: most of it (a cropped follow-up lies on the baseline whole; a rigid fit of a scan 5 %
#: larger leaves about a third on it).
MIN_OVERLAP = 0.5


@dataclass(frozen=True)
class Registered:
    """A follow-up registered to the baseline (docs/math.md, section 15).

    Attributes
    ----------
    region : MeshRegion, the baseline's region, flattened with its frame
    found : Registration, the transform and the residuals
    follow_boundary : (k, 2, 2) float, the follow-up's region's boundary edges on the
        baseline's map (its faces over the baseline's region, mapped with ``frame``)
    zones : tuple of Outline, checked, to draw
    seeded_by : "landmarks" or "moments"
    overlap : float, the share of the follow-up's area within ``overlap_mm`` of the baseline
    overlap_mm : float, ``OVERLAP_MM``
    rms_mm, p95_mm : float, the residuals over that overlap
    frame : Frame, the baseline's frame expressed for the follow-up
    mm_per_unit : float
    """

    region: MeshRegion
    found: Registration
    seeded_by: str
    overlap: float
    overlap_mm: float
    rms_mm: float
    p95_mm: float
    frame: Frame
    mm_per_unit: float
    follow_boundary: np.ndarray
    zones: tuple[Outline, ...]


def register_scans(mesh: Mesh, params: RegisterParams, settings: Settings) -> Registered:
    """The follow-up (the form's ``follow_up`` part) registered to the baseline ``mesh``
    (:func:`transforms.registration.register`), on the baseline's ``region``; refused when
    too little of it lies on the baseline afterwards."""
    mm_per_unit = _mm_per_unit(params.units)
    follow = load_other_mesh(params, "follow_up", settings)
    region = flatten(mesh, params, settings)
    base = Surface.of(mesh.vertices, mesh.faces)
    focus = Surface.of(mesh.vertices, region_faces(mesh, region.selection))
    moving = Surface.of(follow.vertices, follow.faces)
    pairs = _landmark_pairs(mesh, follow, params)
    similar = params.mode is RegisterMode.SIMILARITY
    ratio = moving.size / base.size
    if not similar and not 1 / OTHER_UNITS < ratio < OTHER_UNITS:
        raise _unregistered("a rigid motion keeps sizes", ratio, similar, landmarks_help=False)
    try:
        found = register(moving, base, pairs, scale=similar, focus=focus)
    except RegistrationAmbiguous as error:
        raise _unregistered(str(error), ratio, similar) from None
    on_base = found.residuals * mm_per_unit <= OVERLAP_MM
    overlap = float(on_base.mean())
    if overlap < MIN_OVERLAP:
        raise _unregistered(
            f"after the best alignment found only {overlap:.0%} of its area lies within "
            f"{OVERLAP_MM:g} mm of the baseline (at least {MIN_OVERLAP:.0%})",
            ratio,
            similar,
        )
    residuals = found.residuals[on_base] * mm_per_unit
    rms, p95 = float(np.sqrt(np.mean(residuals**2))), float(np.percentile(residuals, 95))
    # Baseline local = R (s A p + t - c) = s R A (p - A^T (c - t) / s): the same angles.
    turn, shift = found.matrix[:3, :3] / found.scale, found.matrix[:3, 3]
    rotation = region.frame.rotation @ turn
    center = turn.T @ (region.frame.center - shift) / found.scale
    frame = Frame.from_matrix(rotation, center)
    seeded = "landmarks" if pairs is not None else "moments"
    boundary = _follow_boundary(follow, found, focus, frame, region)
    zones = tuple(checked_zone(zone, k) for k, zone in enumerate(params.zones))
    return Registered(
        region, found, seeded, overlap, OVERLAP_MM, rms, p95, frame, mm_per_unit, boundary,
        zones,
    )  # fmt: skip


#: Follow-ups whose samples spread this many times as far as the baseline's, or as few, are
#: told that their units or scales may differ (a part of a head spreads at least 0.39 as far
#: as the whole: the top tenth of each sample scan); in rigid mode, those beyond
#: ``OTHER_UNITS`` times are refused before any alignment is tried.
SIZE_MISMATCH, OTHER_UNITS = 2.5, 4.0


def _unregistered(
    why: str, size_ratio: float, similar: bool, landmarks_help: bool = True
) -> Problem:
    """The 422 of a follow-up that could not be registered: ``why``, and what may help
    (``size_ratio``: how far its samples spread from their centroid, over the baseline's)."""
    hints = ["give the landmarks of both scans, or a region both show"] if landmarks_help else []
    if not similar and not 1 / SIZE_MISMATCH <= size_ratio <= SIZE_MISMATCH:
        hints.insert(
            0,
            f"it is {size_ratio:.3g} times the baseline's size (its spread about its "
            "centroid): if the scans' units or scales differ, send mode similarity (or the "
            "follow-up in the baseline's units)",
        )
    elif not similar:
        hints.append("or mode similarity, if the scans differ in scale")
    return Problem(
        422,
        f"follow_up: could not register it: {why}; {'; '.join(hints)}",
        "invalid-request",
        "follow_up",
    )


def _follow_boundary(follow: Mesh, found, focus: Surface, frame: Frame, region) -> np.ndarray:
    """(k, 2, 2) float: the boundary edges, on the map, of the follow-up's faces whose
    registered centroids lie on the baseline's region (within two sample spacings of its
    samples), flattened with the baseline's frame expressed for the follow-up."""
    centroids = follow.vertices[follow.faces].mean(axis=1)
    moved = apply(found.matrix, centroids)
    near = focus.tree.query(moved)[0] <= on_surface_distance(focus)
    if not near.any():
        return np.empty((0, 2, 2))
    flat = flatten_region(follow.vertices, follow.faces[near], frame, region.chart,
                          layout=region.flat.layout)  # fmt: skip
    points = np.column_stack([flat.x, flat.y])
    return points[flat.validation.boundary_edges]


def _landmark_pairs(mesh: Mesh, follow: Mesh, params: RegisterParams):
    """The landmarks both scans give, follow-up then baseline ((k, 3) each), or None. The
    baseline's come from params.landmarks.baseline or params.frame."""
    given = params.landmarks
    baseline = given.baseline if given is not None and given.baseline is not None else None
    if baseline is None and params.frame is not None:
        baseline = params.frame.landmarks
    if baseline is None or given is None or given.follow_up is None:
        return None
    base = checked_landmarks(mesh, baseline, "landmarks.baseline").named()
    other = checked_landmarks(follow, given.follow_up, "landmarks.follow_up").named()
    common = [name for name in base if name in other]
    return np.stack([other[n] for n in common]), np.stack([base[n] for n in common])


# -- points --------------------------------------------------------------------------------


@dataclass(frozen=True)
class Angles:
    """(k,) float each: the coordinates of points, radians and distances."""

    theta: np.ndarray
    phi: np.ndarray
    r: np.ndarray


def points_to_angles(request: PointsRequest, settings: Settings) -> Angles:
    """World points to ``(theta, phi, r)`` (:func:`transforms.world_to_angles`)."""
    check_count(len(request.points), settings.max_points, "points")
    points = np.asarray(request.points, dtype=np.float64)
    chart = chart_of(request)  # before the frame: a bad cap is named first
    frame = frame_of(request, np.asarray(request.center, dtype=np.float64))
    theta, phi, r = world_to_angles(points, frame, chart, threads=settings.threads)
    return Angles(theta, phi, r)


def angles_to_points(request: InverseRequest, settings: Settings) -> np.ndarray:
    """(k, 3) float: ``(theta, phi, r)`` back to world points
    (:func:`transforms.angles_to_world`)."""
    check_count(len(request.theta), settings.max_points, "theta")
    chart = chart_of(request)
    frame = frame_of(request, np.asarray(request.center, dtype=np.float64))
    r = 1.0 if request.r is None else request.r
    return angles_to_world(request.theta, request.phi, r, frame, chart)


def check_count(count: int, limit: int, field: str, setting: str = "MESHFLAT_MAX_POINTS") -> None:
    """Refuse more than ``limit`` query points (413, naming ``field`` and the ``setting``)."""
    if count > limit:
        raise Problem(
            413,
            f"{field}: {count:,} items; the limit is {limit:,} ({setting})",
            "too-many-points",
            field,
        )


# -- samples -------------------------------------------------------------------------------


@cache
def _sample_info(name: str) -> SampleInfo:
    sample = SAMPLES[name]
    data = sample.path.read_bytes()
    # A bundled file is trusted: read with the default limits, whatever the service's are.
    mesh = read_mesh(data, format_of(name, None), Settings().limits)
    return SampleInfo(
        name=name,
        format=mesh.format,
        vertices=len(mesh.vertices),
        faces=len(mesh.faces),
        bytes=len(data),
        description=sample.description,
        credit=sample.credit,
        licence=sample.licence,
        url=f"/v1/samples/{name}",
    )


def sample_infos() -> list[SampleInfo]:
    return [_sample_info(name) for name in SAMPLES]


# -- values between the map and the mesh ---------------------------------------------------

#: Bytes a pixel of a transfer's grid may cost: ids, weights, values and their encoding.
TRANSFER_BYTES_PER_PIXEL = 48


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


def transfer(mesh: Mesh, params: TransferParams, settings: Settings) -> Transferred:
    """An image painted over the map carried onto the mesh (the ``image`` part), values a
    vertex drawn on the map (``values``), or, for ``output`` face_ids or barycentric, the
    look-up images; on the grid of the PNG answer."""
    data = params.part("image")
    lookup = params.output in (Output.FACE_IDS, Output.BARYCENTRIC)
    if data is not None and params.values is not None:
        raise refusal("image", "send an image part or params.values, not both")
    if data is not None and lookup:
        raise refusal("image", f"output {params.output.value} answers the look-up image alone")
    if params.output is Output.PNG and params.values is None:
        raise TransformInputError(
            "values", "output png draws params.values: send them (an image part answers JSON)"
        )
    if data is None and params.values is None and not lookup:
        raise refusal(
            "image",
            "nothing to carry: send an image part (the map painted over), params.values (to "
            "draw), or ask for params.output face_ids or barycentric (the look-up images)",
        )
    width, height = params.image_width, params.image_height
    values = None if params.values is None else _vertex_values(mesh, params.values)
    image = None if data is None else read_png(data, "image", (width, height))
    region = flatten(mesh, params, settings)
    charge(TRANSFER_BYTES_PER_PIXEL * width * height)
    x, y = region.layout
    at = Framing.of(x, y, region.flat.layout, width, height).pixels(np.column_stack([x, y]))
    # A face that wraps round the map has no triangle of its own there: no pixel is its.
    drawn = region.flat.validation.drawn_faces(len(region.flat.faces))
    faces = region.flat.faces[drawn]
    found = Transferred(region, width, height)
    if image is not None:
        found = _image_to_mesh(region, image, at, drawn, faces, params, settings)
    elif values is not None:
        vertex_values = values[region.flat.vertex_ids]
        found = _values_to_image(region, vertex_values, drawn, faces, at, params, settings)
    if lookup:
        corners = at[faces]
        ids = pixels.face_ids(corners, height, width, settings.threads)
        weights = pixels.barycentric(corners, ids) if params.output is Output.BARYCENTRIC else None
        found = replace(found, ids=_file_ids(region, drawn, ids), weights=weights)
    return found


def _values_to_image(region: MeshRegion, values, drawn, faces, at, params, settings):
    """The region vertices' ``values`` drawn linear inside each of the ``drawn`` faces
    (``faces``, their corners; ``at``, the vertices' pixels), 0 to 1 of the range
    (``value_range``, or the values' least and largest; for values all equal to ``v``, a
    range of 1 from ``v`` towards 0, which the values' bound admits when sent back)."""
    low, high = params.value_range or (float(values.min()), float(values.max()))
    if high <= low:
        low, high = (low, low + 1.0) if low < 0 else (low - 1.0, low)
    scaled = (values - low) / (high - low)
    width, height = params.image_width, params.image_height
    image, ids = pixels.vertex_image(at[faces], scaled[faces], height, width, settings.threads)
    ids = _file_ids(region, drawn, ids)
    return Transferred(region, width, height, (low, high), image=np.clip(image, 0, 1), ids=ids)


def _image_to_mesh(region: MeshRegion, image, at, drawn, faces, params, settings):
    """The image's values at the region's vertices and over its ``drawn`` faces (``faces``,
    their corners; the others uncovered; :func:`transforms.pixels.onto_mesh`), mapped to
    ``value_range``."""
    low, high = params.value_range or (0.0, 1.0)
    height, width = image.values.shape
    vertex, found_means, found_coverage = pixels.onto_mesh(
        at, faces, image.values, image.alpha, settings.threads
    )
    means, coverage = np.full(len(region.flat.faces), np.nan), np.zeros(len(region.flat.faces))
    means[drawn], coverage[drawn] = found_means, found_coverage
    vertex_values = low + (high - low) * vertex  # NaN where nothing reaches the vertex
    face_values = low + (high - low) * means  # NaN stays NaN: no coverage
    return Transferred(region, width, height, (low, high), vertex_values, face_values, coverage)


def _file_ids(region: MeshRegion, drawn: np.ndarray, ids: np.ndarray) -> np.ndarray:
    """The grid of positions in the ``drawn`` faces as the file's face ids (-1 stays)."""
    file_ids = region.faces[drawn].astype(np.int32)
    return np.where(ids >= 0, file_ids[np.maximum(ids, 0)], -1).astype(np.int32, copy=False)


def _vertex_values(mesh: Mesh, values) -> np.ndarray:
    """(n,) float: ``params.values``, one a vertex of the file, or the file's per-vertex
    property of that name.

    Raises
    ------
    TransformInputError
        Not one a vertex, a property the file lacks, or a NaN among them.
    """
    if isinstance(values, str):
        found = mesh.attributes.vertex.get(values)
        if found is None:
            raise _lacking(mesh, "values", f"per-vertex property {values!r}")
        array = np.asarray(found, dtype=np.float64)
    else:
        array = np.asarray(values, dtype=np.float64)
        if len(array) != len(mesh.vertices):
            raise TransformInputError(
                "values",
                f"{len(array):,} values; the file has {len(mesh.vertices):,} vertices (one "
                "value a vertex, in the file's order)",
            )
    bad = np.flatnonzero(~np.isfinite(array))
    if bad.size:
        raise TransformInputError(
            "values", f"vertex {int(bad[0])}'s value is not a number", indices=bad
        )
    return array
