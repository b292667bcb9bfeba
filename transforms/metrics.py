"""Distortion of the ``(phi, theta)`` layout (docs/math.md, section 7).

For each triangle the affine map from the 3D triangle (in its own plane) to its 2D triangle
has singular values ``s1 >= s2``; the layout is first scaled by one factor so that its total
area equals the region's 3D area. Per triangle:

* conformal distortion ``s1 / s2`` (1: angles kept);
* area distortion ``|log(s1 s2)|`` (0: areas kept);
* isometric distortion ``(s1^2 + s2^2 + s1^-2 + s2^-2) / 4`` (1: an isometry).

Summaries are weighted by 3D area: mean, median (p50), 95th percentile, maximum. Degenerate
triangles (zero area in 3D or in the layout) have no affine map and are left out; the validation
lists them.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from .arrays import blocks
from .errors import TransformInputError
from .faces import FaceMeasures

#: Below this many values the weighted quantile simply sorts them.
_SORT_BELOW = 65536
#: Size of the sample that brackets the quantile, and the bracket's half-width in weight.
_SAMPLE = 32768
_BRACKET = 0.004
#: The quantiles every summary gives: the median and the 95th percentile.
_P50, _P95 = 0.5, 0.95
_BINS = 1024

#: Values around the ``q`` quantile of a weighted sample: ``(sample, weights, q)`` to
#: ``(low, high)`` (:func:`_bracket`).
Bracket = Callable[[np.ndarray, np.ndarray, float], tuple[float, float]]


@dataclass(frozen=True)
class Summary:
    """Area-weighted statistics of one per-triangle measure: the mean, the median (``p50``:
    a few slivers cannot move it), the 95th percentile and the maximum."""

    mean: float
    p50: float
    p95: float
    max: float


@dataclass(frozen=True)
class Distortion:
    """The three measures of a layout.

    Attributes
    ----------
    conformal, area, isometric : Summary
    measured_faces : int, faces the statistics cover (the non-degenerate ones)
    layout_scale : float, the factor applied to ``(phi, theta)`` (per unit of the mesh's
        length) to give the layout the region's 3D area
    """

    conformal: Summary
    area: Summary
    isometric: Summary
    measured_faces: int
    layout_scale: float


@dataclass(frozen=True)
class FaceDistortion:
    """Per-triangle measures of the measured (non-degenerate) faces.

    Attributes
    ----------
    faces : (j,) int, positions in the region's face list
    conformal, area, isometric : (j,) float
    weights : (j,) float, 3D areas in the mesh's units
    layout_scale : float, as in :class:`Distortion`
    """

    faces: np.ndarray
    conformal: np.ndarray
    area: np.ndarray
    isometric: np.ndarray
    weights: np.ndarray
    layout_scale: float


def face_distortion(measures: FaceMeasures) -> FaceDistortion:
    """The three measures for every non-degenerate face.

    Raises
    ------
    TransformInputError
        Every face is degenerate.
    """
    measured, squared_scale = _measured_faces(measures)
    conformal = np.empty(measured.size)
    area = np.empty(measured.size)
    isometric = np.empty(measured.size)
    for block in blocks(measured.size):
        conformal[block], area[block], isometric[block] = _measures_of(
            measures, _rows_of(measured, block, len(measures)), squared_scale
        )
    length_scale = measures.scale  # areas back in the mesh's units
    return FaceDistortion(
        faces=measured,
        conformal=conformal,
        area=area,
        isometric=isometric,
        weights=(0.5 / (length_scale * length_scale)) * measures.double_area[measured],
        layout_scale=float(np.sqrt(squared_scale)) / length_scale,
    )


def distortion(measures: FaceMeasures, *, bracket: Bracket | None = None) -> Distortion:
    """Area-weighted mean, median, 95th percentile and maximum of the three measures.

    One pass over the faces computes each measure block by block and keeps only its sums,
    maximum and what :func:`weighted_quantile` needs inside a bracket found from a sample
    (one bracket per quantile); the per-face arrays of :func:`face_distortion` are made only
    if a bracket misses.

    Parameters
    ----------
    measures : FaceMeasures, from :func:`.faces.measure_faces`
    bracket : how the quantiles are bracketed from the sample, here and in
        :func:`weighted_quantile` when a bracket misses; None: :func:`_bracket`. Any bracket
        gives the same answer, a good one sooner.

    Returns
    -------
    Distortion
    """
    measured, squared_scale = _measured_faces(measures)
    weights = measures.double_area  # any common factor cancels in means and quantiles
    total = float(weights[_rows_of(measured, slice(None), len(measures))].sum())
    sample = measured[:: max(measured.size // _SAMPLE, 1)]
    bracket = _bracket if bracket is None else bracket
    scans = [
        [_Scan(q, *bracket(values, weights[sample], q)) for q in (_P50, _P95)]
        for values in _measures_of(measures, sample, squared_scale)
    ]
    sums, largest = np.zeros(3), np.full(3, -np.inf)
    for block in blocks(measured.size):
        faces = _rows_of(measured, block, len(measures))
        w = weights[faces]
        for i, values in enumerate(_measures_of(measures, faces, squared_scale)):
            sums[i] += np.dot(values, w)
            largest[i] = max(largest[i], values.max())
            for scan in scans[i]:
                scan.add(values, w)
    per_face: list[FaceDistortion] = []

    def long_way(i: int, q: float) -> Callable[[], float]:
        def quantile() -> float:  # the sample misled: every face's values
            if not per_face:
                per_face.append(face_distortion(measures))
            found = per_face[0]
            values = (found.conformal, found.area, found.isometric)[i]
            return weighted_quantile(values, found.weights, q, bracket=bracket)

        return quantile

    conformal, area, isometric = (
        Summary(
            mean=float(sums[i] / total),
            p50=scans[i][0].settle(total, long_way(i, _P50)),
            p95=scans[i][1].settle(total, long_way(i, _P95)),
            max=float(largest[i]),
        )
        for i in range(3)
    )
    return Distortion(
        conformal=conformal,
        area=area,
        isometric=isometric,
        measured_faces=int(measured.size),
        layout_scale=float(np.sqrt(squared_scale)) / measures.scale,
    )


@dataclass
class _Scan:
    """One weighted quantile ``q`` found in a pass over blocks of values: the weight below
    the bracket ``[low, high]`` and the values inside it."""

    q: float
    low: float
    high: float
    below: float = 0.0
    inside: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)

    def add(self, values: np.ndarray, weights: np.ndarray) -> None:
        below = values < self.low
        self.below += float(weights[below].sum())  # a dot with the mask casts it: 6x slower
        keep = values <= self.high
        keep &= ~below
        self.inside.append((values[keep], weights[keep]))

    def settle(self, total: float, otherwise: Callable[[], float]) -> float:
        """The quantile of values of weight ``total`` in all, from the bracket when it holds
        the target weight, else ``otherwise()``."""
        values = np.concatenate([v for v, _ in self.inside])
        weights = np.concatenate([w for _, w in self.inside])
        target = self.q * total
        if self.below < target <= self.below + weights.sum():
            return _sorted_quantile(values, weights, target - self.below)
        return otherwise()


def stretched_faces(measures: FaceMeasures, bound: float) -> np.ndarray:
    """(j,) int: positions of the non-degenerate faces whose isometric energy (the layout
    scaled as for :func:`distortion`) is above ``bound``, ascending; none when every face is
    degenerate."""
    if measures.degenerate.all():
        return np.empty(0, dtype=np.intp)
    measured, squared_scale = _measured_faces(measures)
    above = np.empty(measured.size, dtype=bool)
    for block in blocks(measured.size):
        faces = _rows_of(measured, block, len(measures))
        above[block] = _measures_of(measures, faces, squared_scale)[2] > bound
    return measured[above]


def _measured_faces(measures: FaceMeasures) -> tuple[np.ndarray, float]:
    """Positions of the non-degenerate faces, and the square of the factor that gives the
    layout the region's 3D area (docs/math.md, section 7: one factor for the whole layout,
    every face counts).

    Raises
    ------
    TransformInputError
        Every face is degenerate.
    """
    degenerate = measures.degenerate
    measured = np.flatnonzero(~degenerate) if degenerate.any() else np.arange(len(measures))
    if measured.size == 0:
        raise TransformInputError(
            "faces", "every face of the region has zero area in 3D or in the layout"
        )
    squared_scale = measures.double_area.sum() / np.abs(measures.layout_double_area).sum()
    return measured, float(squared_scale)


def _rows_of(measured: np.ndarray, block: slice, m: int) -> np.ndarray | slice:
    """The faces of ``block`` of ``measured``: the block itself when every face is measured
    (a slice reads without copying)."""
    return block if measured.size == m else measured[block]


def _measures_of(
    measures: FaceMeasures, faces: np.ndarray | slice, squared_scale: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Conformal, area and isometric distortion of ``faces`` (positions, non-degenerate).

    Scaling the layout by ``k`` scales both singular values by ``k``; ``k^2`` is
    ``squared_scale``. Isometric: ``(s1^2 + s2^2 + s1^-2 + s2^-2) / 4
    = (s1^2 + s2^2)(1 + 1 / (s1 s2)^2) / 4``.
    """
    s1, s2 = measures.stretch_max[faces], measures.stretch_min[faces]
    conformal = np.maximum(s1 / s2, 1.0)
    product = s1 * s2
    product *= squared_scale
    area = np.abs(np.log(product))
    squares = s1 * s1
    squares += s2 * s2
    squares *= 0.25 * squared_scale
    product *= product
    np.reciprocal(product, out=product)
    product += 1.0
    squares *= product
    return conformal, area, squares


