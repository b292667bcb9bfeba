"""The fit's answer on every face and why it is what it is (docs/math.md, section 9,
stages 4 to 7).

The search saw a sample: on every face the cap is narrowed until the margin holds
(:func:`_keep_margin`); the searched answer, the start and the defaults are ranked by one
order (:func:`_rank`: the seam and the singular points off the region with the margin first,
then the energy on every face) and the best kept (:func:`_keep_the_best`); where that one
lets the seam onto the region although a cap is free of it, the pole moves into that cap
(:func:`_onto_free_cap`). Then the :class:`Fit` is built with its :class:`FitExplanation`:
the energies (section 7) at the start, at the end, of the defaults and at
``REPORTED_SIGMAS``, the kernel's radius and the centre's depth, the empty and the free cap,
the margin, what was kept, and notes on what could not be done.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from ..arrays import unit_rows
from ..cap import PoleCap
from ..chart import Chart, Method
from ..frames import Frame
from ..region import FlatRegion
from .emptycap import region_free_cap
from .problem import CAP_HULL_VERTICES, _Candidate, _cap_radii, _Problem
from .start import _Search, pole_and_roll

#: Sigmas whose energy the explanation reports.
REPORTED_SIGMAS = (0.3, 1.0)
#: Where an answer came from: the search, its start, the defaults (the rotation and sigma a
#: request naming neither gets, at the defaults' centre), or the start's rule again with the
#: pole in the cap free of the region (:func:`_onto_free_cap`).
KEPT = ("search", "start", "defaults", "free_cap")


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
    kept : str, one of :data:`KEPT`: where the answer came from
    energy_defaults : float or None, the energy of the defaults on every face (None: not
        measured, their centre sees the region edge-on or lies on it)
    free_cap_deg : float, angular radius of the largest cap free of the region seen from the
        answer's centre (0: none)
    vertex_gap_deg : float, angular radius of the largest cap free of the region's vertices'
        directions seen from there (a gap between them that faces may cover)
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
    kept: str = "search"
    energy_defaults: float | None = None
    free_cap_deg: float = 0.0
    vertex_gap_deg: float = 0.0


@dataclass(frozen=True)
class Fit:
    """The chosen frame and chart, the region flattened with them, and the explanation (None
    for :func:`transforms.fit.default_choice`, which searches nothing)."""

    frame: Frame
    chart: Chart
    region: FlatRegion
    explanation: FitExplanation | None


@dataclass(frozen=True)
class _Seen:
    """What the explanation reads of the start and of the searched answer, measured before
    the kernel's planes are let go: the depth in the kernel of each centre a contender may
    have (the start's, the searched answer's, the defaults'), the start's and the defaults'
    energies and those at :data:`REPORTED_SIGMAS` with the searched answer's centre and
    rotation (its sigma may still narrow: they do not depend on it), as
    :meth:`.problem._Problem.region_energies` measures them."""

    depths: dict
    energy_start: float
    energy_at_sigma: dict
    energy_defaults: list = field(default_factory=list)

    @classmethod
    def of(cls, problem: _Problem, search: _Search, found: _Candidate, others: list) -> _Seen:
        """``others``: the defaults' candidates (their energies measured as the start's)."""
        first = search.initial
        every = [first.center, found.center, *(c.center for c in others)]
        depth = problem.planes.depths(np.array(every))
        reported = _reported(problem, found)
        energies = problem.region_energies([first, *others, *reported])
        k = len(others)
        return cls(
            depths={_key(c): float(d) for c, d in zip(every, depth, strict=True)},
            energy_start=float(energies[0]),
            energy_at_sigma=dict(zip(REPORTED_SIGMAS, energies[1 + k :].tolist(), strict=False)),
            energy_defaults=energies[1 : 1 + k].tolist(),
        )


def _key(center: np.ndarray) -> tuple:
    return tuple(np.asarray(center, dtype=np.float64).tolist())


@dataclass(frozen=True)
class _Flattened:
    """A candidate with its region flattened on every face, its least margin, and where it
    came from (one of :data:`KEPT`)."""

    candidate: _Candidate
    flat: FlatRegion
    margin_deg: float
    kept: str = "search"


def _flattened(problem: _Problem, candidate: _Candidate) -> _Flattened:
    flat = problem.flatten(candidate)
    return _Flattened(candidate, flat, _margin_deg(flat))


def _margin_deg(flat: FlatRegion) -> float:
    v = flat.validation
    return min(v.margin_deg_seam, v.margin_deg_north, v.margin_deg_south)


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


def _rank(contender: _Flattened, search: _Search) -> tuple[int, float]:
    """The order of "keep the best" (docs/math.md, section 9, stage 5): first whether the
    seam and the singular points stay off the region with ``min_margin_deg`` (0), off it with
    less (1) or on it (2), for a region with a boundary (a closed one is on it whatever is
    chosen); then the isometric energy on every face (section 7)."""
    energy = contender.flat.distortion.isometric.mean
    energy = energy if math.isfinite(energy) else math.inf
    if search.margin is None:
        return 0, energy
    if not contender.flat.validation.seam_free:
        return 2, energy
    return int(contender.margin_deg < search.bounds.min_margin_deg), energy


def _keep_the_best(search: _Search, contenders: list[_Flattened]) -> _Flattened:
    """The first of ``contenders`` (the searched answer first) of least :func:`_rank`."""
    return min(contenders, key=lambda contender: _rank(contender, search))


def _sound(contender: _Flattened, search: _Search) -> bool:
    """Whether ``contender`` keeps the seam and the singular points off the region with the
    margin (or the region is closed, and nothing can)."""
    return _rank(contender, search)[0] == 0


@dataclass(frozen=True)
class _FreeCap:
    """The largest cap free of the region seen from a centre (:func:`.emptycap.free_cap`):
    its middle, its radius clear of the region and of its vertices (radians), and the
    region's unit directions from the centre."""

    pole: np.ndarray
    free: float
    vertex_cap: float
    directions: np.ndarray


