"""``growth`` of /v1/sites (docs/math.md, section 19), through the API: each site's direction
is unit, tilted off the scalp by its exit angle, tangent to it along the field; on a flow's
own triangles the field is the lifted flow's tangent; parallel flows give a uniform field;
a whorl turns it once, in the sense asked, and nothing else turns it; the field is the same,
turned, for the head moved and turned; and every way to ask for a field that cannot be is a
422 naming the item."""

from __future__ import annotations

import io
import json
import struct

import httpx
import numpy as np
import pytest
from PIL import Image
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from service.cli import main
from service.samples import SAMPLES
from transforms.arrays import solve_2x2

from .conftest import grid_mesh, load_sample, real_servers
from .test_api import flatten, obj_of, problem
from .test_landmarks import on_head
from .test_serve import running
from .test_sites import NAME, SCALP, check_the_same_sites, posed, scalp_map, sites

pytestmark = pytest.mark.anyio


async def centre_of_map(client) -> tuple[float, float, float]:
    """The middle of the scalp's map, and its size (the larger side of its box)."""
    x, y = await scalp_map(client)
    return (x.min() + x.max()) / 2, (y.min() + y.max()) / 2, max(np.ptp(x), np.ptp(y))


def hairline_and_crown(cx: float, cy: float, size: float) -> dict:
    """A flow along the front of the map, and a whorl behind the middle."""
    return {
        "flow": [
            {
                "name": "hairline",
                "x": [cx - 0.3 * size, cx + 0.3 * size],
                "y": [cy - 0.3 * size, cy - 0.32 * size],
            }
        ],
        "whorls": [{"x": cx, "y": cy + 0.1 * size, "turn": "clockwise"}],
    }


def unit(vectors) -> np.ndarray:
    vectors = np.asarray(vectors, dtype=np.float64)
    return vectors / np.linalg.norm(vectors, axis=-1, keepdims=True)


def angles_deg(first, second) -> np.ndarray:
    cosine = np.einsum("pd,pd->p", unit(first), unit(second))
    return np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))


