"""``POST /v1/measure`` (zones and curves drawn on the map, measured on the surface) and
``/v1/locate`` with ``via: map``, through the API; ``meshflat measure`` on the command line.
The core's exactness is pinned in tests/test_zones.py; here, that the answers carry it."""

from __future__ import annotations

import json
import math
import tracemalloc

import httpx
import numpy as np
import pytest
import shapely

from service.app import create_app
from service.cli import main
from service.samples import SAMPLES
from service.server.jobs import Ticket
from service.settings import Settings

from .test_api import flatten, problem

pytestmark = pytest.mark.anyio

NAME = "fsaverage-head.ply"
#: The scalp of the fsaverage head, seen from the box centre with the pole at the chin.
PARAMS = {
    "region": {"cone": {"axis": [0, 0, 1], "half_angle_deg": 70}},
    "rotation": {"pole": [0, 0, -1], "up": [0, 1, 0]},
    "sigma": 0.3,
}


async def measure(client, params: dict, name: str = NAME) -> httpx.Response:
    return await flatten(client, name, {**PARAMS, **params}, endpoint="/v1/measure")


async def flat_map(client) -> dict:
    """The flatten answer of the scalp, and its triangles' surface areas by position."""
    answer = (await flatten(client, NAME, PARAMS)).json()
    ids = np.asarray(answer["vertices"]["ids"])
    position = {vertex: k for k, vertex in enumerate(ids.tolist())}
    corners = np.vectorize(position.get)(np.asarray(answer["faces"]["vertices"]))
    x, y = np.asarray(answer["vertices"]["x"]), np.asarray(answer["vertices"]["y"])
    vertices, _ = _sample_vertices()
    p = vertices[ids][corners]
    areas = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    return {"answer": answer, "x": x, "y": y, "corners": corners, "areas": areas}


def _sample_vertices():
    from .conftest import load_sample

    return load_sample(NAME)


def rectangle(name: str, x0: float, x1: float, y0: float, y1: float) -> dict:
    return {"name": name, "outer": {"x": [x0, x1, x1, x0], "y": [y0, y0, y1, y1]}}


def ring(points: np.ndarray) -> dict:
    return {"x": points[:, 0].tolist(), "y": points[:, 1].tolist()}


async def test_a_zone_over_the_whole_map_has_the_regions_surface_area(client):
    scalp = await flat_map(client)
    x, y = scalp["x"], scalp["y"]
    zone = rectangle("all", x.min() - 1, x.max() + 1, y.min() - 1, y.max() + 1)
    response = await measure(client, {"zones": [zone]})
    assert response.status_code == 200, response.text
    measured = response.json()["zones"][0]
    expected = math.fsum(scalp["areas"])
    assert measured["area"] == pytest.approx(expected, rel=1e-9)
    assert measured["faces"] == sorted(scalp["answer"]["faces"]["ids"])
    assert measured["partial_faces"] == []
    assert measured["area_flagged"] == 0.0
    assert measured["area_cm2"] is None and measured["perimeter"] == 0.0
    # The rectangle's map area outside the region's triangles.
    covered = 0.5 * np.abs(_map_areas(scalp)).sum()
    assert measured["area_outside_region"] == pytest.approx(measured["map_area"] - covered)


def _map_areas(scalp: dict) -> np.ndarray:
    c = np.stack([scalp["x"], scalp["y"]], axis=1)[scalp["corners"]]
    e1, e2 = c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]
    return e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]


async def test_zones_that_tile_the_map_sum_to_the_regions_area(client):
    scalp = await flat_map(client)
    x, y = scalp["x"], scalp["y"]
    xs = [x.min() - 1, x.mean() - 0.1, x.mean() + 0.13, x.max() + 1]
    ys = [y.min() - 1, y.mean() + 0.07, y.max() + 1]
    tiles = [
        rectangle(f"tile {i}{j}", xs[i], xs[i + 1], ys[j], ys[j + 1])
        for i in range(3)
        for j in range(2)
    ]
    response = await measure(client, {"zones": tiles})
    assert response.status_code == 200, response.text
    answer = response.json()
    total = math.fsum(zone["area"] for zone in answer["zones"])
    assert total == pytest.approx(math.fsum(scalp["areas"]), rel=1e-9)
    # Tiles that share only edges overlap nowhere.
    assert answer["overlaps"] == []


