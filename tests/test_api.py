"""The HTTP API through httpx against the app, on the bundled scans, checked against the core
on the same data."""

from __future__ import annotations

import base64
import json
import math

import anyio
import httpx
import numpy as np
import pytest
import trimesh

from service.app import create_app
from service.jsonkeys import repeated_key
from service.samples import SAMPLES
from service.settings import Settings
from transforms import Chart, Frame, PoleCap, flatten_region, world_to_angles

from .conftest import grid_mesh, load_sample
from .test_locate import brute_force

pytestmark = pytest.mark.anyio


def world_box_middle(name: str) -> list[float]:
    """The middle of a sample's box in the world axes."""
    vertices = load_sample(name)[0]
    return ((vertices.min(axis=0) + vertices.max(axis=0)) / 2).tolist()


#: The FreeSurfer head is star-shaped from the middle of its box in the world axes: the
#: scalp's centre and its cone's apex, given (the defaults are tests/test_centres.py's).
HEAD_BOX = world_box_middle("fsaverage-head.ply")
SCALP = {
    "fsaverage-head.ply": {
        "center": HEAD_BOX,
        "sigma": 0.3,
        "rotation": {"pole": [0, 0, -1], "up": [0, 1, 0]},
        "region": {"cone": {"axis": [0, 0, 1], "half_angle_deg": 70, "apex": HEAD_BOX}},
    },
    "lee-perry-smith.glb": {
        "center": [0.0, 1.2, -0.3],
        "sigma": 0.3,
        "rotation": {"pole": [0, -1, 0], "up": [0, 0, 1]},
        # The box centre holds the shoulders: the cone starts inside the skull.
        "region": {"cone": {"axis": [0, 1, 0], "half_angle_deg": 60, "apex": [0.0, 1.2, -0.3]}},
    },
}


async def flatten(client, name, params=None, data=None, filename=None, endpoint="/v1/flatten"):
    data = SAMPLES[name].path.read_bytes() if data is None else data
    fields = {"params": json.dumps(params)} if params is not None else {}
    return await client.post(endpoint, files={"mesh": (filename or name, data)}, data=fields)


def problem(response, status, field=None):
    assert response.status_code == status, response.text
    assert response.headers["content-type"] == "application/problem+json"
    body = response.json()
    assert body["status"] == status and body["detail"] and body["type"].startswith("urn:")
    if field is not None:
        assert body.get("field") == field, body
    return body


def obj_of(vertices, faces) -> bytes:
    """An OBJ file of vertices (n, 3) and faces (m, 3), 0-based."""
    lines = [f"v {float(x)!r} {float(y)!r} {float(z)!r}" for x, y, z in vertices]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    return ("\n".join(lines) + "\n").encode()


# -- health and samples ------------------------------------------------------------------


async def test_health_and_readiness(client):
    assert (await client.get("/healthz")).json() == {"status": "ok"}
    assert (await client.get("/readyz")).status_code == 200


async def test_readiness_waits_for_the_self_check():
    app = create_app(Settings())  # lifespan not run
    transport = httpx.ASGITransport(app=app)
    async with httpx.AsyncClient(transport=transport, base_url="http://m") as c:
        problem(await c.get("/readyz"), 503)


async def test_samples_are_listed_with_counts_and_credits(client):
    listed = (await client.get("/v1/samples")).json()
    assert [s["name"] for s in listed] == list(SAMPLES)
    for sample in listed:
        vertices, faces = load_sample(sample["name"])
        assert sample["faces"] == len(faces) and sample["vertices"] == len(vertices)
        assert sample["credit"] and sample["licence"]
        download = await client.get(sample["url"])
        assert download.status_code == 200
        assert download.content == SAMPLES[sample["name"]].path.read_bytes()
    problem(await client.get("/v1/samples/missing.obj"), 404, "name")


# -- points ------------------------------------------------------------------------------


async def test_points_match_the_core_and_invert(client):
    rng = np.random.default_rng(20)
    points = rng.normal(size=(500, 3)).tolist()
    params = {
        "sigma": 0.4,
        "center": [0.1, 0.2, 0.3],
        "rotation": {"pole": [0, 0, -1], "up": [0, 1, 0]},
    }
    response = await client.post("/v1/points", json={"points": points, **params})
    assert response.status_code == 200
    assert {"parse", "compute", "encode"} <= {
        part.split(";")[0].strip() for part in response.headers["server-timing"].split(",")
    }
    got = response.json()
    frame = Frame.from_pole_up([0, 0, -1], [0, 1, 0], [0.1, 0.2, 0.3])
    theta, phi, r = world_to_angles(points, frame, Chart.distorted(PoleCap.from_sigma(0.4)))
    assert np.array_equal(got["theta"], theta) and np.array_equal(got["phi"], phi)
    assert np.array_equal(got["r"], r)
    back = await client.post(
        "/v1/points/inverse",
        json={"theta": got["theta"], "phi": got["phi"], "r": got["r"], **params},
    )
    assert back.status_code == 200
    assert np.allclose(back.json()["points"], points, atol=1e-9)


@pytest.mark.parametrize("method", ["standard", "separable", "distorted"])
async def test_every_method_and_the_pole_angle(client, method):
    params = (
        {"method": method} if method == "standard" else {"method": method, "pole_angle_deg": 40}
    )
    response = await client.post("/v1/points", json={"points": [[1, -2, 0.5]], **params})
    cap = PoleCap.from_rho_deg(40)
    chart = Chart.standard() if method == "standard" else Chart.from_method(method, cap)
    theta, phi, _ = chart.forward([[1, -2, 0.5]])
    assert response.json()["theta"] == [theta[0]] and response.json()["phi"] == [phi[0]]


