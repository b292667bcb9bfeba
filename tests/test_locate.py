"""From the map back to the surface in the core (transforms.locate; docs/math.md, section
10). The HTTP side, /v1/locate, is in test_api.py."""

from __future__ import annotations

import numpy as np

from transforms import Chart, Frame, PoleCap, locate, world_to_angles

from .conftest import scalp


def test_locate_inverts_flatten_in_the_core():
    vertices, faces = scalp()
    frame = Frame.from_pole_up([0, 0, -1], [0, 1, 0], (vertices.min(0) + vertices.max(0)) / 2)
    chart = Chart.distorted(PoleCap.from_sigma(0.3))
    rng = np.random.default_rng(7)
    chosen = rng.integers(0, len(faces), 5000)
    weights = rng.dirichlet([1.0, 1.0, 1.0], len(chosen))
    points = np.einsum("kc,kcj->kj", weights, vertices[faces[chosen]])
    theta, phi, _ = world_to_angles(points, frame, chart)
    hits = locate(frame.to_local(vertices), faces, chart.inverse(theta, phi, 1.0))
    np.testing.assert_array_equal(hits.faces, chosen)
    np.testing.assert_allclose(hits.barycentric, weights, atol=1e-6)
    np.testing.assert_allclose(frame.to_world(hits.points), points, atol=1e-6)
    # A direction into the hole (the chin, straight down) meets no scalp triangle.
    miss = locate(frame.to_local(vertices), faces, [[0.0, 1.0, 0.0]])
    assert miss.faces[0] == -1 and np.isnan(miss.points).all()


def test_locate_takes_the_nearest_of_two_layers():
    # Two parallel squares in front of the centre: the ray meets the nearer one.
    square = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], dtype=float)
    lift = np.array([0.0, 0.0, 1.0])
    vertices = np.concatenate([square + 2 * lift, square + lift])
    faces = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    hits = locate(vertices, faces, [[0.1, 0.2, 1.0]])
    assert hits.faces[0] in (2, 3)
    np.testing.assert_allclose(hits.points[0], [0.1, 0.2, 1.0])
