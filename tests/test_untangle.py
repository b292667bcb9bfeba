"""Untangling a layout (transforms.untangle; docs/math.md, section 11): flipped triangles
repaired by moving as few vertices as needed, every other vertex kept to the bit, and the
orientations judged exactly."""

from __future__ import annotations

import math

import numpy as np
import pytest

from transforms import LAYOUT_ORIENTATION, fit_region, untangle
from transforms.untangle import orientation_signs

from .conftest import grid_mesh, load_sample, sphere_mesh


def dragged_grid():
    """A 10 x 10 grid in the plane, counter-clockwise, one inner vertex dragged over its
    neighbours (two triangles flip)."""
    vertices, faces = grid_mesh(np.arange(10.0), np.arange(10.0), 0.0)
    x, y = vertices[:, 0].copy(), vertices[:, 1].copy()
    x[44] += 1.7
    y[44] += 0.6
    return vertices, faces, x, y


@pytest.mark.parametrize("mirrored", [False, True])
def test_a_dragged_vertex_is_put_back_without_touching_the_rest(mirrored):
    vertices, faces, x, y = dragged_grid()
    orientation = 1
    if mirrored:  # the map's orientation is negative: the same fold, seen in a mirror
        x, orientation = -x, -1
    assert (orientation_signs(x, y, faces) != orientation).sum() == 2
    u = untangle(x, y, faces, vertices, orientation)
    assert len(u.flipped_before) == 2 and len(u.flipped_after) == 0
    assert (orientation_signs(u.x, u.y, faces) == orientation).all()
    still = np.setdiff1d(np.arange(len(x)), u.moved)
    assert np.array_equal(u.x[still], x[still]) and np.array_equal(u.y[still], y[still])
    assert 44 in u.moved and len(u.moved) <= 30  # the fold and a ring or two around it
    assert u.largest_shift == pytest.approx(np.hypot(u.x - x, u.y - y).max(), rel=1e-12)


def test_a_fold_free_layout_is_returned_as_it_is():
    vertices, faces = grid_mesh(np.arange(5.0), np.arange(5.0), 0.0)
    u = untangle(vertices[:, 0], vertices[:, 1], faces, vertices, 1)
    assert len(u.moved) == 0 and len(u.flipped_before) == 0 and u.largest_shift == 0.0


def test_the_fitted_map_of_a_bust_with_overhangs_becomes_fold_free():
    """Nefertiti's top: its sculpted crown faces away from every centre, so the fitted map
    folds there; untangled, every triangle has the map's orientation."""
    vertices, faces = load_sample("nefertiti-lowres.obj")
    centre = (vertices.min(axis=0) + vertices.max(axis=0)) / 2
    directions = vertices[faces].mean(axis=1) - centre
    top = faces[directions[:, 2] / np.linalg.norm(directions, axis=1) > math.cos(1.0)]
    flat = fit_region(vertices, top).region
    orientation = LAYOUT_ORIENTATION * flat.validation.winding
    u = untangle(flat.x, flat.y, flat.faces, vertices[flat.vertex_ids], orientation)
    assert len(u.flipped_before) > 100
    assert len(u.flipped_after) == 0
    assert (orientation_signs(u.x, u.y, flat.faces) == orientation).all()
    assert len(u.moved) < len(flat.x) / 2


def test_a_mostly_flipped_or_closed_region_is_not_untangled_and_says_why():
    vertices, faces, x, y = dragged_grid()
    u = untangle(-x, y, faces, vertices, 1)  # a mirror: every triangle flipped
    assert len(u.moved) == 0 and len(u.flipped_after) == len(u.flipped_before) > 100
    assert "more than 10%" in u.note
    from transforms.untangle import _not_tried

    _, sphere = sphere_mesh(12, 24)  # closed: whatever its layout, a map cannot be fold-free
    assert "closed" in _not_tried(sphere, 1)
    assert _not_tried(faces, 1) is None
