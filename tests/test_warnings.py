"""Warnings, not silence: what is legal but probably wrong is said in the answer's
``warnings`` (a metre mesh declared in millimetres, a zone drawn in degrees off the map, more
sites than a scalp holds), or added to a refusal's detail; every JSON answer carries the
list, empty when nothing looks wrong; /v1/samples says each sample's units."""

from __future__ import annotations

import json
import math
import re
from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.distance import pdist

from service.capabilities import CAPABILITIES, JSON_CAPABILITIES, MESH_CAPABILITIES
from service.capabilities.inputs import MeshPart
from service.capabilities.scalp import PLAUSIBLE_DENSITY_PER_CM2, PLAUSIBLE_SITES
from service.capabilities.units import PLAUSIBLE_ACROSS_CM
from service.capabilities.warnings import MEANINGS, WarningCode
from service.examples import icosahedron_obj, request_example
from service.samples import SAMPLES

from .conftest import load_sample
from .test_api import flatten, obj_of, problem
from .test_docs import DOCS, text
from .test_measure import NAME
from .test_measure import PARAMS as SCALP
from .test_ownframe import dense_points

pytestmark = pytest.mark.anyio

#: The README's first request: the fit of the fsaverage scalp.
FIRST_REQUEST = {
    "region": {"cone": {"axis": [0, 0, 1], "half_angle_deg": 70}},
    "facing": [0, 1, 0],
}


