"""A frame that belongs to the head (transforms.landmarks; docs/math.md, section 14): the
centre, pole and roll from the nasion, the inion and the tragi, the same in any pose; the
anatomical scalp region; and both through the API."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fixtures.landmarks import NEAR, NEAR_LEE_PERRY_SMITH
from transforms import Chart, Landmarks, PoleCap, TransformInputError, flatten_region
from transforms.landmarks import CENTER_RAISE, OFF_SURFACE, distance_to_triangles
from transforms.topology import face_components

from .conftest import load_sample, sphere_mesh
from .test_api import flatten, obj_of, problem

NAME = "fsaverage-head.ply"
VERTICES, FACES = load_sample(NAME)

CHART = Chart.distorted(PoleCap.from_sigma(0.3))


def on_head(vertices: np.ndarray = VERTICES) -> dict[str, list[float]]:
    """The fsaverage vertices nearest the landmarks' places: points of its surface."""
    return {
        name: vertices[np.argmin(np.linalg.norm(vertices - np.asarray(place), axis=1))].tolist()
        for name, place in NEAR.items()
    }


TURN = Rotation.from_euler("zyx", [1.1, -0.5, 2.3])
SHIFT = np.array([310.0, -45.0, 12.5])


def moved(points) -> np.ndarray:
    return TURN.apply(np.array(points, dtype=float)) + SHIFT


# -- the core ---------------------------------------------------------------------------------


def test_the_frame_is_the_anatomical_rule():
    landmarks = Landmarks.of(on_head())
    right, forward, up = landmarks.axes()
    np.testing.assert_allclose(np.stack([right, forward, up]) @ np.stack([right, forward, up]).T,
                               np.eye(3), atol=1e-12)  # fmt: skip
    assert up[2] > 0.9 and forward[1] > 0.9 and right[0] > 0.9  # fsaverage: +z up, +y front
    frame = landmarks.frame()
    expected = landmarks.midpoint + CENTER_RAISE * landmarks.width * up
    np.testing.assert_allclose(frame.center, expected)
    # The pole (local +Y) down the neck, local +Z towards the nasion.
    np.testing.assert_allclose(frame.rotation[1], -up, atol=1e-12)
    nasion = frame.to_local(np.asarray([landmarks.nasion]))[0]
    aside = np.dot(landmarks.nasion - landmarks.midpoint, right)  # off the tragi's mid-plane
    assert nasion[2] > 0 and nasion[0] == pytest.approx(aside, abs=1e-9)


def test_the_same_landmarks_in_another_pose_give_the_same_local_coordinates():
    """Move and turn the head with its landmarks: every point keeps its local coordinates."""
    here = Landmarks.of(on_head()).frame()
    there = Landmarks.of({k: moved(v) for k, v in on_head().items()}).frame()
    np.testing.assert_allclose(there.to_local(moved(VERTICES)), here.to_local(VERTICES), atol=1e-9)


@pytest.mark.parametrize(
    ("change", "field", "words"),
    [
        ({"inion": None}, "landmarks.inion", "missing"),
        ({"right_tragus": "left_tragus"}, "landmarks.right_tragus", "coincides with left_tragus"),
        ({"nasion": "between the tragi"}, "landmarks.nasion", "on the line through the tragi"),
        ({"vertex": "below"}, "landmarks.vertex", "may be swapped"),
    ],
)
def test_bad_landmarks_are_named(change, field, words):
    points = on_head()
    left, right = np.asarray(points["left_tragus"]), np.asarray(points["right_tragus"])
    for name, value in change.items():
        if value == "left_tragus":
            points[name] = (left + 1e-3).tolist()
        elif value == "between the tragi":
            points[name] = (0.3 * left + 0.7 * right).tolist()
        elif value == "below":
            points[name] = [0, -20, -150]
        else:
            points[name] = value
    with pytest.raises(TransformInputError) as caught:
        Landmarks.of(points)
    assert caught.value.field == field and words in str(caught.value)


def test_a_landmark_off_the_surface_is_named_with_the_tolerance():
    landmarks = Landmarks.of(on_head())
    landmarks.check_on_surface(VERTICES, FACES)  # vertices of the mesh: on it
    points = on_head()
    points["nasion"] = (np.asarray(points["nasion"]) + np.array([0, 30, 0])).tolist()  # in front
    with pytest.raises(TransformInputError) as caught:
        Landmarks.of(points).check_on_surface(VERTICES, FACES)
    assert caught.value.field == "landmarks.nasion"
    assert f"({OFF_SURFACE:.0%} of the tragi's distance)" in str(caught.value)


def test_the_distance_to_triangles_is_the_least_over_their_points():
    vertices, faces = sphere_mesh(8, 12)
    rng = np.random.default_rng(3)
    corners = vertices[faces]
    weights = rng.dirichlet([1, 1, 1], (len(faces), 400))
    samples = np.einsum("mpk,mkd->mpd", weights, corners).reshape(-1, 3)
    for point in rng.normal(size=(6, 3)) * 1.4:
        distance = distance_to_triangles(point, vertices, faces)
        brute = np.linalg.norm(samples - point, axis=1).min()
        assert distance <= brute + 1e-12 and brute - distance < 5e-3


