"""``POST /v1/plan`` (a transplant's grafts needed and available from zones drawn on the map),
through the API, against an independent computation from the zones' areas as /v1/measure
answers them; ``meshflat plan`` on the command line; the arithmetic of transforms/plan.py."""

from __future__ import annotations

import io
import json
import math
import xml.etree.ElementTree as ET

import httpx
import numpy as np
import pytest
from PIL import Image

from service.app import create_app
from service.cli import main
from service.samples import SAMPLES
from service.settings import Settings
from transforms.plan import balance, graft_demand, graft_supply, mix_means, pooled_mean

from .test_api import flatten, problem
from .test_measure import NAME, PARAMS, measure, rectangle

pytestmark = pytest.mark.anyio

SVG = "{http://www.w3.org/2000/svg}"
MIX = {"1": 0.2, "2": 0.5, "3": 0.3}


async def plan(client, params: dict) -> object:
    return await flatten(client, NAME, {**PARAMS, "units": "mm", **params}, endpoint="/v1/plan")


async def centre(client) -> tuple[float, float]:
    """The middle of the scalp's map (its layout's mean x and y)."""
    answer = (await flatten(client, NAME, PARAMS)).json()
    return float(np.mean(answer["vertices"]["x"])), float(np.mean(answer["vertices"]["y"]))


def zones_at(cx: float, cy: float) -> tuple[list[dict], list[dict]]:
    """Two recipient and two donor zones side by side on the map, apart."""
    recipient = [
        {**rectangle("frontal", cx - 0.5, cx - 0.3, cy - 0.2, cy + 0.2), "density_per_cm2": 40},
        {
            **rectangle("crown", cx - 0.25, cx - 0.05, cy - 0.2, cy + 0.2),
            "density_per_cm2": 35.5,
            "hairs_per_graft": 2.4,
        },
    ]
    donor = [
        {
            **rectangle("occipital", cx + 0.05, cx + 0.3, cy - 0.2, cy + 0.2),
            "density_per_cm2": 70,
            "hairs_per_graft": MIX,
        },
        {
            **rectangle("temporal", cx + 0.35, cx + 0.5, cy - 0.2, cy + 0.2),
            "density_per_cm2": 65.3,
            "hairs_per_graft": 2.6,
            "extraction_fraction": 0.25,
        },
    ]
    return recipient, donor


def outline(zone: dict) -> dict:
    """A plan zone as /v1/measure takes it: its name and rings alone."""
    return {key: zone[key] for key in ("name", "outer", "holes") if key in zone}


