"""``POST /v1/compare`` and ``meshflat compare``: a follow-up made from a sample (moved,
turned, 0.3 mm of noise, its lowest 20 % cut away) with values raised by exactly 20 % inside
one zone; the zones' changes, the spots found again and the refusals, through the API. The
zone means are checked against an independent integration (shapely's clipping)."""

from __future__ import annotations

import io
import json
import re
from functools import cache

import numpy as np
import pytest
import shapely
from PIL import Image

from fixtures.meshes import subdivided
from service.cli import main
from service.samples import SAMPLES
from transforms import Chart, Frame, Framing, Layout, MapTriangles, PoleCap, cover_zone
from transforms.compare import zone_mean

from .conftest import slow
from .test_api import obj_of, problem
from .test_landmarks import on_head
from .test_measure import NAME
from .test_measure import PARAMS as SCALP
from .test_register import SHIFT, TURN

pytestmark = pytest.mark.anyio

PARAMS = {**SCALP, "units": "mm"}
#: Zones on the scalp's map (x = phi, y = theta): the raised one on the crown, two apart.
RAISED = {"name": "crown", "outer": {"x": [-1.95, -1.2, -1.2, -1.95], "y": [1.3, 1.3, 1.75, 1.75]}}
LEFT = {"name": "left", "outer": {"x": [-0.9, -0.55, -0.55, -0.9], "y": [1.35, 1.35, 1.7, 1.7]}}
RIGHT = {"name": "right", "outer": {"x": [-2.6, -2.3, -2.3, -2.6], "y": [1.35, 1.35, 1.7, 1.7]}}
ZONES = [RAISED, LEFT, RIGHT]
SPOTS = [
    {"name": "vertex", "x": -1.57, "y": 1.5},
    {"name": "temple", "x": -0.75, "y": 1.2},
    {"name": "occiput", "x": -2.4, "y": 1.9},
]


@cache
def scans():
    """fsaverage's head split twice (65k faces) as the baseline, and its follow-up: moved
    and turned, 0.3 mm of noise, its lowest 20 % of faces cut away. Returns the baseline's
    OBJ and vertices, the follow-up's OBJ, its vertices, its faces and each of its vertices'
    true place on the baseline (before the noise)."""
    vertices, faces = subdivided(NAME, 2)
    rng = np.random.default_rng(7)
    height = vertices[faces].mean(axis=1)[:, 2]
    kept = faces[height > np.quantile(height, 0.2)]
    used = np.unique(kept)
    number = np.full(len(vertices), -1)
    number[used] = np.arange(len(used))
    truth = vertices[used]
    moved = TURN.apply(truth) + SHIFT + rng.normal(scale=0.3, size=truth.shape)
    return (
        obj_of(vertices, faces),
        vertices,
        obj_of(moved, number[kept]),
        moved,
        number[kept],
        truth,
    )


def on_map(points: np.ndarray, resolved: dict) -> np.ndarray:
    """(n, 2): the baseline's map position (x = phi, y = theta) of baseline points, by the
    answer's resolved frame and chart (what /v1/points answers)."""
    frame = Frame.from_matrix(np.asarray(resolved["rotation"]), np.asarray(resolved["center"]))
    chart = Chart.from_method(resolved["method"], PoleCap.from_sigma(resolved["sigma"]))
    theta, phi, _ = chart.forward(frame.to_local(points))
    return np.column_stack([phi, theta])


def inside(points: np.ndarray, zone: dict) -> np.ndarray:
    polygon = shapely.Polygon(list(zip(zone["outer"]["x"], zone["outer"]["y"], strict=True)))
    return shapely.contains_xy(polygon, points[:, 0], points[:, 1])


def density(points_on_map: np.ndarray) -> np.ndarray:
    """Values that vary smoothly over the map: a 'density' of 60 to 90."""
    return 75.0 + 10.0 * np.sin(2.0 * points_on_map[:, 0]) + 5.0 * points_on_map[:, 1]


