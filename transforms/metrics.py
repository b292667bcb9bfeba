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

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numba import njit

from .checkpoints import checkpoint
from .errors import TransformInputError
from .faces import FaceMeasures

#: Below this many values the weighted quantile simply sorts them.
_SORT_BELOW = 65536
#: Size of the sample that brackets the quantile, and the bracket's half-width in weight.
_SAMPLE = 32768
_BRACKET = 0.01
#: How much wider the second bracket is, where the sample's first misled.
_WIDE = 4.0
#: The quantiles every summary gives: the median and the 95th percentile.
_P50, _P95 = 0.5, 0.95

#: Values around the ``q`` quantile of a weighted sample: ``(sample, weights, q)`` to
#: ``(low, high)`` (by default the sample's ``q -+ _BRACKET`` quantiles, :func:`_brackets`).
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
    conformal, area, isometric = _values_of(measures, measured, squared_scale)
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

    Each measure is computed once per face (:func:`_values_of`); one pass over its values
    keeps its weighted sum, its maximum and what the quantiles need inside the brackets a
    sample gives them (:func:`_quantiles`).

    Parameters
    ----------
    measures : FaceMeasures, from :func:`.faces.measure_faces`
    bracket : how the quantiles are bracketed from the sample; None: :func:`_brackets`'
        own. Any bracket gives the same answer, a good one sooner.

    Returns
    -------
    Distortion
    """
    measured, squared_scale = _measured_faces(measures)
    values = _values_of(measures, measured, squared_scale)
    return _summarised(measures, measured, values, squared_scale, bracket)


def distortion_and_trusted(
    measures: FaceMeasures, flagged: np.ndarray
) -> tuple[Distortion, Distortion | None]:
    """:func:`distortion` over every measured face, and over those not ``flagged`` ((m,)
    bool) too: the same per-face values (one layout scale for the whole region), computed
    once. None for the second when every face is flagged or degenerate."""
    measured, squared_scale = _measured_faces(measures)
    values = _values_of(measures, measured, squared_scale)
    every = _summarised(measures, measured, values, squared_scale, None)
    kept = ~flagged[measured]
    if not kept.any():
        return every, None
    if kept.all():
        return every, every
    trusted = _summarised(measures, measured[kept], values[:, kept], squared_scale, None)
    return every, trusted


def _summarised(
    measures: FaceMeasures,
    measured: np.ndarray,
    values: np.ndarray,
    squared_scale: float,
    bracket: Bracket | None,
) -> Distortion:
    """The summaries of the three measures' ``values`` ((3, k) float) of the ``measured``
    faces ((k,) positions)."""
    every = measured.size == len(measures)
    # Any common factor of the weights cancels in means and quantiles.
    weights = measures.double_area if every else measures.double_area[measured]
    total = float(weights.sum())
    summaries = []
    sample = _sample_rows(measured.size)
    for measure in values:
        checkpoint()
        weighted, largest, (p50, p95) = _quantiles(
            measure, weights, total, (_P50, _P95), bracket, sample
        )
        summaries.append(Summary(mean=weighted / total, p50=p50, p95=p95, max=largest))
    conformal, area, isometric = summaries
    return Distortion(
        conformal=conformal,
        area=area,
        isometric=isometric,
        measured_faces=int(measured.size),
        layout_scale=float(np.sqrt(squared_scale)) / measures.scale,
    )


#: What one quantile's scan found: the weight below its bracket, and the values inside the
#: bracket with their weights.
_Found = tuple[float, np.ndarray, np.ndarray]


def _scan(
    values: np.ndarray, weights: np.ndarray, brackets: list[tuple[float, float]]
) -> tuple[float, float, list[_Found]]:
    """One pass over ``values`` ((k,) float, finite) and their ``weights``: the weighted
    sum, the maximum, and for each ``(low, high)`` bracket what :func:`_settle` needs."""
    lows = np.array([low for low, _ in brackets], dtype=np.float64)
    highs = np.array([high for _, high in brackets], dtype=np.float64)
    values, weights = np.ascontiguousarray(values), np.ascontiguousarray(weights)
    weighted, largest, below, counts = _scan_pass(values, weights, lows, highs)
    found = []
    for i in range(len(brackets)):
        inside_values, inside_weights = _inside(values, weights, lows[i], highs[i], counts[i])
        found.append((float(below[i]), inside_values, inside_weights))
    return float(weighted), float(largest), found


def _settled(found: _Found, target: float) -> float | None:
    """The quantile of weight ``target`` from a bracket's scan when the bracket holds it."""
    below, values, weights = found
    if below < target <= below + weights.sum():
        return _sorted_quantile(values, weights, target - below)
    return None