@pytest.mark.parametrize(
    ("body", "field"),
    [
        ({"points": [[0, 0, 0]]}, "points"),
        ({"points": [[1, 0, 0]], "sigma": 0.3, "pole_angle_deg": 30}, None),
        ({"points": [[1, 0, 0]], "method": "standard", "sigma": 0.3}, None),
        ({"points": [[1, 0, 0]], "sigma": -1}, "sigma"),
        ({"points": [[1, 0, 0]], "sigma": 1e9}, "sigma"),
        ({"points": [[1, 0, 0]], "pole_angle_deg": 180}, "pole_angle_deg"),
        ({"points": [[1, 0]]}, "points.0"),
        ({"points": []}, "points"),
        ({"points": [[1, 0, 0]], "rotation": [[1, 0, 0], [0, 1, 0], [0, 0, -1]]}, "rotation"),
        ({"points": [[1, 0, 0]], "rotation": {"pole": [0, 1, 0], "up": [0, 2, 0]}}, "rotation.up"),
        ({"points": [[1, 0, 0]], "method": "conformal"}, "method"),
        ({"points": [[1, 0, 0]], "extra": 1}, "extra"),
    ],
)
async def test_bad_point_requests_name_the_field(client, body, field):
    body = problem(await client.post("/v1/points", json=body), 422, field)
    if field is None:
        assert "sigma, pole_angle_deg" in body["detail"]


async def test_nan_and_infinity_are_refused(client):
    body = '{"points": [[1, 0, NaN]]}'
    headers = {"content-type": "application/json"}
    problem(await client.post("/v1/points", content=body, headers=headers), 422)


async def test_inverse_checks_ranges(client):
    response = await client.post("/v1/points/inverse", json={"theta": [4.0], "phi": [0.0]})
    problem(response, 422, "theta")


@pytest.mark.parametrize(
    ("body", "says"),
    [
        ({"theta": [1.0, 2.0], "phi": [0.0]}, "got 2 theta and 1 phi"),
        ({"theta": [1.0], "phi": [0.0], "r": [1.0, 2.0]}, "got 1 theta and 2 r"),
    ],
)
async def test_inverse_needs_one_value_per_point(client, body, says):
    assert says in problem(await client.post("/v1/points/inverse", json=body), 422)["detail"]


async def test_points_need_a_json_body(client):
    response = await client.post(
        "/v1/points", content=b"points=1", headers={"content-type": "text/plain"}
    )
    assert "application/json" in problem(response, 415)["detail"]
    problem(await client.post("/v1/points", content=b"{"), 415)
    broken = await client.post(
        "/v1/points", content=b"{", headers={"content-type": "application/json"}
    )
    assert "JSON" in problem(broken, 422)["detail"]


@pytest.mark.parametrize(
    ("path", "body", "field"),
    [
        (
            "/v1/points",
            b'{"points": [[1, 2, 3]], "center": [0, 0, 0], "center": [1, 1, 1]}',
            "center",
        ),
        (
            "/v1/points",
            b'{"points": [[1, 2, 3]], "rotation": {"pole": [0, 0, 1], "up": [0, 1, 0], '
            b'"pole": [0, 0, -1]}}',
            "rotation.pole",
        ),
        # The same key spelt with an escape is the same key.
        ("/v1/points", b'{"points": [[1, 2, 3]], "sigma": 0.3, "\\u0073igma": 0.5}', "sigma"),
        # Refused even where the value kept would be invalid: the repeat is the fault.
        ("/v1/points/inverse", b'{"theta": [1], "phi": [-1], "sigma": 0.3, "sigma": -1}', "sigma"),
    ],
)
async def test_a_json_body_repeating_a_key_is_refused_naming_its_path(client, path, body, field):
    headers = {"content-type": "application/json"}
    detail = problem(await client.post(path, content=body, headers=headers), 422, field)["detail"]
    assert detail.startswith(f"{field}: given more than once in one JSON object")


@pytest.mark.parametrize(
    ("document", "path"),
    [
        (b'{"a": 1, "b": {"a": 2}}', None),  # one "a" per object
        (b'[{"a": 1}, {"a": 2}]', None),
        (b'{"a": "{\\"b\\": 1, \\"b\\": 2}", "b": ["b", "b"]}', None),  # in strings
        (b'{"e1": 1, "E2": 2, "a.5": 3, "a-6": 4}', None),  # digits, signs, exponents
        (b'{"p": [[1, 2], [3, 4]], "q": [{"k": 1}, [5], {"k": 2, "k": 3}]}', ("q", 2, "k")),
        (b'{"r": {"s": [1, {"t": 0, "t": 1}]}}', ("r", "s", 1, "t")),
        (b'{"\\u00e9": 1, "\xc3\xa9": 2}', ("\u00e9",)),  # one key, two spellings
    ],
)
def test_a_repeated_key_is_found_within_one_object_only(document, path):
    json.loads(document)  # valid JSON, as the check is given
    assert repeated_key(document) == path


async def test_standard_answers_no_cap_and_its_params_can_be_sent_back(client):
    first = await flatten(client, "fsaverage-head.ply", {"method": "standard"})
    params = first.json()["params"]
    assert params["sigma"] is None and params["pole_angle_deg"] is None
    again = await flatten(client, "fsaverage-head.ply", params)
    assert again.status_code == 200 and again.json()["params"] == params


# -- flatten and validate ------------------------------------------------------------------


