"""The map's triangles and the surface's (transforms.mapping; docs/math.md, section 12): which
triangle holds a map point, with which weights, and the cell grid (transforms.cellgrid) that
finds it. The small meshes built here serve tests/test_zones.py too."""

from __future__ import annotations

import numpy as np
import pytest

from transforms import TransformInputError
from transforms.cellgrid import MAX_CELLS_PER_BOX, CellGrid, CellIndex
from transforms.mapping import MapTriangles

# -- small meshes ---------------------------------------------------------------------------


def height(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The curved surface ``z = f(x, y)`` the unit square is lifted to."""
    return 0.35 * np.sin(2.5 * x + 0.3) * np.cos(2.0 * y) + 0.25 * (x - 0.4) ** 2 + 0.15 * x * y


def grid_faces(n: int) -> np.ndarray:
    """The faces of an ``n`` by ``n`` grid of vertices ``j * (n + 1) + i`` at column ``i``
    and row ``j``, two counter-clockwise triangles a cell, the diagonals alternating (a
    union jack: vertices of 4 and 8 triangles, the diagonal ``x = y`` along edges)."""
    faces = []
    for j in range(n):
        for i in range(n):
            v00, v10 = j * (n + 1) + i, j * (n + 1) + i + 1
            v01, v11 = v00 + n + 1, v10 + n + 1
            if (i + j) % 2 == 0:
                faces += [[v00, v10, v11], [v00, v11, v01]]
            else:
                faces += [[v00, v10, v01], [v10, v11, v01]]
    return np.array(faces, dtype=np.int64)


def exact_mesh(n: int = 6) -> MapTriangles:
    """The grid with its vertices at the integers ``0..n`` of the map (every grid line and
    lattice point exact), lifted from the unit square by :func:`height`."""
    i, j = np.meshgrid(np.arange(n + 1.0), np.arange(n + 1.0))
    x, y = i.ravel(), j.ravel()
    surface = np.column_stack([x / n, y / n, height(x / n, y / n)])
    return MapTriangles.of(x, y, surface, grid_faces(n))


def jittered_mesh(n: int = 24, seed: int = 0, jitter: float = 0.25) -> MapTriangles:
    """The grid of the unit square with its vertices moved at random by up to ``jitter`` of a
    cell (those on the border along it, the corners not at all), lifted by :func:`height`."""
    rng = np.random.default_rng(seed)
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1))
    i, j = i.ravel(), j.ravel()
    dx = rng.uniform(-jitter, jitter, len(i)) / n
    dy = rng.uniform(-jitter, jitter, len(i)) / n
    dx[(i == 0) | (i == n)] = 0.0
    dy[(j == 0) | (j == n)] = 0.0
    x, y = i / n + dx, j / n + dy
    triangles = MapTriangles.of(x, y, np.column_stack([x, y, height(x, y)]), grid_faces(n))
    assert (triangles.signed_map_area > 0).all()
    return triangles


def folded_mesh(front: int = 1) -> MapTriangles:
    """Two triangles on the edge ``(0, 0) - (2, 0)`` of the map: ``(0, 0), (2, 0), (1, 2)``
    counter-clockwise (area 2), and ``(2, 0), (0, 0), (1, 1)`` folded back over it (area 1,
    clockwise); on the surface, a crease along that edge."""
    x = np.array([0.0, 2.0, 1.0, 1.0])
    y = np.array([0.0, 0.0, 2.0, 1.0])
    surface = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [1.0, 2.0, 0.0], [1.0, 0.0, 1.0]])
    return MapTriangles.of(x, y, surface, [[0, 1, 2], [1, 0, 3]], front)


def random_points_in(triangles: MapTriangles, count: int, seed: int):
    """``count`` random (triangle, weights, map point) in ``triangles``."""
    rng = np.random.default_rng(seed)
    chosen = rng.integers(0, len(triangles), count)
    weights = rng.dirichlet([1.0, 1.0, 1.0], count)
    points = np.einsum("pk,pkd->pd", weights, triangles.map_points[triangles.faces[chosen]])
    return chosen, weights, points


# -- the triangles ----------------------------------------------------------------------------


def test_meshes_cover_their_square_once():
    """The test meshes are what the zone tests assume: the unit square (or ``[0, 6]^2``)
    tiled by front-facing triangles, and a surface larger than the map."""
    for triangles, side in ((jittered_mesh(), 1.0), (exact_mesh(), 6.0)):
        assert (triangles.front_map_area > 0).all()
        assert np.isclose(triangles.signed_map_area.sum(), side * side, rtol=1e-12)
        assert triangles.surface_area.sum() > 1.0


def test_areas_match_the_corners():
    """Signed map areas are counter-clockwise positive and follow ``front``; surface areas
    are half the cross product of the 3D edges."""
    folded = folded_mesh()
    np.testing.assert_allclose(folded.signed_map_area, [2.0, -1.0])
    np.testing.assert_allclose(folded.front_map_area, [2.0, -1.0])
    np.testing.assert_allclose(folded_mesh(front=-1).front_map_area, [-2.0, 1.0])
    np.testing.assert_allclose(folded.surface_area, [2.0, 1.0])


def test_surface_areas_are_those_of_the_cross_product_on_a_jittered_mesh():
    """The coordinate-by-coordinate areas agree with numpy's cross product of the sides."""
    triangles = jittered_mesh(n=9, seed=4)
    corners = triangles.surface_points[triangles.faces]
    sides = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    expected = 0.5 * np.linalg.norm(sides, axis=1)
    np.testing.assert_allclose(triangles.surface_area, expected, rtol=1e-13)


def test_map_points_and_surface_points_must_pair_up():
    """One map point per surface point, or the error names the map points."""
    with pytest.raises(TransformInputError) as caught:
        MapTriangles.of([0.0, 1.0], [0.0, 0.0], np.zeros((3, 3)), [[0, 1, 2]])
    assert caught.value.field == "map_points"


def test_barycentric_weights_lift_to_the_surface_point():
    """A map point's weights in its triangle rebuild it, and lift to the surface point with
    the same weights."""
    triangles = jittered_mesh()
    chosen, weights, points = random_points_in(triangles, 500, seed=3)
    np.testing.assert_allclose(triangles.barycentric(chosen, points), weights, atol=1e-12)
    expected = np.einsum("pk,pkd->pd", weights, triangles.surface_points[triangles.faces[chosen]])
    np.testing.assert_allclose(triangles.lift(chosen, weights), expected, atol=1e-14)


# -- locate ------------------------------------------------------------------------------------


@pytest.mark.parametrize("mesh", [jittered_mesh, exact_mesh])
def test_locate_finds_the_triangle_and_weights_of_points_inside(mesh):
    """Random points inside random triangles come back with that triangle, their weights,
    and (lifted) the surface point with those weights."""
    triangles = mesh()
    chosen, weights, points = random_points_in(triangles, 3000, seed=1)
    found, found_weights = triangles.locate(points)
    np.testing.assert_array_equal(found, chosen)
    np.testing.assert_allclose(found_weights, weights, atol=1e-9)
    expected = np.einsum("pk,pkd->pd", weights, triangles.surface_points[triangles.faces[chosen]])
    np.testing.assert_allclose(triangles.lift(found, found_weights), expected, atol=1e-9)


def test_locate_returns_minus_one_outside_the_region():
    """Points off the square, by a hair or by far, hold no triangle and have NaN weights;
    points among them are still found."""
    triangles = jittered_mesh()
    outside = np.array(
        [[-1e-9, 0.5], [0.3, 1.0 + 1e-9], [1.2, 1.3], [-5.0, -5.0], [1e6, 0.5], [0.5, -0.01]]
    )
    inside = np.array([[0.5, 0.5], [1e-3, 1e-3], [0.999, 0.5]])
    found, weights = triangles.locate(np.concatenate([outside, inside]))
    np.testing.assert_array_equal(found[: len(outside)], -1)
    assert np.isnan(weights[: len(outside)]).all()
    assert (found[len(outside) :] >= 0).all()
    assert np.isfinite(weights[len(outside) :]).all()


def test_locate_returns_minus_one_in_a_hole_of_the_region():
    """Without some of the grid's triangles, points in their place hold nothing, and points
    in the kept ones find them."""
    full = exact_mesh()
    removed = np.array([14, 15, 16, 27, 40])
    kept = np.setdiff1d(np.arange(len(full)), removed)
    triangles = MapTriangles.of(
        full.map_points[:, 0], full.map_points[:, 1], full.surface_points, full.faces[kept]
    )
    centroids = full.map_points[full.faces].mean(axis=1)
    found, _ = triangles.locate(centroids[removed])
    np.testing.assert_array_equal(found, -1)
    found, _ = triangles.locate(centroids[kept])
    np.testing.assert_array_equal(found, np.arange(len(kept)))


def test_a_vertex_of_several_triangles_is_in_one_of_them():
    """A grid vertex (8 triangles round it, then 4) is located in one of its triangles, with
    all the weight on that corner, and lifts to its surface point."""
    triangles = exact_mesh()
    for vertex in (3 * 7 + 3, 3 * 7 + 2, 0, 48):
        around = np.flatnonzero((triangles.faces == vertex).any(axis=1))
        found, weights = triangles.locate(triangles.map_points[[vertex]])
        assert found[0] in around
        corner = list(triangles.faces[found[0]]).index(vertex)
        np.testing.assert_allclose(weights[0], np.eye(3)[corner], atol=1e-15)
        np.testing.assert_allclose(
            triangles.lift(found, weights)[0], triangles.surface_points[vertex], atol=1e-15
        )
    assert len(np.flatnonzero((triangles.faces == 3 * 7 + 3).any(axis=1))) == 8


def test_a_point_on_a_shared_edge_is_in_one_of_its_two_triangles():
    """Midpoints of interior edges land in one of the two triangles, with no weight on the
    corner opposite."""
    triangles = jittered_mesh(n=8)
    faces = triangles.faces
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    keys, counts = np.unique(np.sort(edges, axis=1), axis=0, return_counts=True)
    shared = keys[counts == 2]
    found, weights = triangles.locate(triangles.map_points[shared].mean(axis=1))
    for (u, v), face, w in zip(shared, found, weights, strict=True):
        assert u in faces[face] and v in faces[face]
        opposite = next(k for k in range(3) if faces[face, k] not in (u, v))
        assert abs(w[opposite]) < 1e-12
        np.testing.assert_allclose(
            triangles.lift(np.array([face]), w[None])[0],
            triangles.surface_points[[u, v]].mean(axis=0),
            atol=1e-12,
        )


def test_locate_on_a_folded_map_prefers_the_front_facing_triangle():
    """Where a back-facing triangle folds over a front-facing one, the front one is found;
    with the front reversed, the other."""
    point = np.array([[1.0, 0.5]])
    found, weights = folded_mesh().locate(point)
    assert found[0] == 0
    np.testing.assert_allclose(folded_mesh().lift(found, weights), [[1.0, 0.5, 0.0]])
    found, weights = folded_mesh(front=-1).locate(point)
    assert found[0] == 1
    np.testing.assert_allclose(folded_mesh().lift(found, weights), [[1.0, 0.0, 0.5]])


def test_locate_handles_no_points_and_repeated_points():
    """No points give empty answers; a point given twice is found twice."""
    triangles = exact_mesh()
    found, weights = triangles.locate(np.empty((0, 2)))
    assert found.shape == (0,) and weights.shape == (0, 3)
    found, weights = triangles.locate([[2.5, 3.25], [2.5, 3.25]])
    assert found[0] == found[1] >= 0
    np.testing.assert_array_equal(weights[0], weights[1])


# -- the cell grid ---------------------------------------------------------------------------


def test_cell_grid_covers_its_box_with_a_margin():
    """Every point of the box falls in an inner cell; the border cells are empty margin;
    positions beyond the grid clamp to it."""
    grid = CellGrid.covering([-1.0, 2.0], [3.0, 2.5], 0.3)
    assert grid.size >= 0.3
    x = np.linspace(-1.0, 3.0, 101)
    y = np.linspace(2.0, 2.5, 101)
    assert (grid.columns(x) >= 1).all() and (grid.columns(x) <= grid.n_columns - 2).all()
    assert (grid.rows(y) >= 1).all() and (grid.rows(y) <= grid.n_rows - 2).all()
    assert grid.columns(np.array([-1e9]))[0] == 0
    assert grid.rows(np.array([1e9]))[0] == grid.n_rows - 1
    huge = CellGrid.covering([0.0, 0.0], [1e6, 1.0], 1e-9)
    assert huge.n_columns <= 1024 and huge.n_rows <= 1024


def random_boxes(rng, count: int, spread: float, size: float):
    low = rng.uniform(0.0, spread, (count, 2))
    return low, low + rng.uniform(0.0, size, (count, 2))


def test_cell_index_pairs_are_the_boxes_that_share_a_cell_once_each():
    """``pairs`` gives every (rectangle, item) with a common cell exactly once, grouped by
    rectangle, as brute force over the cell rectangles finds them; wide rectangles pair with
    every item; ``any_in`` agrees."""
    rng = np.random.default_rng(5)
    grid = CellGrid.covering([0.0, 0.0], [10.0, 10.0], 0.1)
    low, high = random_boxes(rng, 300, 10.0, 0.5)
    items = grid.boxes(low[:, 0], high[:, 0], low[:, 1], high[:, 1])
    index = CellIndex.of(grid, items)
    low, high = random_boxes(rng, 200, 10.0, 2.0)
    low[:3], high[:3] = -100.0, 100.0  # wider than MAX_CELLS_PER_BOX cells: every item
    queries = grid.boxes(low[:, 0], high[:, 0], low[:, 1], high[:, 1])
    assert (queries.n_cells[:3] > MAX_CELLS_PER_BOX).all()
    assert (queries.n_cells[3:] <= MAX_CELLS_PER_BOX).all()
    owner, item = index.pairs(queries)
    meet = (queries.c0[:, None] <= items.c1) & (items.c0 <= queries.c1[:, None])
    meet &= (queries.r0[:, None] <= items.r1) & (items.r0 <= queries.r1[:, None])
    expected = np.argwhere(meet)
    assert (np.diff(owner) >= 0).all()
    got = np.column_stack([owner, item])
    assert len(np.unique(got, axis=0)) == len(got)
    np.testing.assert_array_equal(np.unique(got, axis=0), expected)
    np.testing.assert_array_equal(index.any_in(queries), meet.any(axis=1))


def test_free_to_the_right_is_the_next_empty_cell_in_the_row():
    """For each cell, the first cell at or after it in its row that no item occupies."""
    rng = np.random.default_rng(9)
    grid = CellGrid.covering([0.0, 0.0], [5.0, 5.0], 0.5)
    x, y = rng.uniform(0.0, 5.0, (2, 40))
    index = CellIndex.of(grid, grid.boxes(x, x, y, y))
    occupied = np.zeros((grid.n_rows, grid.n_columns), dtype=bool)
    occupied[grid.rows(y), grid.columns(x)] = True
    free = index.free_to_the_right()
    for row in range(grid.n_rows):
        for column in range(grid.n_columns):
            expected = column + int(np.argmin(occupied[row, column:]))
            assert free[row, column] == expected