async def test_a_zone_that_is_one_triangles_image_has_that_triangles_area(client):
    scalp = await flat_map(client)
    k = 123
    corners = np.stack([scalp["x"], scalp["y"]], axis=1)[scalp["corners"][k]]
    response = await measure(client, {"zones": [{"name": "one", "outer": ring(corners)}]})
    measured = response.json()["zones"][0]
    assert measured["faces"] == [scalp["answer"]["faces"]["ids"][k]]
    assert measured["partial_faces"] == []
    assert measured["area"] == pytest.approx(scalp["areas"][k], rel=1e-9)


async def test_results_do_not_depend_on_the_rings_orientation_or_start(client):
    scalp = await flat_map(client)
    t = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    points = np.stack(
        [scalp["x"].mean() + 0.2 * np.cos(t), scalp["y"].mean() + 0.15 * np.sin(t)], axis=1
    )
    variants = [points, points[::-1], np.roll(points, 7, axis=0), np.roll(points[::-1], 3, axis=0)]
    zones = [{"name": f"v{k}", "outer": ring(v)} for k, v in enumerate(variants)]
    answer = (await measure(client, {"zones": zones})).json()
    first = answer["zones"][0]
    for zone in answer["zones"][1:]:
        assert zone["area"] == pytest.approx(first["area"], rel=1e-12)
        assert zone["perimeter"] == pytest.approx(first["perimeter"], rel=1e-12)
        assert zone["faces"] == first["faces"]
        assert zone["partial_faces"] == first["partial_faces"]
    # Identical zones overlap by their whole area.
    assert all(o["area"] == pytest.approx(first["area"], rel=1e-9) for o in answer["overlaps"])
    assert len(answer["overlaps"]) == 6


async def test_a_hole_takes_its_area_out_and_overlaps_are_measured(client):
    scalp = await flat_map(client)
    cx, cy = scalp["x"].mean(), scalp["y"].mean()
    outer = rectangle("outer", cx - 0.3, cx + 0.3, cy - 0.2, cy + 0.2)
    hole = rectangle("hole", cx - 0.1, cx + 0.1, cy - 0.1, cy + 0.1)
    with_hole = {**outer, "name": "ring", "holes": [hole["outer"]]}
    answer = (await measure(client, {"zones": [outer, hole, with_hole]})).json()
    area = {zone["name"]: zone["area"] for zone in answer["zones"]}
    assert area["ring"] == pytest.approx(area["outer"] - area["hole"], rel=1e-9)
    overlaps = {tuple(o["zones"]): o["area"] for o in answer["overlaps"]}
    assert overlaps[("outer", "hole")] == pytest.approx(area["hole"], rel=1e-9)
    assert overlaps[("outer", "ring")] == pytest.approx(area["ring"], rel=1e-9)
    assert ("hole", "ring") not in overlaps  # they share only the hole's boundary


