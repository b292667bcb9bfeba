"""Connectivity read with corners at one position welded (a triangle soup is the surface it
shows), and a region's connected pieces: ``validation.pieces``, ``validation.stray_faces``
and ``region.pieces`` (docs/math.md, section 8)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from service.samples import SAMPLES

from .conftest import load_sample
from .test_api import obj_of

pytestmark = pytest.mark.anyio

NAME = "fsaverage-head.ply"
#: The top of the head, seen from the whole head's box centre; the map's defaults.
SCALP = {"region": {"cone": {"axis": [0, 0, 1], "half_angle_deg": 70}}}


async def post(client, route: str, filename: str, data: bytes, params: dict) -> dict:
    answer = await client.post(
        route, files={"mesh": (filename, data)}, data={"params": json.dumps(params)}
    )
    assert answer.status_code == 200, answer.text[:400]
    return answer.json()


def close(expected):
    """``expected`` with every number compared to 1e-12, relative (or 1e-15 absolute)."""
    if isinstance(expected, dict):
        return {key: close(value) for key, value in expected.items()}
    if isinstance(expected, list) and expected and isinstance(expected[0], (list, dict)):
        return [close(value) for value in expected]
    if isinstance(expected, (bool, str)) or expected == []:
        return expected
    if isinstance(expected, list) and isinstance(expected[0], int):
        return expected  # ids and counts: exactly
    return pytest.approx(expected, rel=1e-12, abs=1e-15)


def stl_soup(vertices: np.ndarray, faces: np.ndarray) -> bytes:
    """A binary STL of the faces: every triangle with its own three corners."""
    corners = vertices[faces].reshape(-1, 3)
    soup = trimesh.Trimesh(corners, np.arange(len(corners)).reshape(-1, 3), process=False)
    return soup.export(file_type="stl")


def obj_with_face_normals(vertices: np.ndarray, faces: np.ndarray) -> bytes:
    """An OBJ as tools that split corners by normal write one: a vertex per face corner, a
    normal per face (``f 1//1 2//1 3//1``)."""
    corners = vertices[faces].reshape(-1, 3)
    normals = trimesh.Trimesh(vertices, faces, process=False).face_normals
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in corners.tolist()]
    lines += [f"vn {x!r} {y!r} {z!r}" for x, y, z in normals.tolist()]
    lines += [
        f"f {3 * i + 1}//{i + 1} {3 * i + 2}//{i + 1} {3 * i + 3}//{i + 1}"
        for i in range(len(faces))
    ]
    return ("\n".join(lines) + "\n").encode()


def edge_pieces(faces: np.ndarray) -> list[int]:
    """Brute force: the face counts of the pieces of faces joined by a shared edge (each
    pair of faces compared through a dictionary of edges), largest first."""
    on_edge: dict[tuple[int, int], list[int]] = {}
    for face, (a, b, c) in enumerate(faces.tolist()):
        for edge in ((a, b), (b, c), (c, a)):
            on_edge.setdefault(tuple(sorted(edge)), []).append(face)
    rows, columns = [], []
    for sharing in on_edge.values():
        rows += sharing[:-1]
        columns += sharing[1:]
    graph = coo_matrix((np.ones(len(rows)), (rows, columns)), shape=(len(faces),) * 2)
    labels = connected_components(graph, directed=False)[1]
    return sorted(np.bincount(labels).tolist(), reverse=True)


