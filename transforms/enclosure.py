"""Whether a region closes round its centre: seen from the centre it covers every direction,
so no cap of directions is free of it (docs/math.md, section 6, "closed round the centre").

Two cases are known without looking for a free cap:

* **no outline edge**: every edge is smooth interior, so the projection from the centre onto
  the sphere is a local homeomorphism of a surface without boundary: a covering, onto;
* **a closed surface round the centre**: every edge has an even number of faces (the faces
  are a cycle mod 2, folds and overhangs allowed), and a generic ray from the centre crosses
  them an odd number of times. The parity of the crossings is then the same for every
  generic ray (it changes only where a ray crosses the projection of an edge, and each edge
  has an even number of faces), so every generic ray meets a face, and by closedness every
  ray does.

The ray's crossings are counted exactly: faces whose corners cannot surround it are set aside
by the sides of two planes through it (a compiled pass), and the rest decided by exact
orientation signs (:func:`.faces.edge_signs`). A ray that meets an edge
or a vertex, or lies in a face's plane, is not generic: another is drawn (a few tries; then
nothing is claimed).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .arrays import INDEX
from .faces import FaceMeasures, edge_signs

#: Rays drawn before giving up (each is generic with probability 1).
_TRIES = 4
#: Far above the rounding of a plane distance of coordinates below 1 (as the faces' own
#: prefilter, :data:`.faces._SIDE_SLACK`): a face within it of a plane stays a candidate.
_SLACK = 1e-13


def encloses_centre(measures: FaceMeasures, outline: int, odd_edges: int) -> bool:
    """Whether the region of ``measures`` covers every direction seen from its centre
    (the origin of its rows).

    Parameters
    ----------
    measures : FaceMeasures, with exact orientations
    outline : int, how many outline edges the region has (:class:`.topology.RegionEdges`)
    odd_edges : int, how many of its edges have an odd number of faces

    Returns
    -------
    bool: True when it is known to (the region has no outline, or is a cycle mod 2 that a
    generic ray crosses an odd number of times); False otherwise, which claims nothing
    """
    if outline == 0:
        return True
    if odd_edges:
        return False
    rng = np.random.default_rng(0)
    for _ in range(_TRIES):
        direction = rng.normal(size=3)
        crossings = ray_crossings(measures, direction / np.linalg.norm(direction))
        if crossings is not None:
            return crossings % 2 == 1
    return False


def ray_crossings(measures: FaceMeasures, direction: np.ndarray) -> int | None:
    """How many faces the ray from the centre along ``direction`` ((3,) float, unit) meets,
    or None when it meets one at an edge, a vertex or in its plane (not generic)."""
    u = np.cross(direction, [1.0, 0.0, 0.0])
    if np.linalg.norm(u) < 0.5:
        u = np.cross(direction, [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    w = np.cross(direction, u)
    candidates = np.flatnonzero(
        _candidates(
            np.ascontiguousarray(measures.vertices),
            np.ascontiguousarray(measures.faces, dtype=INDEX),
            np.stack([u, w, direction]),
        )
    )
    if candidates.size == 0:
        return 0
    corners = measures.vertices[:, measures.faces[candidates].T]  # (axis, corner, face)
    signs = edge_signs(corners, direction)
    d = measures.orientation[candidates]
    surrounds = (signs > 0).all(axis=0) | (signs < 0).all(axis=0)
    touches = ((signs >= 0).all(axis=0) | (signs <= 0).all(axis=0)) & ~surrounds
    # On an edge or a vertex of a face it may meet, or in the plane of one it surrounds.
    if touches.any() or (surrounds & (d == 0)).any():
        return None
    # Surrounded: met ahead of the centre when det[c0, c1, c2] has the signs' sign.
    return int((surrounds & (np.sign(signs[0]) == d)).sum())


@njit(cache=True, nogil=True)
def _candidates(rows: np.ndarray, faces: np.ndarray, planes: np.ndarray) -> np.ndarray:
    """(m,) bool: the faces the ray along ``planes[2]`` may meet: corners on both sides (within
    ``_SLACK``) of the planes through it with normals ``planes[0]`` and ``planes[1]``, and one
    not behind the centre along it. ``rows`` (3, n), ``faces`` (m, 3)."""
    n, m = rows.shape[1], faces.shape[0]
    codes = np.zeros(n, dtype=np.uint8)
    for v in range(n):
        x, y, z = rows[0, v], rows[1, v], rows[2, v]
        code = 0
        for p in range(2):
            distance = planes[p, 0] * x + planes[p, 1] * y + planes[p, 2] * z
            if distance >= -_SLACK:
                code |= 1 << (2 * p)
            if distance <= _SLACK:
                code |= 2 << (2 * p)
        if planes[2, 0] * x + planes[2, 1] * y + planes[2, 2] * z >= -_SLACK:
            code |= 16
        codes[v] = code
    out = np.empty(m, dtype=np.bool_)
    for f in range(m):
        code = codes[faces[f, 0]] | codes[faces[f, 1]] | codes[faces[f, 2]]
        out[f] = code == 31
    return out