async def test_nested_zones_are_measured_once_each_and_their_overlaps_are_the_inner_ones(
    client, monkeypatch
):
    """Every pair of nested zones overlaps: each pair's shared area is the inner zone's,
    taken from its own measure, not from a zone made of their intersection and measured
    again (a quadratic count of measures: 256 nested 16-gons took over 60 s)."""
    import service.capabilities.measure as module

    measures = []

    def counted(triangles, rings):
        measures.append(len(rings[0]))
        return cover_zone(triangles, rings)

    cover_zone = module.cover_zone
    monkeypatch.setattr(module, "cover_zone", counted)
    scalp = await flat_map(client)
    centre = np.array([scalp["x"].mean(), scalp["y"].mean()])
    turns = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    circle = np.column_stack([np.cos(turns), np.sin(turns)])
    radii = 0.05 + 0.06 * np.arange(24)
    zones = [{"name": f"r{k}", "outer": ring(centre + r * circle)} for k, r in enumerate(radii)]
    answer = (await measure(client, {"zones": zones})).json()
    assert len(measures) == len(zones)
    area = [zone["area"] for zone in answer["zones"]]
    pairs = [(i, j) for i in range(len(zones)) for j in range(i + 1, len(zones))]
    assert [tuple(o["indices"]) for o in answer["overlaps"]] == pairs
    for overlap in answer["overlaps"]:
        assert overlap["area"] == area[overlap["indices"][0]]  # the smaller one
    # Partly overlapping zones share, by shapely, each triangle's map area in both over its
    # map area times its surface area; with no zone measured beyond the two.
    shifted = [np.array([0.0, 0.0]), np.array([0.2, 0.1]), np.array([-0.15, 0.25])]
    crossing = [
        {"name": f"c{k}", "outer": ring(centre + shift + radii[4] * circle)}
        for k, shift in enumerate(shifted)
    ]
    measures.clear()
    answer = (await measure(client, {"zones": crossing})).json()
    assert len(measures) == 3
    c = np.stack([scalp["x"], scalp["y"]], axis=1)[scalp["corners"]]
    triangles = shapely.polygons(np.concatenate([c, c[:, :1]], axis=1))
    polygons = [shapely.Polygon(centre + shift + radii[4] * circle) for shift in shifted]
    assert [o["indices"] for o in answer["overlaps"]] == [[0, 1], [0, 2], [1, 2]]
    for overlap in answer["overlaps"]:
        i, j = overlap["indices"]
        common = shapely.intersection(polygons[i], polygons[j])
        share = shapely.area(shapely.intersection(triangles, common)) / shapely.area(triangles)
        assert overlap["area"] == pytest.approx(math.fsum(share * scalp["areas"]), rel=1e-9)
        assert 0 < overlap["area"] < answer["zones"][i]["area"]


async def test_a_zone_off_the_region_measures_nothing_and_says_so(client):
    zone = rectangle("far", 10.0, 10.5, 10.0, 10.2)
    answer = (await measure(client, {"zones": [zone]})).json()
    measured = answer["zones"][0]
    assert measured["area"] == 0.0 and measured["faces"] == [] and measured["perimeter"] == 0.0
    assert measured["area_outside_region"] == pytest.approx(0.1)
    assert measured["outline"][0]["points"] == []


#: A strip across the scalp's map: a rectangle drawn with its ends at +-147.03 spanned exactly
#: MAX_CELLS_PER_SIDE - 3 cells of the zone's grid, and rounding put its far end in the grid's
#: empty margin: the strip measured a fortieth of its area.
STRIP = (1.0444092486908958, 1.3664327427199252)


async def test_a_zones_numbers_do_not_depend_on_how_far_off_the_map_its_corners_lie(client):
    scalp = await flat_map(client)
    y0, y1 = STRIP
    reaches = (5.0, 65.88, 147.0287641866895, 1e6, 1e15)
    zones = [rectangle(f"to {far:g}", -far, far, y0, y1) for far in reaches]
    answer = (await measure(client, {"zones": zones, "units": "mm"})).json()
    near, *far = answer["zones"]
    # The strip's area by shapely: each triangle's map area inside it, over its map area.
    c = np.stack([scalp["x"], scalp["y"]], axis=1)[scalp["corners"]]
    triangles = shapely.polygons(np.concatenate([c, c[:, :1]], axis=1))
    strip = shapely.box(scalp["x"].min() - 1, y0, scalp["x"].max() + 1, y1)
    shares = shapely.area(shapely.intersection(triangles, strip)) / shapely.area(triangles)
    assert near["area"] == pytest.approx(math.fsum(shares * scalp["areas"]), rel=1e-9)
    for zone in far:
        assert zone["area"] == pytest.approx(near["area"], rel=1e-9), zone["name"]
        assert zone["perimeter"] == pytest.approx(near["perimeter"], rel=1e-9), zone["name"]
        assert zone["faces"] == near["faces"] and zone["partial_faces"] == near["partial_faces"]


