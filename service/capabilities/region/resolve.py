"""A mesh request's region resolved: the faces it names, the chart and frame it asks for
(fitted where any is ``"auto"``), flattened (:func:`flatten`). Every mesh route starts here.

The use-cases know nothing of HTTP: bad input surfaces as the core's
:class:`~transforms.TransformInputError` or as :class:`service.errors.InvalidInput`, both
placed in the request by :func:`service.problems.problem_of`.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, replace
from functools import cached_property
from typing import Generic, NamedTuple, TypeVar

import numpy as np

from transforms import (
    Chart,
    Fit,
    FitBounds,
    FitFixed,
    FlatRegion,
    Frame,
    MapTriangles,
    Method,
    PoleCap,
    TransformInputError,
    Untangled,
    default_choice,
    fit_region,
    flatten_region,
    untangle,
)
from transforms import selection as select
from transforms.fit import HULL_VERTICES
from transforms.fit.emptycap import region_free_cap
from transforms.topology import representatives, welded_by

from ...errors import InvalidInput
from ...meshio import Mesh
from ..context import MAP_BYTES_PER_FACE, Context
from ..inputs import PngFile
from ..units import mm_per_unit
from ..warnings import WarningCode
from .heads import check_facing, checked_landmarks, facing_of, head_frame
from .params import DEFAULT_SIGMA, AutoPole, ChartParams, MeshParams, PoleUp

P = TypeVar("P", bound=MeshParams)


@dataclass(frozen=True)
class MeshInput(Generic[P]):
    """What a mesh route computes on: the mesh, its params, and the ``mask`` part
    (``region.texture_mask``'s PNG), read from a form or the command line.

    Attributes
    ----------
    mesh : Mesh, as read
    params : MeshParams (the route's model)
    mask : PngFile or None, decoded when the region is a texture mask
    """

    mesh: Mesh
    params: P
    mask: PngFile | None = None


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
    parameters ask for (before any fit), the region as answers repeat it (a cone with its
    apex resolved; None for the whole mesh), so that sent back it selects these faces, its
    connected pieces (``region.pieces`` applied: the largest alone is one piece), and its
    faces welded (``links``: file vertex ids, each the lowest at its position; None when no
    corner of the region shares its position with another vertex), what the fit reads.

    ``pieces.count > 1`` is where a warning that the region is several pieces belongs."""

    faces: np.ndarray
    center: np.ndarray
    region: dict | None
    pieces: select.RegionPieces
    links: np.ndarray | None = None


def select_region(given: MeshInput, ctx: Context) -> Selection:
    """The faces and the centre of ``params.region`` and ``params.center``
    (:mod:`transforms.selection`), only the largest piece of them for ``region.pieces``
    ``"largest"``; a named centre is the selected faces', a cone's apex by default the
    whole mesh's box centre. Corners at one position are one vertex for the pieces and the
    fit (:func:`transforms.topology.representatives`).

    Raises
    ------
    TransformInputError
        Ids out of range or repeated, unknown groups, a zero cone axis, a centroid of no
        area; :class:`~transforms.EmptyRegionError` when nothing is selected.
    InvalidInput
        A mask part without a texture_mask region, or the other way round.
    """
    mesh, params = given.mesh, given.params
    region = params.region
    if given.mask is not None and (region is None or region.texture_mask is None):
        raise InvalidInput(
            "mask", "a mask part is read for a region.texture_mask only, and the region is another"
        )
    resolved = None if region is None else region.resolved()
    if region is not None and region.cone is not None:
        faces, apex = _cone_faces(mesh, region.cone)
        resolved["cone"]["apex"] = apex.tolist()
    else:
        faces = select.nonempty(_region_faces(given, ctx))
    whole = len(faces) == len(mesh.faces)  # ascending and distinct: every face, in order
    own = mesh.faces if whole else mesh.faces[faces]
    links = welded_by(own, representatives(mesh.vertices))
    joined = links is not own  # some corner shares its position with another vertex
    pieces, largest = select.region_pieces(links, faces)
    if region is not None and region.pieces is select.Pieces.LARGEST and not largest.all():
        faces, links = faces[largest], links[largest]
        pieces = select.RegionPieces(pieces.sizes[:1], faces[:0])
    if pieces.count > 1:
        _warn_of_pieces(pieces, ctx)
    center = _center(mesh, faces, params.center)
    return Selection(faces, center, resolved, pieces, links if joined else None)


#: How many pieces' face counts a warning lists before it says how many more there are.
LISTED_PIECES = 5


def _warn_of_pieces(pieces: select.RegionPieces, ctx: Context) -> None:
    """The ``region_pieces`` warning: the region is several pieces."""
    sizes = [f"{size:,}" for size in pieces.sizes[:LISTED_PIECES].tolist()]
    if pieces.count > LISTED_PIECES:
        sizes.append(f"and {pieces.count - LISTED_PIECES:,} more")
    ctx.warn(
        WarningCode.REGION_PIECES,
        "region",
        f"the region is {pieces.count:,} pieces that share no edge, of {', '.join(sizes)} "
        f"faces; the {len(pieces.stray):,} faces outside the largest are "
        'validation.stray_faces, and region.pieces "largest" keeps the largest alone',
    )


def _cone_faces(mesh: Mesh, cone) -> tuple[np.ndarray, np.ndarray]:
    """A cone's faces and its apex (by default the whole mesh's box centre, whatever the
    centre is: a fitted centre sent back selects the same faces)."""
    if cone.apex is not None:
        apex = np.asarray(cone.apex, dtype=np.float64)
    else:
        apex = select.bbox_center(mesh.vertices, mesh.faces)
    faces = select.cone_faces(mesh.vertices, mesh.faces, apex, cone.axis, cone.half_angle_deg)
    return select.nonempty(faces), apex


def _region_faces(given: MeshInput, ctx: Context) -> np.ndarray:
    """The file face ids of any region but a cone (all of them for none)."""
    mesh, region, n_faces = given.mesh, given.params.region, len(given.mesh.faces)
    if region is None:
        return np.arange(n_faces)
    if region.scalp is not None:
        scalp = region.scalp
        landmarks = checked_landmarks(mesh, scalp.landmarks, "region.scalp.landmarks")
        offset = scalp.offset_mm / mm_per_unit(scalp.units, "region.scalp.units")
        return landmarks.scalp_faces(mesh.vertices, mesh.faces, offset)
    if region.vertex_color is not None or region.feature_id is not None:
        return _painted_faces(mesh, region)
    if region.texture_mask is not None:
        return _masked_faces(given, ctx)
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
            raise lacking(mesh, "region.vertex_color", "vertex colours")
        return select.faces_by_color(
            mesh.faces, attributes.colors, paint.channel, paint.min, paint.rule
        )
    wanted = region.feature_id
    for per_face, values in ((False, attributes.vertex), (True, attributes.face)):
        if wanted.attribute in values:
            return select.faces_by_ids(
                mesh.faces, values[wanted.attribute], wanted.values, per_face, wanted.rule
            )
    raise lacking(mesh, "region.feature_id.attribute", f"attribute {wanted.attribute!r}")


def _masked_faces(given: MeshInput, ctx: Context) -> np.ndarray:
    """The faces under the form's ``mask`` PNG, read through the mesh's texture coordinates.

    Raises
    ------
    InvalidInput
        No mask part, or not a readable PNG.
    TransformInputError
        The file has no texture coordinates (naming what it has), or no face is in.
    """
    mesh, mask = given.mesh, given.params.region.texture_mask
    if given.mask is None:
        raise InvalidInput(
            "mask",
            "region.texture_mask needs the mask: a multipart part 'mask', a PNG (--mask on "
            "the command line)",
        )
    attributes = mesh.attributes
    if attributes.uv is None:
        raise lacking(
            mesh, "region.texture_mask", "texture coordinates (glTF TEXCOORD_0, OBJ vt, PLY u v)"
        )
    image = given.mask.read(given.params, ctx)
    shade = image.values if image.alpha is None else image.values * image.alpha
    return select.faces_by_mask(attributes.uv, attributes.uv_faces, shade, mask.min)


def lacking(mesh: Mesh, field: str, what: str) -> TransformInputError:
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


def welded_faces(mesh: Mesh, selection: Selection) -> np.ndarray:
    """(m, 3) int: the region's faces welded (``selection.links``), what the fit reads: a
    triangle soup is fitted as the surface it shows."""
    return region_faces(mesh, selection) if selection.links is None else selection.links


def _center(mesh: Mesh, face_ids: np.ndarray, center) -> np.ndarray:
    """A world point, or the centre named (``auto`` starts from the box centre) of the
    faces ``face_ids``, copied out only then (not for the whole mesh)."""
    if not isinstance(center, str):
        return np.asarray(center, dtype=np.float64)
    name = "bbox_center" if center == "auto" else center
    faces = mesh.faces if len(face_ids) == len(mesh.faces) else mesh.faces[face_ids]
    return select.named_center(mesh.vertices, faces, name)


def fixed_choices(
    params: MeshParams,
    center: np.ndarray,
    head: Frame | None = None,
    facing: np.ndarray | None = None,
) -> FitFixed:
    """What the caller fixed for :func:`transforms.fit_region` and
    :func:`transforms.default_choice` (None: choose it; no rotation or no cap given counts
    as chosen); the ``head``'s frame (from landmarks) fixes the centre and the rotation;
    ``facing`` (:func:`facing_of`) the roll of a rotation chosen, and a rotation given must
    agree with it (docs/math.md, section 18).

    Raises
    ------
    InvalidInput
        A rotation given whose roll disagrees with ``facing``.
    TransformInputError
        ``facing`` within ``MIN_FACING_DEG`` of the pole given.
    """
    rotation, up = params.rotation, None
    if head is not None:
        center, rotation = head.center, Frame.from_matrix(head.rotation)
    elif rotation is None or rotation == "auto":
        rotation, up = None, facing
    elif isinstance(rotation, AutoPole):
        rotation, up = None, rotation.up if rotation.up is not None else facing
    else:
        rotation = frame_of(params, np.zeros(3))
        if facing is not None:
            check_facing(rotation.rotation, facing, "the rotation given")
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
    facing : (3,) float or None, where the face looks (:func:`facing_of`; for a landmark
        frame its forward direction)
    """

    mesh: Mesh
    selection: Selection
    chart: Chart
    frame: Frame
    flat: FlatRegion
    fit: Fit | None
    untangled: Untangled | None = None
    facing: np.ndarray | None = None

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

    @property
    def pieces(self) -> select.RegionPieces:
        """The region's connected pieces (``count > 1``: the region is several pieces)."""
        return self.selection.pieces

    @cached_property
    def free_cap(self) -> tuple[float, float | None]:
        """Degrees: the angular radius of the largest cap free of the region seen from its
        centre, and that of the largest gap between its vertices' directions
        (:func:`transforms.fit.emptycap.region_free_cap`; found once, for the validation
        and the warnings). A region that closes round its centre (the validation's
        ``encloses_centre``) leaves no cap free whatever its vertices' gaps: ``(0.0, None)``
        without a search."""
        flat = self.flat
        if flat.validation.encloses_centre:
            return 0.0, None
        points = self.mesh.vertices[flat.vertex_ids]
        boundary = flat.validation.boundary_edges
        _, free, gap = region_free_cap(
            points, flat.faces, self.frame.center, boundary, HULL_VERTICES
        )
        return math.degrees(free), math.degrees(gap)


def resolve(
    mesh: Mesh, selection: Selection, params: MeshParams, ctx: Context
) -> tuple[Chart, Frame, Fit | None]:
    """The chart and frame the parameters name; fitted (with the fit) where any is ``"auto"``
    (and always for /v1/fit's params, whose ``auto`` is always true); the rotation and sigma not
    given chosen by :func:`transforms.default_choice` (no search) otherwise."""
    head = head_frame(mesh, params)
    facing = facing_of(params)
    # A head's frame has its own roll (facing is then its forward direction).
    fixed = fixed_choices(params, selection.center, head, None if head is not None else facing)
    if not params.auto:
        warped = params.method is not Method.STANDARD
        if fixed.rotation is not None and (fixed.sigma is not None or not warped):
            frame = head if head is not None else frame_of(params, selection.center)
            return chart_of(params), frame, None
    # A search (never worse than the defaults, also at the request's default centre), or
    # its start alone.
    choose = fit_region if params.auto else default_choice
    also = {"default_center": selection.center} if params.auto else {}
    fit = choose(
        mesh.vertices,
        welded_faces(mesh, selection),
        fixed,
        fit_bounds(params),
        method=params.method,
        layout=params.layout,
        threads=ctx.threads,
        **also,
    )
    if facing is not None and fixed.rotation is None:
        check_facing(fit.frame.rotation, facing, "the rotation chosen")
    return fit.chart, fit.frame, fit


class Resolved(NamedTuple):
    """A request's region selected, and the chart and frame it is flattened with
    (:func:`resolve`)."""

    selection: Selection
    chart: Chart
    frame: Frame
    fit: Fit | None


#: The params that decide the region, its chart and frame, and its flattening: the key of
#: what a held mesh keeps of them (the route's own params, its format and the mesh's name
#: decide none of it).
REGION_PARAMS = frozenset(MeshParams.model_fields) - {"format", "mesh_sha256"}


def region_key(given: MeshInput) -> tuple:
    """What decides :func:`resolved_region` and :func:`flatten` of ``given`` besides its
    mesh: the params that do (``auto`` too, which a route's params may fix), and the
    mask's bytes."""
    params = given.params
    decided = json.dumps(params.model_dump(mode="json", include=REGION_PARAMS), sort_keys=True)
    mask = None if given.mask is None else hashlib.sha256(given.mask.upload.data).hexdigest()
    return hashlib.sha256(decided.encode()).hexdigest(), params.auto, mask


def resolved_region(given: MeshInput, ctx: Context) -> Resolved:
    """The region selected (:func:`select_region`) and resolved (:func:`resolve`); kept
    with a held mesh for the same :func:`region_key`."""

    def compute(ctx: Context) -> Resolved:
        selection = select_region(given, ctx)
        return Resolved(selection, *resolve(given.mesh, selection, given.params, ctx))

    return ctx.remembered(given.mesh, ("resolved", region_key(given)), compute)


def flatten(given: MeshInput, ctx: Context) -> MeshRegion:
    """The region flattened with the chart and frame :func:`resolve` gives: the use-case of
    /v1/flatten, /v1/validate and /v1/fit, and where every other mesh route starts. Kept
    with a held mesh for the same :func:`region_key`, with its warnings."""
    return ctx.remembered(
        given.mesh, ("flatten", region_key(given)), lambda ctx: _flatten(given, ctx)
    )


def _flatten(given: MeshInput, ctx: Context) -> MeshRegion:
    mesh, params = given.mesh, given.params
    selection, chart, frame, fit = resolved_region(given, ctx)
    if fit is not None and selection.links is None:
        flat = fit.region  # else fitted on the faces welded: flattened with the file's ids
    else:
        faces = region_faces(mesh, selection)
        # No links: the selection found every vertex of the mesh at a position of its own.
        flat = flatten_region(
            mesh.vertices,
            faces,
            frame,
            chart,
            threads=ctx.threads,
            layout=params.layout,
            distinct=selection.links is None,
        )
    untangled = untangle_layout(mesh, flat) if params.untangle else None
    region = MeshRegion(mesh, selection, chart, frame, flat, fit, untangled, facing_of(params))
    if not flat.validation.seam_free:
        _warn_of_the_seam(region, ctx)
    if not flat.validation.star_shaped:
        _warn_of_folds(region, ctx)
    return region


def _warn_of_folds(region: MeshRegion, ctx: Context) -> None:
    """The ``region_folds`` warning: triangles folded in the map or facing away from the
    centre (the map overlaps itself there), how many, and what may help."""
    v = region.flat.validation
    folded, behind, total = len(v.folded_faces), len(v.backfacing_faces), len(region.faces)
    if region.untangled is None:
        after = "untangle: true makes the layout fold-free where it can"
    else:
        after = f"untangling left {len(region.untangled.flipped_after):,} folded"
    ctx.warn(
        WarningCode.REGION_FOLDS,
        "region",
        f"{folded:,} of the region's {total:,} triangles are folded in the map and {behind:,} "
        f"face away from the centre (validation.folded_faces, backfacing_faces): the map "
        f"overlaps itself there and its numbers on them cannot be trusted; {after}. A "
        'narrower region, a centre inside the head beneath it, or "auto" may see it whole',
    )


def _warn_of_the_seam(region: MeshRegion, ctx: Context) -> None:
    """The ``seam_on_region`` warning: why the seam or a singular point lies on the region,
    and whether a pole could keep them off it."""
    free, gap = region.free_cap
    if free > 0:
        ctx.warn(
            WarningCode.SEAM_ON_REGION,
            "rotation",
            f"the seam or a singular point lies on the region, yet a cap of {free:.3g} degrees "
            "is free of it seen from the centre: the rotation or sigma used does not put the "
            'seam there ("auto" or /v1/fit does)',
        )
    else:
        # A region closed round its centre covers every direction whatever its vertices'
        # gaps (region.free_cap does not look for them then).
        gaps = ""
        if gap is not None:
            gaps = f"; the largest gap between its vertices' directions is {gap:.3g} degrees"
        ctx.warn(
            WarningCode.SEAM_ON_REGION,
            "region",
            "the seam or a singular point lies on the region: no cap is free of it seen from "
            f"the centre (its faces close round every direction), so no pole can keep them off"
            f"{gaps}. A smaller region, or a centre that sees it from one side, can be one patch",
        )


def untangle_layout(mesh: Mesh, flat: FlatRegion) -> Untangled:
    """The region's layout made fold-free (:func:`transforms.untangle`), on the faces
    welded (``flat.links``): a vertex that repeats another's position moves with it."""
    shapes = mesh.vertices[flat.vertex_ids]
    front = flat.layout.front_orientation(flat.validation.winding)
    done = untangle(flat.x, flat.y, flat.links, shapes, front)
    if not len(done.moved):
        return done
    x, y = done.x[flat.weld], done.y[flat.weld]
    moved = np.flatnonzero((x != flat.x) | (y != flat.y))
    return replace(done, x=x, y=y, moved=moved)


def map_triangles(region: MeshRegion, ctx: Context) -> MapTriangles:
    """The region's triangles on its answered map (untangled when asked) and on the
    surface: the correspondence of docs/math.md, section 12. Kept with a held region."""
    return ctx.remembered(region, "map_triangles", lambda ctx: _map_triangles(region, ctx))


def _map_triangles(region: MeshRegion, ctx: Context) -> MapTriangles:
    flat = region.flat
    ctx.charge(MAP_BYTES_PER_FACE * len(flat.faces))
    x, y = region.layout
    surface = region.mesh.vertices[flat.vertex_ids]
    front = flat.layout.front_orientation(flat.validation.winding)
    return MapTriangles.of(x, y, surface, flat.faces, front)
