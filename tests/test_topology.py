"""Edge classification: boundary, outline, loops."""

import numpy as np

from transforms import region_edges
from transforms.topology import RegionEdges, face_components

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


def test_threads_give_the_same_edges():
    vertices, faces = sphere_mesh(120, 240)
    orientation = np.where(np.arange(len(faces)) % 97 == 0, -1, 1).astype(np.int8)
    keep = np.arange(len(faces)) % 13 != 0
    one = region_edges(faces[keep], orientation[keep], len(vertices), threads=1)
    for threads in (2, 3):
        many = region_edges(faces[keep], orientation[keep], len(vertices), threads=threads)
        assert as_set(one.boundary) == as_set(many.boundary)
        assert as_set(one.outline) == as_set(many.outline)


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
