"""From the map back to the surface in the core (transforms.locate; docs/math.md, section
10). The HTTP side, /v1/locate, is in test_api.py."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial import ConvexHull

from transforms import Chart, Frame, PoleCap, TransformInputError, locate, world_to_angles
from transforms.locate import DIRECT_QUERIES, FEW_QUERIES, SORTED_QUERIES, LocateIndex

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


# -- the index against brute force ---------------------------------------------------------


def brute_force(points, faces, directions):
    """Every (ray, triangle) pair through the cone test written out: per ray, the depth of
    the nearest hit (inf for none) and every triangle within 1e-9 of that depth."""
    rays = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    c0, c1, c2 = (points[faces[:, i]] for i in range(3))
    e = np.stack([rays @ np.cross(c1, c2).T, rays @ np.cross(c2, c0).T, rays @ np.cross(c0, c1).T])
    total = e.sum(axis=0)  # (k, m)
    with np.errstate(divide="ignore", invalid="ignore"):
        inside = (np.sign(total) * e >= -1e-12 * np.abs(e).sum(axis=0)).all(axis=0)
        depth = np.einsum("mj,mj->m", c0, np.cross(c1, c2)) / total
    depth = np.where(inside & (total != 0) & (depth > 0), depth, np.inf)
    nearest = depth.min(axis=1)
    tied = [
        np.flatnonzero(row <= best * (1 + 1e-9)) for row, best in zip(depth, nearest, strict=True)
    ]
    return nearest, tied


def assert_first_hits(hits, points, faces, directions):
    """``hits`` are the nearest hits brute force finds: misses where it misses, and where a
    ray hits, one of the triangles it meets nearest, at that depth, with weights summing to
    1 that give the point."""
    nearest, tied = brute_force(points, faces, directions)
    missed = ~np.isfinite(nearest)
    np.testing.assert_array_equal(hits.faces == -1, missed)
    assert np.isnan(hits.points[missed]).all() and np.isnan(hits.barycentric[missed]).all()
    rays = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    for row in np.flatnonzero(~missed):
        assert hits.faces[row] in tied[row], (row, hits.faces[row], tied[row])
        np.testing.assert_allclose(hits.points[row], nearest[row] * rays[row], rtol=1e-9)
    hit = ~missed
    corners = points[faces[hits.faces[hit]]]
    np.testing.assert_allclose(hits.barycentric[hit].sum(axis=1), 1.0, rtol=1e-9)
    np.testing.assert_allclose(
        np.einsum("kc,kcj->kj", hits.barycentric[hit], corners), hits.points[hit], atol=1e-9
    )


def both_ways(points, faces, directions):
    """The answers of locate (direct for a few rays), and of a built index."""
    direct = locate(points, faces, directions[:DIRECT_QUERIES])
    return direct, LocateIndex.build(points, faces).query(directions)


def closed_surface(rng, n, wobble):
    """A closed star-shaped surface around the origin: the hull of the six axis directions
    and ``n`` others, each vertex then moved along its ray by up to ``wobble`` of its
    distance."""
    directions = np.concatenate([np.eye(3), -np.eye(3), rng.normal(size=(n, 3))])
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    faces = ConvexHull(directions).simplices
    return directions * rng.uniform(1.0 - wobble, 1.0 + wobble, (n + 6, 1)), faces


@given(seed=st.integers(0, 2**32 - 1), n=st.integers(4, 300), wobble=st.floats(0.0, 0.6))
def test_index_finds_the_one_hit_inside_a_closed_surface(seed, n, wobble):
    rng = np.random.default_rng(seed)
    points, faces = closed_surface(rng, n, wobble)
    directions = rng.normal(size=(200, 3))
    direct, indexed = both_ways(points, faces, directions)
    assert (indexed.faces >= 0).all()  # seen from inside, every ray meets the surface
    assert_first_hits(indexed, points, faces, directions)
    assert_first_hits(direct, points, faces, directions[: len(direct.faces)])


@given(seed=st.integers(0, 2**32 - 1), m=st.integers(1, 120), spread=st.floats(0.01, 3.0))
def test_index_agrees_with_brute_force_on_triangle_soup(seed, m, spread):
    # Triangles of every size at every distance, overlapping, some next to the centre
    # (spanning most of a hemisphere), many crossing the cube's edges.
    rng = np.random.default_rng(seed)
    middles = rng.normal(size=(m, 1, 3)) * rng.uniform(0.2, 3.0, (m, 1, 1))
    points = (middles + rng.normal(size=(m, 3, 3)) * spread).reshape(-1, 3)
    faces = np.arange(3 * m).reshape(m, 3)
    directions = np.concatenate([rng.normal(size=(150, 3)), middles[:, 0]])
    direct, indexed = both_ways(points, faces, directions)
    assert_first_hits(indexed, points, faces, directions)
    assert_first_hits(direct, points, faces, directions[: len(direct.faces)])


def test_rays_through_vertices_and_edges_find_a_triangle_at_the_right_depth():
    rng = np.random.default_rng(3)
    points, faces = closed_surface(rng, 400, 0.3)
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    directions = np.concatenate([points, points[edges].mean(axis=1)])
    hits = LocateIndex.build(points, faces).query(directions)
    assert (hits.faces >= 0).all()
    assert_first_hits(hits, points, faces, directions)
    # Through a vertex: all the weight on it.
    vertex_hits = hits.barycentric[: len(points)]
    np.testing.assert_allclose(vertex_hits.max(axis=1), 1.0, atol=1e-9)


def test_rays_along_the_cube_edges_and_corners_are_found():
    rng = np.random.default_rng(4)
    points, faces = closed_surface(rng, 600, 0.2)
    signs = np.array([[1, 1, 0], [1, 0, -1], [0, -1, 1], [1, 1, 1], [-1, 1, -1], [1, 0, 0]])
    near = signs[:, None, :] + rng.normal(size=(len(signs), 40, 3)) * 1e-7
    directions = np.concatenate([signs, near.reshape(-1, 3)]).astype(float)
    hits = LocateIndex.build(points, faces).query(directions)
    assert (hits.faces >= 0).all()
    assert_first_hits(hits, points, faces, directions)


def test_the_nearer_of_two_nested_surfaces_is_hit_whichever_comes_first():
    rng = np.random.default_rng(5)
    inner, faces = closed_surface(rng, 200, 0.0)
    directions = rng.normal(size=(300, 3))
    for near_first in (True, False):
        layers = [inner, 2.0 * inner] if near_first else [2.0 * inner, inner]
        points = np.concatenate(layers)
        both = np.concatenate([faces, faces + len(inner)])
        for hits in both_ways(points, both, directions):
            nearer = hits.faces < len(faces) if near_first else hits.faces >= len(faces)
            assert nearer.all()
            assert_first_hits(hits, points, both, directions[: len(hits.faces)])


def test_a_triangle_next_to_the_centre_is_tested_against_every_ray():
    # A triangle 0.1 from the centre reaching 10 sideways covers most of a hemisphere: not in
    # front of every cube face it reaches, so no face's grid can hold it.
    points = np.array([[-10.0, -10.0, 0.1], [10.0, -10.0, 0.1], [0.0, 10.0, 0.1]])
    faces = np.array([[0, 1, 2]])
    index = LocateIndex.build(points, faces)
    assert index.everyone.tolist() == [0]
    directions = np.array([[0, 0, 1], [1, 0.2, 0.05], [0, -1, 0.02], [0, 0, -1], [1, 1, -0.1]])
    assert_first_hits(index.query(directions), points, faces, directions)
    assert index.query(directions).faces.tolist() == [0, 0, 0, -1, -1]


def test_rays_that_miss_a_patch_are_misses():
    vertices, faces = scalp()
    frame = Frame.from_pole_up([0, 0, -1], [0, 1, 0], (vertices.min(0) + vertices.max(0)) / 2)
    local = frame.to_local(vertices)
    rng = np.random.default_rng(6)
    directions = rng.normal(size=(500, 3))
    hits = LocateIndex.build(local, faces).query(directions)
    assert 0 < (hits.faces == -1).sum() < len(directions)
    assert_first_hits(hits, local, faces, directions)


def test_many_queries_taken_in_cube_map_order_get_the_answers_each_gets_alone():
    """From SORTED_QUERIES queries on, the compiled walk takes them in cube-map order and
    puts the answers back to their rows: brute force's hits, and bit for bit what each
    query gets alone (the scalar path) and among fewer (the walk in the queries' order)."""
    rng = np.random.default_rng(10)
    inner, faces = closed_surface(rng, 300, 0.3)
    # Two nested layers with a hole above: rays up miss, the others meet the inner one.
    kept = faces[inner[faces].mean(axis=1)[:, 2] < 0.6]
    points = np.concatenate([2.0 * inner, inner])
    both = np.concatenate([kept, kept + len(inner)])
    directions = rng.normal(size=(SORTED_QUERIES + 500, 3))
    index = LocateIndex.build(points, both)
    hits = index.query(directions)
    assert 0 < (hits.faces == -1).sum() < len(directions)
    assert (hits.faces[hits.faces >= 0] >= len(kept)).all()
    assert_first_hits(hits, points, both, directions)
    for rows in (slice(0, FEW_QUERIES), slice(100, 100 + FEW_QUERIES), slice(0, 1000)):
        alone = index.query(directions[rows])
        np.testing.assert_array_equal(alone.faces, hits.faces[rows])
        np.testing.assert_array_equal(alone.barycentric, hits.barycentric[rows])
        np.testing.assert_array_equal(alone.points, hits.points[rows])


def test_the_index_hits_the_triangles_open3d_hits():
    """Against an independent ray caster (Open3D's Embree scene, float32; installed with the
    sites-peers extra): the same triangle for every ray but those within float32's
    rounding of an edge, at the same distance."""
    o3d = pytest.importorskip("open3d")
    vertices, faces = scalp()
    frame = Frame.from_pole_up([0, 0, -1], [0, 1, 0], (vertices.min(0) + vertices.max(0)) / 2)
    local = frame.to_local(vertices)
    directions = np.random.default_rng(11).normal(size=(SORTED_QUERIES + 6000, 3))
    hits = LocateIndex.build(local, faces).query(directions)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(local.astype(np.float32)), o3d.core.Tensor(faces.astype(np.uint32))
    )
    rays = np.zeros((len(directions), 6), dtype=np.float32)
    rays[:, 3:] = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    answer = scene.cast_rays(o3d.core.Tensor(rays))
    theirs = answer["primitive_ids"].numpy().astype(np.int64)
    theirs[theirs == o3d.t.geometry.RaycastingScene.INVALID_ID] = -1
    assert 0 < (theirs == -1).sum() < len(directions)
    differ = np.flatnonzero(hits.faces != theirs)
    assert len(differ) <= len(directions) // 1000
    ours = hits.faces[differ] >= 0
    np.testing.assert_array_less(hits.barycentric[differ[ours]].min(axis=1), 1e-5)
    same = (hits.faces == theirs) & (theirs >= 0)
    depth = np.linalg.norm(hits.points[same], axis=1)
    np.testing.assert_allclose(answer["t_hit"].numpy()[same], depth, rtol=1e-5)


