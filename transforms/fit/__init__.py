"""Choosing the centre, the pole (with the roll about it) and sigma for a region: the three
parameters the paper leaves to the user (docs/math.md, section 9).

The choice minimises the region's area-weighted isometric energy, subject to two bounds:

* the centre stays inside the region's kernel (:mod:`.kernel`) at a depth of at least
  ``min_kernel_depth`` times the kernel's inscribed radius;
* the margin from the region to the seam and the singular points stays at least
  ``min_margin_deg``.

It starts from choices that can be explained one by one: the centre is the kernel's deepest
point (its Chebyshev centre), the pole the middle of the largest cap that holds no region
direction seen from there (:mod:`.emptycap`), the roll the rule of :func:`.start.roll_axis`,
sigma the best of a 1D search with the cap inside the empty cap; then it refines the free
ones together (quasi-Newton steps: scipy's L-BFGS-B, the gradients in closed form, by forward
differences for the separable method). The search works on an area-weighted sample of the
faces (:mod:`transforms.sampling`); the answer is checked, and its energy and margins
reported, on every face. Any of the three may be fixed by the caller. The searched answer,
its start and the defaults (:func:`default_choice` at the defaults' centre) are ranked by one
order, and where a cap is free of the region the answer keeps the seam in it. The whole fit
runs in the region's own frame (:mod:`.pose`), so that it depends on the surface and the
caller's choices only, not on the mesh's pose or unit.

The stages, each in a module of its own, composed here by :func:`fit_region` and
:func:`default_choice`:

* :mod:`.problem`: what the caller fixes and bounds; the region, its sample and what is
  evaluated on them (the sigma search, the slide along the pole, the region's energy);
* :mod:`.start`: the explainable start (stage 1);
* :mod:`.refine`: the refinement with L-BFGS-B (stage 3);
* :mod:`.explain`: the margin on every face, the best of the searched answer, its start and
  the defaults, the free cap, and the :class:`Fit` with its :class:`FitExplanation`
  (stages 4 to 7);
* :mod:`.pose`: the region in its own frame, and the answer taken back to the world;
* :mod:`.objective`, :mod:`.kernel`, :mod:`.emptycap`: the objective for a batch of
  candidates, the kernel and its deepest point, the largest empty cap.
"""

from __future__ import annotations

from dataclasses import replace

from ..chart import Method
from ..errors import TransformInputError
from ..frames import Frame
from ..layouts import Layout
from .explain import (
    KEPT,
    REPORTED_SIGMAS,
    Fit,
    FitExplanation,
    _explain,
    _Flattened,
    _free_cap_seen,
    _keep_margin,
    _keep_the_best,
    _key,
    _onto_free_cap,
    _Seen,
    _sound,
)
from .pose import Posed
from .problem import (
    _EXPLAIN_RUN,
    COARSE_SAMPLE_FACES,
    EXPLAIN_FACES,
    HULL_VERTICES,
    SAMPLE_FACES,
    SIGMA_SEARCH,
    FitBounds,
    FitFixed,
    _Problem,
)
from .refine import refined
from .start import _Choice, _frame_and_sigma, _Search, _start, roll_axis

__all__ = [
    "COARSE_SAMPLE_FACES",
    "EXPLAIN_FACES",
    "HULL_VERTICES",
    "KEPT",
    "REPORTED_SIGMAS",
    "SAMPLE_FACES",
    "SIGMA_SEARCH",
    "Fit",
    "FitBounds",
    "FitExplanation",
    "FitFixed",
    "default_choice",
    "fit_region",
    "roll_axis",
]


