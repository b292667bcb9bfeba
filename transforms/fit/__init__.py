"""Choosing the centre, the pole (with the roll about it) and sigma for a region: the three
parameters the paper leaves to the user (docs/math.md, section 9).

The choice minimises the region's area-weighted isometric energy, subject to two bounds:

* the centre stays inside the region's kernel (:mod:`.kernel`) at a depth of at least
  ``min_kernel_depth`` times the kernel's inscribed radius;
* the margin from the region to the seam and the singular points stays at least
  ``min_margin_deg``.

It starts from choices that can be explained one by one: the centre is the kernel's deepest
point (its Chebyshev centre), the pole the middle of the largest cap that holds no region
direction seen from there (:mod:`.emptycap`), the roll the rule of :func:`roll_axis`, sigma
the best of a 1D search with the cap inside the empty cap; then it refines the free ones
together (quasi-Newton steps: scipy's L-BFGS-B, the gradients in closed form, by forward
differences for the separable method). The search works on an area-weighted sample of the
faces (:mod:`transforms.sampling`) in a frame built from the starting choice, so its path does not
depend on how the mesh is posed; the answer is checked, and its energy and margins
reported, on every face. Any of the three may be fixed by the caller.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from scipy.optimize import minimize

from ..arrays import as_direction, as_faces, as_points, as_vector, blocks, cross_rows, unit_rows
from ..cap import PoleCap
from ..chart import Chart, Method
from ..errors import TransformInputError, listed_rows
from ..frames import Frame
from ..layouts import Layout
from ..region import FlatRegion, flatten_region
from ..sampling import area_sample
from ..viewpoint import check_center_sees_area
from .emptycap import cap_radius, largest_empty_cap
from .kernel import Kernel, chebyshev_center, kernel_planes
from .objective import Candidates, FaceEnergy, Motion, region_energy

#: Faces the search evaluates each candidate on (the slide on fewer), and vertices the pole's
#: hull is built from.
SAMPLE_FACES = 600
COARSE_SAMPLE_FACES = 250
HULL_VERTICES = 500
#: Where sigma is searched (beyond these the warp squeezes the region to a point or a line).
SIGMA_SEARCH = (1e-3, 10.0)
#: Planes nearest the start whose depth the refinement watches (besides the sampled ones).
_NEAR_PLANES = 4096
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
#: Below this sine of the angle between the up hint and the chosen pole, the hint is ignored.
_PARALLEL = 1e-6
#: The refinement's cost where a candidate cannot be measured: finite, so that differences
#: of costs never meet inf - inf, and above any real cost.
_INFEASIBLE = 1e100
#: The refinement: its most quasi-Newton steps, the forward-difference step of its gradients
#: (its coordinates are of order 1), and the weight of a bound's squared shortfall (a
#: shortfall of 1e-4 costs 1e-4, as much as the energy a step can win there).
_REFINE_STEPS = 60
#: Relative decrease of the cost below which the refinement stops: far below the energy
#: differences a plan can see, and below the sample's own noise.
_REFINE_TOLERANCE = 1e-10
_STEP = 1e-7
_PENALTY = 1e4
#: Sigmas whose energy the explanation reports.
REPORTED_SIGMAS = (0.3, 1.0)
#: Faces the explanation's energies (the start's and at ``REPORTED_SIGMAS``) are measured
#: on: every face of a region up to this many, beyond it every k-th (the answer's own
#: energy is always measured on every face).
EXPLAIN_FACES = 16384
_EXPLAIN_RUN = 128


@dataclass(frozen=True)
class FitExplanation:
    """Why the parameters are what they are.

    Attributes
    ----------
    energy_start : float, area-weighted isometric energy of the starting choice (on every
        face up to ``EXPLAIN_FACES``, beyond that on every k-th)
    energy_end : float, the same for the answer
    kernel_inscribed_radius : float, radius of the largest ball in the kernel (0: empty)
    kernel_empty : bool
    center_depth : float, distance from the answer's centre to the nearest kernel plane
        (negative: outside the kernel)
    empty_cap_deg : float, angular radius of the cap around the answer's pole that holds no
        region vertex, seen from the answer's centre
    margin_deg : float, the answer's margin to the seam and the singular points
    energy_at_sigma : dict of float to float, the energy at the sigmas of ``REPORTED_SIGMAS``
        with the answer's centre and rotation (empty for the standard method; measured as
        ``energy_start``)
    backfacing_faces : (k,) int, region face positions seen from behind from the answer's
        centre
    notes : list of str, what the fit could not do, in words
    """

    energy_start: float
    energy_end: float
    kernel_inscribed_radius: float
    kernel_empty: bool
    center_depth: float
    empty_cap_deg: float
    margin_deg: float
    energy_at_sigma: dict
    backfacing_faces: np.ndarray
    notes: list = field(default_factory=list)


@dataclass(frozen=True)
class Fit:
    """The chosen frame and chart, the region flattened with them, and the explanation (None
    for :func:`default_choice`, which searches nothing)."""

    frame: Frame
    chart: Chart
    region: FlatRegion
    explanation: FitExplanation | None


@dataclass(frozen=True)
class FitBounds:
    """The bounds every choice keeps (module docstring).

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
        (local ``+Z`` is its part orthogonal to the pole); None: :func:`roll_axis`
    sigma : float or None
    """

    center: np.ndarray | None = None
    rotation: Frame | None = None
    up: np.ndarray | None = None
    sigma: float | None = None


def fit_region(
    vertices,
    faces,
    fixed: FitFixed | None = None,
    bounds: FitBounds | None = None,
    *,
    method: str | Method = Method.DISTORTED,
    layout: Layout | str = Layout.THETA_PHI,
    threads: int = 1,
) -> Fit:
    """Choose the parameters ``fixed`` leaves as None and flatten the region with them.

    The stages: :func:`_start` (the explainable first choice), the slide along the pole, the
    refinement, :func:`_keep_margin` (on every face), :func:`_keep_the_better` (the start,
    measured on every face, may win) and :func:`_explain`.

    Parameters
    ----------
    vertices : (n, 3) float, world coordinates
    faces : (m, 3) int, the region's faces
    fixed : FitFixed, default: choose all
    bounds : FitBounds, default: ``FitBounds()``
    method : the chart's method; ``standard`` has no sigma
    layout : the layout whose energy is minimised and returned (:mod:`transforms.layouts`)
    threads : int

    Returns
    -------
    Fit

    Raises
    ------
    TransformInputError
        Bad input (as :func:`transforms.region.flatten_region`), or a sigma for ``standard``.
    """
    fixed = fixed or FitFixed()
    bounds = bounds or FitBounds()
    problem = _Problem.checked(vertices, faces, fixed, method, threads, layout)
    search = _start(problem, fixed, bounds)
    start = search.initial
    if search.move_center:
        # The energy has shallow local minima near the deepest point; look along the pole
        # first, towards the hole (a centre nearer the opening sees the region flatter).
        start = problem.slide_towards_pole(
            start, search.kernel, search.min_depth, search.margin, search.choose_sigma
        )
    # Where the kernel is empty, faces seen from behind fold over in the layout and their
    # energy swamps the rest: refining would chase them. Keep the explainable start.
    refine = any(search.free) and not search.kernel.empty
    if refine:
        start = problem.refine(start, search.free, search.kernel, search.min_depth, search.margin)
    seen = _Seen.of(problem, search, start)
    # The kernel's planes and the region's own vertices are let go before the answer is
    # flattened: the fit's peak is then its answer's flatten's.
    problem.release()
    best = _keep_margin(
        problem, start, search.choose_sigma, search.margin, search.bounds.min_margin_deg
    )
    if any(search.free):
        best = _keep_the_better(problem, search, best, seen)
    return _explain(problem, search, best, seen)


@dataclass(frozen=True)
class _Seen:
    """What the explanation reads of the start and of the searched answer, measured before
    the answer is flattened: per candidate (the start first), the depth of its centre in
    the kernel and the empty cap around its pole in degrees; the start's energy and those at
    :data:`REPORTED_SIGMAS` with the searched answer's centre and rotation (its sigma may
    still narrow: they do not depend on it), as :meth:`_Problem.region_energies` measures
    them."""

    depth: tuple[float, float]
    empty_cap_deg: tuple[float, float]
    energy_start: float
    energy_at_sigma: dict

    @classmethod
    def of(cls, problem: _Problem, search: _Search, found: _Candidate) -> _Seen:
        first = search.initial
        depth = problem.planes.depths(np.array([first.center, found.center]))
        caps = [
            _cap_radii(problem.region_points, c.center[None], c.rotation[1])[0]
            for c in (first, found)
        ]
        reported = _reported(problem, found)
        energies = problem.region_energies([first, *reported])
        return cls(
            depth=tuple(depth.tolist()),
            empty_cap_deg=tuple(math.degrees(c) for c in caps),
            energy_start=float(energies[0]),
            energy_at_sigma=dict(zip(REPORTED_SIGMAS, energies[1:].tolist(), strict=False)),
        )


@dataclass
class _Search:
    """What the stages share: the kernel, the bounds in the search's units, which
    parameters are free, the explainable start and the notes so far."""

    kernel: Kernel
    bounds: FitBounds
    min_depth: float
    margin: float | None  # radians; None for a closed region (no margin can be kept)
    choose_sigma: bool
    move_center: bool
    free: list[bool]
    initial: _Candidate
    notes: list[str]


@dataclass(frozen=True)
class _Flattened:
    """A candidate with its region flattened on every face and its least margin."""

    candidate: _Candidate
    flat: FlatRegion
    margin_deg: float


def _start(problem: _Problem, fixed: FitFixed, bounds: FitBounds) -> _Search:
    """The explainable first choice: the kernel's deepest point, the middle of the largest
    empty cap as the pole, the roll of :func:`roll_axis` (or the up hint), the best sigma
    whose cap fits in the empty cap."""
    notes: list[str] = []
    kernel = chebyshev_center(problem.planes)
    move_center = fixed.center is None and not kernel.empty
    if fixed.center is None:
        center = kernel.center
        if kernel.empty:
            notes.append(
                "the region's kernel is empty (no point sees every triangle from the front): "
                "the centre leaves the least back-facing area it could find, and those "
                "triangles are listed"
            )
    else:
        center = as_vector(fixed.center, "center")
    choice = _frame_and_sigma(problem, center, fixed, bounds, notes)
    return _Search(
        kernel=kernel,
        bounds=bounds,
        min_depth=bounds.min_kernel_depth * kernel.inscribed_radius,
        margin=choice.margin,
        choose_sigma=choice.choose_sigma,
        move_center=move_center,
        free=[move_center, fixed.rotation is None, choice.choose_sigma],
        initial=choice.candidate,
        notes=notes,
    )


@dataclass(frozen=True)
class _Choice:
    """The start's frame and sigma at a centre, and the margin the search keeps (radians;
    None for a closed region)."""

    candidate: _Candidate
    margin: float | None
    choose_sigma: bool


def _frame_and_sigma(
    problem: _Problem, center: np.ndarray, fixed: FitFixed, bounds: FitBounds, notes: list[str]
) -> _Choice:
    """Seen from ``center``: the rotation of :func:`_start_rotation` unless fixed, and the
    best sigma whose cap fits inside the empty cap less the margin unless fixed."""
    directions = problem.directions(center)
    if fixed.rotation is None:
        rotation = _start_rotation(directions, problem.hull_rows, fixed.up, notes)
    else:
        rotation = fixed.rotation.rotation
    margin = math.radians(bounds.min_margin_deg)
    if problem.closed:
        # A closed region seen from inside covers every direction: no cap fits, no margin can
        # be kept, and sigma only minimises the energy.
        notes.append(
            "the region is closed (no boundary): it covers every direction seen from inside, "
            "so it cannot be seam-free, and sigma minimises the energy alone"
        )
        margin = None
    room = math.pi if margin is None else cap_radius(directions, rotation[1]) - margin
    choose_sigma = fixed.sigma is None and problem.method is not Method.STANDARD
    sigma = problem.best_sigma(center, rotation, room) if choose_sigma else fixed.sigma
    return _Choice(_Candidate(center, rotation, sigma), margin, choose_sigma)


def default_choice(
    vertices,
    faces,
    fixed: FitFixed,
    bounds: FitBounds | None = None,
    *,
    method: str | Method = Method.DISTORTED,
    layout: Layout | str = Layout.THETA_PHI,
    threads: int = 1,
) -> Fit:
    """The rotation and sigma a request gets when it names neither, at a given centre: the
    start of :func:`fit_region` with no search (docs/math.md, section 9, stage 1), its cap
    narrowed until the margin holds on every face (stage 4). Cheap enough for every request.

    Parameters
    ----------
    vertices, faces, bounds, method, layout, threads : as for :func:`fit_region`
    fixed : FitFixed with ``center`` set; ``rotation`` and ``sigma`` left None are chosen

    Returns
    -------
    Fit, with ``explanation`` None (nothing was searched)

    Raises
    ------
    TransformInputError
        As :func:`fit_region`.
    """
    if fixed.center is None:
        raise TransformInputError("center", "the default choice needs a centre")
    bounds = bounds or FitBounds()
    problem = _Problem.checked(vertices, faces, fixed, method, threads, layout)
    center = as_vector(fixed.center, "center")
    choice = _frame_and_sigma(problem, center, fixed, bounds, [])
    answer = _keep_margin(
        problem, choice.candidate, choice.choose_sigma, choice.margin, bounds.min_margin_deg
    )
    best = answer.candidate
    frame = Frame.from_matrix(best.rotation, best.center)
    return Fit(frame=frame, chart=problem.chart(best.sigma), region=answer.flat, explanation=None)


def _start_rotation(
    directions: np.ndarray, hull_rows: np.ndarray, up, notes: list[str]
) -> np.ndarray:
    """(3, 3): the pole in the middle of the largest empty cap of the directions
    ``hull_rows`` (:func:`_hull_rows`), the roll by ``up`` (unless it is parallel to the
    pole: then a note) or :func:`roll_axis` (of every direction)."""
    pole, _ = largest_empty_cap(directions[hull_rows])
    if up is not None:
        up = as_direction(up, "up")
        if np.linalg.norm(np.cross(up, pole)) < _PARALLEL:
            notes.append(
                "the up hint is parallel to the chosen pole, so it fixes no roll: the "
                "roll follows the region's widest spread instead"
            )
            up = None
    if up is None:
        up = roll_axis(directions, pole)
    return Frame.from_pole_up(pole, up).rotation


def _flattened(problem: _Problem, candidate: _Candidate) -> _Flattened:
    flat = problem.flatten(candidate)
    return _Flattened(candidate, flat, _margin_deg(flat))


def _keep_margin(
    problem: _Problem,
    best: _Candidate,
    choose_sigma: bool,
    margin: float | None,
    min_margin_deg: float,
) -> _Flattened:
    """``best`` on every face, its cap narrowed (when sigma is free and the region has a
    boundary, ``margin`` not None) until ``min_margin_deg`` holds there too: the search saw
    vertices, not edges."""
    answer = _flattened(problem, best)
    if not (choose_sigma and margin is not None):
        return answer
    for _ in range(6):
        if answer.margin_deg >= min_margin_deg:
            break
        shortfall = math.radians(min_margin_deg - answer.margin_deg) + 1e-3
        rho = max(PoleCap.from_sigma(answer.candidate.sigma).rho - shortfall, 1e-4)
        c = answer.candidate
        tried = _flattened(problem, _Candidate(c.center, c.rotation, math.tan(rho / 2.0)))
        if not tried.margin_deg > answer.margin_deg:
            break  # the region covers the pole itself: a smaller cap does not help
        answer = tried
    return answer


def _keep_the_better(
    problem: _Problem, search: _Search, answer: _Flattened, seen: _Seen
) -> _Flattened:
    """The start instead of ``answer`` when, on every face, its energy is lower and it keeps
    the margin: the search saw a sample. The start is flattened only when its energy
    (:class:`_Seen`) is below the answer's."""
    if not seen.energy_start < answer.flat.distortion.isometric.mean:
        return answer
    first = _flattened(problem, search.initial)
    keeps_margin = search.margin is None or first.margin_deg >= min(
        answer.margin_deg, search.bounds.min_margin_deg
    )
    if (
        first.flat.distortion.isometric.mean < answer.flat.distortion.isometric.mean
        and keeps_margin
    ):
        return first
    return answer