@pytest.mark.parametrize("name", list(SCALP))
async def test_flatten_a_scalp_matches_the_core(client, name):
    params = SCALP[name]
    response = await flatten(client, name, params)
    assert response.status_code == 200, response.text
    body = response.json()
    vertices, faces = load_sample(name)
    # The same computation straight from the core on the same file read by trimesh.
    center = np.asarray(body["params"]["center"])
    rotation = params["rotation"]
    frame = Frame.from_pole_up(rotation["pole"], rotation["up"], center)
    chart = Chart.distorted(PoleCap.from_sigma(0.3))
    region = np.asarray(body["faces"]["ids"])
    flat = flatten_region(vertices, faces[region], frame, chart)
    assert body["vertices"]["ids"] == flat.vertex_ids.tolist()
    assert np.array_equal(body["vertices"]["theta"], flat.theta)
    assert np.array_equal(body["vertices"]["phi"], flat.phi)
    assert body["faces"]["vertices"] == faces[region].tolist()
    v = body["validation"]
    assert v["seam_free"] and v["star_shaped"] and v["boundary_loops"] == 1
    assert v["margin_deg"]["seam"] == pytest.approx(flat.validation.margin_deg_seam)
    assert body["metrics"]["isometric"]["mean"] == pytest.approx(flat.distortion.isometric.mean)
    assert body["params"]["sigma"] == 0.3
    assert body["params"]["pole_angle_deg"] == pytest.approx(math.degrees(2 * math.atan(0.3)))
    # The cone: faces whose centroid lies within 60/70 degrees of the axis, from the apex.
    axis = np.asarray(params["region"]["cone"]["axis"], dtype=float)
    directions = vertices[faces].mean(axis=1) - body["params"]["region"]["cone"]["apex"]
    cosine = directions @ axis / np.linalg.norm(directions, axis=1) / np.linalg.norm(axis)
    expected = np.flatnonzero(
        cosine >= math.cos(math.radians(params["region"]["cone"]["half_angle_deg"]))
    )
    assert body["faces"]["ids"] == expected.tolist()


async def test_obj_and_glb_of_one_scan_agree(client):
    params = SCALP["lee-perry-smith.glb"]
    glb = (await flatten(client, "lee-perry-smith.glb", params)).json()
    obj = (await flatten(client, "lee-perry-smith.obj", params)).json()
    assert glb["faces"] == obj["faces"] and glb["vertices"]["ids"] == obj["vertices"]["ids"]
    assert np.allclose(glb["vertices"]["theta"], obj["vertices"]["theta"], atol=1e-6)


async def test_nefertiti_comes_back_with_its_backfacing_faces(client):
    response = await flatten(client, "nefertiti-lowres.obj", endpoint="/v1/validate")
    assert response.status_code == 200
    body = response.json()
    assert set(body) == {"warnings", "params", "validation", "metrics"}
    assert not body["validation"]["star_shaped"]
    vertices, faces = load_sample("nefertiti-lowres.obj")
    center = np.asarray(body["params"]["center"])  # the box centre: tests/test_centres.py
    flat = flatten_region(
        vertices, faces, Frame.identity(center), Chart.distorted(PoleCap.from_sigma(0.3))
    )
    assert body["validation"]["backfacing_faces"] == flat.validation.backfacing_faces.tolist()
    assert len(body["validation"]["backfacing_faces"]) > 0


async def test_regions_by_faces_vertices_and_groups(client):
    _, faces = load_sample("fsaverage-head.ply")
    chosen = [5, 17, 400, 401, 402, 1000]
    by_faces = (
        await flatten(client, "fsaverage-head.ply", {"region": {"faces": chosen[::-1]}})
    ).json()
    assert by_faces["faces"]["ids"] == chosen
    used = np.unique(faces[chosen])
    by_vertices = await flatten(
        client, "fsaverage-head.ply", {"region": {"vertices": used.tolist()}}
    )
    expected = np.flatnonzero(np.isin(faces, used).all(axis=1))
    assert by_vertices.json()["faces"]["ids"] == expected.tolist()
    text = (
        b"v 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\nv 0.5 0.5 2\n"
        b"g left\nf 1 2 3\ng right extra\nusemtl skin\nf 1 3 4\nf 3 4 5\n"
    )
    grouped = await flatten(
        client,
        "fsaverage-head.ply",
        {"region": {"groups": ["right"]}, "center": [0.5, 0.5, 0]},
        data=text,
        filename="quad.obj",
    )
    assert grouped.status_code == 200, grouped.text
    assert grouped.json()["faces"]["ids"] == [1, 2]
    unknown = await flatten(
        client, "x", {"region": {"groups": ["nose"]}}, data=text, filename="q.obj"
    )
    assert "'left'" in problem(unknown, 422, "params.region.groups")["detail"]


@pytest.mark.parametrize(
    ("region", "field", "says"),
    [
        ({"faces": [1, 2, 2]}, "params.region.faces", "more than once"),
        ({"faces": [-1]}, "params.region.faces", "outside"),
        ({"faces": [99999]}, "params.region.faces", "outside [0, 4,062)"),
        ({"vertices": [0]}, "params.region", "selects no faces"),
        (
            {"cone": {"axis": [0, 0, 0], "half_angle_deg": 10}},
            "params.region.cone.axis",
            "non-zero",
        ),
        ({"cone": {"axis": [0, 0, 1], "half_angle_deg": 0.0001}}, "params.region", "no faces"),
        ({"faces": []}, "params.region", None),
        ({"faces": [2**70]}, "params.region.faces", f"face id {2**70} is outside"),
        ({"vertices": [-(2**64)]}, "params.region.vertices", "is outside"),
    ],
)
async def test_bad_regions(client, region, field, says):
    response = await flatten(client, "fsaverage-head.ply", {"region": region})
    body = problem(response, 422)
    assert body["field"].startswith(field)
    if says:
        assert says in body["detail"]