def fit_region(
    vertices,
    faces,
    fixed: FitFixed | None = None,
    bounds: FitBounds | None = None,
    *,
    method: str | Method = Method.DISTORTED,
    layout: Layout | str = Layout.THETA_PHI,
    threads: int = 1,
    explain_faces: int = EXPLAIN_FACES,
    explain_run: int = _EXPLAIN_RUN,
    default_center=None,
) -> Fit:
    """Choose the parameters ``fixed`` leaves as None and flatten the region with them.

    The stages, in the region's own frame (:class:`.pose.Posed`): :func:`.start._start` (the
    explainable first choice), the slide along the pole
    (:meth:`.problem._Problem.slide_towards_pole`), the refinement (:func:`.refine.refined`),
    :func:`.explain._keep_margin` (on every face), :func:`.explain._keep_the_best` (the
    searched answer, the start and the defaults, measured on every face),
    :func:`.explain._onto_free_cap` (the seam into a cap free of the region) and
    :func:`.explain._explain`.

    Parameters
    ----------
    vertices : (n, 3) float, world coordinates
    faces : (m, 3) int, the region's faces
    fixed : FitFixed, default: choose all
    bounds : FitBounds, default: ``FitBounds()``
    method : the chart's method; ``standard`` has no sigma
    layout : the layout whose energy is minimised and returned (:mod:`transforms.layouts`)
    threads : int
    explain_faces, explain_run : int >= 1, where the explanation's energies (the start's
        and at ``REPORTED_SIGMAS``) are measured: on every face of a region of up to
        ``explain_faces``, beyond that on every k-th run of ``explain_run`` consecutive
        faces, about ``explain_faces`` in all (the answer's own energy is always measured
        on every face)
    default_center : (3,) float or None, a centre the defaults are also measured at when the
        centre is chosen (a request's default centre); they always are at the middle of the
        region's box in its own axes. A fixed centre is the defaults' too.

    Returns
    -------
    Fit

    Raises
    ------
    TransformInputError
        Bad input (as :func:`transforms.region.flatten_region`), a sigma for ``standard``,
        or ``explain_faces`` or ``explain_run`` below 1.
    """
    posed = Posed.of(vertices, faces, fixed or FitFixed(), default_center)
    fixed, bounds = posed.fixed, bounds or FitBounds()
    problem = _Problem.checked(
        posed.points,
        posed.faces,
        fixed,
        method,
        threads,
        layout,
        explain_faces=explain_faces,
        explain_run=explain_run,
    )
    posed.flatten_in_world(problem)
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
        start = refined(
            problem,
            start,
            search.free,
            search.kernel,
            search.min_depth,
            search.margin,
            fixed.up,
        )
    defaults = _defaults_choices(problem, posed, bounds)
    seen = _Seen.of(problem, search, start, [choice.candidate for choice in defaults])
    # The kernel's planes and the region's own vertices are let go before the answer is
    # flattened: the fit's peak is then its answer's flatten's.
    problem.release()
    best = _keep_margin(
        problem, start, search.choose_sigma, search.margin, search.bounds.min_margin_deg
    )
    contenders = [best]
    energy = best.flat.distortion.isometric.mean
    # The others are flattened only when they may win: their estimated energy is lower, or
    # the answer lets the seam onto the region and a cap may be free from their centre (when
    # the start is the answer, it is not flattened again).
    unsound = not _sound(best, search)
    if any(search.free) and start is not search.initial:
        if (unsound and _may_be_free(search.free_cap)) or seen.energy_start < energy:
            contenders.append(_start_contender(problem, search, fixed))
    measured = []
    for choice, estimate in zip(defaults, seen.energy_defaults, strict=True):
        if (unsound and _may_be_free(choice.free_cap)) or estimate < energy:
            measured += _measured(problem, choice, search)
    best = _keep_the_best(search, contenders + measured)
    known = {_key(search.initial.center): search.free_cap}
    known.update({_key(choice.candidate.center): choice.free_cap for choice in defaults})
    known = {key: cap for key, cap in known.items() if cap is not None}
    cap = _free_cap_seen(problem, best.flat, best.candidate.center, known)
    if not _sound(best, search):
        moved = _onto_free_cap(problem, search, best, cap, fixed.up)
        best = best if moved is None else _keep_the_best(search, [best, moved])
    measured = _keep_the_best(search, measured) if measured else None
    return posed.to_world(_explain(problem, search, best, seen, measured, cap))


def _may_be_free(cap: tuple | None) -> bool:
    """Whether a cap may be free of the region seen from a centre (:func:`.emptycap.free_cap`'s
    answer there, or None when it was not found)."""
    return cap is None or cap[1] > 0.0


def _start_contender(problem: _Problem, search: _Search, fixed: FitFixed) -> _Flattened:
    """The start on every face, its cap narrowed as the answer's: with a fixed centre it is
    what :func:`default_choice` answers there, so it stands for the defaults."""
    start = _keep_margin(
        problem, search.initial, search.choose_sigma, search.margin, search.bounds.min_margin_deg
    )
    return replace(start, kept="start" if fixed.center is None else "defaults")


def _defaults_choices(problem: _Problem, posed: Posed, bounds: FitBounds) -> list[_Choice]:
    """The defaults' choices when the centre is chosen: the start's rule at the defaults'
    centres, the rotation and sigma the caller fixed kept. The centres: the middle of the
    region's box in its own axes (the same point in any pose) and ``posed.default_center``
    (a request's default centre, which may be the box in world axes), if given. None with a
    fixed centre (the start is the defaults then); a centre with a region vertex on it is
    left out."""
    fixed = posed.fixed
    if fixed.center is not None:
        return []
    points = problem.region_points
    centers = [(points.min(axis=0) + points.max(axis=0)) / 2.0]
    if posed.default_center is not None:
        centers.append(posed.default_center)
    choices = []
    for center in centers:
        at = FitFixed(center=center, rotation=fixed.rotation, up=fixed.up, sigma=fixed.sigma)
        try:
            choices.append(_frame_and_sigma(problem, center, at, bounds, []))
        except TransformInputError:  # a region vertex at that centre
            continue
    return choices


def _measured(problem: _Problem, choice: _Choice, search: _Search) -> list[_Flattened]:
    """The defaults' choice on every face (:func:`.explain._keep_margin`); none where their
    centre sees every face edge-on."""
    try:
        found = _keep_margin(
            problem,
            choice.candidate,
            choice.choose_sigma,
            choice.margin,
            search.bounds.min_margin_deg,
        )
    except TransformInputError:
        return []
    return [replace(found, kept="defaults")]


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
    narrowed until the margin holds on every face (stage 4), in the region's own frame as
    the fit (:mod:`.pose`). Cheap enough for every request.

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
    posed = Posed.of(vertices, faces, fixed)
    fixed = posed.fixed
    problem = _Problem.checked(posed.points, posed.faces, fixed, method, threads, layout)
    posed.flatten_in_world(problem)
    choice = _frame_and_sigma(problem, fixed.center, fixed, bounds, [])
    answer = _keep_margin(
        problem, choice.candidate, choice.choose_sigma, choice.margin, bounds.min_margin_deg
    )
    best = answer.candidate
    frame = Frame.from_matrix(best.rotation, best.center)
    fit = Fit(frame=frame, chart=problem.chart(best.sigma), region=answer.flat, explanation=None)
    return posed.to_world(fit)