def _reported(problem: _Problem, best: _Candidate) -> list[_Candidate]:
    """The answer's centre and rotation at :data:`REPORTED_SIGMAS` (none for the standard
    method, which has no sigma)."""
    if problem.method is Method.STANDARD:
        return []
    return [_Candidate(best.center, best.rotation, sigma) for sigma in REPORTED_SIGMAS]


def _explain(problem: _Problem, search: _Search, answer: _Flattened, seen: _Seen) -> Fit:
    """The fit, with the notes on the bounds it could not keep and the energies at
    :data:`REPORTED_SIGMAS`."""
    best, flat, notes = answer.candidate, answer.flat, search.notes
    if search.margin is not None and answer.margin_deg < search.bounds.min_margin_deg:
        notes.append(
            f"the margin to the seam and the singular points is {answer.margin_deg:.3g} "
            f"degrees, below min_margin_deg ({search.bounds.min_margin_deg:g})"
        )
    kernel = search.kernel
    start_won = best is search.initial
    depth = seen.depth[0 if start_won else 1]
    if not kernel.empty and depth < search.min_depth:
        notes.append(
            f"the centre is {depth:.4g} deep in the kernel, less than min_kernel_depth "
            f"({search.bounds.min_kernel_depth:g} of the inscribed radius "
            f"{kernel.inscribed_radius:.4g})"
        )
    energy_end = flat.distortion.isometric.mean
    energy_at_sigma = seen.energy_at_sigma
    if start_won:  # measured for the searched answer, which lost
        reported = _reported(problem, best)
        energies = problem.region_energies(reported) if reported else []
        energy_at_sigma = dict(zip(REPORTED_SIGMAS, list(energies), strict=False))
    explanation = FitExplanation(
        energy_start=seen.energy_start if any(search.free) else energy_end,
        energy_end=energy_end,
        kernel_inscribed_radius=kernel.inscribed_radius,
        kernel_empty=kernel.empty,
        center_depth=depth,
        empty_cap_deg=seen.empty_cap_deg[0 if start_won else 1],
        margin_deg=answer.margin_deg,
        energy_at_sigma={float(k): float(v) for k, v in energy_at_sigma.items()},
        backfacing_faces=flat.validation.backfacing_faces,
        notes=notes,
    )
    frame = Frame.from_matrix(best.rotation, best.center)
    return Fit(frame=frame, chart=problem.chart(best.sigma), region=flat, explanation=explanation)