async def flat(client, mesh: bytes, name: str, params: dict) -> dict:
    response = await client.post(
        "/v1/flatten", files={"mesh": (name, mesh)}, data={"params": json.dumps(params)}
    )
    assert response.status_code == 200, response.text
    return response.json()


async def compare(client, params: dict, follow: bytes | None = None, **pictures):
    baseline, _, follow_up, *_ = scans()
    files = {"baseline": ("base.obj", baseline), "follow_up": ("follow.obj", follow or follow_up)}
    files.update({name: (f"{name}.png", data) for name, data in pictures.items()})
    return await client.post("/v1/compare", files=files, data={"params": json.dumps(params)})


def landmark_params() -> dict:
    _, vertices, *_ = scans()
    landmarks = on_head(vertices)
    turned = {k: (TURN.apply(np.asarray(v)) + SHIFT).tolist() for k, v in landmarks.items()}
    return {"landmarks": {"baseline": landmarks, "follow_up": turned}}


async def listed_values(client) -> tuple[list[float], list[float]]:
    """Each scan's values a vertex of its file: the density at the vertex's true place on
    the baseline's map, raised by exactly 20 % inside the crown zone on the follow-up."""
    _, vertices, _, _, _, truth = scans()
    resolved = (await flat(client, scans()[0], "base.obj", SCALP))["params"]
    base_map, follow_map = on_map(vertices, resolved), on_map(truth, resolved)
    follow = density(follow_map) * np.where(inside(follow_map, RAISED), 1.2, 1.0)
    return density(base_map).tolist(), follow.tolist()


@slow
@pytest.mark.parametrize("seeded", ["moments", "landmarks"])
async def test_a_zone_raised_20_percent_changes_20_percent_and_spots_are_found(client, seeded):
    base_values, follow_values = await listed_values(client)
    params = {**PARAMS, "zones": ZONES, "spots": SPOTS}
    params |= {"baseline_values": base_values, "follow_up_values": follow_values}
    if seeded == "landmarks":
        params |= landmark_params()
    response = await compare(client, params)
    assert response.status_code == 200, response.text
    answer = response.json()
    assert answer["registration"]["seeded_by"] == seeded
    zones = {zone["name"]: zone for zone in answer["zones"]}
    assert [zone["name"] for zone in answer["zones"]] == ["crown", "left", "right"]
    assert abs(zones["crown"]["change_percent"] - 20.0) <= 1.0, zones["crown"]
    for name in ("left", "right"):
        assert abs(zones[name]["change_percent"]) <= 1.0, zones[name]
    for zone in answer["zones"]:
        assert zone["baseline_coverage"] == pytest.approx(1.0, abs=1e-9)
        assert zone["follow_up_coverage"] >= 0.99
    # Each spot on the follow-up within 1 mm of where the true motion puts its baseline
    # point (the follow-up's surface carries 0.3 mm of noise).
    for spot in answer["spots"]:
        truth = TURN.apply(np.asarray(spot["baseline_position"])) + SHIFT
        assert np.linalg.norm(np.asarray(spot["follow_up_position"]) - truth) <= 1.0, spot
        assert (
            abs(spot["follow_up_x"] - spot["x"]) < 0.02
            and abs(spot["follow_up_y"] - spot["y"]) < 0.02
        )
        assert spot["distance_mm"] <= 1.0
    assert answer["warnings"] == []