async def test_sites_in_a_zone_do_not_depend_on_how_far_off_the_map_its_corners_lie(client):
    y0, y1 = STRIP
    counts = []
    for far in (5.0, 147.0287641866895, 1e15):
        zone = {**rectangle("strip", -far, far, y0, y1), "density_per_cm2": 20}
        params = {**PARAMS, "units": "mm", "zones": [zone], "seed": 3}
        response = await flatten(client, NAME, params, endpoint="/v1/sites")
        assert response.status_code == 200, response.text
        answer = response.json()
        counts.append((answer["count"], answer["zones"][0]["area_cm2"]))
    assert counts[1][0] == counts[2][0] == counts[0][0] > 0
    assert [area for _, area in counts] == pytest.approx([counts[0][1]] * 3, rel=1e-9)


async def test_units_give_square_centimetres_and_millimetres(client):
    scalp = await flat_map(client)
    cx, cy = scalp["x"].mean(), scalp["y"].mean()
    zone = rectangle("crown", cx - 0.2, cx + 0.2, cy - 0.2, cy + 0.2)
    curve = {"name": "line", "x": [cx - 0.3, cx + 0.3], "y": [cy, cy + 0.05]}
    answers = {}
    for units in ("mm", "cm", {"between": [[0, 0, 0], [0, 0, 31]], "mm": 62.0}):
        response = await measure(client, {"zones": [zone], "curves": [curve], "units": units})
        answers[json.dumps(units)] = response.json()
    mm = answers['"mm"']
    area, length = mm["zones"][0]["area"], mm["curves"][0]["length"]
    assert mm["units"] == {"mm_per_unit": 1.0}
    assert mm["zones"][0]["area_cm2"] == pytest.approx(area / 100)
    assert answers['"cm"']["zones"][0]["area_cm2"] == pytest.approx(area)
    assert answers['"cm"']["curves"][0]["length_mm"] == pytest.approx(10 * length)
    known = answers[json.dumps({"between": [[0, 0, 0], [0, 0, 31]], "mm": 62.0})]
    assert known["units"]["mm_per_unit"] == pytest.approx(2.0)
    assert known["zones"][0]["perimeter_mm"] == pytest.approx(2 * mm["zones"][0]["perimeter"])


async def test_a_curve_is_lifted_through_its_points_and_every_edge_it_crosses(client):
    scalp = await flat_map(client)
    cx, cy = scalp["x"].mean(), scalp["y"].mean()
    x = [cx - 0.3, cx, cx + 0.3]
    y = [cy, cy + 0.1, cy]
    answer = (await measure(client, {"curves": [{"name": "hairline", "x": x, "y": y}]})).json()
    curve = answer["curves"][0]
    points, faces = np.asarray(curve["points"]), curve["faces"]
    assert len(faces) == len(points) - 1 > 10
    assert None not in faces  # the curve stays on the region
    map_points = np.asarray(curve["map_points"])
    for own in zip(x, y, strict=True):
        assert np.min(np.linalg.norm(map_points - own, axis=1)) < 1e-12
    steps = np.linalg.norm(np.diff(points, axis=0), axis=1)
    assert curve["length"] == pytest.approx(steps.sum(), rel=1e-9)
    # Each piece's surface points lie on the face the answer names.
    vertices, mesh_faces = _sample_vertices()
    for k in range(len(faces)):
        corners = vertices[mesh_faces[faces[k]]]
        for point in points[k : k + 2]:
            normal = np.cross(corners[1] - corners[0], corners[2] - corners[0])
            assert abs(np.dot(point - corners[0], normal)) <= 1e-6 * np.linalg.norm(normal)


