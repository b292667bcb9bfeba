"""Choosing centre, rotation and sigma: the core (transforms.fit) and /v1/fit."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from service.samples import SAMPLES
from transforms import Chart, Frame, PoleCap, fit_region, flatten_region
from transforms.emptycap import largest_empty_cap
from transforms.fit import SIGMA_SEARCH
from transforms.kernel import chebyshev_center, kernel_planes

from .conftest import grid_mesh, load_sample, sphere_mesh

#: The scalps of the samples: faces whose centroid lies within an angle of the top axis, seen
#: from a point inside the head (None: the box centre; Lee Perry-Smith's box holds the
#: shoulders, and from there the cone would take in the ears).
SCALPS = {
    "fsaverage-head.ply": (None, 2, 70.86),
    "lee-perry-smith.obj": ((0.0, 1.5, 0.0), 1, 70.0),
}


def scalp(name: str = "fsaverage-head.ply"):
    """The sample and its scalp."""
    vertices, faces = load_sample(name)
    centre, top, half_angle_deg = SCALPS[name]
    if centre is None:
        centre = (vertices.min(axis=0) + vertices.max(axis=0)) / 2
    directions = vertices[faces].mean(axis=1) - np.asarray(centre)
    cosine = directions[:, top] / np.linalg.norm(directions, axis=1)
    return vertices, faces[cosine >= math.cos(math.radians(half_angle_deg))]


@pytest.fixture(scope="module")
def fsaverage_fit():
    vertices, faces = scalp()
    return vertices, faces, fit_region(vertices, faces)


# -- the parts -----------------------------------------------------------------------------


def test_chebyshev_centre_of_a_closed_sphere_is_its_centre():
    vertices, faces = sphere_mesh(24, 48)
    kernel = chebyshev_center(kernel_planes(vertices + np.array([3.0, -2.0, 1.0]), faces))
    assert not kernel.empty
    np.testing.assert_allclose(kernel.center, [3.0, -2.0, 1.0], atol=1e-9)
    # The inscribed ball touches the facets: a little less than the unit radius.
    assert 0.98 < kernel.inscribed_radius < 1.0


def test_an_open_cap_is_closed_over_its_hole():
    # The upper half of a sphere faces every point below it: the hole's plane bounds it.
    vertices, faces = sphere_mesh(24, 48)
    upper = faces[vertices[faces].mean(axis=1)[:, 2] > 0.0]
    kernel = chebyshev_center(kernel_planes(vertices, upper))
    assert not kernel.empty and 0.0 < kernel.center[2] < 0.6
    assert kernel.inscribed_radius > 0.4


def test_largest_empty_cap_finds_the_hole():
    vertices, _ = sphere_mesh(24, 48)
    directions = vertices[vertices[:, 2] < math.cos(math.radians(50.0))]  # no point near +Z
    pole, radius = largest_empty_cap(directions)
    np.testing.assert_allclose(pole, [0.0, 0.0, 1.0], atol=1e-9)
    assert math.degrees(radius) >= 50.0


# -- the fit ---------------------------------------------------------------------------------


def test_auto_scalp_is_seam_free_and_star_shaped_with_the_margin(fsaverage_fit):
    _, _, fit = fsaverage_fit
    v, e = fit.region.validation, fit.explanation
    assert v.seam_free and v.star_shaped
    assert min(v.margin_deg_seam, v.margin_deg_north, v.margin_deg_south) >= 2.0
    assert e.margin_deg >= 2.0 and not e.kernel_empty and not e.notes
    assert e.energy_end <= e.energy_start
    assert e.center_depth >= 0.05 * e.kernel_inscribed_radius
    # The optimum of MATH.md's "Distortion": better than either reported sigma.
    assert all(e.energy_end <= energy + 1e-9 for energy in e.energy_at_sigma.values())
    assert fit.region.distortion.isometric.mean == pytest.approx(e.energy_end)


@pytest.mark.parametrize(
    ("name", "up"),
    [
        ("fsaverage-head.ply", [0.3, 1.0, 0.2]),
        ("lee-perry-smith.obj", [0.3, 0.2, 1.0]),
        ("fsaverage-head.ply", None),  # the roll rule
        ("lee-perry-smith.obj", None),
    ],
)
def test_the_choice_turns_and_moves_with_the_mesh(name, up):
    vertices, faces = scalp(name)
    up = None if up is None else np.array(up)
    base = fit_region(vertices, faces, rotation=None, up=up)
    for seed in range(2):
        turn = Rotation.random(random_state=seed).as_matrix()
        shift = np.random.default_rng(seed).normal(size=3) * 50.0
        turned_up = None if up is None else turn @ up
        moved = fit_region(vertices @ turn.T + shift, faces, up=turned_up)
        np.testing.assert_allclose(moved.region.theta, base.region.theta, atol=1e-6, rtol=0)
        np.testing.assert_allclose(moved.region.phi, base.region.phi, atol=1e-6, rtol=0)
        np.testing.assert_allclose(moved.frame.center, turn @ base.frame.center + shift, atol=1e-6)


def test_fixed_parameters_are_kept(fsaverage_fit):
    vertices, faces, fit = fsaverage_fit
    frame = Frame.from_pole_up([0, 0, -1], [0, 1, 0])
    kept = fit_region(vertices, faces, center=fit.frame.center, rotation=frame, sigma=0.4)
    assert kept.chart.cap.sigma == 0.4
    np.testing.assert_array_equal(kept.frame.rotation, frame.rotation)
    np.testing.assert_array_equal(kept.frame.center, fit.frame.center)
    # Only sigma chosen: the answer is the best sigma for that centre and rotation.
    only_sigma = fit_region(vertices, faces, center=fit.frame.center, rotation=frame)
    energy = only_sigma.explanation.energy_end
    for sigma in (0.2, 0.4, 0.8):
        chart = Chart.distorted(PoleCap.from_sigma(sigma))
        moved = Frame.from_matrix(frame.rotation, fit.frame.center)
        other = flatten_region(vertices, faces, moved, chart).distortion.isometric.mean
        assert energy <= other + 1e-3


def test_an_empty_kernel_is_said_and_its_backfacing_faces_listed():
    vertices, faces = load_sample("nefertiti-lowres.obj")
    fit = fit_region(vertices, faces)
    e = fit.explanation
    assert e.kernel_empty and e.kernel_inscribed_radius == 0.0
    assert len(e.backfacing_faces) > 0
    np.testing.assert_array_equal(e.backfacing_faces, fit.region.validation.backfacing_faces)
    assert any("kernel is empty" in note for note in e.notes)


@pytest.mark.parametrize("shape", ["one triangle", "flat square"])
def test_small_and_flat_regions_get_a_centre_behind_them(shape):
    if shape == "one triangle":
        vertices, faces = np.array([[0, 0, 1.0], [1, 0, 1], [0, 1, 1]]), np.array([[0, 1, 2]])
    else:
        vertices, faces = grid_mesh(np.linspace(-1, 1, 12), np.linspace(-1, 1, 12), 0.0)
    fit = fit_region(vertices, faces)
    assert not fit.explanation.kernel_empty and fit.explanation.kernel_inscribed_radius > 0
    assert fit.region.validation.seam_free and fit.region.validation.star_shaped
    assert SIGMA_SEARCH[0] <= fit.chart.cap.sigma <= SIGMA_SEARCH[1]


def test_bad_bounds_are_refused():
    vertices, faces = sphere_mesh(6, 8)
    from transforms import TransformInputError

    with pytest.raises(TransformInputError, match="min_margin_deg"):
        fit_region(vertices, faces, min_margin_deg=95.0)
    with pytest.raises(TransformInputError, match="min_kernel_depth"):
        fit_region(vertices, faces, min_kernel_depth=float("nan"))
    with pytest.raises(TransformInputError, match="sigma"):
        fit_region(vertices, faces, method="standard", sigma=0.3)


# -- /v1/fit and "auto" ------------------------------------------------------------------------

SCALP_REGION = {"cone": {"axis": [0, 0, 1], "half_angle_deg": 70}}


async def post(client, endpoint, params, name="fsaverage-head.ply"):
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
    for name, summary in body["metrics"].items():
        assert again.json()["metrics"][name] == pytest.approx(summary, rel=1e-9)
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
        ({"rotation": {"pole": "auto", "up": [0, 0, 0]}}, "params.up"),
        ({"rotation": {"pole": "automatic"}}, "params.rotation"),
    ],
)
async def test_bad_fit_params_name_the_field(client, params, field):
    answer = await post(client, "/v1/fit", {"region": SCALP_REGION, **params})
    assert answer.status_code == 422, answer.text
    assert answer.json()["field"].startswith(field), answer.json()


# -- /v1/locate --------------------------------------------------------------------------------


def test_locate_inverts_flatten_in_the_core():
    from transforms import locate, world_to_angles

    vertices, faces = scalp()
    frame = Frame.from_pole_up([0, 0, -1], [0, 1, 0], (vertices.min(0) + vertices.max(0)) / 2)
    chart = Chart.distorted(PoleCap.from_sigma(0.3))
    rng = np.random.default_rng(7)
    chosen = rng.integers(0, len(faces), 5000)
    weights = rng.dirichlet([1.0, 1.0, 1.0], len(chosen))
    points = np.einsum("kc,kcj->kj", weights, vertices[faces[chosen]])
    theta, phi, _ = world_to_angles(points, frame, chart)
    hits = locate(frame.to_local(vertices), faces, chart.inverse(theta, phi, 1.0))
    np.testing.assert_array_equal(hits.faces, chosen)
    np.testing.assert_allclose(hits.barycentric, weights, atol=1e-6)
    np.testing.assert_allclose(frame.to_world(hits.points), points, atol=1e-6)
    # A direction into the hole (the chin, straight down) meets no scalp triangle.
    miss = locate(frame.to_local(vertices), faces, [[0.0, 1.0, 0.0]])
    assert miss.faces[0] == -1 and np.isnan(miss.points).all()


def test_locate_takes_the_nearest_of_two_layers():
    # Two parallel squares in front of the centre: the ray meets the nearer one.
    square = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], dtype=float)
    lift = np.array([0.0, 0.0, 1.0])
    vertices = np.concatenate([square + 2 * lift, square + lift])
    faces = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    from transforms import locate

    hits = locate(vertices, faces, [[0.1, 0.2, 1.0]])
    assert hits.faces[0] in (2, 3)
    np.testing.assert_allclose(hits.points[0], [0.1, 0.2, 1.0])


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
async def test_locate_checks_its_queries(client):
    params = {"region": SCALP_REGION}
    answer = await post(client, "/v1/locate", {**params, "theta": [1.0, 2.0], "phi": [0.0]})
    assert answer.status_code == 422 and "one phi per theta" in answer.json()["detail"]
    answer = await post(client, "/v1/locate", {**params, "theta": [4.0], "phi": [0.0]})
    assert answer.status_code == 422 and answer.json()["field"] == "params.theta", answer.json()


# -- layouts ---------------------------------------------------------------------------------


def test_mercator_layout_is_measured_as_returned():
    vertices, faces = scalp()
    frame = Frame.from_pole_up([0, 0, -1], [0, 1, 0], (vertices.min(0) + vertices.max(0)) / 2)
    chart = Chart.distorted(PoleCap.from_sigma(0.3))
    paper = flatten_region(vertices, faces, frame, chart)
    mercator = flatten_region(vertices, faces, frame, chart, layout="mercator")
    np.testing.assert_array_equal(mercator.x, mercator.phi)
    np.testing.assert_allclose(mercator.y, np.log(np.tan((np.pi - mercator.theta) / 2)))
    np.testing.assert_array_equal(paper.y, paper.theta)
    # Mercator keeps the sphere's angles: only the radial projection bends them.
    assert mercator.distortion.conformal.mean < paper.distortion.conformal.mean
    # The same triangles are flagged: validation reads the angles, not the layout.
    assert mercator.validation.folded_faces.tolist() == paper.validation.folded_faces.tolist()


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
    assert "x" not in paper["vertices"]
    assert body["metrics"]["conformal"]["mean"] < paper["metrics"]["conformal"]["mean"]


# -- found by probing --------------------------------------------------------------------------


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_turned_flat_region_is_never_answered_worse_than_the_start(seed):
    vertices, faces = grid_mesh(np.arange(7.0), np.arange(4.0), 0.0)
    turned = vertices @ Rotation.random(random_state=seed).as_matrix().T
    fit = fit_region(turned, faces)
    e = fit.explanation
    assert e.energy_end <= e.energy_start + 1e-12
    assert fit.region.validation.seam_free and e.margin_deg >= 2.0


@pytest.mark.parametrize("scale", [1e90, 1e-100])
def test_huge_and_tiny_coordinates(scale):
    tetrahedron = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float) * scale
    faces = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    fit = fit_region(tetrahedron, faces)
    assert not fit.explanation.kernel_empty
    np.testing.assert_allclose(
        fit.explanation.kernel_inscribed_radius, scale / (3 + math.sqrt(3)), rtol=1e-9
    )
    assert np.isfinite(fit.region.theta).all() and np.isfinite(fit.explanation.energy_end)


def test_a_margin_larger_than_the_starting_cap_is_still_kept(fsaverage_fit):
    vertices, faces, _ = fsaverage_fit
    fit = fit_region(vertices, faces, min_margin_deg=60.0)
    assert fit.explanation.margin_deg >= 60.0 or any("below" in n for n in fit.explanation.notes)
    assert not any("closed" in note for note in fit.explanation.notes)


def test_a_closed_region_gets_the_sigma_of_least_energy():
    vertices, faces = sphere_mesh(8, 12)
    fit = fit_region(vertices * 3.0, faces, center=[0.0, 0.0, 0.0])
    e = fit.explanation
    assert any("closed" in note for note in e.notes)
    assert e.energy_end <= min(e.energy_at_sigma.values()) + 1e-9


def test_an_up_hint_along_the_chosen_pole_falls_back_to_the_rule(fsaverage_fit):
    vertices, faces, fit = fsaverage_fit
    # The pole the search starts from, seen from that centre.
    directions = vertices[np.unique(faces)] - fit.frame.center
    pole, _ = largest_empty_cap(directions / np.linalg.norm(directions, axis=1)[:, None])
    hinted = fit_region(vertices, faces, center=fit.frame.center, up=pole)
    assert any("parallel" in note for note in hinted.explanation.notes)


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