async def test_directions_are_unit_tangent_and_tilted_by_the_exit_angle(client):
    cx, cy, size = await centre_of_map(client)
    growth = hairline_and_crown(cx, cy, size) | {"exit_angle_deg": 12}
    zones = [
        {"name": "front", "outer": {"x": [cx - size, cx + size, cx + size, cx - size],
                                    "y": [cy - size, cy - size, cy, cy]},
         "density_per_cm2": 3, "exit_angle_deg": 35},
        {"name": "back", "outer": {"x": [cx - size, cx + size, cx + size, cx - size],
                                   "y": [cy, cy, cy + size, cy + size]},
         "density_per_cm2": 3},
    ]  # fmt: skip
    response = await sites(client, {"zones": zones, "growth": growth})
    assert response.status_code == 200, response.text
    answer = response.json()
    found = answer["sites"]
    direction, tangent, normal = (np.asarray(found[k]) for k in ("direction", "tangent", "normal"))
    angle = np.asarray(found["exit_angle_deg"])
    np.testing.assert_allclose(np.linalg.norm(direction, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(tangent, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.einsum("pd,pd->p", tangent, normal), 0.0, atol=1e-9)
    sine = np.einsum("pd,pd->p", direction, normal)
    np.testing.assert_allclose(sine, np.sin(np.radians(angle)), atol=1e-9)
    on_map = np.asarray(found["map_direction"])
    np.testing.assert_allclose(np.linalg.norm(on_map, axis=1), 1.0, atol=1e-12)
    front, back = answer["zones"]
    assert front["exit_angle_deg"] == 35 and back["exit_angle_deg"] == 12
    assert set(angle[np.asarray(found["y"]) < cy]) == {35.0}
    assert answer["growth"]["exit_angle_deg"] == 12
    assert answer["growth"]["whorls"] == growth["whorls"]


async def test_on_a_flows_own_triangles_the_tangent_is_the_lifted_flows(client):
    """The flow's direction pushed through each triangle's linear map from the map to the
    surface, computed here from the flatten answer and the file's vertices, is the site's
    tangent within 1 degree (to rounding: the field is the flow's own there)."""
    cx, cy, size = await centre_of_map(client)
    start, end = np.array([cx - 0.3 * size, cy - 0.1 * size]), np.array([cx + 0.3 * size, cy])
    flow = {"name": "f", "x": [start[0], end[0]], "y": [start[1], end[1]]}
    answer = (await sites(client, {"density_per_cm2": 40, "growth": {"flow": [flow]}})).json()
    mapped = (await flatten(client, NAME, SCALP)).json()  # the sites' region and map
    vertices = np.asarray(load_sample(NAME)[0])
    on_map = dict(zip(mapped["faces"]["ids"], mapped["faces"]["vertices"], strict=True))
    vx, vy = np.full(len(vertices), np.nan), np.full(len(vertices), np.nan)  # by file id
    vx[mapped["vertices"]["ids"]], vy[mapped["vertices"]["ids"]] = (
        mapped["vertices"]["x"], mapped["vertices"]["y"])  # fmt: skip
    found = answer["sites"]
    crossed = _crossed_faces(on_map, vx, vy, start, end)
    chosen = [k for k, face in enumerate(found["face"]) if face in crossed]
    assert len(chosen) >= 10
    expected = []
    for k in chosen:
        a, b, c = on_map[found["face"][k]]
        e2 = np.array([[vx[b] - vx[a], vx[c] - vx[a]], [vy[b] - vy[a], vy[c] - vy[a]]])
        e3 = np.column_stack([vertices[b] - vertices[a], vertices[c] - vertices[a]])
        t = e3 @ np.linalg.solve(e2, end - start)
        n = np.asarray(found["normal"][k])
        expected.append(t - (t @ n) * n)
    tangent = np.asarray(found["tangent"])[chosen]
    assert angles_deg(tangent, expected).max() < 1.0


def _crossed_faces(on_map: dict, vx, vy, start, end) -> set[int]:
    """The file ids of the triangles the map segment ``start``-``end`` passes through (its
    points sampled finely, each located by barycentric weights)."""
    ids = np.array(list(on_map))
    corners = np.array([on_map[i] for i in ids])
    ax, ay = vx[corners[:, 0]], vy[corners[:, 0]]
    bx, by = vx[corners[:, 1]], vy[corners[:, 1]]
    qx, qy = vx[corners[:, 2]], vy[corners[:, 2]]
    det = (bx - ax) * (qy - ay) - (by - ay) * (qx - ax)
    crossed = set()
    for t in np.linspace(0.0, 1.0, 4000):
        px, py = start + t * (end - start)
        u = ((px - ax) * (qy - ay) - (py - ay) * (qx - ax)) / det
        v = ((bx - ax) * (py - ay) - (by - ay) * (px - ax)) / det
        inside = (u > 1e-9) & (v > 1e-9) & (u + v < 1 - 1e-9)
        crossed.update(ids[inside].tolist())
    return crossed


def flat_patch() -> tuple[bytes, dict]:
    """A flat square 40 mm across, 100 mm above the centre, finely triangulated, and the
    params that map it (the pole below the centre)."""
    span = np.linspace(-20.0, 20.0, 41)
    vertices, faces = grid_mesh(span, span, 100.0)
    params = {"center": [0, 0, 0], "rotation": {"pole": [0, 0, -1], "up": [0, 1, 0]},
              "sigma": 0.3, "units": "mm"}  # fmt: skip
    return obj_of(vertices, faces), params


async def test_parallel_straight_flows_give_a_uniform_field(client):
    """Three parallel lines drawn on the map of a flat patch: the map direction of every
    site between them is theirs within 0.5 degrees (on a flat patch a site's normal is its
    triangle's, so the tangent keeps the map's direction)."""
    patch, params = flat_patch()
    plain = await flatten(client, "patch.obj", params | {"density_per_cm2": 60}, data=patch,
                          endpoint="/v1/sites")  # fmt: skip
    found = plain.json()["sites"]
    x, y = np.asarray(found["x"]), np.asarray(found["y"])
    cx, cy, size = (x.min() + x.max()) / 2, (y.min() + y.max()) / 2, max(np.ptp(x), np.ptp(y))
    heading = np.array([np.cos(0.4), np.sin(0.4)])
    across = np.array([-heading[1], heading[0]])
    flows = []
    for k, offset in enumerate((-0.15, 0.0, 0.15)):
        middle = np.array([cx, cy]) + offset * size * across
        a, b = middle - 0.25 * size * heading, middle + 0.25 * size * heading
        flows.append({"name": f"line {k}", "x": [a[0], b[0]], "y": [a[1], b[1]]})
    asked = params | {"density_per_cm2": 60, "growth": {"flow": flows}}
    answer = await flatten(client, "patch.obj", asked, data=patch, endpoint="/v1/sites")
    assert answer.status_code == 200, answer.text
    found = answer.json()["sites"]
    points = np.column_stack([found["x"], found["y"]]) - [cx, cy]
    between = (np.abs(points @ across) < 0.15 * size) & (np.abs(points @ heading) < 0.2 * size)
    assert between.sum() > 50
    on_map = np.asarray(found["map_direction"])[between]
    assert angles_deg(on_map, np.tile(heading, (len(on_map), 1))).max() < 0.5


def winding(points: np.ndarray, directions: np.ndarray, centre) -> float:
    """Turns of ``directions`` ((p, 2)) along the loop of ``points`` taken by their angle
    about ``centre``, counter-clockwise."""
    order = np.argsort(np.arctan2(*(points - centre).T[::-1]))
    heading = np.arctan2(directions[order, 1], directions[order, 0])
    steps = np.diff(np.r_[heading, heading[0]])
    steps = (steps + np.pi) % (2 * np.pi) - np.pi
    return float(steps.sum() / (2 * np.pi))


@pytest.mark.parametrize("turn", ["clockwise", "counterclockwise"])
async def test_a_whorl_turns_the_field_once_in_its_sense_and_nothing_else_does(client, turn):
    """Sites in a ring about the whorl: their map directions turn once (+1) about it; in a
    ring about another point, not at all. Seen from outside the head, the hair sweeps round
    the whorl in the sense asked: (ray x tangent) . normal has its sign everywhere."""
    cx, cy, size = await centre_of_map(client)
    whorl = np.array([cx, cy])
    growth = {"whorls": [{"x": cx, "y": cy, "turn": turn}]}
    answer = (await sites(client, {"density_per_cm2": 30, "growth": growth})).json()
    found = answer["sites"]
    points = np.column_stack([found["x"], found["y"]])
    on_map = np.asarray(found["map_direction"])
    ring = np.abs(np.linalg.norm(points - whorl, axis=1) - 0.08 * size) < 0.02 * size
    assert ring.sum() > 30
    assert winding(points[ring], on_map[ring], whorl) == pytest.approx(1.0, abs=1e-9)
    other = whorl + np.array([0.25 * size, 0.0])
    elsewhere = np.abs(np.linalg.norm(points - other, axis=1) - 0.08 * size) < 0.02 * size
    assert elsewhere.sum() > 30
    assert winding(points[elsewhere], on_map[elsewhere], other) == pytest.approx(0.0, abs=1e-9)
    position, tangent, normal = (np.asarray(found[k]) for k in ("position", "tangent", "normal"))
    middle = position[np.argmin(np.linalg.norm(points - whorl, axis=1))]
    sweep = np.einsum("pd,pd->p", np.cross(position[ring] - middle, tangent[ring]), normal[ring])
    assert (np.sign(sweep) == (1 if turn == "counterclockwise" else -1)).all()


async def test_the_field_is_the_same_turned_for_the_head_moved_and_turned(client):
    _, params = posed(Rotation.identity(), 1.0, np.zeros(3), "mm")
    plain = (await sites(client, params | {"density_per_cm2": 5})).json()["sites"]
    x, y = np.asarray(plain["x"]), np.asarray(plain["y"])
    cx, cy, size = (x.min() + x.max()) / 2, (y.min() + y.max()) / 2, max(np.ptp(x), np.ptp(y))
    asked = {"density_per_cm2": 5, "seed": 3, "growth": hairline_and_crown(cx, cy, size)}
    here = (await sites(client, params | asked)).json()
    rng = np.random.default_rng(41)
    turn, shift = Rotation.random(random_state=rng), rng.normal(size=3) * 300
    moved, params = posed(turn, 1.0, shift, "mm")
    there = (await sites(client, params | asked, name="moved.obj", data=moved)).json()
    check_the_same_sites(here, there, turn, 1.0, shift)
    for key in ("direction", "tangent"):
        turned = turn.apply(here["sites"][key])
        np.testing.assert_allclose(there["sites"][key], turned, rtol=0, atol=1e-6)
    np.testing.assert_allclose(
        there["sites"]["map_direction"], here["sites"]["map_direction"], rtol=0, atol=1e-6
    )


async def test_a_hairline_and_a_crown_turn_neighbours_little_away_from_the_whorl(client):
    """The bundled scalp with a hairline flow and a crown whorl: the largest turn of the
    direction between sites within two spacings of each other. Near the whorl it is the
    whorl's own turning (two spacings at 5 mm subtend some 35 degrees: measured 31); beyond
    15 mm it is the steps of the map's linear pieces between triangles of this coarse scalp
    (measured 13). The answer's largest turn covers them all."""
    cx, cy, size = await centre_of_map(client)
    growth = hairline_and_crown(cx, cy, size)
    answer = (await sites(client, {"density_per_cm2": 20, "growth": growth})).json()
    found = answer["sites"]
    position, direction = np.asarray(found["position"]), np.asarray(found["direction"])
    points = np.column_stack([found["x"], found["y"]])
    whorl = [growth["whorls"][0]["x"], growth["whorls"][0]["y"]]
    centre = position[np.argmin(np.linalg.norm(points - whorl, axis=1))]
    spacing = answer["zones"][0]["spacing_mm"]
    pairs = cKDTree(position).query_pairs(2 * spacing, output_type="ndarray")
    distance = np.linalg.norm(position[pairs] - centre, axis=2).min(axis=1)
    turns = angles_deg(direction[pairs[:, 0]], direction[pairs[:, 1]])
    assert turns[distance > 5.0].max() < 36.0
    assert turns[distance > 15.0].max() < 15.0
    assert answer["zones"][0]["largest_turn_deg"] == pytest.approx(turns.max(), abs=1e-9)


async def test_landmarks_alone_give_a_whorl_at_the_vertex_with_hair_running_away(client):
    marks = on_head()
    scalp = {"landmarks": marks, "units": "mm"}
    params = {"region": {"scalp": scalp}, "density_per_cm2": 5, "growth": {}}
    response = await sites(client, params)
    assert response.status_code == 200, response.text
    answer = response.json()
    (whorl,) = answer["growth"]["whorls"]
    assert whorl["turn"] == "clockwise"
    found = answer["sites"]
    position, tangent = np.asarray(found["position"]), np.asarray(found["tangent"])
    points = np.column_stack([found["x"], found["y"]])
    vertex = position[np.argmin(np.linalg.norm(points - [whorl["x"], whorl["y"]], axis=1))]
    assert np.linalg.norm(vertex - marks["vertex"]) < 10.0
    away = position - vertex
    near = (np.linalg.norm(away, axis=1) > 5) & (np.linalg.norm(away, axis=1) < 40)
    assert (np.einsum("pd,pd->p", away[near], tangent[near]) > 0).all()  # out of the whorl


async def test_growth_without_flow_whorls_or_landmarks_asks_for_the_flow(client):
    problem(await sites(client, {"density_per_cm2": 1, "growth": {}}), 422, "params.growth.flow")


async def test_flows_that_cross_or_oppose_and_items_off_the_region_are_named(client):
    cx, cy, size = await centre_of_map(client)
    a = {"name": "a", "x": [cx - 0.2 * size, cx + 0.2 * size], "y": [cy - 0.05 * size] * 2}
    crossing = {"name": "b", "x": [cx, cx + 0.01 * size], "y": [cy - 0.2 * size, cy + 0.2 * size]}
    opposed = {"name": "c", "x": a["x"][::-1], "y": [cy + 0.05 * size] * 2}
    off = {"name": "d", "x": [cx + 50 * size, cx + 51 * size], "y": [cy, cy]}
    cases = [
        ({"flow": [a, crossing]}, "params.growth.flow.1", "crosses growth.flow.0"),
        ({"flow": [a, opposed]}, "params.growth.flow.1", "points against growth.flow.0"),
        ({"flow": [a, off]}, "params.growth.flow.1", "wholly off the region"),
        ({"whorls": [{"x": cx + 50 * size, "y": cy, "turn": "clockwise"}]},
         "params.growth.whorls.0", "off the region"),
        ({"flow": [{"name": "e", "x": [cx, cx], "y": [cy, cy]}]}, "params.growth.flow.0",
         "two distinct points"),
        ({"exit_angle_deg": 91, "flow": [a]}, "params.growth.exit_angle_deg", None),
    ]  # fmt: skip
    for growth, field, words in cases:
        body = problem(await sites(client, {"density_per_cm2": 1, "growth": growth}), 422, field)
        assert words is None or words in body["detail"], body["detail"]


async def test_the_ply_carries_each_sites_direction(client):
    cx, cy, size = await centre_of_map(client)
    asked = {"density_per_cm2": 2, "growth": hairline_and_crown(cx, cy, size), "output": "ply"}
    data = (await sites(client, asked)).content
    header, _, body = data.partition(b"end_header\n")
    assert b"property float dx\nproperty float dy\nproperty float dz\n" in header
    count = int(header.split(b"element vertex ")[1].split(b"\n")[0])
    columns = [(name, "<f8") for name in "xyz"] + [
        (name, "<f4") for name in ("nx", "ny", "nz", "dx", "dy", "dz")
    ]
    row = np.dtype([*columns, ("face", "<i4")])
    table = np.frombuffer(body, dtype=row, count=count)
    answer = (await sites(client, asked | {"output": "json"})).json()
    directions = np.column_stack([table["dx"], table["dy"], table["dz"]])
    np.testing.assert_allclose(directions, answer["sites"]["direction"], atol=1e-6)
    assert json.dumps(answer["sites"]["face"]) == json.dumps(table["face"].tolist())


async def test_the_glb_holds_a_stroke_per_site_coloured_by_its_exit_angle(client):
    cx, cy, size = await centre_of_map(client)
    asked = {"density_per_cm2": 2, "growth": hairline_and_crown(cx, cy, size)}
    answer = (await sites(client, asked)).json()
    document, binary = glb_parts((await sites(client, asked | {"output": "glb"})).content)
    (growth,) = [mesh for mesh in document["meshes"] if mesh["name"] == "growth"]
    (lines,) = growth["primitives"]
    assert lines["mode"] == 1  # LINES
    ends = accessor(document, binary, lines["attributes"]["POSITION"])
    count = answer["count"]
    assert ends.shape == (2 * count, 3)
    position, direction = np.asarray(answer["sites"]["position"]), answer["sites"]["direction"]
    np.testing.assert_allclose(ends[0::2], position, rtol=0, atol=1e-3)
    np.testing.assert_allclose(unit(ends[1::2] - ends[0::2]), direction, atol=1e-4)
    np.testing.assert_allclose(np.linalg.norm(ends[1::2] - ends[0::2], axis=1), 3.0, rtol=1e-5)
    colours = accessor(document, binary, lines["attributes"]["COLOR_0"])
    assert colours.shape == (2 * count, 3) and len(np.unique(colours, axis=0)) == 1  # one angle


@pytest.mark.parametrize("output", ["svg", "png"])
async def test_the_map_shows_the_strokes_flows_and_whorls(client, output):
    cx, cy, size = await centre_of_map(client)
    asked = {"density_per_cm2": 2, "growth": hairline_and_crown(cx, cy, size)}
    with_growth = (await sites(client, asked | {"output": output})).content
    without = (await sites(client, {"density_per_cm2": 2, "output": output})).content
    if output == "svg":
        text = with_growth.decode()
        assert 'class="growth"' in text and "hairline" not in text  # flows by number
        assert "flow 0: flow" in text and "whorl 0: clockwise" in text
        assert 'class="growth"' not in without.decode()
    else:
        shown = np.asarray(Image.open(io.BytesIO(with_growth)).convert("RGB"))
        plain = np.asarray(Image.open(io.BytesIO(without)).convert("RGB"))
        assert (np.all(shown == STROKE_RGB, axis=2)).sum() > 10 * (
            np.all(plain == STROKE_RGB, axis=2)
        ).sum() + 100


STROKE_RGB = (0xB2, 0x18, 0x2B)


def glb_parts(data: bytes) -> tuple[dict, bytes]:
    length = struct.unpack("<I", data[12:16])[0]
    document = json.loads(data[20 : 20 + length])
    return document, data[20 + length + 8 :]


def accessor(document: dict, binary: bytes, index: int) -> np.ndarray:
    found = document["accessors"][index]
    view = document["bufferViews"][found["bufferView"]]
    columns = {"SCALAR": 1, "VEC2": 2, "VEC3": 3}[found["type"]]
    raw = binary[view["byteOffset"] : view["byteOffset"] + view["byteLength"]]
    return np.frombuffer(raw, dtype=np.float32).reshape(found["count"], columns)


async def test_the_command_line_takes_the_flow_from_a_file(client, tmp_path):
    cx, cy, size = await centre_of_map(client)
    growth = hairline_and_crown(cx, cy, size)
    flow = tmp_path / "flow.json"
    flow.write_text(json.dumps(growth))
    out = tmp_path / "sites.json"
    frame = ["--region-cone", "0,0,1:70", "--pole", "0,0,-1", "--up", "0,1,0", "--sigma", "0.3"]
    command = ["sites", str(SAMPLES[NAME].path), *frame, "--units", "mm", "--density", "2"]
    assert main([*command, "--flow", str(flow), "--out", str(out)]) == 0
    expected = (await sites(client, {"density_per_cm2": 2, "growth": growth})).json()
    assert json.loads(out.read_bytes()) == expected
    flow.write_text(json.dumps(growth["flow"]))  # a list: the flow alone
    assert main([*command, "--flow", str(flow), "--out", str(out)]) == 0
    assert json.loads(out.read_bytes())["growth"]["whorls"] == []


def served_with_growth(route: str, params: dict) -> httpx.Response:
    """A real ``meshflat serve``'s answer to ``route`` for the bundled head with ``params``
    and a hairline and a crown whorl drawn on the map it answers first."""
    head = SAMPLES[NAME].path.read_bytes()
    with running() as server, httpx.Client(base_url=server.url, timeout=60) as client:
        mapped = client.post("/v1/flatten", files={"mesh": (NAME, head)},
                             data={"params": json.dumps(SCALP)}).json()["vertices"]  # fmt: skip
        x, y = np.asarray(mapped["x"]), np.asarray(mapped["y"])
        growth = hairline_and_crown((x.min() + x.max()) / 2, (y.min() + y.max()) / 2,
                                    max(np.ptp(x), np.ptp(y)))  # fmt: skip
        return client.post(route, files={"mesh": (NAME, head)},
                           data={"params": json.dumps(params | {"growth": growth})})  # fmt: skip


@real_servers
def test_a_real_server_places_sites_with_their_directions():
    """``meshflat serve`` (the command `make serve` runs), over HTTP: the map, then sites
    with a hairline and a crown whorl, each with its unit direction."""
    params = SCALP | {"units": "mm", "density_per_cm2": 5}
    response = served_with_growth("/v1/sites", params)
    assert response.status_code == 200, response.text
    found = response.json()["sites"]
    assert len(found["direction"]) == response.json()["count"] > 100
    np.testing.assert_allclose(np.linalg.norm(found["direction"], axis=1), 1.0, atol=1e-12)


def test_the_closed_form_solve_is_the_pseudo_inverses():
    """The pushing forward solves its 2 x 2 systems in closed form, by the pseudo-inverse
    where one is near singular (a triangle of no area): both agree with numpy's pinv."""
    rng = np.random.default_rng(5)
    matrices = rng.normal(size=(2000, 2, 2))
    matrices[:50, :, 1] = 3.0 * matrices[:50, :, 0]  # singular: two parallel edges
    matrices[50:60] = 0.0  # no area at all
    right = rng.normal(size=(2000, 2))
    expected = np.einsum("pij,pj->pi", np.linalg.pinv(matrices), right)
    np.testing.assert_allclose(solve_2x2(matrices, right), expected, rtol=1e-9, atol=1e-12)