def test_the_scalp_is_above_the_brow_and_the_inion_and_shrinks_as_the_offset_grows():
    landmarks = Landmarks.of(on_head())
    counts = [len(landmarks.scalp_faces(VERTICES, FACES, offset)) for offset in (0, 10, 30)]
    assert counts[0] > counts[1] > counts[2] > 0
    faces = landmarks.scalp_faces(VERTICES, FACES, 10.0)
    centroids = VERTICES[FACES[faces]].mean(axis=1)
    assert centroids[:, 2].min() > -40  # above the neck and the chin
    there = Landmarks.of({k: moved(v) for k, v in on_head().items()})
    np.testing.assert_array_equal(there.scalp_faces(moved(VERTICES), FACES, 10.0), faces)


def test_the_scalp_is_one_piece_that_the_landmark_frame_sees_whole():
    """Lee Perry-Smith's eye sockets and the tops of his ears rise above the boundary plane
    apart from the scalp; left in, they fold on the map."""
    vertices, faces = load_sample("lee-perry-smith.obj")
    points = {
        name: vertices[np.argmin(np.linalg.norm(vertices - np.asarray(spot), axis=1))]
        for name, spot in NEAR_LEE_PERRY_SMITH.items()
    }
    landmarks = Landmarks.of(points)
    region = landmarks.scalp_faces(vertices, faces, landmarks.width * 10 / 145)
    pieces = face_components(faces[region])
    assert len(region) > 1000 and len(np.unique(pieces)) == 1
    flat = flatten_region(vertices, faces[region], landmarks.frame(), CHART)
    check = flat.validation
    assert check.seam_free and check.star_shaped and check.boundary_loops == 1


def test_a_triangle_soup_gets_the_same_scalp():
    """An STL keeps each triangle's own corners: the scalp's piece is found by position."""
    landmarks = Landmarks.of(on_head())
    soup = np.asarray(VERTICES)[FACES].reshape(-1, 3)
    faces = np.arange(len(soup)).reshape(-1, 3)
    np.testing.assert_array_equal(
        landmarks.scalp_faces(soup, faces, 10.0), landmarks.scalp_faces(VERTICES, FACES, 10.0)
    )


# -- the API ----------------------------------------------------------------------------------


@pytest.mark.anyio
@pytest.mark.parametrize("sigma", [0.3, "auto"])
async def test_two_poses_of_a_head_get_the_same_map(client, sigma):
    """The same head in two poses, each with its landmarks: the same scalp faces and the same
    map (x, y) within rounding; with sigma "auto" only sigma is fitted, to the same value."""
    landmarks = on_head()
    scalp = {"scalp": {"landmarks": landmarks, "units": "mm"}}
    params = {"frame": {"landmarks": landmarks}, "sigma": sigma, "region": scalp}
    here = (await flatten(client, NAME, params)).json()
    turned = {k: moved(v).tolist() for k, v in landmarks.items()}
    params = {"frame": {"landmarks": turned}, "sigma": sigma,
              "region": {"scalp": {"landmarks": turned, "units": "mm"}}}  # fmt: skip
    data = obj_of(moved(VERTICES), FACES)
    there = (await flatten(client, "turned.obj", params, data=data)).json()
    assert here["faces"]["ids"] == there["faces"]["ids"]
    assert here["validation"]["seam_free"] and here["validation"]["star_shaped"]
    np.testing.assert_allclose(there["vertices"]["x"], here["vertices"]["x"], atol=1e-9)
    np.testing.assert_allclose(there["vertices"]["y"], here["vertices"]["y"], atol=1e-9)
    assert there["params"]["sigma"] == pytest.approx(here["params"]["sigma"], rel=1e-9)
    frame = Landmarks.of(landmarks).frame()
    np.testing.assert_allclose(here["params"]["center"], frame.center)
    np.testing.assert_allclose(here["params"]["rotation"], frame.rotation, atol=1e-12)
    # The answer's params, sent back, draw the same map.
    again = (await flatten(client, NAME, here["params"])).json()
    assert again["vertices"]["x"] == here["vertices"]["x"]


@pytest.mark.anyio
async def test_bad_landmark_requests_are_422s_naming_the_landmark(client):
    landmarks = on_head()
    both = {"frame": {"landmarks": landmarks}, "center": [0, 0, 0]}
    body = problem(await flatten(client, NAME, both), 422)
    assert "leave out center" in body["detail"]
    off = {**landmarks, "inion": (np.asarray(landmarks["inion"]) - np.array([0, 40, 0])).tolist()}
    body = problem(
        await flatten(client, NAME, {"frame": {"landmarks": off}}), 422,
        "params.frame.landmarks.inion",
    )  # fmt: skip
    assert "from the surface; at most" in body["detail"]
    scalp = {"region": {"scalp": {"landmarks": landmarks}}}
    problem(await flatten(client, NAME, scalp), 422, "params.region.scalp.units")
    swapped = {**landmarks, "left_tragus": landmarks["right_tragus"],
               "right_tragus": landmarks["left_tragus"]}  # fmt: skip
    body = problem(
        await flatten(client, NAME, {"frame": {"landmarks": swapped}}), 422,
        "params.frame.landmarks.vertex",
    )  # fmt: skip
    # A known distance for the scale: the tragi's, as callipers measure it.
    width = float(np.linalg.norm(np.subtract(landmarks["right_tragus"], landmarks["left_tragus"])))
    known = {"between": [landmarks["left_tragus"], landmarks["right_tragus"]], "mm": width}
    by_distance = {"region": {"scalp": {"landmarks": landmarks, "units": known}}}
    by_unit = {"region": {"scalp": {"landmarks": landmarks, "units": "mm"}}}
    first = (await flatten(client, NAME, by_distance)).json()["faces"]["ids"]
    assert first == (await flatten(client, NAME, by_unit)).json()["faces"]["ids"]