@slow
async def test_value_pictures_on_each_scans_own_map_give_the_same_changes(client):
    """Values as pictures: the baseline's on its own grid, the follow-up's on the grid
    /v1/transfer gives it with the registration's frame and its region."""
    _, _, follow_up, _, faces, truth = scans()
    first = await compare(client, {**PARAMS, "zones": ZONES})
    assert first.status_code == 200, first.text
    frame = first.json()["registration"]["frame"]
    # The follow-up's region: its faces whose true places lie on the baseline's scalp cone.
    centroids = truth[faces].mean(axis=1)
    region = {"faces": np.flatnonzero(centroids[:, 2] > -10.0).tolist()}
    size = {"image_width": 1600, "image_height": 1200}
    pictures = {}
    value_range = [50.0, 120.0]
    for name, mesh, params, raised in (
        ("baseline_values", scans()[0], SCALP, False),
        ("follow_up_values", follow_up, {**frame, "region": region}, True),
    ):
        answer = await flat(client, mesh, f"{name}.obj", params)
        x, y = np.asarray(answer["vertices"]["x"]), np.asarray(answer["vertices"]["y"])
        pictures[name] = _picture(x, y, raised, size, value_range)
    params = {**PARAMS, **size, "zones": ZONES, "follow_up_region": region}
    params["value_range"] = value_range
    response = await compare(client, params, **pictures)
    assert response.status_code == 200, response.text
    zones = {zone["name"]: zone for zone in response.json()["zones"]}
    assert abs(zones["crown"]["change_percent"] - 20.0) <= 1.0, zones["crown"]
    for name in ("left", "right"):
        assert abs(zones[name]["change_percent"]) <= 1.0, zones[name]


def _picture(x, y, raised: bool, size: dict, value_range) -> bytes:
    """A 16-bit grey PNG on the PNG answer's grid of the map ``x``, ``y``: the density at
    each pixel centre's map point, raised by 20 % inside the crown zone."""
    width, height = size["image_width"], size["image_height"]
    framing = Framing.of(x, y, Layout.THETA_PHI, width, height)
    columns, rows = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    points = np.column_stack([
        framing.view[0] + (columns.ravel() - framing.plot[0]) / framing.scale,
        (framing.view[2] + (rows.ravel() - framing.plot[1]) / framing.scale) * framing.s_sign,
    ])  # fmt: skip
    values = density(points)
    if raised:
        values *= np.where(inside(points, RAISED), 1.2, 1.0)
    low, high = value_range
    grey = np.clip(np.rint((values - low) / (high - low) * 65535), 0, 65535).astype(np.uint16)
    out = io.BytesIO()
    Image.fromarray(grey.reshape(height, width)).save(out, format="PNG")
    return out.getvalue()


def test_a_zone_mean_is_the_exact_integral_of_the_linear_values():
    """zone_mean against shapely: each triangle clipped by the zone, the linear values
    integrated over the piece at its centroid, summed by surface area."""
    rng = np.random.default_rng(3)
    xs, ys = np.meshgrid(np.linspace(0, 1, 13), np.linspace(0, 1, 11))
    points = np.column_stack([xs.ravel(), ys.ravel()]) + rng.normal(scale=0.01, size=(143, 2))
    faces = shapely.delaunay_triangles(shapely.MultiPoint(points), only_edges=False)
    triangles_xy = np.array([np.asarray(t.exterior.coords)[:3] for t in faces.geoms])
    index = {tuple(p): k for k, p in enumerate(points.tolist())}
    tri = np.array([[index[tuple(p)] for p in t.tolist()] for t in triangles_xy])
    surface = np.column_stack([points, 0.3 * points[:, 0] ** 2])  # a curved surface
    values = rng.uniform(1, 5, size=len(points))
    triangles = MapTriangles.of(points[:, 0], points[:, 1], surface, tri)
    zone = shapely.Polygon([(0.13, 0.21), (0.8, 0.1), (0.9, 0.7), (0.5, 0.95), (0.2, 0.6)])
    hole = shapely.Polygon([(0.4, 0.4), (0.6, 0.42), (0.5, 0.6)])
    rings = [np.asarray(zone.exterior.coords)[:-1], np.asarray(hole.exterior.coords)[:-1][::-1]]
    found = zone_mean(triangles, cover_zone(triangles, rings), values)
    shape = zone.difference(hole)
    total = weight = 0.0
    for corners in tri:
        piece = shapely.Polygon(points[corners]).intersection(shape)
        if piece.area == 0:
            continue
        # The value at the piece's centroid, by barycentric weights in the map triangle.
        a, b, c = points[corners]
        centroid = np.asarray(piece.centroid.coords[0])
        w = np.linalg.solve(np.array([[a[0], b[0], c[0]], [a[1], b[1], c[1]], [1, 1, 1]]),
                            np.array([centroid[0], centroid[1], 1.0]))  # fmt: skip
        map_area = shapely.Polygon(points[corners]).area
        surface_area = 0.5 * np.linalg.norm(
            np.cross(
                surface[corners[1]] - surface[corners[0]], surface[corners[2]] - surface[corners[0]]
            )
        )
        area = piece.area / map_area * surface_area
        total += area * float(w @ values[corners])
        weight += area
    assert found.mean == pytest.approx(total / weight, rel=1e-12)
    assert found.area == pytest.approx(weight, rel=1e-12)
    assert found.valued_area == found.area


