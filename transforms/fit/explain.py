"""The fit's answer on every face and why it is what it is (docs/math.md, section 9,
stages 4 to 6).

The search saw a sample: on every face the cap is narrowed until the margin holds
(:func:`_keep_margin`) and the start is kept where it does better (:func:`_keep_the_better`).
Then the :class:`Fit` is built with its :class:`FitExplanation`: the energies (section 7) at
the start, at the end and at ``REPORTED_SIGMAS``, the kernel's radius and the centre's depth,
the empty cap, the margin, and notes on what could not be done.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..cap import PoleCap
from ..chart import Chart, Method
from ..frames import Frame
from ..region import FlatRegion
from .problem import _Candidate, _cap_radii, _Problem
from .start import _Search

#: Sigmas whose energy the explanation reports.
REPORTED_SIGMAS = (0.3, 1.0)


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
    for :func:`transforms.fit.default_choice`, which searches nothing)."""

    frame: Frame
    chart: Chart
    region: FlatRegion
    explanation: FitExplanation | None


@dataclass(frozen=True)
class _Seen:
    """What the explanation reads of the start and of the searched answer, measured before
    the answer is flattened: per candidate (the start first), the depth of its centre in
    the kernel and the empty cap around its pole in degrees; the start's energy and those at
    :data:`REPORTED_SIGMAS` with the searched answer's centre and rotation (its sigma may
    still narrow: they do not depend on it), as :meth:`.problem._Problem.region_energies`
    measures them."""

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


@dataclass(frozen=True)
class _Flattened:
    """A candidate with its region flattened on every face and its least margin."""

    candidate: _Candidate
    flat: FlatRegion
    margin_deg: float


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