async def test_the_plan_is_the_arithmetic_of_the_areas_measure_answers(client):
    recipient, donor = zones_at(*await centre(client))
    asked = {"recipient": recipient, "donor": donor, "max_grafts_per_session": 400}
    response = await plan(client, asked)
    assert response.status_code == 200, response.text
    answer = response.json()
    measured = await measure(
        client, {"zones": [outline(z) for z in recipient + donor], "units": "mm"}
    )
    area = {zone["name"]: zone["area_cm2"] for zone in measured.json()["zones"]}
    assert all(value > 1 for value in area.values()), area  # zones of some cm² each

    # The donor zones: grafts present, available (floored) and their hairs from the mix.
    means = {"occipital": 0.2 * 1 + 0.5 * 2 + 0.3 * 3, "temporal": 2.6}
    fractions = {"occipital": 0.3, "temporal": 0.25}  # 0.3: the default
    assert [zone["name"] for zone in answer["donor"]] == ["occipital", "temporal"]
    for zone, given in zip(answer["donor"], donor, strict=True):
        name, density = zone["name"], given["density_per_cm2"]
        assert zone["area_cm2"] == area[name]
        assert zone["grafts_present"] == pytest.approx(area[name] * density, rel=1e-12)
        assert zone["grafts_available"] == math.floor(area[name] * density * fractions[name])
        assert zone["extraction_fraction"] == fractions[name]
        assert zone["hairs_per_graft"] == pytest.approx(means[name], rel=1e-12)
        assert zone["hairs_available"] == pytest.approx(
            zone["grafts_available"] * means[name], rel=1e-12
        )
    available = sum(zone["grafts_available"] for zone in answer["donor"])
    hairs_available = sum(
        zone["grafts_available"] * means[zone["name"]] for zone in answer["donor"]
    )

    # The recipient zones: the frontal one gives no hairs a graft: the donors' pooled mean.
    pooled = hairs_available / available
    own = {"frontal": (pooled, "donor"), "crown": (2.4, "zone")}
    assert [zone["name"] for zone in answer["recipient"]] == ["frontal", "crown"]
    for zone, given in zip(answer["recipient"], recipient, strict=True):
        name, density = zone["name"], given["density_per_cm2"]
        assert zone["area_cm2"] == area[name]
        assert zone["grafts_needed"] == round(area[name] * density)
        assert zone["hairs_per_graft"] == pytest.approx(own[name][0], rel=1e-12)
        assert zone["hairs_per_graft_from"] == own[name][1]
        assert zone["hairs_needed"] == pytest.approx(zone["grafts_needed"] * own[name][0])
    needed = sum(round(area[z["name"]] * z["density_per_cm2"]) for z in recipient)
    hairs_needed = sum(zone["hairs_needed"] for zone in answer["recipient"])

    assert answer["grafts_needed"] == needed and answer["grafts_available"] == available
    assert answer["hairs_needed"] == pytest.approx(hairs_needed, rel=1e-12)
    assert answer["hairs_available"] == pytest.approx(hairs_available, rel=1e-12)
    assert answer["balance"]["grafts"] == available - needed
    assert answer["balance"]["hairs"] == pytest.approx(hairs_available - hairs_needed, abs=1e-6)
    assert answer["max_grafts_per_session"] == 400
    assert answer["sessions"] == math.ceil(needed / 400) > 1
    assert answer["units"] == {"mm_per_unit": 1.0} and answer["warnings"] == []


async def test_zones_in_either_order_give_the_same_answer(client):
    recipient, donor = zones_at(*await centre(client))
    first = (await plan(client, {"recipient": recipient, "donor": donor})).json()
    turned = await plan(client, {"recipient": recipient[::-1], "donor": donor[::-1]})
    assert turned.status_code == 200, turned.text
    second = turned.json()
    # The lists come in the order asked; each zone's entry and every total are the same.
    assert [z["name"] for z in second["recipient"]] == [z["name"] for z in recipient[::-1]]
    assert second["recipient"] == first["recipient"][::-1]
    assert second["donor"] == first["donor"][::-1]
    for key in ("grafts_needed", "grafts_available", "hairs_needed", "hairs_available"):
        assert second[key] == first[key], key
    assert second["balance"] == first["balance"] and second["sessions"] == first["sessions"]


async def test_without_donor_zones_nothing_is_available_and_hairs_take_the_default(client):
    recipient, _ = zones_at(*await centre(client))
    answer = (await plan(client, {"recipient": recipient})).json()
    frontal, crown = answer["recipient"]
    assert answer["donor"] == [] and answer["grafts_available"] == 0
    assert answer["balance"]["grafts"] == -answer["grafts_needed"] < 0
    assert answer["max_grafts_per_session"] == 3000
    assert answer["sessions"] == math.ceil(answer["grafts_needed"] / 3000)
    assert (frontal["hairs_per_graft"], frontal["hairs_per_graft_from"]) == (2.2, "default")
    assert (crown["hairs_per_graft"], crown["hairs_per_graft_from"]) == (2.4, "zone")


async def test_overlapping_zones_are_a_422_naming_the_pair(client):
    recipient, donor = zones_at(*await centre(client))
    shifted = {**recipient[1], "outer": recipient[0]["outer"]}  # over the frontal zone
    body = problem(await plan(client, {"recipient": [recipient[0], shifted]}), 422)
    assert body["field"] == "params.recipient.1"
    assert "('crown')" in body["detail"] and "params.recipient.0 ('frontal')" in body["detail"]

    over = {**donor[0], "outer": recipient[1]["outer"]}  # the donor drawn over the crown
    body = problem(await plan(client, {"recipient": recipient, "donor": [over]}), 422)
    assert body["field"] == "params.donor.0"
    assert "('occipital')" in body["detail"] and "params.recipient.1 ('crown')" in body["detail"]

    twice = {**donor[1], "outer": donor[0]["outer"]}
    body = problem(await plan(client, {"recipient": recipient, "donor": [donor[0], twice]}), 422)
    assert body["field"] == "params.donor.1" and "params.donor.0 ('occipital')" in body["detail"]