def roll_axis(directions: np.ndarray, pole: np.ndarray) -> np.ndarray:
    """The default roll: local ``+Z`` along the direction in which the region spreads most
    about the pole.

    That is the principal axis of the directions' parts orthogonal to ``pole`` (the
    eigenvector of their second moment with the largest eigenvalue), pointing to the side
    with the larger third moment. Both moments turn with the data, so rotating the whole
    input rotates the axis with it.

    Parameters
    ----------
    directions : (k, 3) float, unit directions from the centre to the region's vertices
    pole : (3,) float, unit

    Returns
    -------
    (3,) float, unit, orthogonal to ``pole``
    """
    across = directions - np.outer(directions @ pole, pole)
    _, vectors = np.linalg.eigh(across.T @ across)
    axis = vectors[:, -1] - (vectors[:, -1] @ pole) * pole
    axis /= np.linalg.norm(axis)
    if float(((across @ axis) ** 3).sum()) < 0.0:
        axis = -axis
    return axis


def _margin_deg(flat: FlatRegion) -> float:
    v = flat.validation
    return min(v.margin_deg_seam, v.margin_deg_north, v.margin_deg_south)


@dataclass(frozen=True)
class _Candidate:
    center: np.ndarray
    rotation: np.ndarray
    sigma: float | None


