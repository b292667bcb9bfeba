"""The front of the head at the top of the map (docs/math.md, section 18): ``facing`` rolls
the frame about the pole, the same way in every pose; the landmarks do the same; what
cannot fix the roll, or contradicts a rotation given, is a 422 naming ``params.facing``."""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fixtures.landmarks import NEAR
from service.outputs.lookup import read_lookup
from service.samples import SAMPLES
from transforms import Chart, FitFixed, Frame, PoleCap, default_choice, fit_region, flatten_region
from transforms.fit.refine import _rotation_slopes, _rotations_from_pole_up
from transforms.frames import facing_across

from .conftest import load_sample, scalp
from .test_api import flatten, obj_of, problem

pytestmark = pytest.mark.anyio


@dataclass(frozen=True)
class Head:
    """A bundled head, where its face looks and a cone over its top (forehead, crown and
    back), from the mesh alone."""

    name: str
    top: np.ndarray  # the cone's axis
    front: int  # the axis along which the face looks: the nose's tip is furthest along it
    apex: tuple[float, float, float] | None  # None: the box centre

    @property
    def mesh(self) -> tuple[np.ndarray, np.ndarray]:
        return load_sample(self.name)

    @property
    def facing(self) -> np.ndarray:
        """From the vertices' mean to the nose's tip."""
        vertices = self.mesh[0]
        return vertices[np.argmax(vertices[:, self.front])] - vertices.mean(axis=0)

    @property
    def cone_apex(self) -> np.ndarray:
        vertices = self.mesh[0]
        box = (vertices.min(axis=0) + vertices.max(axis=0)) / 2
        return box if self.apex is None else np.asarray(self.apex)


HEADS = {
    "fsaverage-head.ply": Head("fsaverage-head.ply", np.array([0.0, 0.0, 1.0]), 1, None),
    # Y up, the face towards +Z; its box holds the shoulders, so the cone starts in the head.
    "lee-perry-smith.obj": Head("lee-perry-smith.obj", np.array([0.0, 1.0, 0.0]), 2,
                                (0.0, 1.5, 0.0)),
}  # fmt: skip
HEAD = HEADS["fsaverage-head.ply"]
NAME = HEAD.name
VERTICES, FACES = HEAD.mesh
FACING = HEAD.facing
APEX = HEAD.cone_apex

TURN = Rotation.from_rotvec([0.7, -1.9, 0.4])
SHIFT = np.array([40.0, -300.0, 17.0])

POSES = {
    "as scanned": (np.eye(3), np.zeros(3)),
    "turned and moved": (TURN.as_matrix(), SHIFT),
}


def posed(pose: str, extra: dict, head: Head = HEAD) -> tuple[dict, bytes, str]:
    """The request of a cone over the head with ``facing``, and the mesh, in ``pose``: the
    mesh, the cone and facing all turned (and the points moved) together."""
    turn, shift = POSES[pose]
    cone = {"axis": (turn @ head.top).tolist(), "half_angle_deg": 75.0,
            "apex": (turn @ head.cone_apex + shift).tolist()}  # fmt: skip
    params = {"region": {"cone": cone}, "center": "centroid",
              "facing": (turn @ head.facing).tolist(), **extra}  # fmt: skip
    if pose == "as scanned":
        return params, SAMPLES[head.name].path.read_bytes(), head.name
    vertices, faces = head.mesh
    return params, obj_of(vertices @ turn.T + shift, faces), "turned.obj"


def forehead(ids: np.ndarray, head: Head = HEAD, k: int = 12) -> np.ndarray:
    """Positions in ``ids`` of the ``k`` region vertices furthest along facing: the forehead."""
    return np.argsort(head.mesh[0][ids] @ head.facing)[-k:]


def expected_up(answer: dict) -> np.ndarray:
    """facing's part across the answer's pole, made unit, computed here."""
    pole = np.asarray(answer["params"]["rotation"][1])
    facing = np.asarray(answer["params"]["facing"])
    across = facing - (facing @ pole) * pole
    return across / np.linalg.norm(across)