def _free_cap_seen(
    problem: _Problem, flat: FlatRegion, center: np.ndarray, known: dict
) -> _FreeCap:
    """The free cap seen from ``center`` of the region as ``flat`` holds it: ``known``'s, by
    centre, when a stage found it there; else found, its hull started on the boundary's
    vertices and ``CAP_HULL_VERTICES`` spread over the rest."""
    points = problem.points[flat.vertex_ids]
    directions = unit_rows(points - center)[0]
    found = known.get(_key(center))
    if found is None:
        boundary = flat.validation.boundary_edges
        found = region_free_cap(points, flat.faces, center, boundary, CAP_HULL_VERTICES)
    pole, free, vertex_cap = found
    return _FreeCap(pole, free, vertex_cap, directions)


def _onto_free_cap(
    problem: _Problem, search: _Search, best: _Flattened, cap: _FreeCap, up
) -> _Flattened | None:
    """Where ``best`` lets the seam or a singular point onto the region but a cap is free of
    it seen from its centre: the pole in the middle of that cap, the roll as the start's,
    and the best sigma whose cap fits inside it with the margin to spare (half of it when it
    is narrower than twice the margin), narrowed on every face as the answer's
    (:func:`_keep_margin`). None when no cap is free or the rotation is the caller's."""
    if cap.free <= 0.0 or not search.free[1] or search.margin is None:
        return None
    c = best.candidate
    rotation = pole_and_roll(cap.directions, cap.pole, up, [])
    room = cap.free - search.margin if cap.free > 2.0 * search.margin else cap.free / 2.0
    sigma = problem.best_sigma(c.center, rotation, room) if search.choose_sigma else c.sigma
    found = _keep_margin(
        problem,
        _Candidate(c.center, rotation, sigma),
        search.choose_sigma,
        search.margin,
        search.bounds.min_margin_deg,
    )
    return replace(found, kept="free_cap")


