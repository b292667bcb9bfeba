"""The fit's start (docs/math.md, section 9, stage 1): choices that can each be explained.

The centre is the kernel's deepest point (its Chebyshev centre, :mod:`.kernel`); the pole the
middle of the largest cap that holds no region direction seen from there (:mod:`.emptycap`);
the roll the caller's up hint or the rule of :func:`roll_axis`; sigma the best of a search in
``log sigma`` whose cap fits inside the empty cap less the margin
(:meth:`.problem._Problem.best_sigma`). :class:`_Search` holds what the later stages share.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..arrays import as_direction, as_vector
from ..chart import Method
from ..frames import Frame
from .emptycap import cap_radius, free_cap
from .kernel import Kernel, chebyshev_center
from .problem import FitBounds, FitFixed, _Candidate, _Problem

#: Below this sine of the angle between the up hint and the chosen pole, the hint is ignored.
_PARALLEL = 1e-6


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
    free_cap: tuple | None = None


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
        free_cap=choice.free_cap,
    )


@dataclass(frozen=True)
class _Choice:
    """The start's frame and sigma at a centre, and the margin the search keeps (radians;
    None for a closed region)."""

    candidate: _Candidate
    margin: float | None
    choose_sigma: bool
    #: :func:`.emptycap.free_cap` seen from the centre (pole, free, vertex gap), when the
    #: rotation was chosen; None when it was given.
    free_cap: tuple | None = None


def _frame_and_sigma(
    problem: _Problem, center: np.ndarray, fixed: FitFixed, bounds: FitBounds, notes: list[str]
) -> _Choice:
    """Seen from ``center``: unless fixed, the rotation with its pole in the middle of the
    cap free of the region (:func:`.emptycap.free_cap`: the largest cap free of every vertex
    direction, its hull started on ``problem.cap_rows``, or one free of the boundary's
    directions, whichever the region leaves clearer) and the roll of :func:`pole_and_roll`;
    unless fixed, the best sigma whose cap fits inside the empty cap less the margin."""
    directions = problem.directions(center)
    cap = None
    if fixed.rotation is None:
        cap = free_cap(
            directions,
            problem.region_faces,
            problem.cap_rows,
            problem.boundary_edges,
            problem.boundary_loops,
        )
        rotation = pole_and_roll(directions, cap[0], fixed.up, notes)
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
    return _Choice(_Candidate(center, rotation, sigma), margin, choose_sigma, cap)


def pole_and_roll(directions: np.ndarray, pole: np.ndarray, up, notes: list[str]) -> np.ndarray:
    """(3, 3): the rotation with local ``+Y`` along ``pole`` and the roll by ``up`` (unless it
    is parallel to the pole: then a note) or :func:`roll_axis` of ``directions``."""
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