def scalp_faces(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """SCALP's region, found here: the faces whose centroids, seen from the middle of the
    bounding box, lie within 70 degrees of +Z."""
    centre = (vertices.min(axis=0) + vertices.max(axis=0)) / 2
    directions = vertices[faces].mean(axis=1) - centre
    cosine = directions[:, 2] / np.linalg.norm(directions, axis=1)
    return faces[cosine >= math.cos(math.radians(70))]


def scalp_vertices(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    return vertices[np.unique(scalp_faces(vertices, faces))]


def principal_box_diagonal(vertices: np.ndarray, faces: np.ndarray) -> float:
    """The diagonal of the box of the region's vertices along the principal axes of its
    surface, those from a dense quadrature of the triangles (tests/test_ownframe.py)."""
    region = scalp_faces(vertices, faces)
    points, weights = dense_points(vertices, region)
    centred = points - weights @ points / weights.sum()
    _, axes = np.linalg.eigh((centred * weights[:, None]).T @ centred)
    along = vertices[np.unique(region)] @ axes
    return float(np.linalg.norm(np.ptp(along, axis=0)))


def numbers(message: str) -> list[float]:
    return [
        float(n.replace(",", "")) for n in re.findall(r"-?\d[\d,]*(?:\.\d+)?(?:e-?\d+)?", message)
    ]


def only(answer: dict, code: WarningCode) -> dict:
    found = [w for w in answer["warnings"] if w["code"] == code]
    assert len(found) == 1, answer["warnings"]
    return found[0]


# -- units ------------------------------------------------------------------------------


async def test_a_metre_mesh_declared_in_mm_places_sites_with_a_units_warning(client):
    vertices, faces = load_sample(NAME)  # millimetres
    metres = obj_of(vertices / 1000, faces)
    params = {**SCALP, "units": "mm", "density_per_cm2": 30}
    response = await flatten(client, NAME, params, data=metres, filename="head.obj",
                             endpoint="/v1/sites")  # fmt: skip
    assert response.status_code == 200, response.text
    answer = response.json()
    assert answer["count"] == 0  # legal, and silent before: 0.0006 cm² of scalp
    warning = only(answer, WarningCode.UNITS_IMPLAUSIBLE)
    assert warning["field"] == "params.units"
    # The size across in cm as declared (m read as mm: a thousandth), and as it would be in m.
    across = principal_box_diagonal(vertices / 1000, faces)
    diameter = pdist(scalp_vertices(vertices / 1000, faces)).max()
    assert diameter <= across <= math.sqrt(3) * diameter
    said, fitting = numbers(warning["message"].split("where")[0])[0], warning["message"]
    assert said == pytest.approx(across / 10, rel=2e-3)
    assert "with units 'm' it would be" in fitting
    would = re.search(r"it would be ([\d.]+) cm across", fitting)
    assert float(would[1]) == pytest.approx(across * 100, rel=2e-3)
    assert "5 to 60 cm" in fitting


async def test_a_mm_mesh_declared_in_metres_is_refused_with_its_size_and_the_unit(client):
    params = {**SCALP, "units": "m", "density_per_cm2": 30}
    response = await flatten(client, NAME, params, endpoint="/v1/sites")
    body = problem(response, 413, "sites")
    vertices, faces = load_sample(NAME)
    across = principal_box_diagonal(vertices, faces)  # mm
    assert "MESHFLAT_MAX_SITES" in body["detail"]
    declared = re.search(r"with units 'm' the region is ([\d,.]+) cm across", body["detail"])
    assert float(declared[1].replace(",", "")) == pytest.approx(across * 100, rel=1e-3)
    fitting = re.search(r"with units 'mm' it would be ([\d.]+) cm across", body["detail"])
    assert float(fitting[1]) == pytest.approx(across / 10, rel=2e-3)


async def test_measure_in_plausible_units_warns_of_nothing_and_a_known_distance_is_named(client):
    response = await flatten(client, NAME, {**SCALP, "units": "mm"}, endpoint="/v1/measure")
    assert response.json()["warnings"] == []
    # The pupils 60 mm apart, given 1,000 times too far: 0.06 mm per unit.
    wrong = {"between": [[-30.0, 80.0, 0.0], [30.0, 80.0, 0.0]], "mm": 3.6}
    response = await flatten(client, NAME, {**SCALP, "units": wrong}, endpoint="/v1/measure")
    warning = only(response.json(), WarningCode.UNITS_IMPLAUSIBLE)
    assert warning["field"] == "params.units"
    assert "the known distance (0.06 mm per mesh unit)" in warning["message"]
    assert "with units 'mm' it would be" in warning["message"]


# -- zones and curves off the map -------------------------------------------------------


async def map_extent(client) -> tuple[float, float, float, float]:
    vertices = (await flatten(client, NAME, SCALP)).json()["vertices"]
    return min(vertices["x"]), max(vertices["x"]), min(vertices["y"]), max(vertices["y"])


def in_degrees(x0, x1, y0, y1) -> dict:
    """The rectangle from (x0, y0) to (x1, y1) in degrees."""
    xs, ys = np.degrees([x0, x1, x1, x0]).tolist(), np.degrees([y0, y0, y1, y1]).tolist()
    return {"x": xs, "y": ys}


@pytest.mark.parametrize("endpoint", ["/v1/measure", "/v1/sites"])
async def test_a_zone_drawn_in_degrees_warns_with_the_maps_extent(client, endpoint):
    x0, x1, y0, y1 = await map_extent(client)
    middle = ((x0 + x1) / 2, (y0 + y1) / 2)
    inside = {"name": "inside", "outer": {"x": [middle[0], x1, x1], "y": [middle[1], y0, y1]}}
    degrees = {"name": "crown", "outer": in_degrees(middle[0], x1, middle[1], y1)}
    params = {**SCALP, "units": "mm", "zones": [inside, degrees]}
    if endpoint == "/v1/sites":
        params["density_per_cm2"] = 2
    else:
        params["curves"] = [{"name": "hairline", **in_degrees(x0, x1, y0, y0)}]
    response = await flatten(client, NAME, params, endpoint=endpoint)
    assert response.status_code == 200, response.text
    warnings = response.json()["warnings"]
    fields = [w["field"] for w in warnings]
    expected = ["params.zones.1"] + (["params.curves.0"] if endpoint == "/v1/measure" else [])
    assert fields == expected  # the zone inside the map is not warned of
    for warning in warnings:
        assert warning["code"] == WarningCode.DRAWN_OUTSIDE_MAP
        extent = f"x {x0:.4g} to {x1:.4g} and y {y0:.4g} to {y1:.4g}"
        assert extent in warning["message"] and "theta_phi" in warning["message"]
        assert "look like degrees" in warning["message"]


async def test_a_zone_off_the_map_in_radians_is_not_called_degrees(client):
    _, x1, y0, y1 = await map_extent(client)
    beside = {"name": "beside", "outer": {"x": [x1 + 1, x1 + 2, x1 + 2], "y": [y0, y0, y1]}}
    response = await flatten(client, NAME, {**SCALP, "zones": [beside]}, endpoint="/v1/measure")
    warning = only(response.json(), WarningCode.DRAWN_OUTSIDE_MAP)
    assert "'beside' lies wholly outside" in warning["message"]
    assert "degrees" not in warning["message"]


@pytest.mark.slow
async def test_register_warns_of_a_zone_in_degrees(client):
    x0, x1, y0, y1 = await map_extent(client)
    data = SAMPLES[NAME].path.read_bytes()
    params = {
        **SCALP,
        "units": "mm",
        "zones": [{"name": "crown", "outer": in_degrees(x0, x1, y0, y1)}],
    }
    files = {"baseline": (NAME, data), "follow_up": (NAME, data)}
    response = await client.post("/v1/register", files=files, data={"params": json.dumps(params)})
    assert response.status_code == 200, response.text
    warning = only(response.json(), WarningCode.DRAWN_OUTSIDE_MAP)
    assert warning["field"] == "params.zones.0" and "look like degrees" in warning["message"]


# -- implausible sites ------------------------------------------------------------------


async def test_sites_denser_than_a_scalp_holds_are_warned_of_naming_what_asked(client):
    zone = {"name": "patch", "outer": {"x": [-1.8, -1.6, -1.6, -1.8], "y": [1.5, 1.5, 1.7, 1.7]}}
    params = {**SCALP, "units": "mm", "zones": [{**zone, "density_per_cm2": 150}]}
    response = await flatten(client, NAME, params, endpoint="/v1/sites")
    answer = response.json()
    warning = only(answer, WarningCode.DENSITY_IMPLAUSIBLE)
    assert warning["field"] == "params.zones.0.density_per_cm2"
    (placed,) = answer["zones"]
    density = placed["sites"] / placed["open_area_cm2"]
    assert density > PLAUSIBLE_DENSITY_PER_CM2
    assert (
        f"{placed['sites']:,} sites" in warning["message"]
        and f"{density:,.1f} per cm²" in (warning["message"])
    )
    # A count on the same patch: the count is what asked.
    params = {**SCALP, "units": "mm", "zones": [zone], "count": 3 * placed["sites"],
              "density_per_cm2": 1}  # fmt: skip
    response = await flatten(client, NAME, params, endpoint="/v1/sites")
    assert only(response.json(), WarningCode.DENSITY_IMPLAUSIBLE)["field"] == "params.count"
    # 30 per cm², as transplants place them: nothing to say.
    params = {**SCALP, "units": "mm", "zones": [{**zone, "density_per_cm2": 30}]}
    assert (await flatten(client, NAME, params, endpoint="/v1/sites")).json()["warnings"] == []


@pytest.mark.slow
async def test_more_sites_than_a_whole_scalp_holds_are_warned_of(client):
    params = {**SCALP, "units": "mm", "count": PLAUSIBLE_SITES + 1, "density_per_cm2": 1}
    answer = (await flatten(client, NAME, params, endpoint="/v1/sites")).json()
    assert answer["count"] == PLAUSIBLE_SITES + 1
    warning = only(answer, WarningCode.SITES_IMPLAUSIBLE)
    assert warning["field"] == "params.count"
    assert f"{PLAUSIBLE_SITES + 1:,} sites in all" in warning["message"]


# -- every JSON answer ------------------------------------------------------------------


@pytest.mark.slow
async def test_every_json_answer_carries_warnings_first(client):
    mesh = icosahedron_obj()
    answers = []
    for capability in MESH_CAPABILITIES:
        params = json.dumps(request_example(capability.params))
        meshes = [part.name for part in capability.parts if isinstance(part, MeshPart)]
        files = {name: ("ico.obj", mesh) for name in meshes}
        answers.append(await client.post(capability.path, files=files, data={"params": params}))
    for capability in JSON_CAPABILITIES:
        answers.append(await client.post(capability.path, json=request_example(capability.request)))
    assert len(answers) == len(CAPABILITIES)
    for response in answers:
        assert response.status_code == 200, response.text
        answer = response.json()
        assert next(iter(answer)) == "warnings", response.url
        for warning in answer["warnings"]:
            assert set(warning) == {"code", "field", "message"}
            assert warning["code"] in set(WarningCode) and warning["field"]


async def test_the_readmes_requests_answer_no_warnings(client):
    """The fit of the README's first request, then its plan (step 4) measured and given
    grafts on that map: nothing in them looks wrong."""
    response = await flatten(client, NAME, FIRST_REQUEST, endpoint="/v1/fit")
    assert response.status_code == 200, response.text
    assert response.json()["warnings"] == []
    frontal = {
        "name": "frontal",
        "outer": {"x": [-1.8, -1.35, -1.35, -1.8], "y": [1.1, 1.1, 1.4, 1.4]},
    }
    plan = {**response.json()["params"], "units": "mm", "zones": [frontal]}
    for endpoint, extra in (("/v1/measure", {}), ("/v1/sites", {"density_per_cm2": 40})):
        answer = (await flatten(client, NAME, {**plan, **extra}, endpoint=endpoint)).json()
        assert answer["warnings"] == [] and answer["zones"][0]["area_cm2"] > 50, endpoint
    assert "y: [1.1, 1.1, 1.4, 1.4]}}]}' params.json > plan.json" in text(DOCS.parent / "README.md")
    assert '"facing": [0, 1, 0]}\' > fit.json' in text(DOCS.parent / "README.md")


def test_a_row_whose_answer_cannot_carry_warnings_is_refused_at_import():
    from service.encoding import Answer

    class Bare(Answer):
        pass

    with pytest.raises(TypeError, match="carries no warnings"):
        replace(MESH_CAPABILITIES[0], response=Bare)


def test_every_code_is_in_the_docs_table_with_its_meaning():
    api = text(DOCS / "api.md")
    for code, meaning in MEANINGS.items():
        assert f"| `{code.value}` | {meaning} |" in api
    assert set(MEANINGS) == set(WarningCode)
    low, high = PLAUSIBLE_ACROSS_CM
    assert f"{low:g} to {high:g} cm" in api and f"{PLAUSIBLE_SITES:,}" in api


# -- samples ----------------------------------------------------------------------------


async def test_samples_say_their_units_and_when_they_are_estimated(client):
    listed = {entry["name"]: entry for entry in (await client.get("/v1/samples")).json()}
    assert {entry["units"] for entry in listed.values()} <= {"mm", "cm", "m"}
    assert listed["fsaverage-head.ply"]["units"] == "mm"  # the source says millimetres
    assert "millimetres" in listed["fsaverage-head.ply"]["description"]
    for name in ("lee-perry-smith.glb", "lee-perry-smith.obj", "nefertiti-lowres.obj"):
        assert "estimated" in listed[name]["description"]
    # With its unit, each head's scalp reads as a scalp: no units warning.
    params = {**SCALP, "units": listed[NAME]["units"]}
    assert (await flatten(client, NAME, params, endpoint="/v1/measure")).json()["warnings"] == []


# -- the map itself ---------------------------------------------------------------------


async def test_a_seam_on_a_region_that_leaves_a_cap_free_is_blamed_on_the_rotation(client):
    """The scalp with the pole put up through the crown: a cap below is free, the rotation
    given misses it, and "auto" would not."""
    params = {"region": SCALP["region"], "rotation": {"pole": [0, 0, 1], "up": [0, 1, 0]}}
    answer = (await flatten(client, NAME, params, endpoint="/v1/validate")).json()
    assert not answer["validation"]["seam_free"]
    warning = only(answer, WarningCode.SEAM_ON_REGION)
    assert warning["field"] == "params.rotation"
    free = answer["validation"]["free_cap_deg"]
    assert free > 10 and f"a cap of {free:.3g} degrees is free" in warning["message"]
    auto = {"region": SCALP["region"], "center": "auto", "rotation": "auto", "sigma": "auto"}
    fitted = (await flatten(client, NAME, auto, endpoint="/v1/validate")).json()
    assert fitted["validation"]["seam_free"]
    assert WarningCode.SEAM_ON_REGION not in [w["code"] for w in fitted["warnings"]]


async def test_a_closed_region_says_no_cap_is_free_without_searching_its_gaps(client):
    """The whole head seen from inside: its faces close round every direction (no outline
    edge), so no cap is free whatever the gaps between its vertices' directions, and the
    warning does not search for them."""
    vertices, _ = load_sample(NAME)
    answer = (await flatten(client, NAME, {}, endpoint="/v1/validate")).json()
    assert not answer["validation"]["seam_free"] and answer["validation"]["free_cap_deg"] == 0
    warning = only(answer, WarningCode.SEAM_ON_REGION)
    assert warning["field"] == "params.region" and "no cap is free" in warning["message"]
    assert "close round every direction" in warning["message"]
    assert "largest gap" not in warning["message"]
    # Every direction is covered, by brute force over a sphere of probes: each lies inside
    # the cone from the centre over some face (the same side of its three edge planes).
    centre = np.asarray(answer["params"]["center"])
    a, b, c = (vertices[load_sample(NAME)[1][:, i]] - centre for i in range(3))
    k = np.arange(500) + 0.5
    polar, azimuth = np.arccos(1 - 2 * k / len(k)), np.pi * (1 + 5**0.5) * k
    probes = np.stack([np.cos(azimuth) * np.sin(polar), np.sin(azimuth) * np.sin(polar),
                       np.cos(polar)], axis=1)  # fmt: skip
    sides = [np.cross(p, q) @ probes.T for p, q in ((a, b), (b, c), (c, a))]
    inside = (sides[0] >= 0) & (sides[1] >= 0) & (sides[2] >= 0)
    inside |= (sides[0] <= 0) & (sides[1] <= 0) & (sides[2] <= 0)
    inside &= (a + b + c) @ probes.T > 0
    assert inside.any(axis=0).all()


async def test_folded_and_backfacing_triangles_are_said_with_their_counts(client):
    """Lee Perry-Smith's head seen from the box centre of the head and shoulders: the cone
    takes the neck and the chin, which face away from there."""
    params = {"region": {"cone": {"axis": [0, 1, 0], "half_angle_deg": 60}}}
    name = "lee-perry-smith.obj"
    answer = (await flatten(client, name, params, endpoint="/v1/validate")).json()
    v = answer["validation"]
    assert not v["star_shaped"]
    warning = only(answer, WarningCode.REGION_FOLDS)
    folded, total, behind = numbers(warning["message"])[:3]
    assert (folded, total, behind) == (
        len(v["folded_faces"]), len(answer["faces"]["ids"]) if "faces" in answer
        else v["pieces"][0] + len(v["stray_faces"]), len(v["backfacing_faces"]),
    )  # fmt: skip
    assert "untangle: true" in warning["message"]
    untangled = {**params, "untangle": True}
    after = (await flatten(client, name, untangled, endpoint="/v1/validate")).json()
    left = len(after["untangle"]["folded_after"])
    assert f"untangling left {left:,} folded" in only(after, WarningCode.REGION_FOLDS)["message"]
