"""The largest cap free of region directions, where the pole goes (transforms.fit.emptycap;
docs/math.md, section 9)."""

from __future__ import annotations

import math

import numpy as np

from transforms import arcs_to_point
from transforms.fit.emptycap import _clearances, cap_radius, largest_empty_cap

from .conftest import scalp, sphere_mesh


def test_largest_empty_cap_finds_the_hole():
    vertices, _ = sphere_mesh(24, 48)
    directions = vertices[vertices[:, 2] < math.cos(math.radians(50.0))]  # no point near +Z
    pole, radius = largest_empty_cap(directions)
    np.testing.assert_allclose(pole, [0.0, 0.0, 1.0], atol=1e-9)
    assert math.degrees(radius) >= 50.0


def _clear_in_numpy(units, faces, pole):
    """The free cap's radius from ``pole`` as numpy measures it: 0 where a face's spherical
    triangle holds the pole (the same side of its three great circles, on its side of the
    sphere), else the nearest vertex or edge arc (every arc measured)."""
    a, b, c = units[faces[:, 0]], units[faces[:, 1]], units[faces[:, 2]]
    sides = [np.cross(p, q) @ pole for p, q in ((a, b), (b, c), (c, a))]
    same = ((sides[0] >= 0) & (sides[1] >= 0) & (sides[2] >= 0)) | (
        (sides[0] <= 0) & (sides[1] <= 0) & (sides[2] <= 0)
    )
    nonzero = (sides[0] != 0) | (sides[1] != 0) | (sides[2] != 0)
    if (same & ((a + b + c) @ pole > 0) & nonzero).any():
        return 0.0
    free = cap_radius(units, pole)
    for start, end in ((a, b), (b, c), (c, a)):
        free = min(free, float(arcs_to_point(start, end, pole).min()))
    return free


def test_the_compiled_clearance_is_numpys():
    vertices, faces = scalp()
    used, compact = np.unique(faces, return_inverse=True)
    faces = compact.reshape(-1, 3).astype(np.int64)
    middle = (vertices.min(axis=0) + vertices.max(axis=0)) / 2
    units = vertices[used] - middle
    units /= np.linalg.norm(units, axis=1, keepdims=True)
    rng = np.random.default_rng(5)
    poles = np.vstack([-units.mean(axis=0), rng.normal(size=(30, 3))])
    poles /= np.linalg.norm(poles, axis=1, keepdims=True)
    expected = np.array([_clear_in_numpy(units, faces, pole) for pole in poles])
    # Every candidate in one pass, as the free cap measures them.
    np.testing.assert_allclose(_clearances(units, faces, poles), expected, rtol=0, atol=1e-12)
    assert 0 < (expected == 0.0).sum() < len(poles)  # poles on the region and off it