async def test_a_zone_the_cropped_follow_up_misses_in_part_is_said_not_filled_in(client):
    """Cut the follow-up's faces over half the crown zone away: its mean is over the rest,
    its coverage about a half, and a values_missing warning names the zone."""
    _, _, _, moved, faces, truth = scans()
    resolved = (await flat(client, scans()[0], "base.obj", SCALP))["params"]
    centroid_map = on_map(truth[faces].mean(axis=1), resolved)
    half = {**RAISED, "outer": {"x": [-1.95, -1.575, -1.575, -1.95], "y": RAISED["outer"]["y"]}}
    keep = ~inside(centroid_map, half)
    follow = obj_of(moved, faces[keep])
    base_values, _ = await listed_values(client)
    follow_values = density(on_map(truth, resolved)).tolist()
    rest = {"name": "rest", "outer": {"x": [-1.575, -1.2, -1.2, -1.575], "y": RAISED["outer"]["y"]}}
    params = {**PARAMS, "zones": [RAISED, rest], "landmarks": landmark_params()["landmarks"]}
    params |= {"baseline_values": base_values, "follow_up_values": follow_values}
    response = await compare(client, params, follow=follow)
    assert response.status_code == 200, response.text
    answer = response.json()
    zone, kept = answer["zones"]
    assert 0.4 <= zone["follow_up_coverage"] <= 0.6, zone
    # The rest loses the few triangles of its edge whose centroids were on the cut side.
    assert kept["follow_up_coverage"] >= 0.99 and zone["baseline_coverage"] == 1.0
    # The follow-up's mean is over the half it still shows: the baseline's there.
    assert abs(zone["follow_up"] / kept["baseline"] - 1.0) <= 0.005, (zone, kept)
    warned = {w["field"]: w for w in answer["warnings"] if w["code"] == "values_missing"}
    assert "'crown'" in warned["params.zones.0"]["message"]


async def test_a_spot_off_the_follow_up_has_no_follow_up_place_and_is_said(client):
    """The follow-up lacks its lowest 20 %: a spot low at the back is not on it."""
    params = {**PARAMS, "spots": [{"name": "nape", "x": -2.2, "y": 2.5}, SPOTS[0]]}
    params |= landmark_params()
    response = await compare(client, params)
    assert response.status_code == 200, response.text
    answer = response.json()
    nape, vertex = answer["spots"]
    assert nape["baseline_position"] is not None or nape["follow_up_position"] is None
    assert nape["follow_up_position"] is None and nape["follow_up_x"] is None
    assert vertex["follow_up_position"] is not None
    codes = {(w["code"], w["field"]) for w in answer["warnings"]}
    assert ("spot_off_scan", "params.spots.0") in codes


async def test_spot_values_as_measured_give_their_change(client):
    params = {**PARAMS, "spots": [{**SPOTS[0], "baseline": 80.0, "follow_up": 100.0}]}
    params |= landmark_params()
    answer = (await compare(client, params)).json()
    (spot,) = answer["spots"]
    assert spot["baseline"] == 80.0 and spot["follow_up"] == 100.0
    assert spot["change"] == 20.0 and spot["change_percent"] == 25.0


