"""A surface's own frame: its moments against a dense sampling, and moving with the surface."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from transforms.ownframe import OwnFrame

from .conftest import load_sample, scalp
from .test_api import flatten, obj_of


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


@pytest.mark.parametrize("factor", [1e90, 1e-90, 2.0**-300, 1e99])
def test_a_surface_far_from_unit_size_has_the_same_frame_scaled(factor):
    """Moments hold fourth powers of the coordinates: 1e90 would overflow them, 1e-90 lose
    them below the normal floats. The frame is the unit scan's, scaled."""
    vertices, faces = scalp()
    with np.errstate(all="raise"):
        far = OwnFrame.of_triangles(vertices * factor, faces)
    near = OwnFrame.of_triangles(vertices, faces)
    assert np.allclose(far.origin / factor, near.origin, rtol=1e-12, atol=0)
    assert far.scale / factor == pytest.approx(near.scale, rel=1e-12)
    assert np.allclose(far.axes, near.axes, atol=1e-12)


@pytest.mark.anyio
async def test_a_scan_in_units_of_1e90_is_flattened_and_fitted_as_in_millimetres(client):
    """Found on a scan scaled by 1e90 (its own frame overflowed: a 500)."""
    vertices, faces = load_sample("fsaverage-head.ply")
    params = {"region": {"cone": {"axis": [0, 0, 1], "half_angle_deg": 70}}}
    answers = []
    for factor in (1.0, 1e90):
        response = await flatten(client, "m.obj", params, data=obj_of(vertices * factor, faces),
                                 endpoint="/v1/fit")  # fmt: skip
        assert response.status_code == 200, response.text
        answers.append(response.json())
    assert answers[1]["params"]["sigma"] == pytest.approx(answers[0]["params"]["sigma"], rel=1e-9)
    assert answers[1]["metrics"]["isometric"]["p50"] == pytest.approx(
        answers[0]["metrics"]["isometric"]["p50"], rel=1e-9
    )
