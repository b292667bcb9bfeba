"""Sites on a surface at a density: Poisson-disk samples with exact counts and a spacing
that holds everywhere (docs/math.md, section 13).

Random sequential adsorption: candidates drawn uniformly by area are taken in turn, each
kept unless it lies closer than the spacing to a site kept before it, until the quota is
reached. Kept sites are spaced by construction; as every candidate is uniform and the
sites are counted, not thinned, the density is the quota's over the area. The candidates
come in batches, each checked against the sites kept in earlier batches (a k-d tree) and
against those of its own batch that come before it.

The sites depend on the surface's triangles (their order, areas and 3D distances) and the
random stream only, never on the pose or the unit the mesh is stored in: the sizes of the
batches, which decide which candidates are checked together, are computed from counts and
from area ratios rounded to a few bits (:data:`SIZING_BITS`), so that the last bits a move,
a turn or a change of unit leaves in the areas cannot change them.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from .arrays import combine, face_cross, unit_rows
from .checkpoints import checkpoint

#: Random sequential adsorption of disks of diameter ``r`` jams at ``JAMMING / r**2`` sites per
#: unit area (a coverage of 0.547 of the plane).
JAMMING = 0.547 * 4.0 / math.pi
#: The default spacing at a density ``d`` is ``SPACING_RULE / sqrt(d)``: 84 % of the jamming
#: spacing ``sqrt(JAMMING / d)`` and 65 % of a hexagonal grid's ``sqrt(2 / (sqrt(3) d))``.
SPACING_RULE = 0.7
#: Candidates tried per site asked before a part is given up as too full for its spacing.
MAX_TRIES_PER_SITE = 200
#: Candidates per site still needed a batch draws at the most; a batch that large keeping
#: fewer than ``STALLED`` of its candidates means the part is full (about jammed).
MAX_FACTOR, STALLED = 64.0, 1.0 / 2000.0
#: A batch holds at most this many candidates per site the part could hold at its spacing
#: (memory: the pairs among them grow with the candidates' density).
BATCH_PER_CAPACITY = 4.0
#: The least share of candidates expected inside a part that its tries are scaled up for.
MIN_YIELD = 1e-3
#: The most candidates drawn at once (memory: about 100 bytes each).
MAX_BATCH = 1 << 20
#: Significant bits kept of the measures that size the batches (a part's yield and capacity,
#: ratios of areas): the same surface moved, turned or scaled gives areas that differ in their
#: last bits, and a batch one candidate longer changes every site after it.
SIZING_BITS = 8


def default_spacing(density: float) -> float:
    """The spacing of sites at ``density`` (sites per unit area, > 0) by the default rule."""
    return SPACING_RULE / math.sqrt(density)


def settled(value: float) -> float:
    """``value`` (finite, >= 0) rounded to :data:`SIZING_BITS` significant bits.

    A measure that is the same in exact arithmetic for the same surface in any pose (a ratio
    of its areas) but differs in its last bits is then the same number, unless it lies within
    those bits of a midpoint between two such numbers: about ``2 * 1e-15 * 2**8``, 5e-13, of
    the time for a ratio of sums of areas (a yield of exactly 1, a whole region's, is never
    near one). Unsettled, a yield of 1 + 2e-16 truncated a batch of ``need * factor / yield``
    candidates one shorter than a yield of 1 did, and every site after it moved."""
    mantissa, exponent = math.frexp(float(value))
    steps = 1 << SIZING_BITS
    return math.ldexp(round(mantissa * steps) / steps, exponent)


@dataclass(frozen=True)
class SitePart:
    """A part of the surface that gets ``quota`` sites, at least ``spacing`` apart.

    Attributes
    ----------
    triangles : (j,) int, positions in the faces
    area : (j,) float >= 0, the area of each triangle in the part (its surface area, or the
        share of it inside a zone)
    quota : int >= 0
    spacing : float > 0, or (j,) float > 0 per triangle: a site keeps at least its own
        triangle's spacing from every site placed before it
    density : (j,) float >= 0 or None: how much more often candidates fall on a triangle
        (per unit area; None: evenly)
    partial : (j,) bool, the triangles only partly in the part: candidates are drawn over
        the whole triangle (``whole_area``) and kept only where ``inside`` says
    inside : callable ``(triangles (p,), weights (p, 3)) -> (p,) bool`` or None
    whole_area : (j,) float or None, the triangles' whole areas (for ``partial``)
    name : str, for errors
    """

    triangles: np.ndarray
    area: np.ndarray
    quota: int
    spacing: float | np.ndarray
    density: np.ndarray | None = None
    partial: np.ndarray | None = None
    inside: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None
    whole_area: np.ndarray | None = None
    name: str = "region"

    @property
    def least_spacing(self) -> float:
        """The least spacing of the triangles sites may go on (a triangle of density 0 gets
        none, whatever spacing it was given); 0 for none."""
        spacing = np.broadcast_to(self.spacing, self.triangles.shape)
        if self.density is not None:
            spacing = spacing[self.density > 0]
        return float(spacing.min()) if spacing.size else 0.0

    def draw_weight(self) -> np.ndarray:
        """(j,) float: how often candidates fall on each triangle (whole triangles where
        the part cuts them: a candidate there is uniform over the triangle, kept inside)."""
        area = self.area if self.whole_area is None else self.whole_area
        return area if self.density is None else area * self.density

    def expected_yield(self) -> float:
        """The share of drawn candidates that fall inside the part, to :data:`SIZING_BITS`
        bits (the same in every pose and unit: it sizes the batches)."""
        drawn = self.draw_weight().sum()
        inside = self.area.sum() if self.density is None else np.dot(self.area, self.density)
        return settled(inside / drawn) if drawn > 0 else 0.0

    def capacity(self) -> float:
        """About the most sites the part holds at its spacing: its area over the jamming
        area a site takes, ``s^2 / JAMMING``, summed over its triangles (more fit along a
        border: this sizes the batches, it bounds nothing), to :data:`SIZING_BITS` bits."""
        spacing = np.broadcast_to(self.spacing, self.triangles.shape)
        held = self.area if self.density is None else self.area * (self.density > 0)
        return settled(np.sum(held * JAMMING / spacing**2))


@dataclass(frozen=True)
class Sites:
    """Sites on triangles.

    Attributes
    ----------
    triangles : (n,) int, positions in the faces
    weights : (n, 3) float, barycentric weights of the triangle's corners, >= 0, sum 1
    points : (n, 3) float, the surface points (the corners combined by the weights)
    part : (n,) int, the part each belongs to
    """

    triangles: np.ndarray
    weights: np.ndarray
    points: np.ndarray
    part: np.ndarray


class SitesDoNotFit(ValueError):
    """A part could not take its quota at its (least) spacing: ``placed`` sites were placed
    before it was given up."""

    def __init__(self, part: int, name: str, placed: int, quota: int, spacing: float):
        self.part, self.name, self.placed, self.quota, self.spacing = (
            part, name, placed, quota, spacing,
        )  # fmt: skip
        super().__init__(f"{name}: {self.words}, at a spacing of {spacing:.6g}")

    @property
    def words(self) -> str:
        """What happened, without the part's name and the spacing's unit."""
        return (
            f"{self.placed:,} of {self.quota:,} sites were placed within "
            f"{MAX_TRIES_PER_SITE} candidates a site (random sequential adsorption jams at "
            "about 0.697 / spacing² sites per unit area)"
        )


def place_sites(
    points: np.ndarray, faces: np.ndarray, parts: Sequence[SitePart], rng: np.random.Generator
) -> Sites:
    """Poisson-disk sites on the ``parts`` of a triangle mesh (section 13), one part after
    the other, each spaced from the sites of all parts before it too.

    Parameters
    ----------
    points : (k, 3) float
    faces : (m, 3) int
    parts : sequence of SitePart
    rng : numpy Generator (the same generator state gives the same sites)

    Returns
    -------
    Sites, the parts' sites, the densest part's (the least spacing) first

    Raises
    ------
    SitesDoNotFit
        A part's quota did not fit at its spacing within ``MAX_TRIES_PER_SITE`` candidates per
        site (or the candidates stopped finding room: about jammed).
    """
    kept = _Kept()
    triangles, weights, which = [np.empty(0, dtype=np.int64)], [np.empty((0, 3))], []
    # Densest first: a site of a sparser part keeps its own, larger, spacing from the denser
    # parts' sites, so two sites of different parts are at least the larger spacing apart.
    order = sorted(range(len(parts)), key=lambda k: parts[k].least_spacing)
    for number in order:
        part = parts[number]
        found, found_weights = _adsorb(points, faces, part, rng, kept)
        if len(found) < part.quota:
            raise SitesDoNotFit(number, part.name, len(found), part.quota, part.least_spacing)
        triangles.append(found)
        weights.append(found_weights)
        which.append(np.full(len(found), number))
    triangles, weights = np.concatenate(triangles), np.concatenate(weights)
    part = np.concatenate(which) if which else np.empty(0, dtype=np.int64)
    return Sites(triangles, weights, combine(points, faces, triangles, weights), part)


class _Kept:
    """The sites kept so far: a k-d tree of the older ones and a list of the recent ones,
    merged into the tree when they grow past half of it (a query costs the tree's depth; a
    rebuild, all of it)."""

    def __init__(self) -> None:
        self.old = np.empty((0, 3))
        self.tree: cKDTree | None = None
        self.recent: list[np.ndarray] = []
        self.recent_count = 0

    def clear_of(self, candidates: np.ndarray, spacing: np.ndarray) -> np.ndarray:
        """(p,) bool: the candidates no older site is within their ``spacing`` ((p,)) of."""
        if self.tree is None or len(candidates) == 0:
            return np.ones(len(candidates), dtype=bool)
        bound = float(spacing.max())
        distance, _ = self.tree.query(candidates, k=1, distance_upper_bound=bound)
        return ~(distance < spacing)

    def recent_points(self) -> np.ndarray:
        return np.concatenate(self.recent) if self.recent else np.empty((0, 3))

    def add(self, new: np.ndarray) -> None:
        self.recent.append(new)
        self.recent_count += len(new)
        if self.recent_count > max(len(self.old), 1024) // 2:
            self.old = np.concatenate([self.old, self.recent_points()])
            self.tree = _tree(self.old)
            self.recent, self.recent_count = [], 0


def _tree(points: np.ndarray) -> cKDTree:
    # Built for a handful of queries, not many: the unbalanced, uncompacted tree builds in
    # half the time.
    return cKDTree(points, balanced_tree=False, compact_nodes=False)


def _adsorb(points, faces, part: SitePart, rng, kept: _Kept):
    """The triangles and weights of ``part``'s sites (up to its quota), by batches of
    candidates; the sites are added to ``kept``."""
    cumulative = np.cumsum(part.draw_weight(), dtype=np.float64)
    total = cumulative[-1] if len(cumulative) else 0.0
    found_triangles, found_weights, count, tried = [], [], 0, 0
    factor = 1.3  # candidates per site still needed; grows as the part fills
    inside = max(part.expected_yield(), MIN_YIELD)
    budget = MAX_TRIES_PER_SITE * part.quota / inside
    largest = max(256, BATCH_PER_CAPACITY * part.capacity() / inside)
    while count < part.quota and total > 0 and tried < budget:
        checkpoint()
        need = part.quota - count
        size = int(min(max(need * factor / inside, 256), largest, MAX_BATCH, budget - tried + 256))
        tried += size
        pick = np.searchsorted(cumulative, rng.random(size) * total, side="right")
        pick = np.minimum(pick, len(cumulative) - 1)
        weights = _uniform_in_triangle(rng, size)
        triangles = part.triangles[pick]
        spacing = np.broadcast_to(part.spacing, part.triangles.shape)[pick]
        if part.inside is not None and part.partial is not None:
            check = part.partial[pick]
            keep = np.ones(size, dtype=bool)
            keep[check] = part.inside(triangles[check], weights[check])
            triangles, weights, spacing = triangles[keep], weights[keep], spacing[keep]
        candidates = combine(points, faces, triangles, weights)
        clear = kept.clear_of(candidates, spacing)
        triangles, weights, candidates = triangles[clear], weights[clear], candidates[clear]
        first = _first_apart(kept.recent_points(), candidates, spacing[clear])[:need]
        kept.add(candidates[first])
        found_triangles.append(triangles[first])
        found_weights.append(weights[first])
        count += len(first)
        if factor == MAX_FACTOR and len(first) < STALLED * size * inside:
            break
        if len(first) < 0.25 * need:
            factor = min(factor * 2.0, MAX_FACTOR)
    if not found_triangles:
        return np.empty(0, dtype=np.int64), np.empty((0, 3))
    return np.concatenate(found_triangles), np.concatenate(found_weights)


def _uniform_in_triangle(rng: np.random.Generator, size: int) -> np.ndarray:
    """(size, 3) float: barycentric weights uniform over a triangle's area (the square root
    of one uniform number picks the distance from the first corner)."""
    root, t = np.sqrt(rng.random(size)), rng.random(size)
    return np.column_stack([1.0 - root, root * (1.0 - t), root * t])


def _first_apart(recent: np.ndarray, candidates: np.ndarray, spacing: np.ndarray) -> np.ndarray:
    """(q,) int, ascending: the candidates ((p, 3)) no ``recent`` site ((r, 3)) and no
    earlier candidate is within their ``spacing`` ((p,)) of (an earlier candidate counts even
    when it is itself left out: fewer kept per batch, never two too close)."""
    both = np.concatenate([recent, candidates])
    if len(candidates) == 0 or len(both) < 2:
        return np.arange(len(candidates))
    pairs = _tree(both).query_pairs(float(spacing.max()), output_type="ndarray")
    apart = np.ones(len(both), dtype=bool)
    if len(pairs):
        later = pairs.max(axis=1)  # a candidate: the recent sites come first
        gap = np.linalg.norm(both[pairs[:, 0]] - both[pairs[:, 1]], axis=1)
        close = later >= len(recent)
        close[close] = gap[close] < spacing[later[close] - len(recent)]
        apart[later[close]] = False
    return np.flatnonzero(apart[len(recent) :])


def vertex_normals(points: np.ndarray, faces: np.ndarray, cross=None) -> np.ndarray:
    """(k, 3) float: unit vertex normals, each the sum of its faces' normals weighted by
    their areas (the faces' sides' cross products, summed), following the faces' winding;
    zero for a vertex of no face with area.

    Parameters
    ----------
    points : (k, 3) float
    faces : (m, 3) int
    cross : (m, 3) float or None, :func:`~transforms.arrays.face_cross` when at hand
    """
    normals = face_cross(points, faces) if cross is None else cross
    summed = np.zeros((len(points), 3))
    for c in range(3):
        for k in range(3):
            summed[:, c] += np.bincount(faces[:, k], normals[:, c], len(points))
    unit, _ = unit_rows(summed)
    return unit


def site_normals(points: np.ndarray, faces: np.ndarray, sites: Sites, center) -> np.ndarray:
    """(n, 3) float: unit normals at the sites, the vertex normals
    (:func:`vertex_normals`) interpolated with the sites' weights, pointing away from
    ``center`` ((3,) float): all turned over when the faces wind inwards (their normals'
    sum, weighted by area, points towards it)."""
    cross = face_cross(points, faces)
    normals = outward_sign(points, faces, center, cross) * vertex_normals(points, faces, cross)
    unit, _ = unit_rows(combine(normals, faces, sites.triangles, sites.weights))
    return unit


def outward_sign(points: np.ndarray, faces: np.ndarray, center, cross=None) -> int:
    """+1 when the winding normals of ``faces`` point away from ``center`` ((3,)) on the
    whole (their area-weighted sum), else -1: the sign that turns them outwards."""
    cross = face_cross(points, faces) if cross is None else cross
    centroids = points[faces].mean(axis=1)
    return 1 if np.einsum("md,md->", cross, centroids - np.asarray(center)) >= 0 else -1


def minimum_distance(points: np.ndarray) -> float:
    """The smallest distance between two of ``points`` ((n, 3)); inf for fewer than two."""
    if len(points) < 2:
        return math.inf
    distance, _ = cKDTree(points).query(points, k=2)
    return float(distance[:, 1].min())