@pytest.mark.parametrize("tiny", [1e-300, 1e-320])  # 1e-320 is subnormal
@pytest.mark.parametrize("which", ["axis", "pole", "up", "up of an automatic pole"])
async def test_a_direction_however_small_is_its_direction(client, which, tiny):
    """One rule for the cone's axis, the pole and up: three finite numbers, not all zero, are
    a direction, whatever their size; only [0, 0, 0] is refused, with the same message."""

    def params(size: float) -> dict:
        chosen = {
            "sigma": 0.3,
            "rotation": {"pole": [0, 0, -1], "up": [0, 1, 0]},
            "region": {"cone": {"axis": [0, 0, 1], "half_angle_deg": 70}},
        }
        if which == "axis":
            chosen["region"]["cone"]["axis"] = [0, 0, size]
        elif which == "pole":
            chosen["rotation"]["pole"] = [0, 0, -size]
        elif which == "up":
            chosen["rotation"]["up"] = [0, size, 0]
        else:
            chosen["rotation"] = {"pole": "auto", "up": [0, size, 0]}
        return chosen

    unit = (await flatten(client, "fsaverage-head.ply", params(1.0))).json()
    small = await flatten(client, "fsaverage-head.ply", params(tiny))
    assert small.status_code == 200, small.text
    small = small.json()
    assert small["faces"] == unit["faces"] and small["vertices"] == unit["vertices"]
    assert small["params"]["rotation"] == unit["params"]["rotation"]
    zero = await flatten(client, "fsaverage-head.ply", params(0.0))
    field = {"axis": "params.region.cone.axis", "pole": "params.rotation.pole"}.get(
        which, "params.rotation.up"
    )
    assert "must be a non-zero direction" in problem(zero, 422, field)["detail"]


async def test_a_centre_on_a_vertex_names_it(client):
    vertices, _ = load_sample("fsaverage-head.ply")
    response = await flatten(client, "fsaverage-head.ply", {"center": vertices[123].tolist()})
    body = problem(response, 422, "mesh")
    assert body["indices"] == [123] and "vertex 123" in body["detail"]


#: Flat regions whose bounding-box centre, the default centre, lies in their plane: on the
#: triangle's long edge, on the grid's middle vertex (12).
FLAT = {
    "triangle": (np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]), np.array([[0, 1, 2]])),
    "grid": grid_mesh(np.linspace(0, 1, 5), np.linspace(0, 1, 5), 0.0),
}
#: Their box centres: in the triangle's principal axes (along its mirror line and across
#: it) the middle of its box is a quarter of the way along both legs.
FLAT_CENTRES = {"triangle": "[0.25, 0.25, 0]", "grid": "[0.5, 0.5, 0]"}


@pytest.mark.parametrize("name", list(FLAT))
async def test_a_centre_in_the_plane_of_a_flat_region_is_named_as_the_centre(client, name):
    data = obj_of(*FLAT[name])
    response = await client.post("/v1/flatten", files={"mesh": ("flat.obj", data)})
    body = problem(response, 422, "params.center")
    detail = body["detail"]
    assert detail.startswith(f"params.center: the centre {FLAT_CENTRES[name]} lies in the plane")
    assert "edge-on" in detail and "move the centre off that plane" in detail
    assert "zero area" not in detail
    if name == "grid":
        assert body["indices"] == [12] and "on vertex 12" in detail
    # Off the plane, given or as the detail suggests, the same region flattens.
    suggested = json.loads(detail.rpartition("for example to ")[2])
    for center in ([0.25, 0.25, -1.0], suggested):
        response = await flatten(client, "x", {"center": center}, data=data, filename="f.obj")
        assert response.status_code == 200, response.text


@pytest.mark.parametrize(
    ("endpoint", "params"),
    [
        ("/v1/flatten", {"rotation": {"pole": [0, 0, -1], "up": [0, 1, 0]}, "sigma": 0.3}),
        ("/v1/validate", {"center": [5.0, 5.0, 0.0]}),  # in the plane, beside the region
        ("/v1/fit", {"center": "centroid"}),
        (
            "/v1/locate",
            {"rotation": "identity", "sigma": 0.3, "theta": [1.0], "phi": [-1.0]},
        ),
    ],
)
async def test_every_mesh_route_names_a_centre_in_the_regions_plane(client, endpoint, params):
    data = obj_of(*FLAT["grid"])
    response = await flatten(client, "x", params, data=data, filename="f.obj", endpoint=endpoint)
    assert "lies in the plane of every face" in problem(response, 422, "params.center")["detail"]


async def test_a_region_whose_faces_have_no_area_names_the_faces_not_the_centre(client):
    data = obj_of([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]], [[0, 1, 2]])
    for params in ({}, {"center": [1.0, 1.0, 1.0]}):
        response = await flatten(client, "x", params, data=data, filename="line.obj")
        assert "every face of the region has zero area" in problem(response, 422, "mesh")["detail"]


async def test_a_fitted_centre_leaves_the_plane_of_a_flat_region(client):
    data = obj_of(*FLAT["grid"])
    response = await flatten(client, "x", {}, data=data, filename="f.obj", endpoint="/v1/fit")
    assert response.status_code == 200, response.text
    assert response.json()["params"]["center"][2] != 0.0


@pytest.mark.parametrize(
    ("params", "field"),
    [
        ({"sigma": 0}, "params.sigma"),
        ({"sigma": 0.2, "pole_angle_deg": 10}, "params"),
        ({"method": "standard", "pole_angle_deg": 10}, "params"),
        ({"rotation": [[2, 0, 0], [0, 1, 0], [0, 0, 1]]}, "params.rotation"),
        ({"center": "middle"}, "params.center"),
        ({"format": "fbx"}, "params.format"),
        ({"region": {"sphere": 1}}, "params.region"),
    ],
)
async def test_bad_mesh_params_name_the_field(client, params, field):
    body = problem(await flatten(client, "fsaverage-head.ply", params), 422)
    assert body["field"].startswith(field)