def _quantiles(
    values: np.ndarray,
    weights: np.ndarray,
    total: float,
    qs: tuple[float, ...],
    bracket: Bracket | None,
    sample: np.ndarray | slice | None = None,
) -> tuple[float, float, list[float]]:
    """The weighted sum and the maximum of ``values`` ((k,) float, finite; ``weights`` sum
    to ``total`` > 0) and their weighted quantiles ``qs``, exactly: a sample's brackets
    (:func:`_brackets`), checked and read in one pass (:func:`_scan`). Where the sample
    misled, once more with a bracket four times as wide, then the quickselect over every
    value. ``sample``: the rows of the sample, :func:`_sample_rows` when None."""
    sample = _sample_rows(values.size) if sample is None else sample
    brackets = _brackets(values[sample], weights[sample], qs, bracket)
    weighted, largest, scans = _scan(values, weights, brackets)
    found = []
    for q, scan in zip(qs, scans, strict=True):
        target = q * total
        quantile = _settled(scan, target)
        if quantile is None and bracket is None:
            wide = _brackets(values[sample], weights[sample], (q,), None, _WIDE)
            quantile = _settled(_scan(values, weights, wide)[2][0], target)
        if quantile is None:
            quantile = _sorted_quantile(values, weights, target)  # every value: linear too
        found.append(quantile)
    return weighted, largest, found


@njit(cache=True, nogil=True)
def _scan_pass(values, weights, lows, highs):
    """The weighted sum and the maximum of ``values``, and per bracket ``i`` the weight of
    the values below ``lows[i]`` and how many lie in ``[lows[i], highs[i]]``."""
    weighted, largest = 0.0, -np.inf
    below = np.zeros(lows.size)
    counts = np.zeros(lows.size, dtype=np.int64)
    for f in range(values.size):
        value, weight = values[f], weights[f]
        weighted += value * weight
        largest = max(largest, value)
        for i in range(lows.size):
            if value < lows[i]:
                below[i] += weight
            elif value <= highs[i]:
                counts[i] += 1
    return weighted, largest, below, counts


@njit(cache=True, nogil=True)
def _inside(values, weights, low, high, count):
    """The ``count`` values in ``[low, high]``, and their weights, in their order."""
    inside_values, inside_weights = np.empty(count), np.empty(count)
    at = 0
    for f in range(values.size):
        if low <= values[f] <= high:
            inside_values[at], inside_weights[at] = values[f], weights[f]
            at += 1
    return inside_values, inside_weights


def stretched_faces(measures: FaceMeasures, bound: float) -> np.ndarray:
    """(j,) int: positions of the non-degenerate faces whose isometric energy (the layout
    scaled as for :func:`distortion`) is above ``bound``, ascending; none when every face is
    degenerate."""
    if measures.degenerate.all():
        return np.empty(0, dtype=np.intp)
    measured, squared_scale = _measured_faces(measures)
    return measured[_values_of(measures, measured, squared_scale, isometric_only=True)[0] > bound]


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


def _values_of(
    measures: FaceMeasures, measured: np.ndarray, squared_scale: float, isometric_only=False
) -> np.ndarray:
    """(3, k) float: the conformal, area and isometric distortion of the ``measured`` faces
    ((k,) positions, non-degenerate); (1, k), the isometric alone, with ``isometric_only``.

    Scaling the layout by ``k`` scales both singular values by ``k``; ``k^2`` is
    ``squared_scale``. Isometric: ``(s1^2 + s2^2 + s1^-2 + s2^-2) / 4
    = (s1^2 + s2^2)(1 + 1 / (s1 s2)^2) / 4``.
    """
    rows = measured if measured.size < len(measures) else np.empty(0, dtype=np.intp)
    return _face_values(
        np.ascontiguousarray(measures.stretch_max),
        np.ascontiguousarray(measures.stretch_min),
        np.ascontiguousarray(rows, dtype=np.intp),
        float(squared_scale),
        bool(isometric_only),
    )


@njit(cache=True, nogil=True)
def _face_values(stretch_max, stretch_min, rows, squared_scale, isometric_only):
    """:func:`_values_of` over ``rows`` of the stretches (every face when it is empty), one
    face at a time."""
    k = rows.size if rows.size else stretch_max.size
    out = np.empty((1 if isometric_only else 3, k))
    quarter = 0.25 * squared_scale
    for f in range(k):
        face = rows[f] if rows.size else f
        s1, s2 = stretch_max[face], stretch_min[face]
        product = s1 * s2 * squared_scale
        isometric = (s1 * s1 + s2 * s2) * quarter * (1.0 / (product * product) + 1.0)
        if isometric_only:
            out[0, f] = isometric
        else:
            out[0, f] = max(s1 / s2, 1.0)
            out[1, f] = abs(math.log(product))
            out[2, f] = isometric
    return out