@pytest.mark.parametrize(
    ("zone", "field", "words"),
    [
        (
            {"name": "bow", "outer": {"x": [0, 1, 0, 1], "y": [0, 1, 1, 0]}},
            "params.zones.0.outer",
            "crosses or touches itself near (0.5, 0.5)",
        ),
        (
            {"name": "flat", "outer": {"x": [0, 1, 0, 1], "y": [0, 1, 0, 1]}},
            "params.zones.0.outer",
            "at least three distinct points",
        ),
        (
            {
                "name": "holed",
                "outer": {"x": [0, 1, 1, 0], "y": [0, 0, 1, 1]},
                "holes": [{"x": [2, 3, 3], "y": [0, 0, 1]}],
            },
            "params.zones.0.holes.0",
            "must lie inside the outer ring",
        ),
        (
            {
                "name": "bad hole",
                "outer": {"x": [0, 1, 1, 0], "y": [0, 0, 1, 1]},
                "holes": [{"x": [0.2, 0.4, 0.2, 0.4], "y": [0.2, 0.4, 0.4, 0.2]}],
            },
            "params.zones.0.holes.0",
            "crosses or touches itself",
        ),
        (
            {"name": "short", "outer": {"x": [0, 1, 1, 0], "y": [0, 0, 1]}},
            "params.zones.0.outer",
            "one y per x",
        ),
    ],
)
async def test_a_bad_ring_is_a_422_naming_the_zone_and_the_ring(client, zone, field, words):
    response = await measure(client, {"zones": [rectangle("fine", 0, 1, 0, 1), zone]})
    body = problem(response, 422)
    expected = field.replace("zones.0", "zones.1")
    assert body["field"].startswith(expected), body
    assert words in body["detail"]
    if "one y per x" not in words:
        assert repr(zone["name"]) in body["detail"]


async def test_bad_curves_and_units_are_422s(client):
    curve = {"name": "dot", "x": [0.5, 0.5], "y": [0.2, 0.2]}
    body = problem(await measure(client, {"curves": [curve]}), 422, "params.curves.0")
    assert "two distinct points" in body["detail"]
    units = {"between": [[1, 2, 3], [1, 2, 3]], "mm": 62.0}
    problem(await measure(client, {"units": units}), 422, "params.units.between")
    body = problem(await measure(client, {"units": "inch"}), 422, "params.units")
    assert "[" not in body["field"], body  # no pydantic union member in the field's name
    body = await measure(client, {"zones": [{"name": "", "outer": {"x": [0], "y": [0]}}]})
    problem(body, 422)


async def test_zones_and_curves_need_names_of_their_own(client):
    """Overlaps, the legend and the answers name what was drawn: two zones (or curves) of
    one name are a 422 naming the second."""
    zones = [rectangle("crown", 0, 1, 0, 1), rectangle("crown", 1, 2, 0, 1)]
    body = problem(await measure(client, {"zones": zones}), 422, "params")
    assert "zones.1: the name 'crown' is that of zones.0" in body["detail"]
    curves = [{"name": "line", "x": [0, 1], "y": [0, 1]}] * 2
    body = problem(await measure(client, {"curves": curves}), 422, "params")
    assert "curves.1: the name 'line' is that of curves.0" in body["detail"]
    # The same name for a zone and a curve is fine.
    fine = {"zones": zones[:1], "curves": [{"name": "crown", "x": [0, 1], "y": [0, 1]}]}
    assert (await measure(client, fine)).status_code == 200


async def test_too_many_drawn_points_is_a_413():
    app = create_app(Settings(max_drawn_points=10))
    async with app.router.lifespan_context(app):
        transport = httpx.ASGITransport(app=app)
        async with httpx.AsyncClient(transport=transport, base_url="http://meshflat") as client:
            t = np.linspace(0, 6, 11, endpoint=False)
            zone = {"name": "many", "outer": ring(np.stack([np.cos(t), np.sin(t)], axis=1))}
            body = problem(await measure(client, {"zones": [zone]}), 413, "params.zones")
            assert "the limit is 10 (MESHFLAT_MAX_DRAWN_POINTS)" in body["detail"]


async def zig_zag(client, n: int) -> dict:
    """A curve of ``n`` points from one side of the scalp's map to the other and back, each
    pass a little higher: every pass crosses a row of triangles."""
    answer = (await flatten(client, NAME, PARAMS)).json()
    x, y = np.asarray(answer["vertices"]["x"]), np.asarray(answer["vertices"]["y"])
    xs = np.where(np.arange(n) % 2 == 0, x.min(), x.max())
    return {"name": "zig-zag", "x": xs.tolist(), "y": np.linspace(y.min(), y.max(), n).tolist()}