def _reported(problem: _Problem, best: _Candidate) -> list[_Candidate]:
    """The answer's centre and rotation at :data:`REPORTED_SIGMAS` (none for the standard
    method, which has no sigma)."""
    if problem.method is Method.STANDARD:
        return []
    return [_Candidate(best.center, best.rotation, sigma) for sigma in REPORTED_SIGMAS]


def _explain(
    problem: _Problem,
    search: _Search,
    answer: _Flattened,
    seen: _Seen,
    defaults: _Flattened | None,
    cap: _FreeCap,
) -> Fit:
    """The fit, with the notes on the bounds it could not keep, on what was kept and on the
    free cap, and the energies at :data:`REPORTED_SIGMAS`."""
    best, flat, notes = answer.candidate, answer.flat, search.notes
    _note_the_margin(search, answer, cap, notes)
    kernel = search.kernel
    depth = seen.depths[_key(best.center)]
    if not kernel.empty and depth < search.min_depth:
        notes.append(
            f"the centre is {depth:.4g} deep in the kernel, less than min_kernel_depth "
            f"({search.bounds.min_kernel_depth:g} of the inscribed radius "
            f"{kernel.inscribed_radius:.4g})"
        )
    if answer.kept == "defaults":
        notes.append(
            "the defaults (the rotation and sigma a request naming neither gets, at the "
            "defaults' centre) do better than the search on every face, so they are kept"
        )
    energy_end = flat.distortion.isometric.mean
    energy_at_sigma = seen.energy_at_sigma
    if answer.kept != "search":  # measured for the searched answer, which lost
        reported = _reported(problem, best)
        energies = problem.region_energies(reported) if reported else []
        energy_at_sigma = dict(zip(REPORTED_SIGMAS, list(energies), strict=False))
    points = problem.points[flat.vertex_ids]
    explanation = FitExplanation(
        energy_start=seen.energy_start if any(search.free) else energy_end,
        energy_end=energy_end,
        kernel_inscribed_radius=kernel.inscribed_radius,
        kernel_empty=kernel.empty,
        center_depth=depth,
        empty_cap_deg=math.degrees(_cap_radii(points, best.center[None], best.rotation[1])[0]),
        margin_deg=answer.margin_deg,
        energy_at_sigma={float(k): float(v) for k, v in energy_at_sigma.items()},
        backfacing_faces=flat.validation.backfacing_faces,
        notes=notes,
        kept=answer.kept,
        energy_defaults=None if defaults is None else defaults.flat.distortion.isometric.mean,
        free_cap_deg=math.degrees(cap.free),
        vertex_gap_deg=math.degrees(cap.vertex_cap),
    )
    frame = Frame.from_matrix(best.rotation, best.center)
    return Fit(frame=frame, chart=problem.chart(best.sigma), region=flat, explanation=explanation)


def _note_the_margin(search: _Search, answer: _Flattened, cap: _FreeCap, notes: list) -> None:
    """Notes on a margin below the bound and on whether a cap was free of the region."""
    if search.margin is None:
        return
    if answer.margin_deg < search.bounds.min_margin_deg:
        notes.append(
            f"the margin to the seam and the singular points is {answer.margin_deg:.3g} "
            f"degrees, below min_margin_deg ({search.bounds.min_margin_deg:g})"
        )
    if cap.free <= 0.0:
        notes.append(
            "no cap is free of the region seen from the centre (its faces close round "
            "every direction), so the seam and the singular points cannot be kept off it: "
            f"the largest gap between its vertices' directions is "
            f"{math.degrees(cap.vertex_cap):.3g} degrees"
        )
    elif not answer.flat.validation.seam_free:
        notes.append(
            f"a cap of {math.degrees(cap.free):.3g} degrees is free of the region seen from "
            "the centre, but the rotation or sigma given does not put the seam inside it"
        )