def weighted_quantile(
    values: np.ndarray, weights: np.ndarray, q: float, *, bracket: Bracket | None = None
) -> float:
    """The smallest value ``v`` with at least the fraction ``q`` of the weight on values
    ``<= v``.

    Exact, in linear time. A strided sample brackets the answer (the sample's quantiles at
    ``q -+ _BRACKET``); one pass checks that the bracket holds the target weight and collects
    the values inside it, which are then sorted. When the sample misleads (it cannot when it
    is the whole input) the search narrows a weighted histogram instead.

    Parameters
    ----------
    values : (k,) float, finite, k >= 1
    weights : (k,) float, >= 0, positive sum
    q : float in [0, 1]
    bracket : how the sample brackets the answer; None: :func:`_bracket`. Any bracket gives
        the same answer (one that misses falls back to the histogram), a good one sooner.
    """
    values = np.asarray(values, dtype=np.float64)
    weights = np.asarray(weights, dtype=np.float64)
    if values.size == 0 or values.shape != weights.shape:
        raise TransformInputError(
            "values", f"need one weight per value and at least one value, got {values.shape}"
        )
    target = q * weights.sum()
    if len(values) <= _SORT_BELOW:
        return _sorted_quantile(values, weights, target)
    stride = max(len(values) // _SAMPLE, 1)
    bracket = _bracket if bracket is None else bracket
    scan = _Scan(q, *bracket(values[::stride], weights[::stride], q))
    for block in blocks(len(values)):
        scan.add(values[block], weights[block])
    return scan.settle(float(weights.sum()), lambda: _histogram_quantile(values, weights, target))


def _bracket(sample: np.ndarray, weights: np.ndarray, q: float) -> tuple[float, float]:
    """Values around the ``q`` quantile of a weighted sample (its ``q -+ _BRACKET``
    quantiles); the whole range when the sample has no weight."""
    total = weights.sum()
    if not total > 0:
        return -np.inf, np.inf
    order = np.argsort(sample)
    share = np.cumsum(weights[order]) / total
    picks = np.searchsorted(share, [q - _BRACKET, q + _BRACKET]).clip(0, len(order) - 1)
    low, high = sample[order[picks]]
    return float(low), float(high)


def _sorted_quantile(values: np.ndarray, weights: np.ndarray, target: float) -> float:
    """The smallest value whose cumulative weight, in ascending order, reaches ``target``."""
    order = np.argsort(values, kind="stable")
    cumulative = np.cumsum(weights[order])
    return float(values[order[min(int(np.searchsorted(cumulative, target)), len(values) - 1)]])


def _histogram_quantile(values: np.ndarray, weights: np.ndarray, target: float) -> float:
    """:func:`weighted_quantile` by repeatedly narrowing a weighted histogram to the bin that
    holds ``target``, then sorting what is left."""
    below = 0.0  # weight of the values already known to lie under the candidates
    while len(values) > _SORT_BELOW:
        low, high = float(values.min()), float(values.max())
        if not high - low > 4e-16 * max(abs(low), abs(high)):
            return low  # all candidates equal, up to rounding
        per_unit = _BINS / (high - low)
        bins = np.minimum(((values - low) * per_unit).astype(np.intp), _BINS - 1)
        cumulative = below + np.cumsum(np.bincount(bins, weights=weights, minlength=_BINS))
        chosen = min(int(np.searchsorted(cumulative, target)), _BINS - 1)
        keep = bins == chosen
        if not keep.any():
            break  # rounding in the cumulative sums; sort what is left instead
        if chosen > 0:
            below = float(cumulative[chosen - 1])
        values, weights = values[keep], weights[keep]
    return _sorted_quantile(values, weights, target - below)