@pytest.mark.parametrize("name", HEADS)
@pytest.mark.parametrize(
    "extra",
    [
        {},  # the default choice: pole and sigma by the rule, the roll by facing
        {"layout": "mercator"},
        {"center": "auto", "rotation": "auto", "sigma": "auto"},  # the fit
    ],
    ids=["default", "mercator", "fit"],
)
async def test_facing_puts_the_forehead_at_the_top_in_any_pose(client, extra, name):
    head = HEADS[name]
    vertices = head.mesh[0]
    answers = {}
    for pose in POSES:
        params, data, filename = posed(pose, extra, head)
        answer = (await flatten(client, filename, params, data=data)).json()
        answers[pose] = answer
        assert answer["validation"]["seam_free"]
        # The roll: local +Z is facing's part across the pole.
        np.testing.assert_allclose(answer["params"]["rotation"][2], expected_up(answer),
                                   atol=1e-9)  # fmt: skip
        theta = np.asarray(answer["vertices"]["theta"])
        ids = np.asarray(answer["vertices"]["ids"])
        # The pictures' rows grow with theta (both layouts): the forehead in the top half.
        middle = (theta.min() + theta.max()) / 2
        assert (theta[forehead(ids, head)] < middle).all()
        # Exactly the vertices on the face's side of the plane through the centre and the
        # pole lie above theta = pi/2 (the warp keeps the sign of local z).
        turn, shift = POSES[pose]
        points = (vertices[ids] @ turn.T + shift) - answer["params"]["center"]
        ahead = points @ expected_up(answer)
        clear = np.abs(ahead) > 1e-9 * np.abs(points).max()
        assert ((theta[clear] < np.pi / 2) == (ahead[clear] > 0)).all()
    here, there = answers["as scanned"], answers["turned and moved"]
    np.testing.assert_allclose(here["params"]["facing"], head.facing / np.linalg.norm(head.facing))
    assert here["vertices"]["ids"] == there["vertices"]["ids"]
    for coordinate in ("x", "y"):
        np.testing.assert_allclose(there["vertices"][coordinate], here["vertices"][coordinate],
                                   atol=1e-7)  # fmt: skip
    assert there["params"]["sigma"] == pytest.approx(here["params"]["sigma"], rel=1e-7)


async def test_the_forehead_is_in_the_top_half_of_the_picture_in_both_poses(client):
    """The look-up image of face ids (the PNG answer's pixels, rows down): the forehead's
    triangles cover rows above the middle of the map's rows, alike in both poses."""
    rows = {}
    for pose in POSES:
        params, data, name = posed(pose, {"output": "face_ids", "image_width": 600,
                                          "image_height": 400})  # fmt: skip
        form = {"mesh": (name, data)}
        lookup = await client.post("/v1/transfer", files=form, data={"params": json.dumps(params)})
        ids, _ = read_lookup(lookup.content)
        region = ids >= 0
        covered = np.flatnonzero(region.any(axis=1))
        shown_vertices = np.unique(FACES[np.unique(ids[region])])
        front = shown_vertices[forehead(shown_vertices)]
        front_faces = np.flatnonzero(np.isin(FACES, front).any(axis=1))
        shown = np.isin(ids, front_faces)
        assert shown.any()
        rows[pose] = np.flatnonzero(shown.any(axis=1))
        assert rows[pose].max() < (covered.min() + covered.max()) / 2
    assert abs(rows["as scanned"].mean() - rows["turned and moved"].mean()) <= 1.0


async def test_facing_along_the_pole_is_a_422_naming_params_facing(client):
    given = {"rotation": {"pole": [0, 0, -1], "up": [0, 1, 0]}, "sigma": 0.5}
    for facing in ([0, 0, 1], [0, 0.01, -1]):  # the pole's opposite, 0.6 degrees from it
        body = problem(await flatten(client, NAME, {**given, "facing": facing}), 422,
                       "params.facing")  # fmt: skip
        assert "at least 1 needed" in body["detail"]
    # The pole chosen (by the default rule) lies along facing: refused, not rolled at random.
    params = posed("as scanned", {})[0]
    unfaced = {key: value for key, value in params.items() if key != "facing"}
    pole = (await flatten(client, NAME, unfaced)).json()["params"]["rotation"][1]
    params["facing"] = pole
    body = problem(await flatten(client, NAME, params), 422, "params.facing")
    assert "degrees from the pole" in body["detail"]
    problem(await flatten(client, NAME, {"facing": [0, 0, 0]}), 422, "params.facing")


async def test_a_rotation_given_must_agree_with_facing(client):
    params, data, name = posed("as scanned", {})
    answer = (await flatten(client, name, params, data=data)).json()
    # The answer's params (rotation matrix, facing, sigma) sent back: the same map.
    again = (await flatten(client, name, answer["params"], data=data)).json()
    assert again["vertices"]["x"] == answer["vertices"]["x"]
    assert again["vertices"]["y"] == answer["vertices"]["y"]
    # A rotation whose +Z is 90 degrees from facing's part across its pole: refused.
    rolled = {**params, "rotation": {"pole": answer["params"]["rotation"][1],
                                     "up": answer["params"]["rotation"][0]}}  # fmt: skip
    body = problem(await flatten(client, name, rolled, data=data), 422, "params.facing")
    assert "90 degrees from facing" in body["detail"]
    problem(await flatten(client, name, {**params, "rotation": "identity"}, data=data), 422,
            "params.facing")  # fmt: skip


async def test_facing_beside_landmarks_or_an_up_hint_is_refused(client):
    landmarks = on_head()
    both = {"frame": {"landmarks": landmarks}, "facing": FACING.tolist()}
    body = problem(await flatten(client, NAME, both), 422, "params.facing")
    assert "leave out facing" in body["detail"]
    hinted = {"rotation": {"pole": "auto", "up": [0, 1, 0]}, "facing": FACING.tolist()}
    problem(await flatten(client, NAME, hinted), 422, "params.facing")