@pytest.mark.parametrize(
    ("params", "field"),
    [
        ('{"center": [0, 0, 1], "center": "bbox_center"}', "params.center"),
        (
            '{"region": {"cone": {"axis": [0, 0, 1], "half_angle_deg": 70, "axis": [0, 1, 0]}}}',
            "params.region.cone.axis",
        ),
    ],
)
async def test_params_repeating_a_key_are_refused_naming_its_path(client, params, field):
    data = SAMPLES["fsaverage-head.ply"].path.read_bytes()
    response = await client.post(
        "/v1/flatten", files={"mesh": ("a.ply", data)}, data={"params": params}
    )
    assert "given more than once" in problem(response, 422, field)["detail"]


async def test_params_must_be_json(client):
    response = await client.post(
        "/v1/flatten",
        files={"mesh": ("a.ply", SAMPLES["fsaverage-head.ply"].path.read_bytes())},
        data={"params": "{sigma: 1"},
    )
    problem(response, 422, "params")


@pytest.mark.parametrize(
    ("data", "filename", "says"),
    [
        (b"", "empty.obj", "empty"),
        (b"\x00\xff" * 100, "junk.obj", "no vertex"),
        (b"v 0 0 0\nv 1 0 0\nf 1 2 9\n", "past.obj", "refers to vertex 9"),
        (b"v 0 0 0\nv 1 0 0\nv 0 nan 1\nf 1 2 3\n", "nan.obj", "vertex 2 (line 3)"),
        (b"glTF" + b"\x02\x00\x00\x00" + b"\xff\x00\x00\x00", "lie.glb", "declares"),
        (b"solid x\nendsolid", "empty.stl", None),
        (
            b"ply\nformat binary_little_endian 1.0\nelement vertex 1000000\nproperty float x\n"
            b"property float y\nproperty float z\nelement face 1\n"
            b"property list uchar int vertex_indices\nend_header\n\x00\x00",
            "short.ply",
            "need at least 12,000,000 bytes but 2 follow",
        ),
    ],
)
async def test_unreadable_files_are_422(client, data, filename, says):
    body = problem(await flatten(client, "x", {}, data=data, filename=filename), 422, "mesh")
    if says:
        assert says in body["detail"]


def gltf_with(uri: str) -> bytes:
    return json.dumps(
        {
            "asset": {"version": "2.0"},
            "buffers": [{"byteLength": 36, "uri": uri}],
            "bufferViews": [{"buffer": 0, "byteLength": 36}],
            "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"}],
            "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
        }
    ).encode()


async def test_gltf_reads_embedded_buffers_and_refuses_external_ones(client):
    triangle = np.array([[1, 0, 1], [0, 1, 1], [-1, -1, 1]], dtype="<f4").tobytes()
    uri = "data:application/octet-stream;base64," + base64.b64encode(triangle).decode()
    ok = await flatten(client, "x", {"center": [0, 0, 0]}, data=gltf_with(uri), filename="t.gltf")
    assert ok.status_code == 200, ok.text
    assert ok.json()["faces"]["vertices"] == [[0, 1, 2]]
    for external in ("triangle.bin", "file:///etc/passwd", "https://example.com/t.bin"):
        body = problem(
            await flatten(client, "x", {}, data=gltf_with(external), filename="t.gltf"), 422
        )
        assert external in body["detail"]


async def test_stl_and_format_parameter(client):
    vertices, faces = load_sample("fsaverage-head.ply")
    stl = trimesh.Trimesh(vertices, faces, process=False).export(file_type="stl")
    response = await flatten(client, "x", {"format": "stl"}, data=stl, filename="no-extension")
    assert response.status_code == 200, response.text
    assert len(response.json()["faces"]["ids"]) == len(faces)


async def test_limits():
    app = create_app(Settings(max_upload_bytes=100_000, max_faces=1000))
    async with app.router.lifespan_context(app):
        transport = httpx.ASGITransport(app=app)
        async with httpx.AsyncClient(transport=transport, base_url="http://m") as c:
            big = SAMPLES["lee-perry-smith.glb"].path.read_bytes()
            problem(await flatten(c, "x", {}, data=big, filename="a.glb"), 413)

            async def chunks():  # no Content-Length: counted as it streams in
                for _ in range(150):
                    yield b"x" * 1000

            response = await c.post(
                "/v1/flatten",
                content=chunks(),
                headers={"content-type": "multipart/form-data; boundary=b"},
            )
            problem(response, 413)
            small = SAMPLES["fsaverage-head.ply"].path.read_bytes()
            body = problem(await flatten(c, "x", {}, data=small, filename="a.ply"), 413, "mesh")
            assert "MESHFLAT_MAX_FACES" in body["detail"]


async def test_json_bodies_are_limited_as_they_stream_in():
    app = create_app(Settings(max_upload_bytes=10_000))
    transport = httpx.ASGITransport(app=app)
    async with httpx.AsyncClient(transport=transport, base_url="http://m") as c:

        async def chunks():
            yield b'{"points": ['
            for _ in range(2000):
                yield b"[1, 2, 3],"

        headers = {"content-type": "application/json"}
        response = await c.post("/v1/points", content=chunks(), headers=headers)
        assert "MESHFLAT_MAX_UPLOAD_BYTES" in problem(response, 413)["detail"]
        response = await c.post(
            "/v1/points", content=b"{}", headers=headers | {"content-length": "x"}
        )
        problem(response, 400)