async def test_a_soup_and_its_welded_twin_get_the_same_validation_and_metrics(client):
    vertices, faces = load_sample(NAME)
    welded = await post(client, "/v1/flatten", "head.obj", obj_of(vertices, faces), SCALP)
    assert welded["validation"]["boundary_loops"] == 1
    soups = {
        "head.stl": stl_soup(vertices, faces),
        "head.obj": obj_with_face_normals(vertices, faces),
    }
    for filename, data in soups.items():
        soup = await post(client, "/v1/flatten", filename, data, SCALP)
        # Without welding every one of its triangles would be a piece and a boundary loop.
        # The default rotation sums over the vertices in another order: numbers to the last
        # bits, face lists and counts exactly.
        assert soup["validation"] == close(welded["validation"]), filename
        assert soup["metrics"] == close(welded["metrics"]), filename
        assert soup["params"]["center"] == close(welded["params"]["center"])
        assert soup["params"]["rotation"] == close(welded["params"]["rotation"])
        assert soup["faces"]["ids"] == welded["faces"]["ids"]
        # The file's own vertices answered, each the same as its welded twin.
        ids = soup["vertices"]["ids"]
        assert ids == sorted({v for face in soup["faces"]["vertices"] for v in face})
        twin = faces.ravel()[ids]  # soup vertex 3 i + k is corner k of face i
        where = {v: k for k, v in enumerate(welded["vertices"]["ids"])}
        for key in ("theta", "phi", "x", "y"):
            expected = np.asarray(welded["vertices"][key])[[where[v] for v in twin.tolist()]]
            assert soup["vertices"][key] == close(expected.tolist()), (filename, key)


async def test_a_soup_is_fitted_as_its_welded_twin(client):
    """The fit's kernel closes the soup's one boundary loop, not one loop a triangle: the
    centre it chooses sees the scalp whole."""
    vertices, faces = load_sample(NAME)
    auto = {**SCALP, "center": "auto"}
    welded = await post(client, "/v1/validate", "head.obj", obj_of(vertices, faces), auto)
    soup = await post(client, "/v1/validate", "head.stl", stl_soup(vertices, faces), auto)
    assert soup["validation"]["seam_free"] and soup["validation"]["star_shaped"]
    assert soup["validation"]["boundary_loops"] == 1
    assert soup["params"]["center"] == pytest.approx(welded["params"]["center"], rel=1e-6)
    assert soup["metrics"]["isometric"]["mean"] == pytest.approx(
        welded["metrics"]["isometric"]["mean"], rel=1e-6
    )


async def test_untangling_a_soup_moves_each_corner_with_its_twins(client):
    vertices, faces = load_sample(NAME)
    # Seen from near its side, the scalp's far side folds over: something to untangle.
    params = {
        "center": [78.3, -12.5, 40.0],
        "rotation": {"pole": [0, 0, -1], "up": [0, 1, 0]},
        "sigma": 0.3,
        "region": SCALP["region"],
        "untangle": True,
    }
    welded = await post(client, "/v1/flatten", "head.obj", obj_of(vertices, faces), params)
    soup = await post(client, "/v1/flatten", "head.stl", stl_soup(vertices, faces), params)
    assert welded["untangle"]["folded_before"] > 0
    assert soup["untangle"]["folded_before"] == welded["untangle"]["folded_before"]
    assert soup["untangle"]["folded_after"] == welded["untangle"]["folded_after"] == []
    # Every corner at one position has the same repaired coordinates (the minimiser's
    # variables come in another order, so not the twin's to the bit).
    twin = faces.ravel()[soup["vertices"]["ids"]]
    for key in ("x", "y"):
        values = np.asarray(soup["vertices"][key])
        first = np.full(twin.max() + 1, np.nan)
        first[twin[::-1]] = values[::-1]
        assert (values == first[twin]).all(), key
    moved = np.isin(soup["vertices"]["ids"], soup["untangle"]["moved_vertices"])
    moved_twins = np.unique(twin[moved])
    assert moved.sum() == np.isin(twin, moved_twins).sum() > 0  # each with all its corners


def head_and_box() -> tuple[bytes, np.ndarray, np.ndarray, np.ndarray]:
    """The head with a 20 mm box 20 mm above its top, as one GLB: its bytes, vertices,
    faces, and the box's face ids."""
    vertices, faces = load_sample(NAME)
    top = vertices[:, 2].max()
    box = trimesh.creation.box(extents=[20.0, 20.0, 20.0])
    box.apply_translation([vertices[:, 0].mean(), vertices[:, 1].mean(), top + 30.0])
    both = trimesh.Trimesh(
        np.concatenate([vertices, box.vertices]),
        np.concatenate([faces, box.faces + len(vertices)]),
        process=False,
    )
    data = both.export(file_type="glb")
    return data, both.vertices, both.faces, np.arange(len(faces), len(both.faces))


