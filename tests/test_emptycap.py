"""The largest cap free of region directions, where the pole goes (transforms.fit.emptycap;
docs/math.md, section 9)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from transforms import arcs_to_point
from transforms.fit.emptycap import _clear, _covers, _Sides, cap_radius, largest_empty_cap

from .conftest import scalp, sphere_mesh


def test_largest_empty_cap_finds_the_hole():
    vertices, _ = sphere_mesh(24, 48)
    directions = vertices[vertices[:, 2] < math.cos(math.radians(50.0))]  # no point near +Z
    pole, radius = largest_empty_cap(directions)
    np.testing.assert_allclose(pole, [0.0, 0.0, 1.0], atol=1e-9)
    assert math.degrees(radius) >= 50.0


def _clear_in_numpy(units, faces, pole):
    """The free cap's radius from ``pole`` as numpy measures it: 0 where a face's spherical
    triangle holds the pole, else the nearest vertex or edge arc."""
    a, b, c = units[faces[:, 0]], units[faces[:, 1]], units[faces[:, 2]]
    if _covers(_Sides.of(a, b, c), pole).any():
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
    sides = _Sides.of(units[faces[:, 0]], units[faces[:, 1]], units[faces[:, 2]])
    rng = np.random.default_rng(5)
    poles = np.vstack([-units.mean(axis=0), rng.normal(size=(30, 3))])
    covered = 0
    for pole in poles / np.linalg.norm(poles, axis=1, keepdims=True):
        expected = _clear_in_numpy(units, faces, pole)
        covered += expected == 0.0
        assert _clear(units, faces, sides, pole) == pytest.approx(expected, abs=1e-12)
    assert 0 < covered < len(poles)  # poles on the region and off it