async def test_jobs_wait_for_a_slot(monkeypatch):
    """With MESHFLAT_MAX_JOBS=1, requests are computed one at a time."""
    import threading
    import time

    from service import routes

    running, most, lock = 0, 0, threading.Lock()
    real = routes.answer_json

    def counted(*args):
        nonlocal running, most
        with lock:
            running += 1
            most = max(most, running)
        time.sleep(0.3)  # long enough for the others to arrive, on a loaded machine too
        with lock:
            running -= 1
        return real(*args)

    monkeypatch.setattr(routes, "answer_json", counted)
    for jobs, expected in ((1, 1), (3, 3)):
        running = most = 0
        app = create_app(Settings(max_jobs=jobs, max_waiting=2))
        transport = httpx.ASGITransport(app=app)
        async with httpx.AsyncClient(transport=transport, base_url="http://m") as c:
            statuses = []

            async def post(client=c, statuses=statuses):
                response = await client.post("/v1/points", json={"points": [[1, 0, 0]]})
                statuses.append(response.status_code)

            async with anyio.create_task_group() as group:
                for _ in range(3):
                    group.start_soon(post)
        assert statuses == [200] * 3
        assert most == expected


async def test_multipart_details(client):
    data = SAMPLES["fsaverage-head.ply"].path.read_bytes()
    body = (
        b'--AbC\r\nContent-Disposition: form-data; name="mesh"; filename="a.ply"\r\n\r\n'
        + data
        + b"\r\n--AbC--\r\n"
    )
    for content_type in (
        "multipart/form-data; BOUNDARY=AbC",
        'multipart/form-data; boundary = "AbC"',
    ):
        response = await client.post(
            "/v1/validate", content=body, headers={"content-type": content_type}
        )
        assert response.status_code == 200, (content_type, response.text)
    nameless = body.replace(b'; filename="a.ply"', b"")
    response = await client.post(
        "/v1/validate",
        content=nameless,
        headers={"content-type": "multipart/form-data; boundary=AbC"},
    )
    assert "no file name" in problem(response, 422, "mesh")["detail"]


@pytest.mark.parametrize("repeated", ["mesh", "params"])
async def test_a_form_repeating_the_mesh_or_params_part_is_refused_naming_it(client, repeated):
    data = SAMPLES["fsaverage-head.ply"].path.read_bytes()
    files = [("mesh", ("a.ply", data))] * (2 if repeated == "mesh" else 1)
    fields = {"params": ["{}", '{"sigma": 0.2}']} if repeated == "params" else {}
    response = await client.post("/v1/flatten", files=files, data=fields)
    assert f"more than one '{repeated}' part" in problem(response, 422, repeated)["detail"]


async def test_wrong_content_type(client):
    response = await client.post("/v1/flatten", json={"mesh": "no"})
    problem(response, 415)


# -- the OpenAPI examples are answers ------------------------------------------------------


async def test_openapi_examples_are_what_the_service_answers(client):
    from service.capabilities.region.params import MESH_PARAMS_EXAMPLE
    from service.examples import icosahedron_obj

    document = (await client.get("/openapi.json")).json()

    def example(path, status, media="application/json"):
        (operation,) = document["paths"][path].values()
        return operation["responses"][status]["content"][media]["example"]

    def close(answer, shown):
        if isinstance(shown, dict):
            assert answer.keys() == shown.keys()
            for key in shown:
                close(answer[key], shown[key])
        elif isinstance(shown, list):
            assert len(answer) == len(shown)
            for a, b in zip(answer, shown, strict=True):
                close(a, b)
        elif isinstance(shown, float):
            assert answer == pytest.approx(shown, abs=1e-6)
        else:
            assert answer == shown

    ico = icosahedron_obj()
    for endpoint in ("/v1/flatten", "/v1/validate"):
        answer = await flatten(client, "", MESH_PARAMS_EXAMPLE, ico, "icosahedron.obj", endpoint)
        close(answer.json(), example(endpoint, "200"))
    for path in ("/v1/points", "/v1/points/inverse"):
        (operation,) = document["paths"][path].values()
        request = operation["requestBody"]["content"]["application/json"]["example"]
        close((await client.post(path, json=request)).json(), example(path, "200"))
    bad = dict(MESH_PARAMS_EXAMPLE, region={"faces": [3, 20]})
    answer = problem(await flatten(client, "", bad, ico, "icosahedron.obj"), 422)
    assert answer == example("/v1/flatten", "422", "application/problem+json")
    assert (await client.get("/v1/samples")).json() == example("/v1/samples", "200")


# -- /v1/fit and "auto" ------------------------------------------------------------------------

SCALP_REGION = {"cone": {"axis": [0, 0, 1], "half_angle_deg": 70}}


async def post(client, endpoint, params, name="fsaverage-head.ply"):
    """``params`` and a bundled scan to a mesh route."""
    data = SAMPLES[name].path.read_bytes()
    fields = {"params": json.dumps(params)}
    return await client.post(endpoint, files={"mesh": (name, data)}, data=fields)


@pytest.mark.anyio
async def test_fit_answers_params_that_flatten_reproduces(client):
    answer = await post(client, "/v1/fit", {"region": SCALP_REGION})
    assert answer.status_code == 200, answer.text
    body = answer.json()
    explain = body["explain"]
    assert body["validation"]["seam_free"] and body["validation"]["star_shaped"]
    assert explain["margin_deg"] >= 2.0 and explain["energy_end"] <= explain["energy_start"]
    assert [item["sigma"] for item in explain["energy_at_sigma"]] == [0.3, 1.0]
    assert body["metrics"]["isometric"]["mean"] == pytest.approx(explain["energy_end"])
    # The resolved params sent back to /v1/flatten give the same map. The cone is selected
    # around the mesh's box centre, so send the region as the faces fit used.
    flat = await post(client, "/v1/flatten", {"region": SCALP_REGION, "center": "auto"})
    faces = flat.json()["faces"]["ids"]
    again = await post(client, "/v1/validate", {**body["params"], "region": {"faces": faces}})
    assert again.status_code == 200, again.text
    for name in ("conformal", "area", "isometric"):
        assert again.json()["metrics"][name] == pytest.approx(body["metrics"][name], rel=1e-9)
    assert again.json()["metrics"]["trusted"]["faces"] == body["metrics"]["trusted"]["faces"]
    assert again.json()["validation"]["margin_deg"] == pytest.approx(
        body["validation"]["margin_deg"]
    )