async def test_a_box_beside_the_head_is_a_second_piece_and_largest_leaves_it_out(client):
    data, vertices, faces, box_ids = head_and_box()
    answer = await post(client, "/v1/flatten", "both.glb", data, SCALP)
    selected = np.asarray(answer["faces"]["ids"])
    assert set(box_ids) <= set(selected.tolist())  # the cone takes the box in
    validation = answer["validation"]
    assert validation["pieces"] == edge_pieces(faces[selected])
    assert validation["pieces"][1:] == [len(box_ids)]
    assert validation["stray_faces"] == box_ids.tolist()
    (warning,) = [w for w in answer["warnings"] if w["code"] == "region_pieces"]  # said
    assert warning["code"] == "region_pieces" and warning["field"] == "params.region"
    assert f"of {validation['pieces'][0]:,}, {len(box_ids)} faces" in warning["message"]

    largest = {"region": {**SCALP["region"], "pieces": "largest"}}
    kept = await post(client, "/v1/flatten", "both.glb", data, largest)
    assert kept["faces"]["ids"] == sorted(set(selected.tolist()) - set(box_ids.tolist()))
    assert kept["validation"]["pieces"] == [len(kept["faces"]["ids"])]
    assert kept["validation"]["stray_faces"] == []
    assert kept["params"]["region"]["pieces"] == "largest"
    assert "region_pieces" not in [w["code"] for w in kept["warnings"]]
    # Sent back, the answer's params select the same faces.
    again = await post(client, "/v1/flatten", "both.glb", data, kept["params"])
    assert again["faces"]["ids"] == kept["faces"]["ids"]
    # The centre is the head's: the box no longer draws it up.
    head = vertices[faces[kept["faces"]["ids"]]].reshape(-1, 3)
    assert head.min(axis=0)[2] < kept["params"]["center"][2] < head.max(axis=0)[2]


async def test_a_region_of_one_piece_has_no_stray_faces(client):
    data = SAMPLES[NAME].path.read_bytes()
    answer = await post(client, "/v1/validate", NAME, data, SCALP)
    assert answer["validation"]["pieces"] == [1534]
    assert answer["validation"]["stray_faces"] == []
    assert "pieces" not in answer["params"]["region"]
    assert answer["warnings"] == []


async def test_pieces_alone_is_no_region(client):
    answer = await client.post(
        "/v1/validate",
        files={"mesh": (NAME, SAMPLES[NAME].path.read_bytes())},
        data={"params": json.dumps({"region": {"pieces": "largest"}})},
    )
    assert answer.status_code == 422, answer.text
    assert "give exactly one of faces" in answer.json()["detail"]


async def test_a_zone_on_a_soup_measures_as_on_its_welded_twin(client):
    """Zones are cut and lifted on the map's triangles, which a soup's corners share."""
    vertices, faces = load_sample(NAME)
    params = {**SCALP, "rotation": {"pole": [0, 0, -1], "up": [0, 1, 0]}, "sigma": 0.3}
    welded = await post(client, "/v1/flatten", "head.obj", obj_of(vertices, faces), params)
    x, y = np.asarray(welded["vertices"]["x"]), np.asarray(welded["vertices"]["y"])
    cx, cy = x.mean(), y.mean()
    zone = {"name": "z", "outer": {"x": [cx - 0.3, cx + 0.2, cx], "y": [cy - 0.2, cy, cy + 0.3]}}
    measured = {
        filename: (await post(client, "/v1/measure", filename, data, {**params, "zones": [zone]}))
        for filename, data in (
            ("head.obj", obj_of(vertices, faces)),
            ("head.stl", stl_soup(vertices, faces)),
        )
    }
    one, other = measured["head.obj"]["zones"][0], measured["head.stl"]["zones"][0]
    assert one["area"] > 0
    for key in ("area", "perimeter", "faces"):
        assert other[key] == close(one[key]), key
    assert len(other["outline"][0]["points"]) == len(one["outline"][0]["points"])
