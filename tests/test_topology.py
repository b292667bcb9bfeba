"""Edge classification: boundary, outline, loops."""

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from transforms import region_edges
from transforms.topology import RegionEdges, face_components, representatives

from .conftest import grid_mesh, sphere_mesh


def edges_of(faces, orientation):
    faces = np.asarray(faces, dtype=np.int64)
    n = int(faces.max()) + 1
    return region_edges(faces, np.asarray(orientation, dtype=np.int8), n)


def as_set(pairs):
    return {tuple(int(v) for v in p) for p in pairs}


def test_two_triangles_sharing_an_edge():
    # Both front-facing, consistently wound: the shared edge (1, 2) is smooth.
    found = edges_of([[0, 1, 2], [2, 1, 3]], [1, 1])
    assert as_set(found.boundary) == {(0, 1), (0, 2), (1, 3), (2, 3)}
    assert as_set(found.outline) == as_set(found.boundary)
    assert found.boundary_loops() == 1


def test_a_fold_puts_the_shared_edge_on_the_outline():
    # The second face is seen from behind: both third vertices on one side of (1, 2).
    found = edges_of([[0, 1, 2], [2, 1, 3]], [1, -1])
    assert (1, 2) in as_set(found.outline)
    assert (1, 2) not in as_set(found.boundary)


def test_edge_on_and_non_manifold_edges_are_outline():
    found = edges_of([[0, 1, 2], [2, 1, 3]], [1, 0])
    assert (1, 2) in as_set(found.outline)
    found = edges_of([[0, 1, 2], [2, 1, 3], [1, 2, 4]], [1, 1, 1])
    assert (1, 2) in as_set(found.outline)


def test_an_edge_with_thousands_of_faces_is_counted_exactly():
    # 2^13 + 2 faces on the edge (0, 1): 3 seen edge-on (side 0), the rest from behind. In
    # 13 count bits its sum would read as a smooth edge's (count 2, sides 0 and 4): the
    # classification must notice and count in 64 bits.
    uses = 2**13 + 2
    faces = [[0, 1, 2 + k] for k in range(uses)]
    orientation = [0, 0, 0] + [-1] * (uses - 3)
    found = edges_of(faces, orientation)
    assert (0, 1) in as_set(found.outline)
    assert (0, 1) not in as_set(found.boundary)
    assert len(found.boundary) == 2 * uses


def test_loops_of_disk_annulus_and_closed_surface():
    vertices, faces = grid_mesh(np.arange(6.0), np.arange(6.0), 1.0)
    ones = np.ones(len(faces), dtype=np.int8)
    assert region_edges(faces, ones, len(vertices)).boundary_loops() == 1
    centre = {(2, 2), (2, 3), (3, 2), (3, 3)}  # cells removed for a hole
    keep = [i for i, f in enumerate(faces) if (f.min() // 6, f.min() % 6) not in centre]
    assert region_edges(faces[keep], ones[keep], len(vertices)).boundary_loops() == 2
    vertices, faces = sphere_mesh(10, 12)
    closed = region_edges(faces, np.ones(len(faces), dtype=np.int8), len(vertices))
    assert closed.boundary_loops() == 0 and len(closed.boundary) == 0


def _edges_by_brute_force(faces, orientation):
    """Boundary and outline as sorted (low, high) lists, from a dict of each edge's sides."""
    sides = {}
    for face, turn in zip(faces.tolist(), orientation.tolist(), strict=True):
        for c in range(3):
            a, b = face[c], face[(c + 1) % 3]
            if a != b:
                sides.setdefault((min(a, b), max(a, b)), []).append(turn if a < b else -turn)
    smooth = {edge for edge, s in sides.items() if sorted(s) == [-1, 1]}
    boundary = sorted(edge for edge, s in sides.items() if len(s) == 1)
    return boundary, sorted(set(sides) - smooth)


def _pieces_by_brute_force(faces):
    """Labels numbered by first face, from scipy's components of the faces-sharing-an-edge
    graph built with a dict."""
    on_edge = {}
    for f, face in enumerate(faces.tolist()):
        for c in range(3):
            a, b = face[c], face[(c + 1) % 3]
            on_edge.setdefault((min(a, b), max(a, b)), []).append(f)
    pairs = [(fs[0], g) for fs in on_edge.values() for g in fs[1:]]
    rows, cols = zip(*pairs, strict=True) if pairs else ((), ())
    graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(len(faces), len(faces)))
    return connected_components(graph, directed=False)[1]


@pytest.mark.parametrize("seed", range(40))
def test_edges_and_pieces_agree_with_brute_force_on_random_soups(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(3, 60))
    faces = rng.integers(0, n, (int(rng.integers(1, 150)), 3))
    orientation = rng.integers(-1, 2, len(faces)).astype(np.int8)
    edges = region_edges(faces, orientation, n)
    boundary, outline = _edges_by_brute_force(faces, orientation)
    assert edges.boundary.tolist() == [list(e) for e in boundary]
    assert edges.outline.tolist() == [list(e) for e in outline]
    assert (face_components(faces) == _pieces_by_brute_force(faces)).all()


def test_a_fan_of_many_faces_round_one_vertex_is_sorted_exactly():
    # Above the insertion sort's bucket size: the merge sort's path.
    k = 500
    rng = np.random.default_rng(3)
    faces = np.stack([np.zeros(k, int), np.arange(1, k + 1), np.arange(2, k + 2)], axis=1)
    faces = faces[rng.permutation(k)]
    orientation = rng.choice(np.array([-1, 1], dtype=np.int8), k)
    edges = region_edges(faces, orientation, k + 2)
    boundary, outline = _edges_by_brute_force(faces, orientation)
    assert edges.boundary.tolist() == [list(e) for e in boundary]
    assert edges.outline.tolist() == [list(e) for e in outline]
    assert (face_components(faces) == 0).all()


def test_empty_boundary_has_no_loops():
    empty = np.zeros((0, 2), dtype=np.int64)
    assert RegionEdges(boundary=empty, outline=empty).boundary_loops() == 0


def test_faces_sharing_an_edge_are_one_piece_and_a_shared_vertex_is_not():
    # Two triangles on an edge, and a third touching them at one vertex only.
    faces = np.array([[0, 1, 2], [1, 3, 2], [3, 4, 5]])
    pieces = face_components(faces)
    assert pieces[0] == pieces[1] != pieces[2]
    _, faces = sphere_mesh(10, 12)
    assert len(np.unique(face_components(faces))) == 1
    assert len(face_components(np.zeros((0, 3), dtype=np.int64))) == 0


def test_a_triangle_soup_is_one_piece_where_its_triangles_meet():
    # Two triangles sharing an edge, written as an STL writes them: six corners, none shared.
    corners = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    soup = np.arange(6).reshape(2, 3)
    assert len(np.unique(face_components(soup))) == 2
    assert len(np.unique(face_components(soup, corners))) == 1


@pytest.mark.parametrize("seed", range(10))
def test_each_point_is_welded_to_the_first_row_at_its_exact_position(seed):
    rng = np.random.default_rng(seed)
    distinct = rng.integers(-3, 4, (int(rng.integers(1, 40)), 3)).astype(float) * 0.5
    points = distinct[rng.integers(0, len(distinct), int(rng.integers(1, 400)))]
    points[rng.random(points.shape) < 0.2] *= -1.0  # -0.0 where a coordinate is 0
    first = {}
    expected = [first.setdefault(tuple(p), i) for i, p in enumerate(points.tolist())]
    assert representatives(points).tolist() == expected  # -0.0 == 0.0 as dict keys too
