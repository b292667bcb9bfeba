"""A surface's own frame: its moments against a dense sampling, and moving with the surface."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from transforms.ownframe import OwnFrame

from .conftest import load_sample, scalp


def dense_points(vertices: np.ndarray, faces: np.ndarray, n: int = 20) -> tuple:
    """Points of a barycentric grid of ``n`` steps in every triangle, each with its area
    weight: a quadrature independent of the closed forms."""
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    keep = i + j < n
    u = (i[keep] + 1 / 3) / n  # centroids of the grid's upright small triangles
    w = (j[keep] + 1 / 3) / n
    corners = vertices[faces]
    points = (corners[:, None, 0] * (1 - u - w)[:, None] + corners[:, None, 1] * u[:, None]
              + corners[:, None, 2] * w[:, None])  # fmt: skip
    areas = np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0],
                                    corners[:, 2] - corners[:, 0]), axis=1) / 2  # fmt: skip
    weights = np.repeat(areas[:, None], len(u), axis=1)
    return points.reshape(-1, 3), weights.reshape(-1)


def test_origin_axes_and_scale_match_a_dense_quadrature_of_the_surface():
    vertices, faces = scalp()
    frame = OwnFrame.of_triangles(vertices, faces)
    points, weights = dense_points(vertices, faces)
    centroid = weights @ points / weights.sum()
    offsets = points - centroid
    covariance = (offsets * weights[:, None]).T @ offsets / weights.sum()
    size = np.sqrt(np.trace(covariance))
    assert np.allclose(frame.origin, centroid, atol=1e-3 * size)
    assert frame.scale == pytest.approx(size, rel=1e-3)
    _, vectors = np.linalg.eigh(covariance)
    for row, column in zip(range(3), (2, 1, 0), strict=True):
        assert abs(frame.axes[row] @ vectors[:, column]) == pytest.approx(1, abs=1e-4)
    assert np.allclose(frame.axes @ frame.axes.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(frame.axes) == pytest.approx(1)
    # The first two axes point where the surface's third moment along them is positive.
    for row in range(2):
        assert weights @ (offsets @ frame.axes[row]) ** 3 > 0


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_frame_moves_turns_and_scales_with_the_surface(seed):
    vertices, faces = load_sample("nefertiti-lowres.obj")
    rng = np.random.default_rng(seed)
    turn = Rotation.random(random_state=rng).as_matrix()
    shift, factor = rng.normal(size=3) * 100, 10 ** rng.uniform(-3, 3)
    moved = (vertices @ turn.T) * factor + shift
    before = OwnFrame.of_triangles(vertices, faces)
    after = OwnFrame.of_triangles(moved, faces)
    assert np.allclose(after.origin, before.origin @ turn.T * factor + shift,
                       rtol=0, atol=1e-9 * after.scale)  # fmt: skip
    assert after.scale == pytest.approx(before.scale * factor, rel=1e-12)
    assert np.allclose(after.axes, before.axes @ turn.T, atol=1e-9)
    # Hence every point lands on the same own coordinates in both poses.
    assert np.allclose(after.to_own(moved), before.to_own(vertices), rtol=0, atol=1e-9)


def test_points_and_directions_go_to_the_frame_and_back():
    vertices, faces = scalp()
    frame = OwnFrame.of_triangles(vertices, faces)
    own = frame.to_own(vertices)
    assert np.allclose(frame.from_own(own), vertices, rtol=0, atol=1e-12 * frame.scale * 100)
    d = np.array([[0.0, 0.0, 2.0], [1.0, -1.0, 0.5]])
    assert np.allclose(frame.directions_from_own(frame.directions_to_own(d)), d)
    assert np.allclose(np.linalg.norm(frame.directions_to_own(d), axis=1),
                       np.linalg.norm(d, axis=1))  # fmt: skip


def test_the_frame_is_immutable():
    vertices, faces = scalp()
    frame = OwnFrame.of_triangles(vertices, faces)
    with pytest.raises(ValueError):
        frame.axes[0, 0] = 2.0
    with pytest.raises(AttributeError):
        frame.scale = 2.0
