"""Triangles and segments painted into a label image (transforms.raster)."""

import numpy as np

from transforms.raster import paint_segments, paint_triangles


def test_a_triangle_paints_the_pixel_centres_it_holds():
    image = np.zeros((10, 10), dtype=np.uint8)
    # The lower-left half of the square [0, 10]^2 (column <= row), label 3.
    paint_triangles(image, np.array([[[0.0, 0.0], [0.0, 10.0], [10.0, 10.0]]]), np.array([3]))
    rows, columns = np.indices(image.shape)
    assert np.array_equal(image == 3, columns + 0.5 <= rows + 0.5)


def test_larger_labels_win_and_tiny_triangles_paint_their_centroid():
    image = np.zeros((4, 4), dtype=np.uint8)
    square = np.array([[[0.0, 0.0], [4.0, 0.0], [4.0, 4.0]], [[0.0, 0.0], [4.0, 4.0], [0.0, 4.0]]])
    paint_triangles(image, square, np.array([1, 1], dtype=np.uint8))
    tiny = np.array([[[2.2, 1.2], [2.3, 1.2], [2.2, 1.3]]])  # holds no pixel centre
    paint_triangles(image, tiny, np.array([5], dtype=np.uint8))
    assert image[1, 2] == 5 and (image[image != 5] == 1).all()
    paint_triangles(image, square, np.array([2, 2], dtype=np.uint8))
    assert image[1, 2] == 5 and (image[image != 5] == 2).all()


def test_the_budget_bounds_the_work_to_centroids():
    image = np.zeros((100, 100), dtype=np.uint8)
    big = np.array([[[0.0, 0.0], [100.0, 0.0], [0.0, 100.0]]])
    paint_triangles(image, big, np.array([1], dtype=np.uint8), budget=10)
    assert image.sum() == 1  # only the centroid's pixel


def test_segments_are_drawn_end_to_end():
    image = np.zeros((5, 20), dtype=np.uint8)
    paint_segments(image, np.array([[[0.5, 2.5], [19.5, 2.5]]]), 7)
    assert (image[2] == 7).all() and image.sum() == 7 * 20
