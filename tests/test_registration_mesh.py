"""The registration's last rounds onto the baseline's mesh (transforms.onmesh; docs/math.md,
section 15, eq. 15.4): the nearest points are libigl's exact ones, and a follow-up with no
noise lands back exactly, where ICP on the samples alone stops a curvature's bias away."""

from __future__ import annotations

import igl
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fixtures.meshes import subdivided
from transforms import registration
from transforms.onmesh import MeshNearest, _closest, on_mesh

TURN = Rotation.from_rotvec(np.radians(10.0) * np.array([1.0, 2.0, 3.0]) / np.sqrt(14.0))
SHIFT = np.array([3.0, -2.0, 2.0])


def head(times: int = 1):
    return subdivided("fsaverage-head.ply", times)


def truth() -> np.ndarray:
    matrix = np.eye(4)
    matrix[:3, :3] = TURN.inv().as_matrix()
    matrix[:3, 3] = -TURN.inv().apply(SHIFT)
    return matrix


def largest_error(found: np.ndarray, points: np.ndarray) -> float:
    true = truth()
    gap = registration.apply(found, points) - registration.apply(true, points)
    return float(np.linalg.norm(gap, axis=1).max())


@pytest.mark.parametrize("noise", [0.05, 0.5])
def test_the_nearest_points_are_libigls(noise):
    """Points within a scan's noise of the surface: the walk from the nearest vertex finds
    libigl's nearest point (the same distance), cold and from the last answer's faces."""
    vertices, faces = head()
    rng = np.random.default_rng(3)
    points = vertices[rng.choice(len(vertices), 3000)] + rng.normal(scale=noise, size=(3000, 3))
    tree = igl.AABB()
    tree.init(vertices, faces)
    squared, _, _ = tree.squared_distance(vertices, faces, points)
    mesh = MeshNearest(vertices, faces)
    cold = mesh.nearest(points)
    warm = mesh.nearest(points + 0.01, cold)
    squared_warm, _, _ = tree.squared_distance(vertices, faces, points + 0.01)
    for found, exact in ((cold, squared), (warm, squared_warm)):
        wrong = np.abs(found.distance - np.sqrt(exact)) > 1e-9
        assert wrong.mean() < 0.002  # a point stuck between two folds, at the most
        assert np.allclose(np.linalg.norm(found.normals, axis=1), 1.0)
    on_face = np.einsum("pd,pd->p", cold.points - vertices[faces[cold.faces, 0]], cold.normals)
    assert np.abs(on_face).max() < 1e-9


def test_each_triangles_nearest_point_is_the_brute_forces():
    """Ericson's regions against the nearest of a fine grid of each triangle's points."""
    rng = np.random.default_rng(5)
    corners = rng.normal(size=(200, 3, 3))
    points = rng.normal(scale=2.0, size=(200, 3))
    found = []
    for point, (a, b, c) in zip(points, corners, strict=True):
        s, t = _closest(*point, *a, *b, *c)
        found.append(a + s * (b - a) + t * (c - a))
    u, v = np.meshgrid(np.linspace(0, 1, 401), np.linspace(0, 1, 401))
    inside = u + v <= 1
    u, v = u[inside], v[inside]
    for point, triangle, foot in zip(points, corners, found, strict=True):
        grid = triangle[0] + np.outer(u, triangle[1] - triangle[0])
        grid += np.outer(v, triangle[2] - triangle[0])
        best = np.linalg.norm(grid - point, axis=1).min()
        assert np.linalg.norm(foot - point) <= best + 1e-9
        assert np.linalg.norm(foot - point) >= best - 0.02


@pytest.mark.parametrize("landmarks", [False, True])
def test_a_follow_up_with_no_noise_lands_back_exactly(landmarks):
    """Turned 10 degrees, shifted, its lowest 30 % cut away, no noise: every follow-up
    vertex lands within 1e-6 mm of its place (on the samples alone, about 0.04 mm off). A
    head of 65k faces: the last rounds run on follow-ups with as many vertices as samples."""
    vertices, faces = head(2)
    moved = TURN.apply(vertices) + SHIFT
    height = vertices[faces].mean(axis=1)[:, 2]
    kept = faces[height > np.quantile(height, 0.3)]
    base = registration.Surface.of(vertices, faces)
    follow = registration.Surface.of(moved, kept)
    pairs = None
    if landmarks:
        marks = vertices[[10, 500, 1000, 1500, 2000]]  # fsaverage's own, first in the list
        pairs = (TURN.apply(marks) + SHIFT + 1.0, marks)
    assert registration.dense(follow)
    found = registration.register(follow, base, pairs)
    assert largest_error(found.matrix, moved[np.unique(kept)]) < 1e-6
    sparse = registration.register(follow, base, pairs, last="samples")
    assert largest_error(sparse.matrix, moved[np.unique(kept)]) > 1e-3


def test_the_last_rounds_fit_the_scale_too():
    """In similarity mode the last rounds take the scale to the truth as well."""
    vertices, faces = head()
    moved = 1.5 * (TURN.apply(vertices) + SHIFT)
    base = registration.Surface.of(vertices, faces)
    follow = registration.Surface.of(moved, faces)
    start = np.eye(4)
    start[:3, :3] = TURN.inv().as_matrix() / 1.49
    start[:3, 3] = -TURN.inv().apply(SHIFT) + 0.2
    found = on_mesh(follow, base.mesh, start, scale=True, bounds=(0.1, 10.0))
    true = np.eye(4)
    true[:3, :3] = TURN.inv().as_matrix() / 1.5
    true[:3, 3] = -TURN.inv().apply(SHIFT)
    gap = registration.apply(found, moved) - registration.apply(true, moved)
    assert np.linalg.norm(gap, axis=1).max() < 1e-6


def test_a_coarse_follow_up_is_refined_on_its_samples():
    """Fewer vertices than samples: no last rounds on the mesh (they did worse there)."""
    vertices, faces = head(0)
    assert not registration.dense(registration.Surface.of(vertices, faces))
