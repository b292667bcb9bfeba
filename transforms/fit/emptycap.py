"""The largest spherical cap that holds none of a set of directions: where the warp's pole
goes (docs/math.md, section 9: put ``+Y`` in the middle of the part of the sphere the region
does not cover).

Every facet of the convex hull of unit directions cuts off a cap that holds none of them
(all lie on the facet's inner side), and the largest empty cap is one of these: its boundary
circle passes through at least three directions. So the pole is the outward normal of the
facet whose plane lies nearest the origin (the smaller that distance, the larger the cap it
cuts off), and the cap's angular radius is ``acos`` of that distance.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from ..arrays import unit_rows


def largest_empty_cap(directions: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre and angular radius of the largest cap holding none of ``directions``.

    Parameters
    ----------
    directions : (k, 3) float, non-zero (normalised here)

    Returns
    -------
    pole : (3,) float, unit
    radius : float, radians in ``[0, pi]``
    """
    units = unit_rows(np.asarray(directions, dtype=np.float64))[0]
    try:
        hull = ConvexHull(units)
    except (QhullError, ValueError):
        # Too few or coplanar directions: the cap opposite their mean.
        mean = units.sum(axis=0)
        norm = float(np.linalg.norm(mean))
        pole = -mean / norm if norm > 0 else np.array([0.0, 1.0, 0.0])
        return pole, cap_radius(units, pole)
    # Qhull's facets: normal . x + offset <= 0 inside, normals outward and unit.
    # The plane nearest the origin cuts off the largest cap (radius acos of its distance).
    nearest = int(np.argmin(-hull.equations[:, 3]))
    pole = hull.equations[nearest, :3] / np.linalg.norm(hull.equations[nearest, :3])
    return pole, cap_radius(units, pole)


def cap_radius(directions: np.ndarray, pole: np.ndarray) -> float:
    """Angular radius (radians) of the largest cap around unit ``pole`` that holds none of
    the unit ``directions`` (k, 3): the angle to the nearest one."""
    cosine = float(np.clip((directions @ pole).max(), -1.0, 1.0))
    return math.acos(cosine)
