"""The fit's problem (docs/math.md, section 9): what the caller fixes (:class:`FitFixed`),
the bounds every choice keeps (:class:`FitBounds`), and the region with what the stages
evaluate on it (:class:`_Problem`).

The region's kernel planes (:mod:`.kernel`), the area-weighted sample of its faces every
candidate is scored on (:mod:`.objective`; a coarser one for the slide), and the rows of its
vertices the pole's hull is found among are made once. On them: the best sigma along lines
of candidates (a grid in log sigma, then finer grids), the slide along the pole (stage 2),
and the energy of the region on every face, or on runs of them beyond ``EXPLAIN_FACES``
(section 7), which the explanation reports.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from numbers import Integral

import numpy as np

from ..arrays import as_faces, as_points, as_vector, blocks, unit_rows
from ..cap import PoleCap
from ..chart import Chart, Method
from ..checkpoints import checkpoint
from ..errors import TransformInputError, listed_rows
from ..frames import Frame
from ..layouts import Layout
from ..region import FlatRegion, flatten_region
from ..sampling import area_sample
from ..viewpoint import check_center_sees_area
from .emptycap import boundary_loops
from .kernel import Kernel, kernel_planes
from .objective import Candidates, FaceEnergy, region_energy

#: Faces the search evaluates each candidate on (the slide on fewer), and vertices the pole's
#: hull is built from.
SAMPLE_FACES = 600
COARSE_SAMPLE_FACES = 250
HULL_VERTICES = 500
#: Vertices the free cap's hull starts from (:func:`.emptycap.exact_empty_cap`: every
#: boundary vertex and as many spread over the rest, each thinned to this many at most). Any
#: start ends on the same cap, the directions it holds added; a small one is the fastest.
CAP_HULL_VERTICES = 64
#: Where sigma is searched (beyond these the warp squeezes the region to a point or a line).
SIGMA_SEARCH = (1e-3, 10.0)
#: How far from the region's middle the centre may go, in region sizes.
_REACH = 3.0
#: Centres tried along the pole before the refinement, in inscribed radii from the deepest point.
_SLIDE = (0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 4.0)
#: The sigma search: grid points in log sigma, finer grids after (each of ``_ZOOM_POINTS``
#: spanning the step either side of the best so far), and the relative difference of
#: energies below which they count as equal.
_SIGMA_GRID = 17
_ZOOMS = 3
_ZOOM_POINTS = 7
_TIE = 1e-9
#: The slide's coarser sigma search per centre (the refinement tunes sigma after): grid
#: points, zooms and points per zoom.
_SLIDE_SIGMA_SEARCH = (9, 1, 5)
#: Faces the explanation's energies (the start's and at ``REPORTED_SIGMAS``) are measured
#: on: every face of a region up to this many, beyond it every k-th run of ``_EXPLAIN_RUN``
#: (the answer's own energy is always measured on every face). The defaults of
#: :func:`transforms.fit.fit_region`'s ``explain_faces`` and ``explain_run``.
EXPLAIN_FACES = 16384
_EXPLAIN_RUN = 128


@dataclass(frozen=True)
class FitBounds:
    """The bounds every choice keeps (:mod:`transforms.fit`).

    Attributes
    ----------
    min_kernel_depth : float in [0, inf), fraction of the kernel's inscribed radius the
        centre stays inside the kernel
    min_margin_deg : float in [0, 90), least margin from the region to the seam and the
        singular points

    Raises
    ------
    TransformInputError
        A bound out of range (named).
    """

    min_kernel_depth: float = 0.05
    min_margin_deg: float = 2.0

    def __post_init__(self) -> None:
        for name in ("min_kernel_depth", "min_margin_deg"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and 0.0 <= value < math.inf):
                raise TransformInputError(name, f"must be a finite number >= 0, got {value!r}")
        if self.min_margin_deg >= 90.0:
            raise TransformInputError(
                "min_margin_deg", f"must be below 90, got {self.min_margin_deg}"
            )


@dataclass(frozen=True)
class FitFixed:
    """What the caller fixes; every field left None is chosen.

    Attributes
    ----------
    center : (3,) float or None
    rotation : Frame or None (choose the pole and the roll); only its rotation is used
    up : (3,) float or None, a world direction the roll follows when the rotation is chosen
        (local ``+Z`` is its part orthogonal to the pole); None: :func:`.start.roll_axis`
    sigma : float or None
    """

    center: np.ndarray | None = None
    rotation: Frame | None = None
    up: np.ndarray | None = None
    sigma: float | None = None


@dataclass(frozen=True)
class _Candidate:
    """A choice: a centre (3,), a world-to-local rotation (3, 3) and sigma (None for the
    standard method)."""

    center: np.ndarray
    rotation: np.ndarray
    sigma: float | None


class _Problem:
    """A region, its kernel planes, and its sample: what the search evaluates.

    ``explain_faces`` and ``explain_run``: where :meth:`region_energies` measures the region
    (as :func:`transforms.fit.fit_region` takes them)."""

    def __init__(
        self,
        points: np.ndarray,
        faces: np.ndarray,
        method: Method,
        threads: int,
        layout: Layout,
        *,
        explain_faces: int = EXPLAIN_FACES,
        explain_run: int = _EXPLAIN_RUN,
    ):
        self.points, self.faces, self.method, self.threads = points, faces, method, threads
        self.layout = layout
        self.explain_faces, self.explain_run = explain_faces, explain_run
        #: Where :meth:`flatten` flattens: these points, with a candidate's own frame, unless
        #: the fit runs in the region's own frame (:mod:`.pose`), which sets the input's
        #: points and the candidate's frame there.
        self.world_points: np.ndarray = points
        self.world_frame: Callable[[np.ndarray, np.ndarray], Frame] = _frame_of
        self.used = np.flatnonzero(np.bincount(faces.ravel(), minlength=len(points)))
        self.region_points = points[self.used]
        self.planes = kernel_planes(points, faces)
        j = len(self.planes.faces)
        areas = np.zeros(len(faces))
        areas[self.planes.faces] = self.planes.areas[:j]
        picked = area_sample(areas, SAMPLE_FACES)
        self.sample_points, self.sample_faces = _compacted(points, faces[picked])
        self.sample_areas = areas[picked]
        self.sample = FaceEnergy(self.sample_points, self.sample_faces, method, layout)
        self.areas = areas
        # The rows of region_points the pole's hull and the slide's caps are judged on.
        self.hull_rows = _hull_rows(self.used, self.planes.boundary_vertices)
        self.hull_points = self.region_points[self.hull_rows]
        # The rows the free cap's hull starts from.
        self.cap_rows = _hull_rows(self.used, self.planes.boundary_vertices, CAP_HULL_VERTICES)

    @classmethod
    def checked(
        cls,
        vertices,
        faces,
        fixed: FitFixed,
        method,
        threads: int,
        layout,
        *,
        explain_faces: int = EXPLAIN_FACES,
        explain_run: int = _EXPLAIN_RUN,
    ) -> _Problem:
        """The problem of a caller's region, its input checked (as
        :func:`transforms.fit.fit_region`)."""
        for name, value in (("explain_faces", explain_faces), ("explain_run", explain_run)):
            if isinstance(value, bool) or not isinstance(value, Integral) or value < 1:
                raise TransformInputError(name, f"must be a whole number >= 1, got {value!r}")
        method = Method(method)
        points = as_points(vertices, "vertices")
        faces = as_faces(faces, len(points))
        if len(faces) == 0:
            raise TransformInputError("faces", "the region has no faces")
        if fixed.sigma is not None and method is Method.STANDARD:
            raise TransformInputError(
                "sigma", "method 'standard' has no warp, so it takes no sigma"
            )
        if fixed.center is not None:
            check_center_sees_area(points, faces, as_vector(fixed.center, "center"))
        return cls(
            points,
            faces,
            method,
            threads,
            Layout(layout),
            explain_faces=explain_faces,
            explain_run=explain_run,
        )

    @cached_property
    def coarse(self) -> FaceEnergy:
        """The slide's sample: it only picks the basin the refinement starts in, so fewer
        faces do (made when a fit slides; the default choice never does)."""
        picked = area_sample(self.areas, COARSE_SAMPLE_FACES)
        return FaceEnergy(*_compacted(self.points, self.faces[picked]), self.method, self.layout)

    @cached_property
    def region_faces(self) -> np.ndarray:
        """(m, 3) int: the region's faces as rows of ``region_points``."""
        position = np.zeros(len(self.points), dtype=np.int64)
        position[self.used] = np.arange(len(self.used))
        return position[self.faces]

    @cached_property
    def boundary_edges(self) -> np.ndarray:
        """(b, 2) int: the region's boundary edges, rows of ``region_points`` (the kernel's,
        renumbered: ``used`` ascends, so each edge keeps its order and its lower end first)."""
        position = np.zeros(len(self.points), dtype=np.int64)
        position[self.used] = np.arange(len(self.used))
        return position[self.planes.boundary_edges]

    @cached_property
    def boundary_loops(self) -> tuple[np.ndarray, np.ndarray]:
        """:func:`.emptycap.boundary_loops` of :attr:`boundary_edges`: the boundary's
        vertices (rows of ``region_points``) and their loops."""
        return boundary_loops(len(self.used), self.boundary_edges)

    def release(self) -> None:
        """Let go of what only the search reads: the kernel's planes, the region's own
        vertices and faces and the hull's (the flatten and the energies read the input's
        arrays)."""
        self.planes = self.region_points = self.used = self.hull_points = self.hull_rows = None
        self.cap_rows = None
        self.__dict__.pop("region_faces", None)
        self.__dict__.pop("boundary_edges", None)
        self.__dict__.pop("boundary_loops", None)

    @property
    def closed(self) -> bool:
        """Whether the region has no boundary (no closing planes)."""
        return len(self.planes.normals) == len(self.planes.faces)

    def chart(self, sigma: float | None) -> Chart:
        if self.method is Method.STANDARD:
            return Chart.standard()
        return Chart.from_method(self.method, PoleCap.from_sigma(sigma))

    def directions(self, center: np.ndarray) -> np.ndarray:
        """(n, 3) unit directions from ``center`` to the region's vertices."""
        units, zero = unit_rows(self.region_points - center)
        if zero.any():
            # Named as flatten_region names it: the vertices at the centre, by their rows.
            at_centre = np.zeros(len(self.points), dtype=bool)
            at_centre[self.used[zero]] = True
            text, rows = listed_rows(at_centre, "vertex")
            raise TransformInputError(
                "vertices",
                f"{text}: at the centre, so no direction is defined; choose a centre that is "
                "not on the surface",
                rows,
            )
        return units

    def flatten(self, candidate: _Candidate) -> FlatRegion:
        """The region flattened on every face with ``candidate``, in the input's coordinates
        (so that the answer's params, sent back, give the same map to the last bit)."""
        frame = self.world_frame(candidate.center, candidate.rotation)
        return flatten_region(
            self.world_points,
            self.faces,
            frame,
            self.chart(candidate.sigma),
            threads=self.threads,
            layout=self.layout,
        )

    def region_energies(self, candidates: list[_Candidate]) -> np.ndarray:
        """(k,) the energy of the region for each candidate (docs/math.md, section 7), as
        :meth:`flatten` would report it, without the validation: on every face up to
        ``explain_faces``, beyond that on every k-th run of ``explain_run`` faces in the
        region's order (a ratio estimate of the area-weighted mean, its weights unbiased)."""
        faces, most, run = self.faces, self.explain_faces, self.explain_run
        if len(faces) > most:
            # Every k-th run of consecutive faces: neighbours in a file share vertices, so
            # the runs cost fewer vertices' angles than single faces would.
            runs = np.arange(0, len(faces), run * -(-len(faces) // most))
            picked = (runs[:, None] + np.arange(run)).ravel()
            faces = faces[picked[picked < len(faces)]]
        used = np.flatnonzero(np.bincount(faces.ravel(), minlength=len(self.points)))
        position = np.zeros(len(self.points), dtype=np.int64)
        position[used] = np.arange(len(used))
        batch = _batch(candidates)
        points = self.points[used]
        return region_energy(points, position[faces], batch, self.method, self.layout)

    def energy(self, candidate: _Candidate) -> float:
        """The robust objective on the sample (docs/math.md, section 9): the fraction of its
        area seen from behind from the candidate's centre (such faces fold whatever the
        pole and sigma), times ``BACKFACING_WEIGHT``, plus the area-weighted isometric
        energy of the faces seen from the front; inf where it cannot be measured.

        So a few slivers seen from behind, whose energy can be thousands, do not steer the
        choice: a centre is first judged by how much it cannot see, then by the rest.
        """
        return float(self.sample.scores(_batch([candidate])).objective[0])

    def best_sigmas(
        self,
        centers: np.ndarray,
        rotations: np.ndarray,
        largest_rho: np.ndarray,
        search: tuple[int, int, int] = (_SIGMA_GRID, _ZOOMS, _ZOOM_POINTS),
        coarse: bool = False,
    ) -> np.ndarray:
        """(k,) for each of ``k`` centres (k, 3) and rotations (k, 3, 3), the sigma of least
        sample energy with the cap's angle at most ``largest_rho`` (k,).

        A grid of ``search[0]`` points in log sigma, then ``search[1]`` finer grids of
        ``search[2]`` points around the best point so far, all lines at once. Energies equal
        to ``_TIE`` (relative) count as equal and the larger sigma wins, so that rounding,
        which differs with the mesh's pose, cannot pick another point of a flat stretch.
        ``coarse``: on the coarse sample.
        """
        sample = self.coarse if coarse else self.sample
        low, high = SIGMA_SEARCH
        floor = 2.0 * math.atan(low)
        highs = np.minimum(high, np.tan(np.maximum(largest_rho, floor) / 2.0))
        bottom, tops = math.log(low), np.log(np.maximum(highs, low))
        points, zooms, zoom_points = search
        grid = bottom + np.outer(tops - bottom, np.linspace(0.0, 1.0, points))
        energies = self._line_energies(centers, rotations, grid, sample)
        best_x, best_e = _best_on_grid(grid, energies)
        step = (tops - bottom) / (points - 1)
        for _ in range(zooms):
            checkpoint()
            grid = best_x[:, None] + np.outer(step, np.linspace(-1.0, 1.0, zoom_points))
            grid = np.clip(grid, bottom, tops[:, None])
            energies = self._line_energies(centers, rotations, grid, sample)
            # The best so far stays in the running (the finer grid may miss it).
            best_x, best_e = _best_on_grid(
                np.column_stack([grid, best_x]), np.column_stack([energies, best_e])
            )
            step = step * 2.0 / (zoom_points - 1)
        return np.where(highs <= low, highs, np.exp(best_x))

    def _line_energies(
        self, centers, rotations, grid: np.ndarray, sample: FaceEnergy
    ) -> np.ndarray:
        """(k, g) objective on ``sample`` at ``exp(grid)`` (k, g) along each line."""
        k, g = grid.shape
        batch = Candidates.of(
            np.repeat(centers, g, axis=0), np.repeat(rotations, g, axis=0), np.exp(grid).ravel()
        )
        return sample.scores(batch).objective.reshape(k, g)

    def best_sigma(self, center: np.ndarray, rotation: np.ndarray, largest_rho: float) -> float:
        """:meth:`best_sigmas` for one centre and rotation."""
        return float(self.best_sigmas(center[None], rotation[None], np.array([largest_rho]))[0])

    def slide_towards_pole(
        self,
        start: _Candidate,
        kernel: Kernel,
        min_depth: float,
        margin: float | None,
        choose_sigma: bool,
    ) -> _Candidate:
        """The best of ``start`` and centres moved along its pole by multiples of the
        inscribed radius (``_SLIDE``), each with its best sigma, up to the first that leaves
        the kernel's depth or the region's reach. All are scored in one batch."""
        pole = start.rotation[1]
        centers = start.center + np.outer(_SLIDE, kernel.inscribed_radius * pole)
        depth = self.planes.depths(centers)
        away = np.linalg.norm(centers - self.planes.middle, axis=1)
        inside = (depth >= min_depth) & (depth > 0) & (away <= _REACH * self.planes.size)
        centers = centers[: int(np.argmin(inside)) if not inside.all() else len(inside)]
        if len(centers) == 0:
            return start
        rotations = np.repeat(start.rotation[None], len(centers), axis=0)
        if choose_sigma:
            room = np.full(len(centers), math.pi)
            if margin is not None:
                room = _cap_radii(self.hull_points, centers, pole) - margin
            sigmas = self.best_sigmas(centers, rotations, room, _SLIDE_SIGMA_SEARCH, coarse=True)
        else:
            sigmas = np.full(len(centers), _sigma_or_one(start.sigma))
        batch = Candidates.of(np.vstack([start.center, centers]), start.rotation, 0.0)
        batch = Candidates(
            batch.centers, batch.rotations, np.r_[_sigma_or_one(start.sigma), sigmas]
        )
        energies = self.coarse.scores(batch).objective
        best = int(np.argmin(energies))
        if not energies[best] < energies[0]:
            return start
        sigma = float(sigmas[best - 1]) if start.sigma is not None else None
        return _Candidate(centers[best - 1], start.rotation, sigma)


def _frame_of(center: np.ndarray, rotation: np.ndarray) -> Frame:
    return Frame.from_matrix(rotation, center)


def _cap_radii(points: np.ndarray, centers: np.ndarray, pole: np.ndarray) -> np.ndarray:
    """(k,) angular radius of the largest cap around ``pole`` holding no direction from each
    of ``centers`` (k, 3) to ``points`` (n, 3) (:func:`.emptycap.cap_radius` for a batch),
    block by block."""
    largest = np.full(len(centers), -1.0)
    for block in blocks(len(points)):
        offsets = points[None, block] - centers[:, None]
        cosine = (offsets @ pole) / np.linalg.norm(offsets, axis=2)
        np.maximum(largest, cosine.max(axis=1), out=largest)
    return np.arccos(np.clip(largest, -1.0, 1.0))


def _best_on_grid(grid: np.ndarray, energies: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per row of ``grid`` (k, g), ascending, the point of least energy and that energy;
    energies equal to ``_TIE`` (relative) count as equal and the larger point wins (the first
    point where every energy is inf)."""
    least = energies.min(axis=1, keepdims=True)
    with np.errstate(invalid="ignore"):
        tied = energies <= least + _TIE * np.abs(least)
    tied &= np.isfinite(least)
    order = np.argsort(grid, axis=1, kind="stable")
    ranked = np.take_along_axis(tied, order, axis=1)
    last = grid.shape[1] - 1 - np.argmax(ranked[:, ::-1], axis=1)
    pick = np.where(np.isfinite(least[:, 0]), order[np.arange(len(grid)), last], 0)
    rows = np.arange(len(grid))
    return grid[rows, pick], energies[rows, pick]


def _hull_rows(used: np.ndarray, boundary: np.ndarray, count: int = HULL_VERTICES) -> np.ndarray:
    """Rows of the region's vertices (``used``, ascending ids) whose directions the largest
    empty cap is found among: every boundary vertex and ``count`` spread over the rest, each
    list thinned evenly to ``count`` at most.

    Seen from inside the kernel, the part of the sphere the region leaves empty is bounded
    by its boundary loops' directions (no triangle is seen edge-on there), so the cap the
    hull finds is that of every vertex; the spread rows keep it close where the kernel is
    empty and folds bound it too. The hull of directions on a sphere has every one as a
    vertex (20,000 cost 0.2 s), so fewer is faster."""
    spread = np.linspace(0, len(used) - 1, min(count, len(used))).astype(np.int64)
    edge = np.searchsorted(used, boundary)
    if len(edge) > count:
        edge = edge[np.linspace(0, len(edge) - 1, count).astype(np.int64)]
    return np.union1d(spread, edge)


def _compacted(points: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The vertices ``faces`` use, and the faces indexing them."""
    used, compact = np.unique(faces, return_inverse=True)
    return points[used], compact.reshape(-1, 3)


def _sigma_or_one(sigma: float | None) -> float:
    """The sigma a batch carries: 1 (no warp) for the standard method, which has none."""
    return 1.0 if sigma is None else float(sigma)


def _batch(candidates: list[_Candidate]) -> Candidates:
    return Candidates(
        np.array([c.center for c in candidates]),
        np.array([c.rotation for c in candidates]),
        np.array([_sigma_or_one(c.sigma) for c in candidates]),
    )