def test_the_index_is_immutable_and_reused():
    points, faces = closed_surface(np.random.default_rng(7), 50, 0.1)
    index = LocateIndex.build(points, faces)
    for array in (index.cell_start, index.entry_face, index.entry_box, index.levels):
        assert not array.flags.writeable
    first = index.query([[0.0, 0.0, 1.0]])
    again = index.query(np.array([[0.0, 0.0, 5.0], [1.0, 0.0, 0.0]]))
    assert again.faces[0] == first.faces[0]


def test_the_index_stays_small_for_a_region_along_a_line():
    # Thin slivers along one long line: the grid's cells stay bounded by the faces.
    m = 2000
    x = np.linspace(-50.0, 50.0, m + 1)
    points = np.concatenate(
        [np.stack([x, np.full_like(x, 1.0), np.full_like(x, 1.0)], axis=1),
         np.stack([x, np.full_like(x, 1.0), np.full_like(x, 1.0 + 1e-6)], axis=1)]
    )  # fmt: skip
    faces = np.stack([np.arange(m), np.arange(m) + 1, np.arange(m) + m + 1], axis=1)
    index = LocateIndex.build(points, faces)
    assert len(index.cell_start) - 1 <= 8 * len(faces) and len(index.entry_face) <= 4 * 6 * m


