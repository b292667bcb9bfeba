"""A follow-up scan registered to a baseline (docs/math.md, section 15): seeded by landmarks
(Umeyama's least squares, :func:`trimesh.registration.procrustes`) or by the surfaces'
moments from several starts, refined by point-to-plane ICP over area-weighted samples with
the pairs beyond a trimming distance left out, so that a cropped follow-up still aligns:
first on the whole scans, then region to region (the follow-up's faces over the baseline's
region on that region, :func:`register_region`). ICP runs coarse to fine (a quarter of the
follow-up's samples until they settle), and the last rounds take the follow-up's vertices
onto the nearest points of the baseline's mesh itself (:func:`on_mesh`): a plane through
the nearest baseline sample is off a curved surface by hundredths of a millimetre.

The ICP is small_gicp's (``PLANE_ICP``: about 1 MB installed, numpy only); Open3D ships the
same at about 900 MB, and trimesh's ICP is point-to-point, which slides along a smooth head
and converges slowly. small_gicp is rigid; the scale of ``similarity`` mode is fitted between
its stages in closed form.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import small_gicp
from scipy.spatial.transform import Rotation
from trimesh.registration import procrustes

from .arrays import blocks, combine, face_cross, triangle_areas, unit_rows
from .checkpoints import checkpoint
from .onmesh import SPARSE_EVERY, SPARSE_LEAST, MeshNearest, NearestTree, dense, onto_mesh
from .sampling import systematic_picks

#: A scale's bounds (least, most), or None for none.
Bounds = tuple[float, float] | None

#: Samples drawn on each surface (area-weighted, the same for any pose of it).
SAMPLES = 20_000
#: ICP rounds at the most (and for comparing starts), taken in stages of ``STAGE_ROUNDS``
#: (each with its own trimming distance), and the step (radians, and in units of the
#: follow-up samples' RMS distance from their centroid) that ends them.
MAX_ROUNDS, COARSE_ROUNDS, STAGE_ROUNDS, SETTLED = 60, 15, 5, 1e-4
#: Rounds at the most for the runner-up of the global search: an alternative that fits
#: settles as fast as the best (15 to 20 rounds); one still sliding after these is no rival
#: (on the 100k-face head, the 45 rounds more it took were a sixth of the time).
RUNNER_UP_ROUNDS = 30
#: The most follow-up vertices the last rounds fit (:attr:`Surface.corners`).
CORNERS_MOST = 100_000
#: Neighbours whose plane gives a target sample its normal for small_gicp (its default).
NORMAL_NEIGHBOURS = 20
#: The starts are compared on every ``COARSE_EVERY``-th sample; the ``REFINED_STARTS`` that
#: put the most of them on the baseline are refined there.
COARSE_EVERY, REFINED_STARTS = 20, 24
#: A follow-up shorter than the baseline along an axis by more than this share of the
#: baseline's extent is taken as cropped there (:func:`moment_starts`).
CROPPED = 0.1
#: Alignments farther apart than this (degrees) are distinct; two distinct ones whose shares
#: of samples on the baseline differ by less than ``AMBIGUOUS`` are refused, when the better
#: puts at least ``PLAUSIBLE`` of them on it (below, neither fits: the better is answered,
#: for its caller's overlap to judge).
DISTINCT_DEG, AMBIGUOUS, PLAUSIBLE = 10.0, 0.1, 0.5
#: Pairs farther apart than this many times the ``TRIM_QUANTILE`` of their distances are
#: left out of a round: up to about two thirds of either surface may have no counterpart.
TRIM, TRIM_QUANTILE = 2.5, 30.0


@dataclass(frozen=True)
class Surface:
    """Area-weighted samples of a surface and their unit normals ((n, 3) float each); when
    drawn from a mesh (:meth:`of`), its ``vertices`` and ``faces`` too, for the last rounds'
    nearest points on the mesh itself (:attr:`mesh`)."""

    points: np.ndarray
    normals: np.ndarray
    vertices: np.ndarray | None = None
    faces: np.ndarray | None = None
    on: np.ndarray | None = None  # (n,) int: the face (a row of ``faces``) each sample is on

    @classmethod
    def of(cls, vertices: np.ndarray, faces: np.ndarray, count: int = SAMPLES) -> Surface:
        """Samples at evenly spaced points of the faces' cumulative area (systematic, so the
        same surface in any pose gives the same samples; :func:`systematic_picks`), each at
        the share of its face's area it falls at (from the first corner, halfway between the
        other two), with the face's normal."""
        face, share = systematic_picks(triangle_areas(vertices, faces), count)
        root = np.sqrt(share)
        weights = np.column_stack([1.0 - root, 0.5 * root, 0.5 * root])
        normals, _ = unit_rows(face_cross(vertices, faces[face]))
        return cls(combine(vertices, faces, face, weights), normals, vertices, faces, face)

    @staticmethod
    def log_size(vertices: np.ndarray, faces: np.ndarray) -> float:
        """log2 of :attr:`size` for the surface ``faces`` ((m, 3) int) of ``vertices`` ((n, 3)
        float), computed on the vertices divided by a power of two near their largest
        coordinate (an exact scaling), so that no area or square overflows or underflows
        whatever the scan's unit (section 15); -inf for a surface of no area."""
        top = float(np.max(np.abs(vertices[faces]))) if len(faces) else 0.0
        if not 0.0 < top < math.inf:
            return -math.inf
        exponent = int(np.frexp(top)[1])
        scaled = np.ldexp(vertices, -exponent)
        if not triangle_areas(scaled, faces).sum() > 0:
            return -math.inf
        size = Surface.of(scaled, faces).size
        return math.log2(size) + exponent if size > 0 else -math.inf

    @cached_property
    def size(self) -> float:
        """The samples' RMS distance from their centroid."""
        return float(np.sqrt(np.mean(np.sum((self.points - self.points.mean(axis=0)) ** 2, 1))))

    @cached_property
    def tree(self) -> NearestTree:
        """A k-d tree of the samples (built once: every ICP and measure on this surface
        pairs with it)."""
        return NearestTree(self.points)

    @cached_property
    def cloud(self) -> tuple[small_gicp.PointCloud, small_gicp.KdTree]:
        """The samples as small_gicp's target: a point cloud with normals from the planes
        of their ``NORMAL_NEIGHBOURS`` nearest samples, and its k-d tree."""
        cloud = small_gicp.PointCloud(self.points)
        tree = self.tree.kdtree
        small_gicp.estimate_normals(cloud, tree, num_neighbors=NORMAL_NEIGHBOURS)
        return cloud, tree

    @cached_property
    def mesh(self) -> MeshNearest | None:
        """Nearest points on the mesh the samples were drawn from (None: no mesh)."""
        if self.vertices is None or self.faces is None:
            return None
        seeds = None if self.on is None else (self.tree.kdtree, self.on)
        return MeshNearest(self.vertices, self.faces, seeds)

    def every(self, step: int) -> Surface:
        """Every ``step``-th sample (of the same mesh): a coarser surface for comparing
        starts and for the first rounds of ICP."""
        if step == 1:
            return self
        on = None if self.on is None else self.on[::step]
        return Surface(self.points[::step], self.normals[::step], self.vertices, self.faces, on)

    @cached_property
    def corners(self) -> Surface:
        """The mesh's vertices that its faces use (every k-th, for at most ``CORNERS_MOST``),
        as points (without normals): each carries the scan's noise of its own, where the
        samples of a face share its three corners', so the last rounds fit them (against the
        samples alone, the transform's error was about 1.5 times as large); the samples
        themselves when there is no mesh."""
        if self.vertices is None or self.faces is None:
            return self
        used = np.unique(self.faces)
        used = used[:: -(-len(used) // CORNERS_MOST)]
        return Surface(self.vertices[used], np.zeros((len(used), 3)))

    @cached_property
    def sparse(self) -> Surface:
        """Every ``SPARSE_EVERY``-th sample, taken once: the follow-up ICP starts on."""
        return self.every(SPARSE_EVERY)


@dataclass(frozen=True)
class Registration:
    """A 4x4 ``matrix`` taking the follow-up onto the baseline (``scale`` 1 when rigid);
    ``residuals`` are the follow-up samples' point-to-plane distances to the baseline (n,),
    ``distances`` to their nearest baseline samples."""

    matrix: np.ndarray
    scale: float
    residuals: np.ndarray
    distances: np.ndarray

    def scaled(self, factor: float) -> Registration:
        """The same registration of the scans with their lengths multiplied by ``factor``
        (its matrix's translation, the residuals and distances; rotation and scale stay)."""
        matrix = self.matrix.copy()
        matrix[:3, 3] *= factor
        return Registration(matrix, self.scale, self.residuals * factor, self.distances * factor)


def unit_of(log2_size: float) -> float:
    """The power of two that brings a spread of ``2 ** log2_size`` to between 1/sqrt(2) and
    sqrt(2) (section 15). Scans registered in it compute no subnormal number (whose arithmetic
    is a hundred times slower) and meet every tolerance at the scale it was set for, and the
    scaling is exact."""
    return math.ldexp(1.0, -round(log2_size))


def apply(matrix: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(n, 3) float: ``points`` moved by the 4x4 ``matrix``."""
    return points @ matrix[:3, :3].T + matrix[:3, 3]


def from_pairs(source: np.ndarray, target: np.ndarray, scale: bool) -> np.ndarray:
    """The 4x4 rigid (or similarity) transform that takes ``source`` onto ``target`` ((n, 3)
    each) in least squares (Umeyama; :func:`trimesh.registration.procrustes`)."""
    matrix, _, _ = procrustes(source, target, reflection=False, translation=True, scale=scale)
    return matrix


def moment_starts(
    source: Surface, target: Surface, scale: bool = False, bounds: Bounds = None
) -> list[np.ndarray]:
    """4x4 starts that take ``source``'s principal axes onto ``target``'s in each of the 24
    proper ways (the axes' order and signs: a cropped scan's axes may come in another order
    than the whole one's), each with the translation that matches the centroids and, along
    every axis of ``target`` on which the turned ``source`` is shorter by more than
    ``CROPPED`` of its extent, the two that match its one end or the other: a cropped scan's
    centroid is not the whole one's. With ``scale``, every start comes twice: unscaled, and
    scaled by the ratio of the samples' RMS distances from their centroids (the scale ICP
    then refines), each scale held within ``bounds`` (:func:`clamped`)."""
    frames = []
    for surface in (source, target):
        centre = surface.points.mean(axis=0)
        _, _, axes = np.linalg.svd(surface.points - centre, full_matrices=False)
        frames.append((centre, axes))
    (c_s, a_s), (c_t, a_t) = frames
    # With a scale, both the scans' own sizes and their spreads matched: a cropped scan
    # spreads less than the whole, so the second alone would enlarge it past its place.
    grows = (1.0, target.size / source.size) if scale and source.size > 0 else (1.0,)
    grows = tuple(dict.fromkeys(clamped(grow, bounds) for grow in grows))
    target_low, target_high = _extent(target.points @ a_t.T)
    starts = []
    for grow, order in itertools.product(grows, itertools.permutations(range(3))):
        for signs in itertools.product((1, -1), repeat=3):
            rotation = a_t.T @ (np.diag(signs) @ a_s[list(order)])
            if np.linalg.det(rotation) < 0:
                continue
            matrix = np.eye(4)
            matrix[:3, :3] = grow * rotation
            matrix[:3, 3] = c_t - grow * rotation @ c_s
            starts.append(matrix)
            low, high = _extent(apply(matrix, source.points) @ a_t.T)
            shorter = (high - low) < (1.0 - CROPPED) * (target_high - target_low)
            for axis in np.flatnonzero(shorter):
                for shift in (target_low[axis] - low[axis], target_high[axis] - high[axis]):
                    moved = matrix.copy()
                    moved[:3, 3] += shift * a_t[axis]
                    starts.append(moved)
    return starts


def clamped(grow: float, bounds: Bounds) -> float:
    """``grow`` held within ``bounds`` (least, most), when given."""
    return grow if bounds is None else float(np.clip(grow, *bounds))


def held(grow: float, bounds: Bounds) -> bool:
    """Whether the scale ``grow`` lies at either bound of ``bounds`` (to rounding): where
    :func:`icp` held a scale that would have gone beyond."""
    if bounds is None:
        return False
    low, high = bounds
    return bool(grow <= low * (1 + 1e-9) or grow >= high * (1 - 1e-9))


def _extent(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return points.min(axis=0), points.max(axis=0)


def icp(
    source: Surface,
    target: Surface,
    start: np.ndarray,
    scale: bool = False,
    rounds: int = MAX_ROUNDS,
    bounds: Bounds = None,
    last: str = "samples",
) -> Registration:
    """Point-to-plane ICP from ``start`` (eq. 15.1), coarse to fine: by small_gicp's
    ``PLANE_ICP`` (:func:`_stages`) on every ``SPARSE_EVERY``-th follow-up sample until they
    settle (when there are at least ``SPARSE_LEAST`` of them), then per ``last``: ``"sparse"``
    stops there; ``"samples"`` goes on with all the samples until they settle; ``"mesh"``
    takes all the samples onto the nearest points of the baseline's mesh itself
    (:func:`on_mesh`, when ``target`` was drawn from one; else as ``"samples"``). The
    residuals are all the samples'. With ``scale``, the scale about the follow-up's centroid
    is fitted too, held within ``bounds``."""
    matrix = start
    sparse = source.sparse if len(source.points) >= SPARSE_EVERY * SPARSE_LEAST else source
    if sparse is not source:
        matrix = _stages(sparse, target, matrix, scale, rounds, bounds)
    exact = last == "mesh" and target.mesh is not None and dense(source)
    if sparse is source or (last != "sparse" and not exact):
        matrix = _stages(source, target, matrix, scale, rounds, bounds)
    if exact:
        matrix = onto_mesh(source, target.mesh, matrix, scale, bounds)
    return measured(source, target, matrix)


def _stages(source, target, start, scale, rounds, bounds) -> np.ndarray:
    """The 4x4 transform small_gicp's point-to-plane ICP (eq. 15.1) reaches from ``start``,
    in stages of ``STAGE_ROUNDS`` rounds: each stage leaves out the pairs farther apart than
    the trimming distance of the pose it starts from, so the distance shrinks as the surfaces
    settle; with ``scale``, each stage then takes the scale about the follow-up's centroid
    that best fits the pairs along the target normals (eq. 15.2), held within ``bounds``
    (least, most: so that it cannot collapse to a point lying on the target, nor blow up;
    the start's scale is held there too, about the follow-up's centroid). It stops when a
    stage moves the samples by less than ``SETTLED`` of their spread (in radians, and in
    units of the spread), or after ``rounds`` rounds."""
    cloud, cloud_tree = target.cloud
    centre = source.points.mean(axis=0)
    spread = source.size + 1e-300
    grow = float(np.cbrt(np.linalg.det(start[:3, :3])))
    rigid = start.copy()
    rigid[:3, :3] /= grow
    rigid[:3, 3] += (grow - 1.0) * rigid[:3, :3] @ centre  # start = rigid @ (scale about c)
    grow = clamped(grow, bounds) if scale else grow
    points = moving = None
    for _ in range(max(rounds // STAGE_ROUNDS, 1)):
        checkpoint()
        if moving is None or scale:  # the samples as scaled now (rigid: once)
            points = centre + grow * (source.points - centre)
            moving = small_gicp.PointCloud(points)
        landed = apply(rigid, centre[None, :])[0]
        distance, _ = target.tree.query(apply(rigid, points))
        found = small_gicp.align(
            cloud,
            moving,
            cloud_tree,
            init_T_target_source=rigid,
            registration_type="PLANE_ICP",
            max_correspondence_distance=_trim(distance),
            max_iterations=STAGE_ROUNDS,
            rotation_epsilon=SETTLED,
            translation_epsilon=SETTLED * grow * spread,
        )
        step = found.T_target_source @ np.linalg.inv(rigid)
        rigid = found.T_target_source
        # How far the stage moved the samples: their centroid's shift, plus the turn at
        # their spread (as scaled), plus the change of scale at it.
        turn = float(Rotation.from_matrix(step[:3, :3]).magnitude())
        moved = np.linalg.norm(apply(rigid, centre[None, :])[0] - landed) + turn * grow * spread
        if scale:
            before = grow
            grow = clamped(_scale_fit(source, target, rigid, centre, grow), bounds)
            moved += abs(grow - before) * spread
        if moved < SETTLED * grow * spread:
            break
    matrix = rigid.copy()
    matrix[:3, :3] *= grow
    matrix[:3, 3] += (1.0 - grow) * rigid[:3, :3] @ centre
    return matrix


def _scale_fit(source, target, rigid, centre, grow) -> float:
    """The scale ``s`` about ``centre`` that, under ``rigid``, best fits the follow-up's
    pairs (those within the trimming distance) along the target normals (eq. 15.2)."""
    turn = rigid[:3, :3]
    fixed = apply(rigid, centre[None, :])[0]  # where the centre lands, whatever the scale
    arms = (source.points - centre) @ turn.T
    distance, nearest = target.tree.query(fixed + grow * arms)
    keep = distance <= _trim(distance)
    normals = target.normals[nearest[keep]]
    along = np.einsum("pd,pd->p", arms[keep], normals)
    gap = np.einsum("pd,pd->p", target.points[nearest[keep]] - fixed, normals)
    fit = float(np.dot(along, gap) / (np.dot(along, along) + 1e-300)) if keep.any() else grow
    return fit if np.isfinite(fit) and fit > 0 else grow  # pairs that give no scale: keep it


def _trim(distance: np.ndarray, times: float = TRIM) -> float:
    return times * float(np.percentile(distance, TRIM_QUANTILE)) + 1e-12


def measured(source: Surface, target: Surface, matrix: np.ndarray) -> Registration:
    """``matrix`` with the residuals of ``source``'s samples against ``target``: their
    point-to-plane distances to the nearest target samples, and those samples' distances."""
    moved = apply(matrix, source.points)
    distance, nearest = target.tree.query(moved)
    gap = moved - target.points[nearest]
    residuals = np.abs(np.einsum("pd,pd->p", gap, target.normals[nearest]))
    factor = float(np.cbrt(np.linalg.det(matrix[:3, :3])))
    return Registration(matrix, factor, residuals, distance)


class RegistrationAmbiguous(ValueError):
    """Two different alignments fit the follow-up about as well: the surfaces alone cannot
    tell them apart (landmarks can)."""

    def __init__(self, angle: float, shares: tuple[float, float]):
        self.angle, self.shares = angle, shares
        super().__init__(
            f"two alignments {angle:.0f} degrees apart fit about as well ({shares[0]:.0%} and "
            f"{shares[1]:.0%} of the follow-up on the baseline)"
        )


def register(
    source: Surface,
    target: Surface,
    pairs: tuple[np.ndarray, np.ndarray] | None = None,
    scale: bool = False,
    bounds: Bounds = None,
    last: str = "mesh",
) -> Registration:
    """The follow-up (``source``) registered to the baseline (``target``, the whole scan):
    from the landmarks' ``pairs`` ((k, 3) each, follow-up then baseline) when given; else
    each of :func:`moment_starts` is refined on every ``COARSE_EVERY``-th sample, the two
    best distinct ones (by the share of samples on the target, a scale :func:`held` at a
    bound ranked last) on all of them, and the better kept, unless the other fits about as
    well (``AMBIGUOUS``) and either fits (``PLAUSIBLE``), neither held. The residuals are
    against the whole baseline (:func:`register_region` goes on to the region). With
    ``scale``, every scale is held within ``bounds`` (:func:`icp`). ``last`` is how far the
    answer is refined (:func:`icp`): onto the baseline's mesh itself by default; ``"sparse"``
    when :func:`register_region` goes on from it.

    Raises
    ------
    RegistrationAmbiguous
        Without landmarks, two alignments more than ``DISTINCT_DEG`` apart leave shares on
        the baseline within ``AMBIGUOUS`` of each other, the better at least ``PLAUSIBLE``.
    """
    if pairs is not None:
        start = from_pairs(*pairs, scale=scale)
        return icp(source, target, start, scale, bounds=bounds, last=last)
    return _best_of_moments(source, target, scale, bounds, last)


def _best_of_moments(source: Surface, target: Surface, scale: bool, bounds: Bounds, last: str):
    coarse_source, coarse_target = source.every(COARSE_EVERY), target.every(COARSE_EVERY)
    coarse_tolerance = on_surface_distance(coarse_target)
    starts = moment_starts(source, target, scale, bounds)

    def landed(start: np.ndarray) -> float:  # the share of samples the start puts on it
        distance, _ = coarse_target.tree.query(apply(start, coarse_source.points))
        return float(np.mean(distance <= coarse_tolerance))

    trials = [
        icp(coarse_source, coarse_target, starts[i], scale, COARSE_ROUNDS, bounds)
        for i in _chosen(starts, [landed(start) for start in starts])
    ]
    # Ranked on the whole baseline: the coarse samples lie too far apart to tell a head
    # turned half round from the right one.
    tolerance = on_surface_distance(target)

    # A scale held at a bound ranks last: shrunk towards a point, any follow-up lies on it.
    def rank(trial: Registration) -> tuple[bool, float]:
        share = _share(measured(coarse_source, target, trial.matrix), tolerance)
        return held(trial.scale, bounds), -share

    trials.sort(key=rank)
    best = [trials[0]]
    best += [
        t
        for t in trials[1:]
        if _angle(t.matrix, trials[0].matrix) > DISTINCT_DEG and not held(t.scale, bounds)
    ][:1]
    # Each compared on the sparse samples (the shares differ by far more than their
    # settling does), the better then refined as asked.
    refined = sorted(
        (
            icp(source, target, trial.matrix, scale, rounds, bounds, last="sparse")
            for trial, rounds in zip(best, (MAX_ROUNDS, RUNNER_UP_ROUNDS), strict=False)
        ),
        key=lambda found: (held(found.scale, bounds), -_share(found, tolerance)),
    )
    if (
        len(refined) > 1
        and not any(held(found.scale, bounds) for found in refined)
        and (_angle(refined[0].matrix, refined[1].matrix) > DISTINCT_DEG)
    ):
        shares = (_share(refined[0], tolerance), _share(refined[1], tolerance))
        if shares[0] >= PLAUSIBLE and shares[0] - shares[1] < AMBIGUOUS:
            raise RegistrationAmbiguous(_angle(refined[0].matrix, refined[1].matrix), shares)
    if last == "sparse":
        return refined[0]
    return icp(source, target, refined[0].matrix, scale, bounds=bounds, last=last)


@dataclass(frozen=True)
class RegionScans:
    """The follow-up (``follow_vertices`` (n, 3) float, ``follow_faces`` (m, 3) int), the
    baseline (``base_vertices``, ``base_faces``) and its region (``region``: (k,) int, ids of
    ``base_faces``, ascending and distinct), each sampled once (section 15)."""

    follow_vertices: np.ndarray
    follow_faces: np.ndarray
    base_vertices: np.ndarray
    base_faces: np.ndarray
    region: np.ndarray

    def scaled(self, factor: float) -> RegionScans:
        """The same scans with their lengths multiplied by ``factor`` (a power of two:
        :func:`unit_of`)."""
        return RegionScans(self.follow_vertices * factor, self.follow_faces,
                           self.base_vertices * factor, self.base_faces, self.region)  # fmt: skip

    @cached_property
    def follow(self) -> Surface:
        """The whole follow-up's samples."""
        return Surface.of(self.follow_vertices, self.follow_faces)

    @cached_property
    def base(self) -> Surface:
        """The whole baseline's samples."""
        return Surface.of(self.base_vertices, self.base_faces)

    @cached_property
    def target(self) -> Surface:
        """The baseline's region's samples (``SAMPLES`` of them, whatever its share)."""
        if len(self.region) == len(self.base_faces):
            return self.base
        return Surface.of(self.base_vertices, self.base_faces[self.region])

    @cached_property
    def _centroids(self) -> tuple[NearestTree, np.ndarray]:
        """A k-d tree of the baseline's face centroids, and which lie in the region."""
        inside = np.zeros(len(self.base_faces), dtype=bool)
        inside[self.region] = True
        return NearestTree(self.base_vertices[self.base_faces].mean(axis=1)), inside

    def over(self, matrix: np.ndarray) -> np.ndarray:
        """(m,) bool: the follow-up's region under the 4x4 ``matrix``: its faces whose moved
        centroid's nearest baseline face centroid is a region face's (a scan registered to
        itself has the region's own faces)."""
        tree, inside = self._centroids
        over = np.empty(len(self.follow_faces), dtype=bool)
        for block in blocks(len(over)):
            moved = apply(matrix, self.follow_vertices[self.follow_faces[block]].mean(axis=1))
            over[block] = inside[tree.query(moved)[1]]
        return over

    def agreement(self, matrix: np.ndarray, within: float) -> tuple[float, float]:
        """How far the whole scans agree under the 4x4 ``matrix``: the share of the
        follow-up's samples within ``within`` of the baseline's (along its normals, and no
        farther than ``within`` plus twice their spacing from the nearest), and the share of
        the baseline's within it of the moved follow-up's."""
        moved = Surface(apply(matrix, self.follow.points), unit_rows(
            self.follow.normals @ matrix[:3, :3].T)[0])  # fmt: skip
        shares = []
        for source, target, pose in ((self.follow, self.base, matrix), (self.base, moved, None)):
            found = measured(source, target, np.eye(4) if pose is None else pose)
            near = found.distances <= within + on_surface_distance(target)
            shares.append(float(np.mean((found.residuals <= within) & near)))
        return shares[0], shares[1]

    def surface_over(self, over: np.ndarray) -> Surface | None:
        """The samples of the follow-up faces ``over`` ((m,) bool), or None if none is."""
        if not over.any():
            return None
        if over.all():
            return self.follow
        return Surface.of(self.follow_vertices, self.follow_faces[over])


@dataclass(frozen=True)
class OnRegion:
    """A follow-up registered on the baseline's region: ``found``, with the residuals of the
    follow-up's region's samples (``source``, None when no follow-up face lies over the
    region; its residuals then are empty) against the baseline's region; ``faces``, (m,)
    bool, the follow-up's faces over the region."""

    found: Registration
    faces: np.ndarray
    source: Surface | None

    def scaled(self, factor: float) -> OnRegion:
        """The same with lengths multiplied by ``factor`` (:meth:`Registration.scaled`)."""
        source = None if self.source is None else Surface(self.source.points * factor,
                                                          self.source.normals)  # fmt: skip
        return OnRegion(self.found.scaled(factor), self.faces, source)


#: Times the follow-up's region is chosen again and aligned on the baseline's at the most:
#: each alignment moves its border, which the next choice follows.
REGION_ROUNDS = 3


def register_region(
    scans: RegionScans, whole: Registration, scale: bool = False, bounds: Bounds = None
) -> OnRegion:
    """The follow-up registered on the baseline's region (section 15), from ``whole``, its
    registration on the whole scans (:func:`register`, which a cropped follow-up survives):
    up to ``REGION_ROUNDS`` times, the follow-up's faces over the region chosen
    (:meth:`RegionScans.over`) and their samples aligned by :func:`icp` on the region's,
    until the choice holds (with ``scale``, held within ``bounds``). The residuals are the
    follow-up's region's, against the baseline's region alone."""
    found = whole
    over = np.zeros(len(scans.follow_faces), dtype=bool)
    source = None
    for _ in range(REGION_ROUNDS):
        checkpoint()
        chosen = scans.over(found.matrix)
        if np.array_equal(chosen, over):
            break
        over, source = chosen, scans.surface_over(chosen)
        if source is None:
            break
        if source is scans.follow and scans.target is scans.base:  # the start's own pair
            break
        found = icp(source, scans.target, found.matrix, scale, bounds=bounds, last="sparse")
    if source is None:
        empty = np.empty(0)
        return OnRegion(Registration(found.matrix, found.scale, empty, empty), over, None)
    # The last rounds, onto the region's mesh itself; the choice of faces is not made again
    # (they move the follow-up by hundredths of a millimetre).
    matrix = found.matrix
    if scans.target.mesh is not None and dense(source):
        matrix = onto_mesh(source, scans.target.mesh, matrix, scale, bounds)
    else:  # a coarse follow-up: ICP on all its samples
        matrix = _stages(source, scans.target, matrix, scale, MAX_ROUNDS, bounds)
    return OnRegion(measured(source, scans.target, matrix), over, source)


def _chosen(starts: list[np.ndarray], landed: list[float]) -> list[int]:
    """Which ``starts`` (4x4 each) to refine: those that put the most samples on the target
    (``landed``), ``REFINED_STARTS`` in all, an equal number of each scale: a follow-up
    started far smaller than the target lies on it whole wherever it starts (a tenth of the
    size, any start near its surface), and would take every place."""
    ranked = np.argsort(landed, kind="stable")[::-1]
    grows = [round(float(np.cbrt(np.linalg.det(start[:3, :3]))), 9) for start in starts]
    each = REFINED_STARTS // len(set(grows))
    taken: dict[float, int] = {}
    chosen = []
    for i in ranked:
        if taken.get(grows[i], 0) < each:
            chosen.append(int(i))
            taken[grows[i]] = taken.get(grows[i], 0) + 1
    return chosen


def on_surface_distance(surface: Surface) -> float:
    """How close a point must be to a surface's samples to lie on it: twice their median
    spacing."""
    distance, _ = surface.tree.query(surface.points, k=2)
    return 2.0 * float(np.median(distance[:, 1]))


def _share(found: Registration, tolerance: float) -> float:
    """The share of the samples within ``tolerance`` of the target's nearest sample."""
    return float(np.mean(found.distances <= tolerance))


def _angle(first: np.ndarray, second: np.ndarray) -> float:
    """Degrees between the rotations of two 4x4 transforms (their scales divided out)."""
    turn = first[:3, :3] @ second[:3, :3].T
    turn /= np.cbrt(np.linalg.det(turn))
    return float(np.degrees(Rotation.from_matrix(turn).magnitude()))
