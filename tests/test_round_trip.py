"""The ``params`` of any mesh answer, sent back with the same mesh to any mesh route, select
the identical faces and give identical numbers: on every bundled scan, every kind of region
and every mesh route, starting from a fitted centre (the case where a cone taken around the
centre used to select other faces)."""

from __future__ import annotations

import json
import math

import httpx
import pytest

from service.app import create_app
from service.meshio import format_of, read_mesh
from service.samples import SAMPLES
from service.settings import Settings

from .conftest import slow

pytestmark = pytest.mark.anyio

#: The top of each scan (its scalp's side) as a cone axis.
TOPS = {
    "fsaverage-head.ply": [0, 0, 1],
    "lee-perry-smith.glb": [0, 1, 0],
    "lee-perry-smith.obj": [0, 1, 0],
    "nefertiti-lowres.obj": [0, 0, 1],
}
#: The scans whose round trip takes over 4 s on a core (the others: about 1 s).
SLOW = ("lee-perry-smith.glb", "lee-perry-smith.obj", "nefertiti-lowres.obj")
ROUTES = ("/v1/flatten", "/v1/validate", "/v1/fit", "/v1/locate")
#: Directions asked of /v1/locate: about the middle of the map, and one into the cap.
QUERIES = {"theta": [math.pi / 2, 1.2, 0.0], "phi": [-math.pi / 2, -1.0, 0.0]}
#: What an answer's numbers are, by route.
NUMBERS = {
    "/v1/flatten": ("vertices", "faces", "validation", "metrics", "untangle"),
    "/v1/validate": ("validation", "metrics", "untangle"),
    "/v1/fit": ("validation", "metrics", "untangle"),
    "/v1/locate": ("hits",),
}


@pytest.fixture(scope="module")
def app():
    return create_app(Settings())


@pytest.fixture
async def client(app):
    transport = httpx.ASGITransport(app=app)
    async with httpx.AsyncClient(transport=transport, base_url="http://m", timeout=120) as c:
        yield c


async def post(client, route: str, name: str, params: dict) -> dict:
    if route == "/v1/locate":
        params = {**params, **QUERIES}
    data = SAMPLES[name].path.read_bytes()
    answer = await client.post(
        route, files={"mesh": (name, data)}, data={"params": json.dumps(params)}
    )
    assert answer.status_code == 200, (route, name, answer.text[:300])
    return answer.json()


async def regions(client, name: str) -> dict[str, dict | None]:
    """Every kind of region on ``name``: a cone over its top, a part of that cone as face ids
    and as vertex ids, a group of the file (when it has one), and the whole mesh."""
    cone = {"cone": {"axis": TOPS[name], "half_angle_deg": 50}}
    selected = await post(client, "/v1/flatten", name, {"region": cone, "rotation": "identity"})
    faces = selected["faces"]["ids"][::3]
    kinds = {
        "cone": cone,
        "faces": {"faces": faces},
        "vertices": {"vertices": sorted({v for f in selected["faces"]["vertices"] for v in f})},
        "whole mesh": None,
    }
    mesh = read_mesh(SAMPLES[name].path.read_bytes(), format_of(name, None), Settings().limits)
    if mesh.groups:
        kinds["groups"] = {"groups": [sorted(mesh.groups)[0]]}
    return kinds


@pytest.mark.parametrize(
    "name", [pytest.param(name, marks=slow) if name in SLOW else name for name in SAMPLES]
)
async def test_sent_back_params_select_the_same_faces_and_give_the_same_numbers(client, name):
    for kind, region in (await regions(client, name)).items():
        first = {"region": region, "center": "auto"}  # the fit moves the centre
        if kind == "cone":
            first["untangle"] = True  # and a layout repaired comes back repaired
        expected_faces = None
        for route in ROUTES:
            answer = await post(client, route, name, first)
            again = await post(client, route, name, answer["params"])
            where = (name, kind, route)
            assert again["params"] == answer["params"], where
            for key in NUMBERS[route]:
                assert again.get(key) == answer.get(key), (*where, key)
            # The same faces, whichever route the params came from.
            faces = (await post(client, "/v1/flatten", name, answer["params"]))["faces"]["ids"]
            expected_faces = faces if expected_faces is None else expected_faces
            assert faces == expected_faces, where


async def test_a_cones_apex_defaults_to_the_box_centre_whatever_the_centre(client):
    """The apex is the whole mesh's box centre (in its principal axes, as the whole mesh's
    bbox_center), whatever the centre is."""
    name = "lee-perry-smith.glb"
    cone = {"axis": [0, 1, 0], "half_angle_deg": 60}
    near = await post(
        client, "/v1/flatten", name, {"region": {"cone": cone}, "center": [0, 1.2, 0]}
    )
    far = await post(client, "/v1/flatten", name, {"region": {"cone": cone}, "center": [0, 0, 0]})
    assert near["faces"]["ids"] == far["faces"]["ids"]
    apex = near["params"]["region"]["cone"]["apex"]
    whole = {"center": "bbox_center", "rotation": "identity", "sigma": 0.3}
    box = (await post(client, "/v1/validate", name, whole))["params"]["center"]
    assert apex == box
    # An apex inside the skull takes the scalp without the shoulders.
    inside = await post(
        client, "/v1/flatten", name, {"region": {"cone": {**cone, "apex": [0, 1.2, -0.3]}}}
    )
    assert len(inside["faces"]["ids"]) != len(near["faces"]["ids"])
