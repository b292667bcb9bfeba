"""The largest cap free of region directions, where the pole goes (transforms.fit.emptycap;
docs/math.md, section 9)."""

from __future__ import annotations

import math

import numpy as np

from transforms.fit.emptycap import largest_empty_cap

from .conftest import sphere_mesh


def test_largest_empty_cap_finds_the_hole():
    vertices, _ = sphere_mesh(24, 48)
    directions = vertices[vertices[:, 2] < math.cos(math.radians(50.0))]  # no point near +Z
    pole, radius = largest_empty_cap(directions)
    np.testing.assert_allclose(pole, [0.0, 0.0, 1.0], atol=1e-9)
    assert math.degrees(radius) >= 50.0
