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
faces (:mod:`transforms.sampling`) in a frame built from the starting choice, so its path
does not depend on how the mesh is posed; the answer is checked, and its energy and margins
reported, on every face. Any of the three may be fixed by the caller.

The stages, each in a module of its own, composed here by :func:`fit_region` and
:func:`default_choice`:

* :mod:`.problem`: what the caller fixes and bounds; the region, its sample and what is
  evaluated on them (the sigma search, the slide along the pole, the region's energy);
* :mod:`.start`: the explainable start (stage 1);
* :mod:`.refine`: the refinement with L-BFGS-B (stage 3);
* :mod:`.explain`: the margin on every face, the better of start and answer, and the
  :class:`Fit` with its :class:`FitExplanation` (stages 4 to 6);
* :mod:`.objective`, :mod:`.kernel`, :mod:`.emptycap`: the objective for a batch of
  candidates, the kernel and its deepest point, the largest empty cap.
"""

from __future__ import annotations

from ..arrays import as_vector
from ..chart import Method
from ..errors import TransformInputError
from ..frames import Frame
from ..layouts import Layout
from .explain import (
    REPORTED_SIGMAS,
    Fit,
    FitExplanation,
    _explain,
    _keep_margin,
    _keep_the_better,
    _Seen,
)
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
from .start import _frame_and_sigma, _start, roll_axis

__all__ = [
    "COARSE_SAMPLE_FACES",
    "EXPLAIN_FACES",
    "HULL_VERTICES",
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
) -> Fit:
    """Choose the parameters ``fixed`` leaves as None and flatten the region with them.

    The stages: :func:`.start._start` (the explainable first choice), the slide along the
    pole (:meth:`.problem._Problem.slide_towards_pole`), the refinement
    (:func:`.refine.refined`), :func:`.explain._keep_margin` (on every face),
    :func:`.explain._keep_the_better` (the start, measured on every face, may win) and
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

    Returns
    -------
    Fit

    Raises
    ------
    TransformInputError
        Bad input (as :func:`transforms.region.flatten_region`), a sigma for ``standard``,
        or ``explain_faces`` or ``explain_run`` below 1.
    """
    fixed = fixed or FitFixed()
    bounds = bounds or FitBounds()
    problem = _Problem.checked(
        vertices,
        faces,
        fixed,
        method,
        threads,
        layout,
        explain_faces=explain_faces,
        explain_run=explain_run,
    )
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
