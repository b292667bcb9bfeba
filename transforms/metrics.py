"""Distortion of the ``(phi, theta)`` layout (MATH.md, "Distortion").

For each triangle the affine map from the 3D triangle (in its own plane) to its 2D triangle
has singular values ``s1 >= s2``; the layout is first scaled by one factor so that its total
area equals the region's 3D area. Per triangle:

* conformal distortion ``s1 / s2`` (1: angles kept);
* area distortion ``|log(s1 s2)|`` (0: areas kept);
* isometric distortion ``(s1^2 + s2^2 + s1^-2 + s2^-2) / 4`` (1: an isometry).

Summaries are weighted by 3D area: mean, 95th percentile, maximum. Degenerate triangles (zero
area in 3D or in the layout) have no affine map and are left out; the validation lists them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .arrays import blocks
from .errors import TransformInputError
from .faces import FaceMeasures

#: Below this many values the weighted quantile simply sorts them.
_SORT_BELOW = 65536
#: Size of the sample that brackets the quantile, and the bracket's half-width in weight.
_SAMPLE = 16384
_BRACKET = 0.01
_BINS = 1024


@dataclass(frozen=True)
class Summary:
    """Area-weighted statistics of one per-triangle measure."""

    mean: float
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

    Scaling the layout by ``k`` scales both singular values by ``k``; ``k^2`` is the 3D area
    over the layout area.

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
    double_area = measures.double_area
    stretch_max, stretch_min = measures.stretch_max, measures.stretch_min
    if measured.size < len(measures):
        double_area, stretch_max, stretch_min = (
            v[measured] for v in (double_area, stretch_max, stretch_min)
        )
    # MATH.md: one factor gives the whole layout the region's 3D area (every face counts).
    squared_scale = measures.double_area.sum() / np.abs(measures.layout_double_area).sum()
    conformal = np.empty(measured.size)
    area = np.empty(measured.size)
    isometric = np.empty(measured.size)
    for block in blocks(measured.size):
        s1, s2 = stretch_max[block], stretch_min[block]
        np.maximum(s1 / s2, 1.0, out=conformal[block])
        product = s1 * s2
        product *= squared_scale
        np.abs(np.log(product), out=area[block])
        # (s1^2 + s2^2 + s1^-2 + s2^-2) / 4 = (s1^2 + s2^2)(1 + 1 / (s1 s2)^2) / 4
        squares = s1 * s1
        squares += s2 * s2
        squares *= squared_scale
        np.multiply(0.25 * squares, 1.0 + 1.0 / (product * product), out=isometric[block])
    length_scale = measures.scale  # areas back in the mesh's units
    return FaceDistortion(
        faces=measured,
        conformal=conformal,
        area=area,
        isometric=isometric,
        weights=(0.5 / (length_scale * length_scale)) * double_area,
        layout_scale=float(np.sqrt(squared_scale)) / length_scale,
    )


def distortion(measures: FaceMeasures) -> Distortion:
    """Area-weighted mean, 95th percentile and maximum of the three measures.

    Parameters
    ----------
    measures : FaceMeasures, from :func:`.faces.measure_faces`

    Returns
    -------
    Distortion
    """
    faces = face_distortion(measures)
    total = faces.weights.sum()

    def summary(values: np.ndarray) -> Summary:
        return Summary(
            mean=float(np.dot(values, faces.weights) / total),
            p95=weighted_quantile(values, faces.weights, 0.95),
            max=float(values.max()),
        )

    return Distortion(
        conformal=summary(faces.conformal),
        area=summary(faces.area),
        isometric=summary(faces.isometric),
        measured_faces=len(faces.faces),
        layout_scale=faces.layout_scale,
    )


def weighted_quantile(values: np.ndarray, weights: np.ndarray, q: float) -> float:
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
    """
    values = np.asarray(values, dtype=np.float64)
    weights = np.asarray(weights, dtype=np.float64)
    if values.size == 0 or values.shape != weights.shape:
        raise TransformInputError(
            "values", f"need one weight per value and at least one value, got {values.shape}"
        )
    target = q * weights.sum()
    if len(values) > _SORT_BELOW:
        stride = max(len(values) // _SAMPLE, 1)
        sample, sample_weights = values[::stride], weights[::stride]
        if not sample_weights.sum() > 0:
            return _histogram_quantile(values, weights, target)
        order = np.argsort(sample)
        share = np.cumsum(sample_weights[order]) / sample_weights.sum()
        picks = np.searchsorted(share, [q - _BRACKET, q + _BRACKET]).clip(0, len(order) - 1)
        low, high = sample[order[picks]]
        below, inside = 0.0, []
        for block in blocks(len(values)):
            v = values[block]
            below += float(weights[block][v < low].sum())
            keep = (v >= low) & (v <= high)
            inside.append((v[keep], weights[block][keep]))
        inside_values = np.concatenate([v for v, _ in inside])
        inside_weights = np.concatenate([w for _, w in inside])
        if below < target <= below + inside_weights.sum():
            return _sorted_quantile(inside_values, inside_weights, target - below)
        return _histogram_quantile(values, weights, target)
    return _sorted_quantile(values, weights, target)


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