class _Problem:
    """A region, its kernel planes, and its sample: what the search evaluates."""

    def __init__(
        self, points: np.ndarray, faces: np.ndarray, method: Method, threads: int, layout: Layout
    ):
        self.points, self.faces, self.method, self.threads = points, faces, method, threads
        self.layout = layout
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

    @classmethod
    def checked(cls, vertices, faces, fixed: FitFixed, method, threads: int, layout) -> _Problem:
        """The problem of a caller's region, its input checked (as :func:`fit_region`)."""
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
        return cls(points, faces, method, threads, Layout(layout))

    @cached_property
    def coarse(self) -> FaceEnergy:
        """The slide's sample: it only picks the basin the refinement starts in, so fewer
        faces do (made when a fit slides; the default choice never does)."""
        picked = area_sample(self.areas, COARSE_SAMPLE_FACES)
        return FaceEnergy(*_compacted(self.points, self.faces[picked]), self.method, self.layout)

    def release(self) -> None:
        """Let go of what only the search reads: the kernel's planes, the region's own
        vertices and the hull's (the flatten and the energies read the input's arrays)."""
        self.planes = self.region_points = self.used = self.hull_points = self.hull_rows = None

    @property
    def closed(self) -> bool:
        """Whether the region has no boundary (no closing planes)."""
        return len(self.planes.normals) == len(self.planes.faces)

    def within_reach(self, center: np.ndarray, slack: bool = False):
        """Whether ``center`` is within ``_REACH`` region sizes of the region's middle (far
        away every region looks flat); with ``slack``, by how much (negative: beyond)."""
        away = float(np.linalg.norm(center - self.planes.middle))
        room = _REACH * self.planes.size - away
        return room if slack else room >= 0.0

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
        frame = Frame.from_matrix(candidate.rotation, candidate.center)
        return flatten_region(
            self.points,
            self.faces,
            frame,
            self.chart(candidate.sigma),
            threads=self.threads,
            layout=self.layout,
        )

    def region_energies(self, candidates: list[_Candidate]) -> np.ndarray:
        """(k,) the energy of the region for each candidate (docs/math.md, section 7), as
        :meth:`flatten` would report it, without the validation: on every face up to
        ``EXPLAIN_FACES``, beyond that on every k-th run of ``_EXPLAIN_RUN`` faces in the
        region's order (a ratio estimate of the area-weighted mean, its weights unbiased)."""
        faces = self.faces
        if len(faces) > EXPLAIN_FACES:
            # Every k-th run of consecutive faces: neighbours in a file share vertices, so
            # the runs cost fewer vertices' angles than single faces would.
            runs = np.arange(0, len(faces), _EXPLAIN_RUN * -(-len(faces) // EXPLAIN_FACES))
            picked = (runs[:, None] + np.arange(_EXPLAIN_RUN)).ravel()
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

    def refine(
        self,
        start: _Candidate,
        free: list[bool],
        kernel: Kernel,
        min_depth: float,
        margin: float | None,
    ) -> _Candidate:
        """Quasi-Newton steps (L-BFGS-B) over the free parameters (:class:`_Coordinates`),
        each gradient from one batch of forward differences. The bounds are quadratic
        penalties, smooth where they start to bind; what they let slip is taken back on
        every face after (the margin by :func:`_keep_margin`, the depth here)."""
        unit = max(kernel.inscribed_radius, 1e-3 * self.planes.size)
        coordinates = _Coordinates(start, free, unit)
        cost = _RefinementCost(self, coordinates, min_depth, margin, unit)
        x0 = coordinates.start()
        found = minimize(
            cost.value_and_gradient,
            x0,
            jac=True,
            method="L-BFGS-B",
            bounds=coordinates.bounds(),
            options={"maxiter": _REFINE_STEPS, "ftol": _REFINE_TOLERANCE, "gtol": 1e-6},
        )
        ends = cost(np.vstack([x0, found.x]))
        if not ends[1] < ends[0]:
            return start
        best = coordinates.candidate(found.x)
        if free[0] and self.planes.depth(best.center) < min_depth:
            # A plane outside the subset binds: back towards the start, which is deep enough.
            best = self.back_inside(start, best, min_depth)
        return best

    def back_inside(self, start: _Candidate, best: _Candidate, min_depth: float) -> _Candidate:
        """``best`` with its centre moved back towards ``start``'s (which is deep enough) to
        the last point found at least ``min_depth`` deep (30 bisections)."""
        inside, outside = 0.0, 1.0
        for _ in range(30):
            middle = 0.5 * (inside + outside)
            center = start.center + middle * (best.center - start.center)
            if self.planes.depth(center) >= min_depth:
                inside = middle
            else:
                outside = middle
        center = start.center + inside * (best.center - start.center)
        return _Candidate(center, best.rotation, best.sigma)


class _RefinementCost:
    """The refinement's cost of a batch of coordinates: the sample objective plus
    ``_PENALTY`` times the squared shortfalls of the bounds (the kernel's depth and the
    region's reach in units of ``unit``, the margin in radians)."""

    def __init__(
        self,
        problem: _Problem,
        coordinates: _Coordinates,
        min_depth: float,
        margin: float | None,
        unit: float,
    ) -> None:
        self.problem, self.coordinates = problem, coordinates
        self.min_depth, self.margin, self.unit = min_depth, margin, unit
        # The depth on the planes that can bind near the start (the exact one is checked
        # after): the nearest ones and an area-weighted sample.
        planes, center = problem.planes, coordinates.start_candidate.center
        j = len(planes.faces)
        slack = planes.offsets[:j] - planes.normals[:j] @ center
        nearest = np.argpartition(slack, _NEAR_PLANES)[:_NEAR_PLANES] if j > _NEAR_PLANES else []
        rows = np.union1d(nearest, area_sample(planes.areas[:j], SAMPLE_FACES)).astype(np.int64)
        self.normals, self.offsets = planes.normals[rows], planes.offsets[rows]

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """(k,) cost of the coordinates ``x`` (k, d)."""
        batch = self.coordinates.candidates(x)
        scores = self.problem.sample.scores(batch)
        shortfalls = self._shortfalls(batch.centers, batch.sigmas, scores.cap_cosine)
        value = scores.objective + _PENALTY * (shortfalls**2).sum(axis=0)
        return np.where(np.isfinite(value), value, _INFEASIBLE)

    def value_and_gradient(self, x: np.ndarray) -> tuple[float, np.ndarray]:
        """The cost at ``x`` (d,) and its gradient: through the closed-form warp
        (:meth:`.objective.FaceEnergy.slope`), or for the separable method, whose angles
        come from a root search, by forward differences in one batch."""
        if self.problem.method is Method.SEPARABLE:
            costs = self(np.vstack([x, x + _STEP * np.eye(len(x))]))
            return float(costs[0]), (costs[1:] - costs[0]) / _STEP
        batch = self.coordinates.candidates(x[None])
        motion = self.coordinates.motion(x)
        slope = self.problem.sample.slope(batch, motion)
        value = float(slope.scores.objective[0])
        if not math.isfinite(value):
            return _INFEASIBLE, np.zeros(len(x))
        cap_cosine = slope.scores.cap_cosine
        shortfalls = self._shortfalls(batch.centers, batch.sigmas, cap_cosine)[:, 0]
        slopes = self._shortfall_slopes(batch, cap_cosine[0], motion, slope.cap_cosine)
        value += _PENALTY * float((shortfalls**2).sum())
        return value, slope.energy + 2.0 * _PENALTY * (shortfalls @ slopes)

    def _shortfalls(self, centers, sigmas, cap_cosine) -> np.ndarray:
        """(3, k): by how much each candidate misses the kernel's depth and the region's
        reach (in ``unit``) and the margin (radians); 0 where it keeps them."""
        shortfalls = np.zeros((3, len(centers)))
        if self.coordinates.move_center:
            depth = (self.offsets - centers @ self.normals.T).min(axis=1)
            shortfalls[0] = np.maximum(0.0, self.min_depth - depth) / self.unit
            planes = self.problem.planes
            away = np.linalg.norm(centers - planes.middle, axis=1)
            shortfalls[1] = np.maximum(0.0, away - _REACH * planes.size) / self.unit
        if self.margin is not None:
            cap = np.arccos(np.clip(cap_cosine, -1.0, 1.0))
            shortfalls[2] = np.maximum(0.0, self._cap_angle(sigmas) + self.margin - cap)
        return shortfalls

    def _shortfall_slopes(
        self, batch: Candidates, cap_cosine: float, motion: Motion, cap_slope: np.ndarray
    ) -> np.ndarray:
        """(3, d): the gradients of one candidate's :meth:`_shortfalls` where they are
        positive (the gradient of the nearest plane's depth, of the distance to the middle,
        and of the cap's angle less the empty cap's)."""
        center, d = batch.centers[0], len(motion.log_sigma)
        slopes = np.zeros((3, d))
        if self.coordinates.move_center:
            nearest = int(np.argmin(self.offsets - self.normals @ center))
            slopes[0] = motion.center @ self.normals[nearest] / self.unit
            away = center - self.problem.planes.middle
            length = float(np.linalg.norm(away))
            if length > 0:
                slopes[1] = motion.center @ away / (length * self.unit)
        if self.margin is not None:
            sigma = float(batch.sigmas[0])
            turns = 0.0 if self.problem.method is Method.STANDARD else 1.0
            rho_slope = turns * 2.0 * sigma / (1.0 + sigma * sigma) * motion.log_sigma
            sine = math.sqrt(max(1.0 - cap_cosine * cap_cosine, 1e-30))
            slopes[2] = rho_slope + cap_slope / sine
        return slopes

    def _cap_angle(self, sigmas: np.ndarray) -> np.ndarray:
        """(k,) the cap's angle ``rho = 2 atan(sigma)`` (90 degrees for the standard method)."""
        if self.problem.method is Method.STANDARD:
            return np.full(len(sigmas), math.pi / 2)
        return 2.0 * np.arctan(sigmas)


class _Coordinates:
    """The refinement's coordinates, in the start's frame: the centre's offset (in units of
    the inscribed radius, along the start's axes), the pole's tilt (radians, towards the
    start's local X and Z) and log sigma, each only when free."""

    def __init__(self, start: _Candidate, free: list[bool], unit: float) -> None:
        self.start_candidate, self.unit = start, unit
        self.move_center, self.turn_pole, self.change_sigma = free

    def start(self) -> np.ndarray:
        """The start's coordinates."""
        x0 = [0.0] * (3 * self.move_center + 2 * self.turn_pole)
        if self.change_sigma:
            x0.append(math.log(self.start_candidate.sigma))
        return np.array(x0)

    def bounds(self) -> list[tuple[float | None, float | None]]:
        """Per coordinate: only log sigma is bounded, to the search's range (a flat
        landscape must not drift beyond it)."""
        free = [(None, None)] * (3 * self.move_center + 2 * self.turn_pole)
        low, high = SIGMA_SEARCH
        return free + [(math.log(low), math.log(high))] * self.change_sigma

    def candidates(self, x: np.ndarray) -> Candidates:
        """The candidates of the coordinates ``x`` (k, d)."""
        start = self.start_candidate
        axes = start.rotation  # rows: local X, Y (the pole), Z
        k = len(x)
        column = 0
        centers = np.broadcast_to(start.center, (k, 3))
        if self.move_center:
            centers = start.center + self.unit * (x[:, :3] @ axes)
            column = 3
        rotations = np.broadcast_to(start.rotation, (k, 3, 3))
        if self.turn_pole:
            tilt = x[:, column : column + 2]
            poles = axes[1] + tilt[:, :1] * axes[0] + tilt[:, 1:] * axes[2]
            rotations = _rotations_from_pole_up(poles, axes[2])
            column += 2
        sigmas = np.full(k, _sigma_or_one(start.sigma))
        if self.change_sigma:
            low, high = SIGMA_SEARCH
            sigmas = np.exp(np.clip(x[:, column], math.log(low), math.log(high)))
        return Candidates(centers, rotations, sigmas)

    def motion(self, x: np.ndarray) -> Motion:
        """How the candidate of the coordinates ``x`` (d,) moves with each of them."""
        start = self.start_candidate
        axes = start.rotation
        d = len(x)
        motion = Motion(np.zeros((d, 3, 3)), np.zeros((d, 3)), np.zeros(d))
        column = 0
        if self.move_center:
            motion.center[:3] = self.unit * axes
            column = 3
        if self.turn_pole:
            tilt = x[column : column + 2]
            pole = axes[1] + tilt[0] * axes[0] + tilt[1] * axes[2]
            motion.rotation[column : column + 2] = _rotation_slopes(pole, axes[2], axes[[0, 2]])
            column += 2
        if self.change_sigma:
            low, high = SIGMA_SEARCH
            motion.log_sigma[column] = float(math.log(low) < x[column] < math.log(high))
        return motion

    def candidate(self, x: np.ndarray) -> _Candidate:
        """The candidate of the coordinates ``x`` (d,)."""
        batch = self.candidates(x[None])
        sigma = float(batch.sigmas[0]) if self.start_candidate.sigma is not None else None
        return _Candidate(batch.centers[0].copy(), batch.rotations[0].copy(), sigma)


def _rotations_from_pole_up(poles: np.ndarray, up: np.ndarray) -> np.ndarray:
    """(k, 3, 3) world-to-local rotations with local ``+Y`` along ``poles`` (k, 3) and the
    part of ``up`` (3,) orthogonal to it as local ``+Z``:
    :meth:`transforms.Frame.from_pole_up` for a batch (``up`` is the start's local Z, far
    from parallel to a slightly tilted pole)."""
    y_axes = poles / np.linalg.norm(poles, axis=1, keepdims=True)
    x_axes = cross_rows(y_axes, up)
    x_axes /= np.linalg.norm(x_axes, axis=1, keepdims=True)
    # A second pass of Gram-Schmidt, as Frame.from_pole_up does.
    x_axes -= np.einsum("kj,kj->k", x_axes, y_axes)[:, None] * y_axes
    x_axes /= np.linalg.norm(x_axes, axis=1, keepdims=True)
    return np.stack([x_axes, y_axes, cross_rows(x_axes, y_axes)], axis=1)


def _rotation_slopes(pole: np.ndarray, up: np.ndarray, turns: np.ndarray) -> np.ndarray:
    """(t, 3, 3): the derivatives of :func:`_rotations_from_pole_up` of ``pole`` (3,) and
    ``up`` (3,) as the pole moves along each of ``turns`` (t, 3)."""
    length = np.linalg.norm(pole)
    y_axis = pole / length
    across = cross_rows(y_axis, up)
    width = np.linalg.norm(across)
    x_axis = across / width
    dy = (turns - np.outer(turns @ y_axis, y_axis)) / length
    d_across = cross_rows(dy, up)
    dx = (d_across - np.outer(d_across @ x_axis, x_axis)) / width
    dz = cross_rows(dx, y_axis) + cross_rows(x_axis, dy)
    return np.stack([dx, dy, dz], axis=1)


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


def _hull_rows(used: np.ndarray, boundary: np.ndarray) -> np.ndarray:
    """Rows of the region's vertices (``used``, ascending ids) whose directions the largest
    empty cap is found among: every boundary vertex and ``HULL_VERTICES`` spread over the
    rest, each list thinned evenly to ``HULL_VERTICES`` at most.

    Seen from inside the kernel, the part of the sphere the region leaves empty is bounded
    by its boundary loops' directions (no triangle is seen edge-on there), so the cap the
    hull finds is that of every vertex; the spread rows keep it close where the kernel is
    empty and folds bound it too. The hull of directions on a sphere has every one as a
    vertex (20,000 cost 0.2 s), so fewer is faster."""
    spread = np.linspace(0, len(used) - 1, min(HULL_VERTICES, len(used))).astype(np.int64)
    edge = np.searchsorted(used, boundary)
    if len(edge) > HULL_VERTICES:
        edge = edge[np.linspace(0, len(edge) - 1, HULL_VERTICES).astype(np.int64)]
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