@pytest.mark.parametrize(
    ("params", "parts", "field"),
    [
        ({"baseline_values": [1.0, 2.0]}, {}, "params.baseline_values"),
        ({"zones": [], "spots": []}, {}, "params"),
        ({"value_range": [0, 1], "spots": SPOTS}, {}, "params.value_range"),
        ({"value_range": [1, 0], "spots": SPOTS}, {"baseline_values": "png"}, "params.value_range"),
        ({"spots": SPOTS}, {"follow_up_values": "png"}, "params.follow_up_region"),
        ({"baseline_values": "no_such_property", "spots": SPOTS}, {}, "params.baseline_values"),
        (
            {"follow_up_region": {"texture_mask": {"min": 0.5}}, "spots": SPOTS},
            {},
            "params.follow_up_region.texture_mask",
        ),
    ],
)
async def test_refusals_name_the_field(client, params, parts, field):
    pictures = {name: _tiny_png() for name in parts}
    response = await compare(client, {**PARAMS, "zones": [RAISED], **params}, **pictures)
    body = problem(response, 422)
    assert body["field"] == field or body["field"].startswith(field), body


def _tiny_png() -> bytes:
    out = io.BytesIO()
    Image.new("L", (480, 360), 128).save(out, format="PNG")
    return out.getvalue()


async def test_values_listed_and_pictured_for_one_scan_are_refused(client):
    params = {**PARAMS, "spots": SPOTS, "baseline_values": "x"}
    response = await compare(client, params, baseline_values=_tiny_png())
    body = problem(response, 422)
    assert body["field"] == "params.baseline_values" and "not both" in body["detail"]


@slow
async def test_a_follow_up_of_another_head_does_not_register_and_is_said(client):
    other = SAMPLES["nefertiti-lowres.obj"].path.read_bytes()
    files = {
        "baseline": ("base.obj", scans()[0]),
        "follow_up": ("nefertiti-lowres.obj", other),
    }
    params = {**PARAMS, "spots": SPOTS, "mode": "rigid"}
    response = await client.post("/v1/compare", files=files, data={"params": json.dumps(params)})
    body = problem(response, 422)
    assert body["field"] == "follow_up"


@slow
async def test_the_difference_map_draws_the_zones_and_a_bar_about_zero(client):
    base_values, follow_values = await listed_values(client)
    params = {**PARAMS, "zones": ZONES, "spots": SPOTS, **landmark_params()}
    params |= {"baseline_values": base_values, "follow_up_values": follow_values}
    svg = await compare(client, {**params, "output": "svg"})
    assert svg.status_code == 200 and svg.headers["content-type"].startswith("image/svg+xml")
    text = svg.text
    assert "follow-up minus baseline" in text and "meshflat compare" in text
    # The crown's label: its area and about +20 %; the others about 0.
    assert re.search(r"crown: [0-9.]+ cm², \+(19|20)\.[0-9] %", text), text
    assert "spots: 3" in text
    png = await compare(client, {**params, "output": "png"})
    assert png.status_code == 200
    image = Image.open(io.BytesIO(png.content))
    assert image.size == (1200, 900) or image.size[0] > 0


@slow
def test_meshflat_compare_writes_what_the_api_answers(tmp_path, capsys):
    baseline, _, follow_up, *_ = scans()
    (tmp_path / "base.obj").write_bytes(baseline)
    (tmp_path / "follow.obj").write_bytes(follow_up)
    params = {**SCALP, "spots": SPOTS, **landmark_params()}
    out = tmp_path / "compare.json"
    code = main([
        "compare", str(tmp_path / "base.obj"), str(tmp_path / "follow.obj"), "--units", "mm",
        "--params", json.dumps(params), "--out", str(out),
    ])  # fmt: skip
    assert code == 0, capsys.readouterr()
    answer = json.loads(out.read_text())
    assert [spot["name"] for spot in answer["spots"]] == [spot["name"] for spot in SPOTS]
    assert answer["registration"]["seeded_by"] == "landmarks"