@pytest.mark.anyio
async def test_auto_in_flatten_and_an_up_hint(client):
    params = {
        "region": SCALP_REGION,
        "center": "auto",
        "sigma": "auto",
        "rotation": {"pole": "auto", "up": [0, 1, 0]},
    }
    answer = await post(client, "/v1/flatten", params)
    assert answer.status_code == 200, answer.text
    body = answer.json()
    assert "explain" not in body and body["validation"]["seam_free"]
    rotation = np.array(body["params"]["rotation"])
    assert rotation[2] @ [0, 1, 0] > 0.9  # local +Z follows the hint


@pytest.mark.anyio
@pytest.mark.parametrize(
    ("params", "field"),
    [
        ({"min_margin_deg": 95}, "params.min_margin_deg"),
        ({"min_kernel_depth": -0.1}, "params.min_kernel_depth"),
        ({"method": "standard", "sigma": "auto"}, "params"),
        ({"sigma": "auto", "pole_angle_deg": 30}, "params"),
        ({"rotation": {"pole": "auto", "up": [0, 0, 0]}}, "params.rotation.up"),
        ({"rotation": {"pole": "automatic"}}, "params.rotation"),
    ],
)
async def test_bad_fit_params_name_the_field(client, params, field):
    answer = await post(client, "/v1/fit", {"region": SCALP_REGION, **params})
    assert answer.status_code == 422, answer.text
    assert answer.json()["field"].startswith(field), answer.json()


@pytest.mark.anyio
async def test_locate_through_the_api_inverts_flatten(client):
    params = {
        "region": SCALP_REGION,
        "center": "bbox_center",
        "rotation": {"pole": [0, 0, -1], "up": [0, 1, 0]},
    }
    flat = (await post(client, "/v1/flatten", params)).json()
    faces = np.array(flat["faces"]["ids"])
    vertex_of = {vid: i for i, vid in enumerate(flat["vertices"]["ids"])}
    # Each triangle's centroid in the (phi, theta) map is inside its layout triangle; the
    # true inverse goes through the ray, so ask for the map points of the corners instead.
    corners = np.array(flat["faces"]["vertices"])[:50]
    first = [vertex_of[c[0]] for c in corners]
    theta = [flat["vertices"]["theta"][i] for i in first]
    phi = [flat["vertices"]["phi"][i] for i in first]
    answer = await post(
        client, "/v1/locate", {**params, "theta": [*theta, 0.0], "phi": [*phi, 0.0]}
    )
    assert answer.status_code == 200, answer.text
    hits = answer.json()["hits"]
    vertices, _ = load_sample("fsaverage-head.ply")
    for corner, hit in zip(corners, hits[:-1], strict=True):
        # A corner is shared by several triangles: any of them, with weight 1 on it.
        assert hit is not None and hit["face"] in faces
        np.testing.assert_allclose(hit["point"], vertices[corner[0]], atol=1e-6)
        assert max(hit["barycentric"]) == pytest.approx(1.0, abs=1e-6)
    assert hits[-1] is None  # theta = 0 is a singular point's direction, in the cap


@pytest.mark.anyio
@pytest.mark.parametrize("count", [5, 60])  # without the index, and with it
async def test_locate_answers_the_first_hits_brute_force_finds(client, count):
    params = {
        "region": SCALP_REGION,
        "center": [1.3, -12.5, -32.3],  # about the middle of the head's box
        "rotation": {"pole": [0, 0, -1], "up": [0, 1, 0]},
        "sigma": 0.3,
    }
    rng = np.random.default_rng(count)
    # Over the scalp (theta 1.15 to 2.0, phi -2.0 to -1.14) and beside it.
    theta, phi = rng.uniform(1.0, 2.1, count), rng.uniform(-2.2, -1.0, count)
    answer = await post(
        client, "/v1/locate", {**params, "theta": theta.tolist(), "phi": phi.tolist()}
    )
    assert answer.status_code == 200, answer.text
    hits = answer.json()["hits"]
    vertices, faces = load_sample("fsaverage-head.ply")
    flat = (await post(client, "/v1/flatten", params)).json()
    ids = np.array(flat["faces"]["ids"])
    frame = Frame.from_pole_up([0, 0, -1], [0, 1, 0], flat["params"]["center"])
    directions = Chart.distorted(PoleCap.from_sigma(0.3)).inverse(theta, phi, 1.0)
    nearest, tied = brute_force(frame.to_local(vertices), faces[ids], directions)
    assert 0 < sum(hit is None for hit in hits) < count  # some rays miss the scalp
    for hit, depth, near, direction in zip(hits, nearest, tied, directions, strict=True):
        if hit is None:
            assert not np.isfinite(depth)
            continue
        assert hit["face"] in ids[near]
        local = depth * direction / np.linalg.norm(direction)
        np.testing.assert_allclose(hit["point"], frame.to_world(local[None])[0], atol=1e-9)


@pytest.mark.anyio
async def test_locate_checks_its_queries(client):
    params = {"region": SCALP_REGION}
    answer = await post(client, "/v1/locate", {**params, "theta": [1.0, 2.0], "phi": [0.0]})
    assert answer.status_code == 422 and "one phi per theta" in answer.json()["detail"]
    answer = await post(client, "/v1/locate", {**params, "theta": [4.0], "phi": [0.0]})
    assert answer.status_code == 422 and answer.json()["field"] == "params.theta", answer.json()