@pytest.mark.parametrize(
    ("mix", "says"),
    [
        ({"1": 0.2, "2": 0.5, "3": 0.2}, "sum to 1"),
        ({"1": 0.5, "2": 0.5, "7": 0.0}, "pattern"),
        ({"1": 1.2, "2": -0.2}, "greater than or equal to 0"),
        ({}, "at least 1"),
        (0.5, "greater than or equal to 1"),
    ],
)
async def test_a_bad_mix_is_a_422_naming_its_field(client, mix, says):
    recipient, donor = zones_at(*await centre(client))
    bad = {**donor[0], "hairs_per_graft": mix}
    body = problem(await plan(client, {"recipient": recipient, "donor": [bad]}), 422)
    assert body["field"].startswith("params.donor.0.hairs_per_graft"), body
    assert says in body["detail"], body["detail"]


async def test_a_mix_whose_shares_sum_to_one_within_rounding_is_taken(client):
    recipient, donor = zones_at(*await centre(client))
    thirds = {"1": 1 / 3, "2": 1 / 3, "3": 1 / 3 + 5e-7}
    response = await plan(
        client, {"recipient": recipient, "donor": [{**donor[0], "hairs_per_graft": thirds}]}
    )
    assert response.status_code == 200, response.text
    assert response.json()["donor"][0]["hairs_per_graft"] == pytest.approx(2.0, abs=2e-6)


@pytest.mark.parametrize(
    ("where", "value", "field"),
    [
        (("recipient",), [], "params.recipient"),
        (("units",), None, "params.units"),
        (("recipient", 0, "density_per_cm2"), 500, "params.recipient.0.density_per_cm2"),
        (("donor", 0, "density_per_cm2"), 0, "params.donor.0.density_per_cm2"),
        (("donor", 1, "extraction_fraction"), 1.5, "params.donor.1.extraction_fraction"),
        (("max_grafts_per_session",), 0, "params.max_grafts_per_session"),
    ],
)
async def test_bad_plan_params_are_422s_naming_the_field(client, where, value, field):
    recipient, donor = zones_at(*await centre(client))
    params = {**PARAMS, "units": "mm", "recipient": recipient, "donor": donor}
    if len(where) == 1:
        params[where[0]] = value
    else:
        kind, number, name = where
        params[kind] = [dict(zone) for zone in params[kind]]
        params[kind][number][name] = value
    params = {key: given for key, given in params.items() if given is not None}  # no units
    problem(await flatten(client, NAME, params, endpoint="/v1/plan"), 422, field)


async def test_a_name_given_twice_across_the_lists_is_a_422(client):
    recipient, donor = zones_at(*await centre(client))
    body = problem(
        await plan(client, {"recipient": recipient, "donor": [{**donor[0], "name": "crown"}]}), 422
    )
    assert "donor.0: the name 'crown' is that of recipient.1" in body["detail"]


@pytest.mark.parametrize(
    ("points", "field"), [((11, 3), "params.recipient"), ((4, 8), "params.donor")]
)
async def test_too_many_drawn_points_is_a_413_naming_the_list_that_has_them(points, field):
    """The limit counts the points of both lists: the recipient zones alone over it name
    them, else the donor zones are named."""
    app = create_app(Settings(max_drawn_points=10))
    async with app.router.lifespan_context(app):
        transport = httpx.ASGITransport(app=app)
        async with httpx.AsyncClient(transport=transport, base_url="http://meshflat") as client:
            zones = []
            for kind, count, x in zip(("recipient", "donor"), points, (-1.0, 1.0), strict=True):
                t = np.linspace(0, 6, count, endpoint=False)
                zone = {"name": kind, "outer": {"x": (x + 0.5 * np.cos(t)).tolist(),
                                                "y": (0.5 * np.sin(t)).tolist()}}  # fmt: skip
                zones.append({**zone, "density_per_cm2": 40, "hairs_per_graft": 2.0})
            body = problem(await plan(client, {"recipient": zones[:1], "donor": zones[1:]}), 413)
            assert body["field"] == field
            assert "the limit is 10 (MESHFLAT_MAX_DRAWN_POINTS)" in body["detail"]