def weighted_quantile(
    values: np.ndarray, weights: np.ndarray, q: float, *, bracket: Bracket | None = None
) -> float:
    """The smallest value ``v`` with at least the fraction ``q`` of the weight on values
    ``<= v``.

    Exact, in linear time. A sample (:func:`_sample_rows`) brackets the answer (the
    sample's quantiles at ``q -+ _BRACKET``); one pass checks that the bracket holds the
    target weight and collects the values inside it, whose quantile a quickselect finds.
    When the sample misleads (it cannot when it is the whole input), a wider bracket, then
    the quickselect over every value.

    Parameters
    ----------
    values : (k,) float, finite, k >= 1
    weights : (k,) float, >= 0, positive sum
    q : float in [0, 1]
    bracket : how the sample brackets the answer; None: :func:`_brackets`' own. Any bracket
        gives the same answer (one that misses falls back to the quickselect over every
        value), a good one sooner.
    """
    values = np.asarray(values, dtype=np.float64)
    weights = np.asarray(weights, dtype=np.float64)
    if values.size == 0 or values.shape != weights.shape:
        raise TransformInputError(
            "values", f"need one weight per value and at least one value, got {values.shape}"
        )
    if len(values) <= _SORT_BELOW:
        return _sorted_quantile(values, weights, q * weights.sum())
    return _quantiles(values, weights, float(weights.sum()), (q,), bracket)[2][0]


def _sample_rows(n: int) -> np.ndarray | slice:
    """The rows of ``n`` values that bracket their quantiles: every row when there are at
    most ``_SAMPLE``, else ``_SAMPLE`` drawn with a fixed seed, ascending. Drawn, not every
    k-th: a subdivided scan's values repeat with a period of a few faces, which a stride can
    alias so that the sample's quantile lies outside the bracket (the conformal median of
    the 1.1M-face head did, and took the slow way)."""
    if n <= _SAMPLE:
        return slice(None)
    return np.sort(np.random.default_rng(0).integers(0, n, _SAMPLE))


def _brackets(
    sample: np.ndarray,
    weights: np.ndarray,
    qs: tuple[float, ...],
    bracket: Bracket | None,
    width: float = 1.0,
) -> list[tuple[float, float]]:
    """The bracket of each quantile ``q`` of ``qs`` from a weighted sample: ``bracket``'s, or
    the sample's ``q -+ width * _BRACKET`` quantiles (the whole range when the sample has no
    weight)."""
    if bracket is not None:
        return [bracket(sample, weights, q) for q in qs]
    total = weights.sum()
    if not total > 0:
        return [(-np.inf, np.inf)] * len(qs)
    half = width * _BRACKET
    return [
        (
            _sorted_quantile(sample, weights, (q - half) * total),
            _sorted_quantile(sample, weights, (q + half) * total),
        )
        for q in qs
    ]


def _sorted_quantile(values: np.ndarray, weights: np.ndarray, target: float) -> float:
    """The smallest value whose cumulative weight, in ascending order, reaches ``target``
    (the first value when ``target <= 0``, the last when it is above the total): found by a
    weighted quickselect (:func:`_select`) in linear time, without sorting."""
    return float(_select(np.ascontiguousarray(values), np.ascontiguousarray(weights), target))


@njit(cache=True, nogil=True)
def _select(values: np.ndarray, weights: np.ndarray, target: float) -> float:
    """:func:`_sorted_quantile` of (k,) ``values`` (k >= 1) and ``weights``: partition round
    a pivot (the median of three) into the values below it, equal to it and above it, and go
    on in the part that holds the target weight."""
    v, w = values.copy(), weights.copy()
    low, high = 0, v.size  # the part still searched, [low, high)
    while True:
        a, b, c = v[low], v[(low + high - 1) // 2], v[high - 1]
        pivot = max(min(a, b), min(max(a, b), c))
        below = equal = 0.0
        smaller, i, larger = low, low, high
        while i < larger:
            if v[i] < pivot:
                v[i], v[smaller] = v[smaller], v[i]
                w[i], w[smaller] = w[smaller], w[i]
                below += w[smaller]
                smaller += 1
                i += 1
            elif v[i] > pivot:
                larger -= 1
                v[i], v[larger] = v[larger], v[i]
                w[i], w[larger] = w[larger], w[i]
            else:
                equal += w[i]
                i += 1
        if smaller > low and target <= below:
            high = smaller
        elif target <= below + equal or larger == high:
            return pivot
        else:
            target -= below + equal
            low = larger
