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
together (Nelder-Mead). The search works on an area-weighted sample of the faces
(:mod:`.sampling`) in a frame built from the starting choice, so its path does not depend on
how the mesh is posed; the answer is checked, and its energy and margins reported, on every
face. Any of the three may be fixed by the caller.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import minimize

from .arrays import as_direction, as_faces, as_points, as_vector, unit_rows
from .cap import PoleCap
from .chart import Chart, Method
from .emptycap import cap_radius, largest_empty_cap
from .errors import TransformInputError, listed_rows
from .faces import measure_checked
from .frames import Frame
from .kernel import Kernel, chebyshev_center, kernel_planes
from .layouts import Layout, measured_second
from .metrics import distortion
from .region import FlatRegion, flatten_region
from .sampling import area_sample
from .viewpoint import check_center_sees_area

#: Faces the search evaluates each candidate on, and vertices the pole's hull is built from.
SAMPLE_FACES = 4000
HULL_VERTICES = 20000
#: Where sigma is searched (beyond these the warp squeezes the region to a point or a line).
SIGMA_SEARCH = (1e-3, 10.0)
#: Planes nearest the start whose depth the refinement watches (besides the sampled ones).
_NEAR_PLANES = 4096
#: How far from the region's middle the centre may go, in region sizes.
_REACH = 3.0
#: Centres tried along the pole before the refinement, in inscribed radii from the deepest point.
_SLIDE = (0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 4.0)
#: The sigma search: grid points in log sigma, golden-section steps after, and the relative
#: difference of energies below which they count as equal.
_SIGMA_GRID = 17
_GOLDEN_STEPS = 14
_TIE = 1e-9
#: Below this sine of the angle between the up hint and the chosen pole, the hint is ignored.
_PARALLEL = 1e-6
#: The refinement's cost where a candidate cannot be measured: finite, so that Nelder-Mead's
#: convergence test (differences of costs) never meets inf - inf, and above any real cost.
_INFEASIBLE = 1e100
#: What a centre pays for each unit of the fraction of the region's area it sees from behind
#: (1% costs 10, more than any energy difference the front-facing faces make).
_BACKFACING_WEIGHT = 1000.0
#: Sigmas whose energy the explanation reports.
REPORTED_SIGMAS = (0.3, 1.0)