@pytest.mark.parametrize("output", ["svg", "png"])
async def test_the_picture_shows_the_zones_with_their_grafts_and_the_balance(client, output):
    recipient, donor = zones_at(*await centre(client))
    params = {"recipient": recipient, "donor": donor}
    answer = (await plan(client, params)).json()
    response = await plan(client, {**params, "output": output})
    assert response.status_code == 200, response.text
    assert response.headers["content-type"] == f"image/{'svg+xml' if output == 'svg' else 'png'}"
    if output == "png":
        image = Image.open(io.BytesIO(response.content))
        image.load()
        assert image.size == (1200, 800) and image.mode == "RGB"
        return
    root = ET.fromstring(response.content)
    texts = ["".join(t.itertext()) for t in root.iter(f"{SVG}text")]
    for kind, grafts in (("recipient", "grafts_needed"), ("donor", "grafts_available")):
        for zone in answer[kind]:
            words = f"{zone[grafts]:,} {grafts.replace('_', ' ')}"
            label = f"{zone['name']}: {zone['area_cm2']:.2f} cm², {words}"
            assert label in texts, label
    captions = [t.text for t in root.iter(f"{SVG}text") if t.get("class") == "caption"]
    assert captions[0].startswith(f"meshflat plan: balance {answer['balance']['grafts']:+,} grafts")
    assert f"{answer['sessions']:,} session" in captions[0]
    # Recipient zones in one colour, donor zones in another.
    zones = [g for g in root.iter(f"{SVG}g") if g.get("class") == "zone"]
    colours = [g.find(f"{SVG}path").get("stroke") for g in zones]
    assert len(zones) == 4 and colours[0] == colours[1] != colours[2] == colours[3]


async def test_the_command_line_plans_into_json_and_svg(client, tmp_path):
    recipient, donor = zones_at(*await centre(client))
    params = json.dumps({"recipient": recipient, "donor": donor})
    frame = ["--region-cone", "0,0,1:70", "--pole", "0,0,-1", "--up", "0,1,0", "--sigma", "0.3"]
    command = ["plan", str(SAMPLES[NAME].path), *frame, "--units", "mm", "--params", params]
    out = tmp_path / "plan.json"
    assert main([*command, "--out", str(out)]) == 0
    expected = await plan(client, {"recipient": recipient, "donor": donor})
    assert json.loads(out.read_bytes()) == expected.json()
    picture = tmp_path / "plan.svg"
    assert main([*command, "--out", str(picture)]) == 0
    assert ET.fromstring(picture.read_bytes()).tag == f"{SVG}svg"


def test_grafts_are_rounded_half_to_even_floored_and_sessions_are_ceilings():
    demand = graft_demand([2.5, 3.5, 1.0], [1.0, 1.0, 0.4], [2.0, 2.0, 2.0])
    assert demand.grafts.tolist() == [2, 4, 0]  # as Python's round
    supply = graft_supply([10.0, 1.0], [3.0, 0.5], [0.999, 0.3], [1.0, 3.0])
    assert supply.grafts.tolist() == [29, 0] and supply.present.tolist() == [30.0, 0.5]
    assert pooled_mean(supply) == 1.0
    assert pooled_mean(graft_supply([], [], [], [])) is None
    for needed, sessions in ((0, 0), (3000, 1), (3001, 2), (6000, 2)):
        asked = graft_demand([float(needed)], [1.0], [2.0])
        assert balance(asked, supply, 3000).sessions == sessions
    assert mix_means(np.array([[0.2, 0.5, 0.3], [1.0, 0.0, 0.0]])).tolist() == pytest.approx(
        [2.1, 1.0]
    )
