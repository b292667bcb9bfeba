"""Triangles on a pixel grid (transforms.pixels; docs/math.md, section 16): every pixel centre
to exactly one triangle of a tiling, the later of overlapping ones, and values carried both
ways exactly where they are linear."""

from __future__ import annotations

import numpy as np
import pytest

from transforms import pixels


def tiling(nx: int, ny: int, width: float, height: float, jitter: float, seed: int = 1):
    """(m, 3, 2): a jittered grid of triangles over ``[-3, width + 3] x [-3, height + 3]``."""
    rng = np.random.default_rng(seed)
    xs, ys = np.linspace(-3, width + 3, nx), np.linspace(-3, height + 3, ny)
    points = np.stack(np.meshgrid(xs, ys), -1).reshape(-1, 2)
    column, row = np.arange(len(points)) % nx, np.arange(len(points)) // nx
    inner = (column > 0) & (column < nx - 1) & (row > 0) & (row < ny - 1)
    step = np.array([xs[1] - xs[0], ys[1] - ys[0]])
    points[inner] += rng.uniform(-jitter, jitter, (int(inner.sum()), 2)) * step
    i, j = np.meshgrid(np.arange(nx - 1), np.arange(ny - 1))
    a = (j * nx + i).ravel()
    triangles = np.concatenate(
        [np.stack([a, a + 1, a + nx + 1], 1), np.stack([a, a + nx + 1, a + nx], 1)]
    )
    return points[triangles]


def brute_force(corners: np.ndarray, height: int, width: int) -> np.ndarray:
    """(m, h * w) bool: whether each centre lies in each triangle (edges included)."""
    rows, columns = np.mgrid[0:height, 0:width]
    centres = np.column_stack([columns.ravel() + 0.5, rows.ravel() + 0.5])
    inside = []
    for triangle in corners:
        weights = pixels.weights_at(np.repeat(triangle[None], len(centres), 0), centres)
        inside.append((weights >= -1e-12).all(axis=1))
    return np.array(inside)


@pytest.mark.parametrize("jitter", [0.0, 0.3])
def test_a_tiling_gives_every_centre_to_one_triangle_that_holds_it(jitter):
    # jitter 0: corners and edges run through pixel centres (every tie is met).
    corners = tiling(11, 9, 40, 32, jitter)
    if jitter == 0:
        corners = np.round(corners) + 0.5
    ids = pixels.face_ids(corners, 32, 40)
    assert (ids >= 0).all()
    inside = brute_force(corners, 32, 40)
    assert inside[ids.ravel(), np.arange(ids.size)].all()
    runs = pixels.Runs.of(corners, 32, 40)
    assert runs.centres(len(corners)).sum() == ids.size  # none counted twice


def test_where_triangles_overlap_the_later_one_holds_the_centre():
    big = np.array([[[0, 0], [20, 0], [0, 20]]], dtype=float)
    small = np.array([[[2, 2], [8, 2], [2, 8]]], dtype=float)
    ids = pixels.face_ids(np.concatenate([big, small]), 20, 20)
    assert ids[3, 3] == 1 and ids[12, 3] == 0 and ids[19, 19] == -1
    ids = pixels.face_ids(np.concatenate([small, big]), 20, 20)
    assert ids[3, 3] == 1


def test_the_answer_does_not_depend_on_chunks_or_threads():
    corners = tiling(40, 30, 200, 150, 0.3)
    whole = pixels.face_ids(corners, 150, 200)
    np.testing.assert_array_equal(
        pixels.face_ids(corners, 150, 200, threads=2, chunk_pairs=7), whole
    )


def test_means_of_a_linear_image_are_its_value_at_the_centroid():
    corners = tiling(30, 20, 300, 200, 0.3)
    rows, columns = np.mgrid[0:200, 0:300]
    image = 0.002 * (columns + 0.5) + 0.003 * (rows + 0.5)
    means, coverage = pixels.face_means(corners, image)
    centroid = corners.mean(axis=1)
    on = (centroid > 12).all(axis=1) & (centroid[:, 0] < 288) & (centroid[:, 1] < 188)
    expected = 0.002 * centroid[:, 0] + 0.003 * centroid[:, 1]
    # Pixel centres sample a triangle's area: within about a pixel's worth of the slope.
    np.testing.assert_allclose(means[on], expected[on], atol=0.006)
    np.testing.assert_allclose(coverage[on], 1.0)


def test_coverage_is_the_share_on_the_image_and_the_alpha():
    half_off = np.array([[[-10, 0], [10, 0], [-10, 20]], [[40, 40], [50, 40], [40, 50]]], float)
    image = np.ones((30, 30))
    means, coverage = pixels.face_means(half_off, image)
    assert coverage[0] == pytest.approx(0.25) and means[0] == pytest.approx(1.0)  # 50 of 200
    assert coverage[1] == 0 and np.isnan(means[1])
    alpha = np.zeros((30, 30))
    alpha[:, :5] = 1.0
    means, coverage = pixels.face_means(half_off[:1], image * 0.25, alpha)
    assert means[0] == pytest.approx(0.25) and 0.0 < coverage[0] < 0.5


def test_a_tiny_triangle_takes_its_samples_between_the_pixel_centres():
    tiny = np.array([[[10.2, 10.2], [10.6, 10.3], [10.3, 10.7]]])
    _, columns = np.mgrid[0:20, 0:20]
    image = (columns + 0.5) * 1.0
    means, coverage = pixels.face_means(tiny, image)
    assert means[0] == pytest.approx(tiny[0, :, 0].mean(), abs=1e-9) and coverage[0] == 1.0


def test_values_at_the_corners_come_back_linear_at_every_centre():
    corners = tiling(25, 18, 256, 192, 0.3)
    values = 3.0 + 0.01 * corners[:, :, 0] - 0.02 * corners[:, :, 1]  # linear in x and y
    image, ids = pixels.vertex_image(corners, values, 192, 256)
    rows, columns = np.mgrid[0:192, 0:256]
    np.testing.assert_allclose(image, 3.0 + 0.01 * (columns + 0.5) - 0.02 * (rows + 0.5), atol=1e-9)
    weights = pixels.barycentric(corners, ids)
    np.testing.assert_allclose(weights.sum(axis=2), 1.0, atol=1e-5)
    back = np.einsum("hwk,hwkd->hwd", weights, corners[ids])
    np.testing.assert_allclose(back[..., 0], columns + 0.5, atol=1e-3)
    np.testing.assert_allclose(back[..., 1], rows + 0.5, atol=1e-3)


def test_bilinear_reads_pixel_centres_exactly_and_blends_between():
    image = np.arange(12, dtype=float).reshape(3, 4)
    values, on = pixels.bilinear(image, np.array([[0.5, 0.5], [1.0, 0.5], [3.5, 2.5], [9, 9]]))
    np.testing.assert_allclose(values[:3], [0.0, 0.5, 11.0])
    assert on.tolist() == [True, True, True, False]


def test_the_share_on_the_image_is_the_clipped_area():
    shapely = pytest.importorskip("shapely")
    rng = np.random.default_rng(3)
    corners = rng.uniform(-30, 60, (300, 3, 2))
    image = shapely.box(0, 0, 40, 30)
    triangles = shapely.polygons(corners)
    expected = shapely.area(shapely.intersection(triangles, image)) / shapely.area(triangles)
    np.testing.assert_allclose(pixels.on_image(corners, 30, 40), expected, atol=1e-9)