@dataclass(frozen=True)
class FitExplanation:
    """Why the parameters are what they are.

    Attributes
    ----------
    energy_start : float, area-weighted isometric energy of the starting choice (all faces)
    energy_end : float, the same for the answer
    kernel_inscribed_radius : float, radius of the largest ball in the kernel (0: empty)
    kernel_empty : bool
    center_depth : float, distance from the answer's centre to the nearest kernel plane
        (negative: outside the kernel)
    empty_cap_deg : float, angular radius of the cap around the answer's pole that holds no
        region vertex, seen from the answer's centre
    margin_deg : float, the answer's margin to the seam and the singular points
    energy_at_sigma : dict of float to float, the energy at the sigmas of ``REPORTED_SIGMAS``
        with the answer's centre and rotation (empty for the standard method)
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
    layout : the layout whose energy is minimised and returned (:mod:`.layouts`)
    threads : int

    Returns
    -------
    Fit

    Raises
    ------
    TransformInputError
        Bad input (as :func:`.region.flatten_region`), or a sigma for ``standard``.
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
    best = _keep_margin(
        problem, start, search.choose_sigma, search.margin, search.bounds.min_margin_deg
    )
    if any(search.free):
        best = _keep_the_better(problem, search, best)
    return _explain(problem, search, best)


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
    energy_start: float | None = None


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
        rotation = _start_rotation(directions, fixed.up, notes)
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


def _start_rotation(directions: np.ndarray, up, notes: list[str]) -> np.ndarray:
    """(3, 3): the pole in the middle of the largest empty cap, the roll by ``up`` (unless
    it is parallel to the pole: then a note) or :func:`roll_axis`."""
    hull_rows = np.linspace(0, len(directions) - 1, min(HULL_VERTICES, len(directions)))
    pole, _ = largest_empty_cap(directions[hull_rows.astype(np.int64)])
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


def _keep_the_better(problem: _Problem, search: _Search, answer: _Flattened) -> _Flattened:
    """The start instead of ``answer`` when, on every face, its energy is lower and it keeps
    the margin: the search saw a sample."""
    first = _flattened(problem, search.initial)
    search.energy_start = first.flat.distortion.isometric.mean
    keeps_margin = search.margin is None or first.margin_deg >= min(
        answer.margin_deg, search.bounds.min_margin_deg
    )
    if search.energy_start < answer.flat.distortion.isometric.mean and keeps_margin:
        return first
    return answer


def _explain(problem: _Problem, search: _Search, answer: _Flattened) -> Fit:
    """The fit, with the notes on the bounds it could not keep and the energies at
    :data:`REPORTED_SIGMAS`."""
    best, flat, notes = answer.candidate, answer.flat, search.notes
    if search.margin is not None and answer.margin_deg < search.bounds.min_margin_deg:
        notes.append(
            f"the margin to the seam and the singular points is {answer.margin_deg:.3g} "
            f"degrees, below min_margin_deg ({search.bounds.min_margin_deg:g})"
        )
    kernel = search.kernel
    depth = problem.planes.depth(best.center)
    if not kernel.empty and depth < search.min_depth:
        notes.append(
            f"the centre is {depth:.4g} deep in the kernel, less than min_kernel_depth "
            f"({search.bounds.min_kernel_depth:g} of the inscribed radius "
            f"{kernel.inscribed_radius:.4g})"
        )
    energy_end = flat.distortion.isometric.mean
    energy_at_sigma = {}
    if problem.method is not Method.STANDARD:
        for reported in REPORTED_SIGMAS:
            candidate = _Candidate(best.center, best.rotation, reported)
            energy_at_sigma[reported] = problem.flatten(candidate).distortion.isometric.mean
    explanation = FitExplanation(
        energy_start=energy_end if search.energy_start is None else search.energy_start,
        energy_end=energy_end,
        kernel_inscribed_radius=kernel.inscribed_radius,
        kernel_empty=kernel.empty,
        center_depth=depth,
        empty_cap_deg=math.degrees(cap_radius(problem.directions(best.center), best.rotation[1])),
        margin_deg=answer.margin_deg,
        energy_at_sigma=energy_at_sigma,
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


def _beats(e1: float, x1: float, e2: float, x2: float) -> bool:
    """Whether energy ``e1`` at ``x1`` beats ``e2`` at ``x2``: energies equal to ``_TIE``
    (relative) count as equal, and then the larger ``x`` wins."""
    if abs(e1 - e2) <= _TIE * max(abs(e1), abs(e2)):
        return x1 > x2
    return e1 < e2


def _golden_section(energy, bracket: tuple[float, float], best_x: float, best_e: float) -> float:
    """The best ``x`` found by ``_GOLDEN_STEPS`` golden sections of ``bracket``, starting
    from ``best_x`` of energy ``best_e``."""
    a, b = bracket
    ratio = (math.sqrt(5.0) - 1.0) / 2.0
    for _ in range(_GOLDEN_STEPS):
        x1, x2 = b - ratio * (b - a), a + ratio * (b - a)
        e1, e2 = energy(x1), energy(x2)
        if _beats(e1, x1, e2, x2):
            b = x2
            if _beats(e1, x1, best_e, best_x):
                best_x, best_e = x1, e1
        else:
            a = x1
            if _beats(e2, x2, best_e, best_x):
                best_x, best_e = x2, e2
    return best_x


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
        sample = faces[picked]
        sample_used, compact = np.unique(sample, return_inverse=True)
        self.sample_faces = compact.reshape(-1, 3)
        self.sample_points = points[sample_used]
        self.sample_areas = areas[picked]

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

    def energy(self, candidate: _Candidate) -> float:
        """The robust objective on the sample (docs/math.md, section 9): the fraction of its
        area seen from behind from the candidate's centre (such faces fold whatever the
        pole and sigma), times ``_BACKFACING_WEIGHT``, plus the area-weighted isometric
        energy of the faces seen from the front; inf where it cannot be measured.

        So a few slivers seen from behind, whose energy can be thousands, do not steer the
        choice: a centre is first judged by how much it cannot see, then by the rest.
        """
        frame = Frame.from_matrix(candidate.rotation, candidate.center)
        chart = self.chart(candidate.sigma)
        try:
            rows = np.empty((3, len(self.sample_points)))
            theta, phi, _ = chart.forward_checked(
                self.sample_points, frame, 1, ("vertices", "vertex", None), rows_out=rows
            )
            second = measured_second(theta, self.layout)
            measures = measure_checked(rows, self.sample_faces, second, phi, chart.cap)
            # Seen from behind as validation judges it: against the sample's own winding.
            orientation = measures.orientation
            winding = -1 if int(orientation.sum(dtype=np.int64)) < 0 else 1
            behind = orientation != winding
            # The faces seen from the front measured alone: the layout's scale from them too.
            energy = float(distortion(measures.subset(~behind)).isometric.mean)
        except TransformInputError:  # every face seen from the front is degenerate
            return math.inf
        total = float(self.sample_areas.sum())
        hidden = float(self.sample_areas[behind].sum()) / total if total > 0 else 0.0
        return energy + _BACKFACING_WEIGHT * hidden

    def best_sigma(self, center: np.ndarray, rotation: np.ndarray, largest_rho: float) -> float:
        """The sigma of least sample energy with the cap's angle at most ``largest_rho``.

        A grid in log sigma, then golden sections around its best point. Energies equal to
        ``_TIE`` (relative) count as equal and the larger sigma wins, so that rounding, which
        differs with the mesh's pose, cannot pick another point of a flat stretch.
        """
        low, high = SIGMA_SEARCH
        high = min(high, math.tan(max(largest_rho, 2.0 * math.atan(low)) / 2.0))
        if high <= low:
            return high

        def energy(log_sigma: float) -> float:
            return self.energy(_Candidate(center, rotation, math.exp(log_sigma)))

        grid = np.linspace(math.log(low), math.log(high), _SIGMA_GRID)
        energies = [energy(x) for x in grid]
        best = 0
        for i in range(1, len(grid)):
            if _beats(energies[i], grid[i], energies[best], grid[best]):
                best = i
        bracket = grid[max(best - 1, 0)], grid[min(best + 1, len(grid) - 1)]
        return math.exp(_golden_section(energy, bracket, grid[best], energies[best]))

    def slide_towards_pole(
        self,
        start: _Candidate,
        kernel: Kernel,
        min_depth: float,
        margin: float | None,
        choose_sigma: bool,
    ) -> _Candidate:
        """The best of ``start`` and centres moved along its pole by multiples of the
        inscribed radius (``_SLIDE``), each with its best sigma, inside the kernel."""
        pole = start.rotation[1]
        best, best_energy = start, self.energy(start)
        for steps in _SLIDE:
            center = start.center + steps * kernel.inscribed_radius * pole
            if self.planes.depth(center) < min_depth or not self.within_reach(center):
                break
            try:
                directions = self.directions(center)
            except TransformInputError:  # the centre met a vertex
                break
            room = math.pi if margin is None else cap_radius(directions, pole) - margin
            sigma = self.best_sigma(center, start.rotation, room) if choose_sigma else start.sigma
            candidate = _Candidate(center, start.rotation, sigma)
            energy = self.energy(candidate)
            if energy < best_energy:
                best, best_energy = candidate, energy
        return best

    def refine(
        self,
        start: _Candidate,
        free: list[bool],
        kernel: Kernel,
        min_depth: float,
        margin: float | None,
    ) -> _Candidate:
        """Nelder-Mead over the free parameters (:class:`_Coordinates`). The bounds are
        penalties."""
        move_center = free[0]
        # The depth on the planes that can bind near the start (the exact one is checked after).
        planes = self.planes
        j = len(planes.faces)
        nearest = np.argsort(planes.offsets[:j] - planes.normals[:j] @ start.center)
        rows = np.union1d(nearest[:_NEAR_PLANES], area_sample(planes.areas[:j], SAMPLE_FACES))
        normals, offsets = planes.normals[rows], planes.offsets[rows]

        def depth(center: np.ndarray) -> float:
            return float((offsets - normals @ center).min())

        unit = max(kernel.inscribed_radius, 1e-3 * self.planes.size)
        coordinates = _Coordinates(start, free, unit)
        region = self.sample_points  # the margin is checked on every face afterwards

        def cost(x: np.ndarray) -> float:
            c = coordinates.candidate(x)
            penalty = 0.0
            if move_center:
                penalty += max(0.0, min_depth - depth(c.center)) / unit
                penalty += max(0.0, -self.within_reach(c.center, slack=True)) / unit
            units, zero = unit_rows(region - c.center)
            if zero.any():
                return _INFEASIBLE
            if margin is not None:
                rho = PoleCap.from_sigma(c.sigma).rho if c.sigma is not None else math.pi / 2
                penalty += max(0.0, rho + margin - cap_radius(units, c.rotation[1]))
            value = self.energy(c) + 100.0 * penalty
            return value if math.isfinite(value) else _INFEASIBLE

        x0, simplex = coordinates.start()
        found = minimize(
            cost,
            x0,
            method="Nelder-Mead",
            options={
                "xatol": 1e-4,
                "fatol": 1e-6,
                "maxfev": 120 * len(x0),
                "adaptive": True,
                "initial_simplex": simplex,
            },
        )
        best = coordinates.candidate(found.x)
        if cost(found.x) > cost(x0):
            return start
        if move_center and planes.depth(best.center) < min_depth:
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


class _Coordinates:
    """The refinement's coordinates, in the start's frame: the centre's offset (in units of
    the inscribed radius, along the start's axes), the pole's tilt (radians, towards the
    start's local X and Z) and log sigma, each only when free."""

    def __init__(self, start: _Candidate, free: list[bool], unit: float) -> None:
        self.start_candidate, self.unit = start, unit
        self.move_center, self.turn_pole, self.change_sigma = free

    def start(self) -> tuple[np.ndarray, np.ndarray]:
        """The start's coordinates and the initial simplex around them."""
        x0 = [0.0] * (3 * self.move_center + 2 * self.turn_pole)
        steps = [0.5] * (3 * self.move_center) + [0.1] * (2 * self.turn_pole)
        if self.change_sigma:
            x0.append(math.log(self.start_candidate.sigma))
            steps.append(0.3)
        return np.array(x0), np.vstack([x0, np.array(x0) + np.diag(steps)])

    def candidate(self, x: np.ndarray) -> _Candidate:
        start = self.start_candidate
        axes = start.rotation  # rows: local X, Y (the pole), Z
        x = list(x)
        center = start.center
        if self.move_center:
            center = start.center + self.unit * (np.array(x[:3]) @ axes)
            x = x[3:]
        rotation = start.rotation
        if self.turn_pole:
            pole = axes[1] + x[0] * axes[0] + x[1] * axes[2]
            rotation = Frame.from_pole_up(pole, axes[2]).rotation
            x = x[2:]
        sigma = start.sigma
        if self.change_sigma:
            low, high = SIGMA_SEARCH  # a flat landscape must not drift beyond the search
            sigma = math.exp(min(max(x[0], math.log(low)), math.log(high)))
        return _Candidate(center, rotation, sigma)
