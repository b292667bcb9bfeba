"""Regions and centres in the core (transforms.selection; docs/math.md, section 8): the ids
are the file's, and every refusal names the request field and the offending ids."""

from __future__ import annotations

import re

import numpy as np
import pytest

from transforms import EmptyRegionError, TransformInputError
from transforms import selection as select

from .conftest import grid_mesh


@pytest.fixture(scope="module")
def grid():
    """A 4 x 4 grid of unit squares in the plane z = 1 (32 triangles, 25 vertices)."""
    return grid_mesh(np.arange(5.0), np.arange(5.0), 1.0)


def test_listed_faces_come_back_ascending(grid):
    _, faces = grid
    assert select.faces_listed([7, 3, 0], len(faces)).tolist() == [0, 3, 7]


@pytest.mark.parametrize(
    ("ids", "says", "indices"),
    [
        ([0, 32], "face id 32 is outside [0, 32) (the mesh has 32 faces)", (32,)),
        ([-1], "face id -1 is outside", (-1,)),
        ([2**70], "outside [0, 32)", ()),
        ([4, 5, 4], "face id 4 is listed more than once (1 ids repeat)", (4,)),
    ],
)
def test_bad_face_ids_name_the_field_and_the_ids(grid, ids, says, indices):
    _, faces = grid
    with pytest.raises(TransformInputError, match=re.escape(says)) as caught:
        select.faces_listed(ids, len(faces))
    assert caught.value.field == "region.faces" and caught.value.indices == indices


def test_vertices_select_the_faces_they_close(grid):
    vertices, faces = grid
    corner = np.flatnonzero((vertices[:, 0] <= 1) & (vertices[:, 1] <= 1))  # one square
    chosen = select.faces_of_vertices(faces, corner.tolist(), len(vertices))
    assert len(chosen) == 2 and set(faces[chosen].ravel()) <= set(corner.tolist())
    with pytest.raises(TransformInputError, match="vertex id 25 is outside") as caught:
        select.faces_of_vertices(faces, [25], len(vertices))
    assert caught.value.field == "region.vertices"


def test_groups_are_ranges_of_face_ids():
    groups = {"scalp": np.array([[2, 5]]), "face": np.array([[0, 1], [4, 6]])}
    assert select.faces_of_groups(groups, ["scalp"], 8).tolist() == [2, 3, 4]
    assert select.faces_of_groups(groups, ["scalp", "face"], 8).tolist() == [0, 2, 3, 4, 5]
    with pytest.raises(TransformInputError, match="no group named 'hair'; the file's groups"):
        select.faces_of_groups(groups, ["hair"], 8)


def test_a_cone_takes_the_faces_whose_centroid_is_within_its_angle(grid):
    vertices, faces = grid
    apex = np.array([2.0, 2.0, 0.0])  # under the middle of the grid
    narrow = select.cone_faces(vertices, faces, apex, [0, 0, 1], 30.0)
    centroids = vertices[faces[narrow]].mean(axis=1) - apex
    angles = np.degrees(np.arccos(centroids[:, 2] / np.linalg.norm(centroids, axis=1)))
    assert len(narrow) and (angles <= 30.0).all()
    assert len(select.cone_faces(vertices, faces, apex, [0, 0, 1], 180.0)) == len(faces)
    with pytest.raises(TransformInputError, match="non-zero direction") as caught:
        select.cone_faces(vertices, faces, apex, [0, 0, 0], 30.0)
    assert caught.value.field == "region.cone.axis"


def test_named_centres(grid):
    vertices, faces = grid
    np.testing.assert_allclose(select.bbox_center(vertices, faces), [2.0, 2.0, 1.0])
    np.testing.assert_allclose(select.named_center(vertices, faces, "centroid"), [2, 2, 1])
    flat = np.array([[0, 1, 2]])
    line = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]])
    with pytest.raises(TransformInputError, match="'centroid' needs faces with area") as caught:
        select.area_centroid(line, flat)
    assert caught.value.field == "center"


def test_an_empty_selection_is_its_own_error():
    assert select.nonempty(np.array([3])).tolist() == [3]
    with pytest.raises(EmptyRegionError, match="region: selects no faces"):
        select.nonempty(np.array([], dtype=np.int64))