async def test_a_zig_zag_curve_over_the_crossings_limit_is_a_413_naming_the_setting():
    """A curve's crossings of triangle edges are counted from its length before any is
    built: a few points zig-zagging over the map cross thousands (issue 32)."""
    app = create_app(Settings(max_curve_crossings=1000))
    async with app.router.lifespan_context(app):
        transport = httpx.ASGITransport(app=app)
        async with httpx.AsyncClient(transport=transport, base_url="http://meshflat") as client:
            curve = await zig_zag(client, 40)
            body = problem(await measure(client, {"curves": [curve]}), 413, "params.curves")
            assert "the limit is 1,000 (MESHFLAT_MAX_CURVE_CROSSINGS)" in body["detail"]
            hairline = {"name": "hairline", "x": [-2.0, -1.57, -1.1], "y": [1.45, 1.35, 1.45]}
            assert (await measure(client, {"curves": [hairline]})).status_code == 200


async def test_a_curve_is_charged_at_least_what_measuring_it_allocates(monkeypatch):
    """Every byte the request allocates (tracemalloc's peak: the body, the mesh, the map, the
    curve's trace and its answer) was charged to the budget first, and what a zig-zag of
    1,000 points adds to a short curve's request is within what its crossings add to the
    charge: it once took some 90 MB, charged nothing (issue 32)."""
    charged = []
    charge = Ticket.charge
    monkeypatch.setattr(Ticket, "charge", lambda self, n: (charged.append(n), charge(self, n)))

    async def peak_and_charge(client, curve) -> tuple[int, int]:
        charged.clear()
        tracemalloc.start()
        try:
            response = await measure(client, {"curves": [curve]})
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        assert response.status_code == 200
        return peak, sum(charged)

    app = create_app(Settings())
    async with app.router.lifespan_context(app):
        transport = httpx.ASGITransport(app=app)
        async with httpx.AsyncClient(transport=transport, base_url="http://meshflat") as client:
            short = await peak_and_charge(client, await zig_zag(client, 2))
            long = await peak_and_charge(client, await zig_zag(client, 1000))
    assert long[0] <= long[1], f"{long[0] / 2**20:.0f} MiB taken, {long[1] / 2**20:.0f} charged"
    added, added_charge = long[0] - short[0], long[1] - short[1]
    assert added <= added_charge, (
        f"{added / 2**20:.0f} MiB more, {added_charge / 2**20:.0f} charged"
    )


@pytest.mark.parametrize("output", ["svg", "png"])
async def test_the_picture_shows_each_zone_named_with_its_area(client, output):
    scalp = await flat_map(client)
    cx, cy = scalp["x"].mean(), scalp["y"].mean()
    zones = [rectangle("crown", cx - 0.2, cx + 0.2, cy - 0.2, cy + 0.2)]
    curves = [{"name": "hairline", "x": [cx - 0.3, cx + 0.3], "y": [cy + 0.25, cy + 0.25]}]
    params = {"zones": zones, "curves": curves, "units": "mm", "output": output}
    response = await measure(client, params)
    assert response.status_code == 200
    assert response.headers["content-type"] == f"image/{'svg+xml' if output == 'svg' else 'png'}"
    area = (await measure(client, {**params, "output": "json"})).json()["zones"][0]["area_cm2"]
    if output == "svg":
        text = response.text
        assert 'class="zone"' in text and 'class="curve"' in text
        assert f"crown: {area:.2f} cm²" in text and "hairline: " in text
    else:
        assert response.content.startswith(b"\x89PNG")
    glb = await measure(client, {**params, "output": "glb"})
    problem(glb, 422, "params.output")