@pytest.mark.anyio
async def test_mercator_through_the_api(client):
    params = {
        "region": SCALP_REGION,
        "rotation": {"pole": [0, 0, -1], "up": [0, 1, 0]},
        "layout": "mercator",
    }
    answer = await post(client, "/v1/flatten", params)
    assert answer.status_code == 200, answer.text
    body = answer.json()
    vertices = body["vertices"]
    assert body["params"]["layout"] == "mercator"
    np.testing.assert_allclose(vertices["x"], vertices["phi"])
    np.testing.assert_allclose(
        vertices["y"], np.log(np.tan((np.pi - np.array(vertices["theta"])) / 2))
    )
    paper = (await post(client, "/v1/flatten", {**params, "layout": "theta_phi"})).json()
    # Every layout gives x and y: for theta_phi, phi and theta themselves.
    assert paper["vertices"]["x"] == paper["vertices"]["phi"]
    assert paper["vertices"]["y"] == paper["vertices"]["theta"]
    assert body["metrics"]["conformal"]["mean"] < paper["metrics"]["conformal"]["mean"]


@pytest.mark.anyio
async def test_locate_ignores_vertices_outside_the_region(client):
    obj = b"v 0 0 1\nv 1 0 1\nv 0 1 1\nv 0 0 0\nf 1 2 3\n"
    params = {"center": [0, 0, 0], "theta": [0.1], "phi": [0.5]}
    answer = await client.post(
        "/v1/locate", files={"mesh": ("t.obj", obj)}, data={"params": json.dumps(params)}
    )
    assert answer.status_code == 200, answer.text
    obj = b"v 0 0 0\nv 1 0 1\nv 0 1 1\nf 1 2 3\n"  # now the region's own vertex 0
    answer = await client.post(
        "/v1/locate", files={"mesh": ("t.obj", obj)}, data={"params": json.dumps(params)}
    )
    assert answer.status_code == 422 and answer.json()["indices"] == [0], answer.text
    assert "vertex 0" in answer.json()["detail"]


async def test_trusted_metrics_leave_the_flagged_faces_out(client):
    """Nefertiti whole, seen from its box centre: thousands of faces flagged; the trusted
    measures cover the rest, with the same per-face values, and the caption quotes them."""
    params = {"rotation": "identity", "sigma": 0.3}
    body = (await post(client, "/v1/validate", params, "nefertiti-lowres.obj")).json()
    metrics, v = body["metrics"], body["validation"]
    flagged = set()
    for key in ("singular_point_faces", "seam_faces", "folded_faces", "backfacing_faces"):
        flagged |= set(v[key])
    flagged |= set(v["degenerate_faces"]) | set(v["stretched_faces"])
    trusted = metrics["trusted"]
    assert trusted["flagged_faces"] == len(flagged) > 1000
    assert trusted["faces"] + len(flagged) == 70_000
    assert trusted["isometric"]["mean"] < metrics["isometric"]["mean"]
    assert trusted["isometric"]["max"] <= metrics["isometric"]["max"]
    svg = await post(client, "/v1/flatten", {**params, "output": "svg"}, "nefertiti-lowres.obj")
    energy, stretched = trusted["isometric"], len(v["stretched_faces"])
    assert 0 < stretched < len(flagged)
    assert (
        f"isometric energy p50 {energy['p50']:.3f}, p95 {energy['p95']:.3f} on the trusted "
        f"faces ({len(flagged):,} flagged, {stretched:,} of them stretched)"
    ) in svg.text


async def test_a_star_shaped_region_trusts_every_face(client):
    body = (await post(client, "/v1/validate", {"region": SCALP_REGION, "sigma": 0.3})).json()
    assert body["validation"]["star_shaped"] and body["validation"]["seam_free"]
    trusted = body["metrics"]["trusted"]
    assert trusted["flagged_faces"] == 0
    for name in ("conformal", "area", "isometric"):
        assert trusted[name] == body["metrics"][name]


# -- untangle ----------------------------------------------------------------------------------


async def test_a_pole_parallel_to_up_names_the_rotations_up(client):
    rotation = {"pole": [0, 0, -1], "up": [0, 0, 2]}
    body = problem(await post(client, "/v1/flatten", {"rotation": rotation}), 422)
    assert body["field"] == "params.rotation.up", body


async def test_untangle_makes_the_answered_layout_fold_free(client):
    """Nefertiti's top, centre fitted: its crown faces away from every centre, so the map
    folds there. With untangle the answered layout has every triangle the map's way round,
    only the vertices listed moved, and theta and phi stay the transform's."""
    from transforms import LAYOUT_ORIENTATION
    from transforms.untangle import orientation_signs

    name = "nefertiti-lowres.obj"
    region = {"cone": {"axis": [0, 0, 1], "half_angle_deg": math.degrees(1.0)}}
    params = {"region": region, "center": "auto", "untangle": True}
    body = (await post(client, "/v1/flatten", params, name)).json()
    report, vertices = body["untangle"], body["vertices"]
    assert report["folded_before"] > 100
    assert report["folded_after"] == [] and report["notes"] == []
    x, y = np.array(vertices["x"]), np.array(vertices["y"])
    kept = ~np.isin(vertices["ids"], report["moved_vertices"])
    assert np.array_equal(x[kept], np.array(vertices["phi"])[kept])
    assert np.array_equal(y[kept], np.array(vertices["theta"])[kept])
    position = {vid: i for i, vid in enumerate(vertices["ids"])}
    faces = np.vectorize(position.get)(np.array(body["faces"]["vertices"]))
    winding = 1 if body["validation"]["winding"] == "outward" else -1
    assert (orientation_signs(x, y, faces) == LAYOUT_ORIENTATION * winding).all()
    # The transform's own validation is kept; validate and fit answer the same block.
    assert len(body["validation"]["folded_faces"]) > 0
    again = (await post(client, "/v1/validate", {**body["params"], "untangle": True}, name)).json()
    assert again["untangle"] == report
    plain = (await post(client, "/v1/validate", {**body["params"], "untangle": False}, name)).json()
    assert "untangle" not in plain and plain["params"]["untangle"] is False