def on_head() -> dict[str, list[float]]:
    """The fsaverage vertices nearest the landmarks' places."""
    return {
        name: VERTICES[np.argmin(np.linalg.norm(VERTICES - np.asarray(place), axis=1))].tolist()
        for name, place in NEAR.items()
    }


@pytest.mark.parametrize("how", ["frame", "scalp"])
async def test_landmarks_put_the_nasion_at_the_top(client, how):
    """A landmark frame, or a scalp by landmarks with the rotation left to meshflat: local
    +Z along the forward direction (nasion minus inion, across the tragi), which the answer
    gives as facing; the vertices nearest the nasion in the top half of the map."""
    landmarks = on_head()
    scalp_region = {"scalp": {"landmarks": landmarks, "units": "mm", "offset_mm": -15.0}}
    params = {"region": scalp_region}
    if how == "frame":
        params["frame"] = {"landmarks": landmarks}
    answer = (await flatten(client, NAME, params)).json()
    points = {name: np.asarray(p) for name, p in landmarks.items()}
    right = points["right_tragus"] - points["left_tragus"]
    right /= np.linalg.norm(right)
    along = points["nasion"] - points["inion"]
    forward = along - (along @ right) * right
    forward /= np.linalg.norm(forward)
    np.testing.assert_allclose(answer["params"]["facing"], forward, atol=1e-12)
    np.testing.assert_allclose(answer["params"]["rotation"][2], expected_up(answer), atol=1e-9)
    ids, theta = np.asarray(answer["vertices"]["ids"]), np.asarray(answer["vertices"]["theta"])
    near_nasion = np.argsort(np.linalg.norm(VERTICES[ids] - points["nasion"], axis=1))[:5]
    assert (theta[near_nasion] < (theta.min() + theta.max()) / 2).all()
    # Sent back (rotation, facing, the region), the same map.
    again = (await flatten(client, NAME, answer["params"])).json()
    assert again["vertices"]["y"] == answer["vertices"]["y"]


# -- the core ---------------------------------------------------------------------------------


def test_a_roll_about_the_pole_changes_the_energy_every_half_turn():
    """The chart is not symmetric about the pole (eq. 1's axis is local Z): a quarter turn
    of the roll changes the region's energy; a half turn, (x, z) -> (-x, -z), mirrors the
    map through its middle and keeps it."""
    vertices, faces = scalp()
    fit = default_choice(vertices, faces, FitFixed(center=APEX))
    axes, chart = fit.frame.rotation, Chart.distorted(PoleCap.from_sigma(fit.chart.cap.sigma))
    energies = [
        flatten_region(vertices, faces, Frame.from_pole_up(axes[1], up, APEX),
                       chart).distortion.isometric.mean
        for up in (axes[2], axes[0], -axes[2])
    ]  # fmt: skip
    assert abs(energies[1] - energies[0]) > 1e-3
    assert energies[2] == pytest.approx(energies[0], rel=1e-9)


def test_the_fit_keeps_the_roll_facing_fixes_as_the_pole_tilts():
    """The refinement tilts the pole; local +Z stays facing's part across it (computed
    here), not the start's +Z carried along."""
    vertices, faces = scalp()
    fit = fit_region(vertices, faces, FitFixed(up=FACING))
    start = default_choice(vertices, faces, FitFixed(center=fit.frame.center, up=FACING))
    pole = fit.frame.rotation[1]
    assert np.degrees(np.arccos(np.clip(pole @ start.frame.rotation[1], -1, 1))) > 0.5
    across = FACING - (FACING @ pole) * pole
    np.testing.assert_allclose(fit.frame.rotation[2], across / np.linalg.norm(across),
                               atol=1e-12)  # fmt: skip
    np.testing.assert_allclose(facing_across(pole, FACING), across / np.linalg.norm(across),
                               atol=1e-15)  # fmt: skip


def test_the_rolls_slope_holds_for_a_facing_not_square_to_the_pole():
    """The refinement's gradient turns the frame by (18.1) with facing as it is, slanted to
    the pole: its closed form against central differences of the rotations themselves."""
    pole = np.array([0.1, -0.2, -1.0])
    turns = np.array([[1.0, 0.3, 0.0], [0.0, 0.2, 1.0]])
    slopes = _rotation_slopes(pole, FACING, turns)
    step = 1e-6
    for turn, slope in zip(turns, slopes, strict=True):
        ahead = _rotations_from_pole_up((pole + step * turn)[None], FACING)[0]
        behind = _rotations_from_pole_up((pole - step * turn)[None], FACING)[0]
        np.testing.assert_allclose(slope, (ahead - behind) / (2 * step), atol=1e-8)
    # And at the pole itself the batch is (18.1).
    rotation = _rotations_from_pole_up(pole[None], FACING)[0]
    np.testing.assert_allclose(rotation[2], facing_across(pole, FACING), atol=1e-15)