async def test_locate_via_map_finds_the_point_the_map_shows(client):
    scalp = await flat_map(client)
    answer = scalp["answer"]
    vertices, _ = _sample_vertices()
    rng = np.random.default_rng(4)
    picked = rng.integers(0, len(scalp["corners"]), 20)
    weights = rng.dirichlet([2, 2, 2], 20)
    plane = np.stack([scalp["x"], scalp["y"]], axis=1)
    points = np.einsum("kc,kcd->kd", weights, plane[scalp["corners"][picked]])
    # theta_phi: x is phi, y is theta.
    params = {**PARAMS, "theta": points[:, 1].tolist(), "phi": points[:, 0].tolist()}
    hits = (await flatten(client, NAME, {**params, "via": "map"}, endpoint="/v1/locate")).json()[
        "hits"
    ]
    ids = np.asarray(answer["vertices"]["ids"])
    expected = np.einsum("kc,kcd->kd", weights, vertices[ids][scalp["corners"][picked]])
    faces = np.asarray(answer["faces"]["ids"])[picked]
    assert [hit["face"] for hit in hits] == faces.tolist()
    np.testing.assert_allclose([hit["point"] for hit in hits], expected, atol=1e-9)
    np.testing.assert_allclose([hit["barycentric"] for hit in hits], weights, atol=1e-9)
    # Off the map: no hit; the default is still the ray.
    off = {**PARAMS, "theta": [0.05], "phi": [3.0], "via": "map"}
    assert (await flatten(client, NAME, off, endpoint="/v1/locate")).json()["hits"] == [None]
    ray = (await flatten(client, NAME, params, endpoint="/v1/locate")).json()
    assert ray["hits"][0]["point"] != hits[0]["point"]
    # The answer's params are the frame and region, for any route; the queries (theta, phi,
    # via) go with them again to locate the same way.
    answer = (await flatten(client, NAME, {**params, "via": "map"}, endpoint="/v1/locate")).json()
    assert "via" not in answer["params"] and answer["params"]["untangle"] is False
    again = {**answer["params"], "theta": params["theta"], "phi": params["phi"], "via": "map"}
    assert (await flatten(client, NAME, again, endpoint="/v1/locate")).json()["hits"] == hits


async def test_the_command_line_measures_zones_from_a_file(client, tmp_path, capsys):
    scalp = await flat_map(client)
    cx, cy = scalp["x"].mean(), scalp["y"].mean()
    zones = [rectangle("crown", cx - 0.2, cx + 0.2, cy - 0.2, cy + 0.2)]
    path = tmp_path / "zones.json"
    path.write_text(json.dumps(zones))
    args = ["--region-cone", "0,0,1:70", "--pole", "0,0,-1", "--up", "0,1,0", "--sigma", "0.3"]
    out = tmp_path / "zones.out.json"
    assert (
        main(["measure", str(SAMPLES[NAME].path), *args, "--zones", str(path), "--out", str(out)])
        == 0
    )
    expected = (await measure(client, {"zones": zones})).json()
    assert json.loads(out.read_bytes()) == expected
    assert main(["measure", str(SAMPLES[NAME].path), "--zones", str(tmp_path / "none.json")]) == 2
    assert "--zones: cannot read" in capsys.readouterr().err


async def test_the_flagged_part_of_a_zone_is_the_area_on_flagged_faces(client):
    # The whole head: a closed mesh, so some triangles cross the seam or hold a singular point.
    params = {"rotation": {"pole": [0, 0, -1], "up": [0, 1, 0]}, "sigma": 0.3}
    answer = (await flatten(client, NAME, params)).json()
    validation = answer["validation"]
    flagged = set()
    for key in ("singular_point_faces", "seam_faces", "folded_faces", "backfacing_faces"):
        flagged.update(validation[key])
    flagged.update(validation["degenerate_faces"])
    flagged.update(validation["stretched_faces"])
    assert flagged
    vertices, faces = _sample_vertices()
    p = vertices[faces[sorted(flagged)]]
    expected = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    x, y = np.asarray(answer["vertices"]["x"]), np.asarray(answer["vertices"]["y"])
    zone = rectangle("all", x.min() - 1, x.max() + 1, y.min() - 1, y.max() + 1)
    response = await flatten(client, NAME, {**params, "zones": [zone]}, endpoint="/v1/measure")
    measured = response.json()["zones"][0]
    # Faces that wrap around the map cover it more than once: the zone counts each face's
    # image, so the flagged area is that of the flagged faces wholly inside or cut.
    inside = set(measured["faces"]) | set(measured["partial_faces"])
    shares = dict(zip(measured["partial_faces"], measured["partial_fraction"], strict=True))
    by_face = dict(zip(sorted(flagged), expected, strict=True))
    total = sum(area * shares.get(face, 1.0) for face, area in by_face.items() if face in inside)
    assert measured["area_flagged"] == pytest.approx(total, rel=1e-9)
    assert measured["area_flagged"] > 0