def test_locate_refuses_a_zero_direction_and_a_vertex_at_the_centre():
    points, faces = closed_surface(np.random.default_rng(8), 20, 0.0)
    with pytest.raises(TransformInputError) as error:
        locate(points, faces, [[0.0, 0.0, 1.0], [0.0, 0.0, 0.0]])
    assert error.value.field == "directions"
    index = LocateIndex.build(points, faces)
    for count in (FEW_QUERIES, FEW_QUERIES + 1, SORTED_QUERIES):
        directions = np.ones((count, 3))
        directions[[1, 3]] = 0.0
        with pytest.raises(TransformInputError, match="zero") as error:
            index.query(directions)
        assert error.value.field == "directions"
    with pytest.raises(TransformInputError) as error:
        LocateIndex.build(np.concatenate([points, [[0.0, 0.0, 0.0]]]), [[0, 1, len(points)]])
    assert error.value.field == "vertices"


def test_no_rays_and_no_triangles_give_empty_answers():
    points, faces = closed_surface(np.random.default_rng(9), 20, 0.0)
    no_faces = np.zeros((0, 3), dtype=np.int64)
    for region in (faces, no_faces):
        for count in (0, 1, DIRECT_QUERIES + 1):
            directions = np.random.default_rng(count).normal(size=(count, 3))
            for hits in (
                locate(points, region, directions),
                LocateIndex.build(points, region).query(directions),
            ):
                assert hits.faces.shape == (count,) and hits.points.shape == (count, 3)
                assert (hits.faces >= 0).all() if len(region) else (hits.faces == -1).all()


