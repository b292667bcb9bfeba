"""The fit's refinement (docs/math.md, section 9, stage 3): quasi-Newton steps of scipy's
L-BFGS-B over the free parameters together, from the start the slide leaves.

The coordinates (:class:`_Coordinates`) are the centre's offset, the pole's tilt and
``log sigma``, each only when free, in the start's frame; the cost
(:class:`_RefinementCost`) is the objective on the sample with the bounds (the kernel's
depth, the region's reach, the margin) as squared penalties. Its gradient comes in closed
form (:meth:`.objective.FaceEnergy.slope`, with the rotations' derivatives here), by forward
differences in one batch for the separable method, whose angles come from a root search.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import minimize

from ..arrays import as_direction, cross_rows
from ..chart import Method
from ..checkpoints import checkpoint
from ..sampling import area_sample
from .kernel import Kernel
from .objective import Candidates, Motion
from .problem import _REACH, SAMPLE_FACES, SIGMA_SEARCH, _Candidate, _Problem, _sigma_or_one
from .start import _PARALLEL

#: Planes nearest the start whose depth the refinement watches (besides the sampled ones).
_NEAR_PLANES = 4096
#: The refinement's cost where a candidate cannot be measured: finite, so that differences
#: of costs never meet inf - inf, and above any real cost.
_INFEASIBLE = 1e100
#: The refinement's most quasi-Newton steps.
_REFINE_STEPS = 60
#: Relative decrease of the cost below which the refinement stops: far below the energy
#: differences a plan can see, and below the sample's own noise.
_REFINE_TOLERANCE = 1e-10
#: The forward-difference step of the separable method's gradients (the coordinates are of
#: order 1), and the weight of a bound's squared shortfall (a shortfall of 1e-4 costs 1e-4,
#: as much as the energy a step can win there).
_STEP = 1e-7
_PENALTY = 1e4


def refined(
    problem: _Problem,
    start: _Candidate,
    free: list[bool],
    kernel: Kernel,
    min_depth: float,
    margin: float | None,
    up: np.ndarray | None = None,
) -> _Candidate:
    """``start`` refined: quasi-Newton steps (L-BFGS-B) over the free parameters
    (:class:`_Coordinates`; ``free``: whether the centre, the rotation and sigma move; ``up``:
    the caller's up hint or facing, which keeps the roll as the pole tilts) on
    ``problem``'s sample, each gradient in closed form (by forward differences in one batch
    for the separable method: :meth:`_RefinementCost.value_and_gradient`). The bounds are
    quadratic penalties, smooth where they start to bind; what they let slip is taken back
    on every face after (the margin by :func:`.explain._keep_margin`, the depth here).
    ``start`` itself when no step lowers the cost."""
    unit = max(kernel.inscribed_radius, 1e-3 * problem.planes.size)
    coordinates = _Coordinates(start, free, unit, up)
    cost = _RefinementCost(problem, coordinates, min_depth, margin, unit)
    x0 = coordinates.start()
    found = minimize(
        cost.value_and_gradient,
        x0,
        jac=True,
        method="L-BFGS-B",
        bounds=coordinates.bounds(),
        options={"maxiter": _REFINE_STEPS, "ftol": _REFINE_TOLERANCE, "gtol": 1e-6},
        callback=lambda _: checkpoint(),
    )
    ends = cost(np.vstack([x0, found.x]))
    if not ends[1] < ends[0]:
        return start
    best = coordinates.candidate(found.x)
    if free[0] and problem.planes.depth(best.center) < min_depth:
        # A plane outside the subset binds: back towards the start, which is deep enough.
        best = _back_inside(problem, start, best, min_depth)
    return best


def _back_inside(
    problem: _Problem, start: _Candidate, best: _Candidate, min_depth: float
) -> _Candidate:
    """``best`` with its centre moved back towards ``start``'s (which is deep enough) to the
    last point found at least ``min_depth`` deep in ``problem``'s kernel (30 bisections)."""
    inside, outside = 0.0, 1.0
    for _ in range(30):
        middle = 0.5 * (inside + outside)
        center = start.center + middle * (best.center - start.center)
        if problem.planes.depth(center) >= min_depth:
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
    start's local X and Z) and log sigma, each only when free. As the pole tilts, local
    ``+Z`` stays the part across it of ``roll``: the caller's up hint (or facing) when the
    start followed it, else the start's own local Z (docs/math.md, sections 9 and 18)."""

    def __init__(
        self, start: _Candidate, free: list[bool], unit: float, up: np.ndarray | None = None
    ) -> None:
        self.start_candidate, self.unit = start, unit
        self.move_center, self.turn_pole, self.change_sigma = free
        self.roll = start.rotation[2]
        if up is not None:
            up = as_direction(up, "up")
            if np.linalg.norm(np.cross(up, start.rotation[1])) >= _PARALLEL:  # the start's rule
                self.roll = up

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
            rotations = _rotations_from_pole_up(poles, self.roll)
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
            motion.rotation[column : column + 2] = _rotation_slopes(pole, self.roll, axes[[0, 2]])
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
    :meth:`transforms.Frame.from_pole_up` for a batch (``up`` is the start's local Z or the
    up hint it followed, not parallel to its pole, so far from parallel to a slightly tilted
    one)."""
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
