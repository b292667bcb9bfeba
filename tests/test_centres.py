"""The named centres and a cone's defaults (docs/math.md, section 8): the centre of the faces
a cone selects, not of the whole mesh; the box centre in the region's own principal axes,
which moves and turns with the mesh."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from fixtures.zoo import SHARED
from transforms import selection as select

from .test_api import obj_of

pytestmark = pytest.mark.anyio

#: The full-body scan (SMPL-X template, metres, Y up; the project's shared meshes, beside
#: the repository): its head is 1/8 of its height.
BODY = SHARED / "human-neutral.obj"
#: A cone on the top of the head: from a point inside the head, 60 degrees around +Y.
HEAD_CONE = {"cone": {"axis": [0, 1, 0], "half_angle_deg": 60, "apex": [0.0, 1.6, 0.0]}}
#: A turn and a move of the whole scan.
TURN = Rotation.from_euler("zyx", [0.7, -0.4, 1.9])
SHIFT = np.array([2.5, -0.8, 0.33])


def body() -> tuple[np.ndarray, np.ndarray]:
    if not BODY.exists():
        pytest.skip(f"{BODY} is not beside the repository")
    mesh = trimesh.load(BODY, process=False, force="mesh")
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)


async def post(client, route: str, data: bytes, params: dict) -> dict:
    answer = await client.post(
        route, files={"mesh": ("body.obj", data)}, data={"params": json.dumps(params)}
    )
    assert answer.status_code == 200, answer.text[:400]
    return answer.json()


async def test_a_cone_on_the_head_of_a_full_body_is_seen_from_inside_the_head(client):
    vertices, faces = body()
    data = obj_of(vertices, faces)
    answer = await post(client, "/v1/flatten", data, {"region": HEAD_CONE})
    validation = answer["validation"]
    assert validation["seam_free"] and validation["star_shaped"], validation
    # The head: every vertex above the shoulders (the neck starts about 1.45 m up).
    head = vertices[vertices[:, 1] > 1.5]
    centre = np.asarray(answer["params"]["center"])
    assert (head.min(axis=0) < centre).all() and (centre < head.max(axis=0)).all(), centre
    assert answer["params"]["region"] == {"cone": {**HEAD_CONE["cone"], "apex": [0.0, 1.6, 0.0]}}
    # Sent back, the answer's params give the same faces and centre.
    again = await post(client, "/v1/flatten", data, answer["params"])
    assert again["faces"]["ids"] == answer["faces"]["ids"]
    assert again["params"]["center"] == answer["params"]["center"]


async def test_a_cones_centres_are_those_of_the_faces_it_selects(client):
    """Without an apex the cone is taken from the whole body's box centre (the pelvis); the
    named centres are then those of the faces it selects, as a faces region of the same ids
    gets them."""
    vertices, faces = body()
    data = obj_of(vertices, faces)
    cone = {"cone": {"axis": [0, 1, 0], "half_angle_deg": 8}}
    for name in ("bbox_center", "centroid"):
        params = {"region": cone, "center": name, "rotation": "identity", "sigma": 0.3}
        answer = await post(client, "/v1/validate", data, params)
        ids = (await post(client, "/v1/flatten", data, answer["params"]))["faces"]["ids"]
        listed = await post(client, "/v1/validate", data, {**params, "region": {"faces": ids}})
        assert answer["params"]["center"] == listed["params"]["center"], name
        assert answer["params"]["center"][1] > 1.3, name  # high in the body: its upper part
    selected = vertices[faces[ids]].reshape(-1, 3)
    areas = trimesh.Trimesh(vertices, faces[ids], process=False).area_faces
    centroid = (vertices[faces[ids]].mean(axis=1) * areas[:, None]).sum(axis=0) / areas.sum()
    assert listed["params"]["center"] == pytest.approx(centroid.tolist(), rel=1e-9)
    assert (selected.min(axis=0) < centroid).all()


async def test_the_defaults_follow_a_turned_and_moved_scan(client):
    """Turned and moved, the scan gets the same faces, its cone's default apex and its
    box centre turned and moved with it."""
    vertices, faces = body()
    size = np.ptp(vertices, axis=0).max()
    moved = TURN.apply(vertices) + SHIFT
    cone = {"axis": [0.0, 1.0, 0.0], "half_angle_deg": 30.0}
    turned_cone = {"axis": TURN.apply(cone["axis"]).tolist(), "half_angle_deg": 30.0}
    params = {"region": {"cone": cone}, "rotation": "identity", "sigma": 0.3}
    first = await post(client, "/v1/flatten", obj_of(vertices, faces), params)
    second = await post(
        client, "/v1/flatten", obj_of(moved, faces), {**params, "region": {"cone": turned_cone}}
    )
    assert second["faces"]["ids"] == first["faces"]["ids"]
    for got, expected in (
        (second["params"]["center"], first["params"]["center"]),
        (second["params"]["region"]["cone"]["apex"], first["params"]["region"]["cone"]["apex"]),
    ):
        np.testing.assert_allclose(got, TURN.apply(expected) + SHIFT, rtol=0, atol=1e-9 * size)
    # The world axes' box of the turned scan has its middle elsewhere: the test can fail.
    world = (moved.min(axis=0) + moved.max(axis=0)) / 2
    box = (vertices.min(axis=0) + vertices.max(axis=0)) / 2
    assert np.linalg.norm(world - (TURN.apply(box) + SHIFT)) > 1e-3 * size


def test_the_box_centre_of_a_mirror_symmetric_surface_is_its_world_box_centre():
    """An ellipsoid's cap, mirror symmetric in x and in y: its principal axes are the world
    axes, so the box centre is the middle of the world axes' box; turned and moved, it
    follows."""
    sphere = trimesh.creation.icosphere(subdivisions=3)
    vertices = sphere.vertices * [1.0, 2.0, 3.0]
    faces = sphere.faces[vertices[sphere.faces].mean(axis=1)[:, 2] > 1.0]
    used = vertices[np.unique(faces)]
    expected = (used.min(axis=0) + used.max(axis=0)) / 2
    assert abs(expected[2] - 2.0) > 0.1  # not the middle of the whole ellipsoid
    np.testing.assert_allclose(select.bbox_center(vertices, faces), expected, atol=1e-12)
    turned = TURN.apply(vertices) + SHIFT
    np.testing.assert_allclose(
        select.bbox_center(turned, faces), TURN.apply(expected) + SHIFT, atol=1e-12
    )