@given(seed=st.integers(0, 2**32 - 1), m=st.integers(1, 120), spread=st.floats(0.01, 3.0))
def test_a_few_queries_alone_get_the_answers_of_a_batch(seed, m, spread):
    """A click queries one ray (the scalar path, FEW_QUERIES or fewer); the same rays among
    many take the vectorised path: the same triangles, weights and points, bit for bit."""
    rng = np.random.default_rng(seed)
    middles = rng.normal(size=(m, 1, 3)) * rng.uniform(0.2, 3.0, (m, 1, 1))
    points = (middles + rng.normal(size=(m, 3, 3)) * spread).reshape(-1, 3)
    faces = np.arange(3 * m).reshape(m, 3)
    # Rays through the triangles' corners and edges' middles as well as anywhere.
    corners = points[faces]
    directions = np.concatenate(
        [rng.normal(size=(40, 3)), corners[:, 0], (corners[:, 1] + corners[:, 2]) / 2]
    )
    index = LocateIndex.build(points, faces)
    batch = index.query(directions)
    assert len(directions) > FEW_QUERIES
    for start in range(0, len(directions), FEW_QUERIES):
        few = index.query(directions[start : start + FEW_QUERIES])
        rows = slice(start, start + FEW_QUERIES)
        np.testing.assert_array_equal(few.faces, batch.faces[rows])
        np.testing.assert_array_equal(few.barycentric, batch.barycentric[rows])
        np.testing.assert_array_equal(few.points, batch.points[rows])
