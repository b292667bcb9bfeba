"""Sites at a density (transforms.sites; docs/math.md, section 13) and ``POST /v1/sites``:
the guarantees the answer makes (on a triangle, spaced, counted, seeded, pose-free) pinned in
the core on small meshes and through the API on the fsaverage scalp; ``meshflat sites``."""

from __future__ import annotations

import io
import json
import math
import struct
import tracemalloc

import httpx
import numpy as np
import pytest
import shapely
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from service.app import create_app
from service.cli import main
from service.samples import SAMPLES
from service.server.jobs import Ticket
from service.settings import Settings
from transforms import Framing, Layout
from transforms.arrays import triangle_areas
from transforms.sites import (
    JAMMING,
    MAX_TRIES_PER_SITE,
    SIZING_BITS,
    SitePart,
    SitesDoNotFit,
    default_spacing,
    minimum_distance,
    place_sites,
    settled,
    site_normals,
    vertex_normals,
)
from transforms.zones import cover_zone

from .conftest import load_sample, sphere_mesh, started
from .test_api import flatten, obj_of, problem
from .test_mapping import jittered_mesh
from .test_measure import NAME
from .test_measure import PARAMS as SCALP

# -- the core ---------------------------------------------------------------------------------


def whole(triangles, quota: int, spacing: float | None = None) -> SitePart:
    """A part over every triangle, its spacing by the default rule unless given."""
    area = triangles.surface_area
    faces = np.arange(len(area))
    spacing = default_spacing(quota / area.sum()) if spacing is None else spacing
    return SitePart(faces, area, quota, spacing)


def zone_part(triangles, ring, quota: int, name: str = "zone") -> SitePart:
    """A part over the zone inside ``ring`` (a map polygon): its whole triangles and the
    shares of the cut ones, candidates in those kept where the zone winds."""
    cover = cover_zone(triangles, [np.asarray(ring, dtype=float)])
    area = triangles.surface_area
    faces = np.concatenate([cover.inside, cover.partial])
    weight = np.concatenate([area[cover.inside], area[cover.partial] * cover.share])
    partial = np.r_[np.zeros(len(cover.inside), bool), np.ones(len(cover.partial), bool)]

    def inside(found, weights):
        return cover.winding(np.einsum("pk,pkd->pd", weights, triangles.corners(found))) != 0

    spacing = default_spacing(quota / weight.sum())
    return SitePart(
        faces, weight, quota, spacing, partial=partial, inside=inside, whole_area=area[faces],
        name=name,
    )  # fmt: skip


def test_sites_lie_on_their_triangles_with_weights_that_sum_to_one():
    triangles = jittered_mesh(n=16, seed=3)
    sites = place_sites(
        triangles.surface_points, triangles.faces, [whole(triangles, 800)], np.random.default_rng(1)
    )
    assert len(sites.triangles) == 800
    assert (sites.weights >= 0).all() and (sites.weights <= 1).all()
    np.testing.assert_allclose(sites.weights.sum(axis=1), 1.0, atol=1e-15)
    corners = triangles.surface_points[triangles.faces[sites.triangles]]
    np.testing.assert_allclose(sites.points, np.einsum("pk,pkd->pd", sites.weights, corners))


def test_no_two_sites_are_closer_than_the_spacing_across_parts():
    """Two zones side by side at different densities, then the rest of the square: the
    least distance between any two sites is the smallest spacing, across the zones' border."""
    triangles = jittered_mesh(n=20, seed=5)
    dense = zone_part(triangles, [[0.1, 0.1], [0.5, 0.1], [0.5, 0.9], [0.1, 0.9]], 600, "dense")
    sparse = zone_part(triangles, [[0.5, 0.1], [0.9, 0.1], [0.9, 0.9], [0.5, 0.9]], 150, "sparse")
    sites = place_sites(
        triangles.surface_points, triangles.faces, [dense, sparse], np.random.default_rng(2)
    )
    assert np.bincount(sites.part).tolist() == [600, 150]
    least = min(dense.spacing, sparse.spacing)
    assert minimum_distance(sites.points) >= least
    # Each part's own sites keep its spacing.
    for number, part in enumerate((dense, sparse)):
        assert minimum_distance(sites.points[sites.part == number]) >= part.spacing
    # And the sparse zone's sites stay as far from the dense zone's as its spacing asks.
    tree = cKDTree(sites.points[sites.part == 0])
    distance, _ = tree.query(sites.points[sites.part == 1])
    assert distance.min() >= sparse.spacing


def test_sites_in_a_zone_stay_inside_it_on_the_map():
    """The zone cuts triangles: candidates there are kept only inside it (shapely agrees)."""
    triangles = jittered_mesh(n=16, seed=7)
    ring = [[0.17, 0.22], [0.83, 0.31], [0.62, 0.87], [0.38, 0.6], [0.2, 0.79]]
    part = zone_part(triangles, ring, 400)
    sites = place_sites(triangles.surface_points, triangles.faces, [part], np.random.default_rng(3))
    on_map = np.einsum("pk,pkd->pd", sites.weights, triangles.corners(sites.triangles))
    assert shapely.contains_xy(shapely.Polygon(ring), on_map[:, 0], on_map[:, 1]).all()


def test_the_density_is_even_over_the_part():
    """The sites of a square fall into its quarters in proportion to their surface areas
    (within a few sites: they are counted, not thinned)."""
    triangles = jittered_mesh(n=24, seed=9)
    sites = place_sites(
        triangles.surface_points,
        triangles.faces,
        [whole(triangles, 2000)],
        np.random.default_rng(4),
    )
    on_map = np.einsum("pk,pkd->pd", sites.weights, triangles.corners(sites.triangles))
    quarter = (on_map[:, 0] > 0.5).astype(int) + 2 * (on_map[:, 1] > 0.5)
    counts = np.bincount(quarter, minlength=4)
    areas = []
    for qx, qy in ((0, 0), (1, 0), (0, 1), (1, 1)):
        ring = np.array([[0, 0], [0.5, 0], [0.5, 0.5], [0, 0.5]]) + np.array([qx, qy]) / 2
        areas.append(cover_zone(triangles, [ring]).total(triangles.surface_area))
    expected = 2000 * np.asarray(areas) / np.sum(areas)
    assert np.abs(counts - expected).max() < 0.08 * expected.min(), (counts, expected)


def test_the_same_seed_gives_the_same_sites_and_another_seed_others():
    triangles = jittered_mesh(n=12, seed=1)

    def run(seed):
        return place_sites(
            triangles.surface_points,
            triangles.faces,
            [whole(triangles, 300)],
            np.random.default_rng(seed),
        )

    first, again, other = run(11), run(11), run(12)
    np.testing.assert_array_equal(first.triangles, again.triangles)
    np.testing.assert_array_equal(first.weights, again.weights)
    assert not np.array_equal(first.weights, other.weights)


def test_moving_turning_and_scaling_the_surface_keeps_the_sites_on_the_same_faces():
    """Sites are drawn as faces and weights and kept by their 3D distances, which a
    similarity keeps when the spacing is scaled with the surface: the same faces and weights
    come back, the points moved. The part has a density per triangle, as the service's have:
    its yield (areas times densities over their sum) is then 1 only to its last bit, which
    sized the batches differently in 2 of these 6 poses before the sizes were rounded to a
    few bits (:func:`transforms.sites.settled`)."""
    triangles = jittered_mesh(n=24, seed=2)
    points, faces = triangles.surface_points, triangles.faces

    def sites_of(points, seed):
        area = triangle_areas(points, faces)
        spacing = default_spacing(3000 / area.sum())
        part = SitePart(np.arange(len(area)), area, 3000, spacing, np.full(len(area), 7.0))
        return place_sites(points, faces, [part], np.random.default_rng(seed))

    rng = np.random.default_rng(100)
    for seed in range(6):
        turn, scale = Rotation.random(random_state=rng), float(np.exp(rng.uniform(-7, 3)))
        shift = rng.normal(size=3) * 100
        here = sites_of(points, seed)
        there = sites_of(scale * turn.apply(points) + shift, seed)
        np.testing.assert_array_equal(here.triangles, there.triangles)
        np.testing.assert_array_equal(here.weights, there.weights)
        np.testing.assert_allclose(
            scale * turn.apply(here.points) + shift,
            there.points,
            rtol=0,
            atol=1e-12 * (scale + 100),
        )


def test_the_measures_that_size_batches_are_settled_to_a_few_bits():
    """A part's yield and capacity, the same in exact arithmetic in every pose, are the same
    numbers when they differ in their last bits; far apart, they stay apart."""
    assert settled(1.0) == settled(np.nextafter(1.0, 0.0)) == settled(1.0 + 2e-16) == 1.0
    assert settled(0.0) == 0.0
    x = 24767.042631948134
    assert settled(x) == settled(x * (1 + 1e-15)) == settled(x * (1 - 1e-15))
    assert settled(x) == pytest.approx(x, rel=2.0**-SIZING_BITS)
    assert settled(0.5) != settled(0.5 * (1 + 2.0 ** (1 - SIZING_BITS)))


def test_a_part_too_full_for_its_spacing_says_how_many_fit():
    """Past the jamming density of random sequential adsorption no spacing holds: the part
    is given up after its tries (or when candidates stop finding room), with the number that
    were placed; far past it, as soon, with memory kept small."""
    triangles = jittered_mesh(n=8, seed=3)
    area = triangles.surface_area.sum()
    quota = 400

    def give_up(over_jamming: float) -> SitesDoNotFit:
        spacing = math.sqrt(area * JAMMING * over_jamming / quota)  # room for 400 / over_jamming
        with pytest.raises(SitesDoNotFit) as caught:
            place_sites(
                triangles.surface_points,
                triangles.faces,
                [whole(triangles, quota, spacing)],
                np.random.default_rng(6),
            )
        return caught.value

    near = give_up(1.5)  # the area's jamming count is 400 / 1.5
    assert 0 < near.placed < quota and near.name == "region"
    assert f"of 400 sites were placed within {MAX_TRIES_PER_SITE} candidates a site" in str(near)
    far = give_up(100.0)  # room for 4
    assert far.placed < 20


def test_a_triangle_of_density_zero_neither_gets_sites_nor_sets_the_least_spacing():
    """A triangle of density 0 (a black pixel of a density map) has a spacing that means
    nothing (the service gives it 1 mesh unit, a length that depends on the unit; here a
    tiny one): it is not the part's least spacing, which orders the parts and is reported
    when a part is too full."""
    triangles = jittered_mesh(n=8, seed=4)
    area = triangles.surface_area
    density = np.where(np.arange(len(area)) % 2 == 0, 0.0, 1.0)
    spacing = np.where(density > 0, 0.05, 1e-6)
    part = SitePart(np.arange(len(area)), area, 40, spacing, density)
    assert part.least_spacing == 0.05
    sites = place_sites(triangles.surface_points, triangles.faces, [part], np.random.default_rng(8))
    assert len(sites.triangles) == 40 and (density[sites.triangles] > 0).all()
    too_many = SitePart(np.arange(len(area)), area, 4000, spacing, density)
    with pytest.raises(SitesDoNotFit) as caught:
        place_sites(triangles.surface_points, triangles.faces, [too_many], np.random.default_rng(8))
    assert caught.value.spacing == 0.05


def test_vertex_normals_of_a_sphere_point_outwards_and_site_normals_follow():
    vertices, faces = sphere_mesh(24, 48)
    normals = vertex_normals(vertices, faces)
    np.testing.assert_allclose(np.einsum("kd,kd->k", normals, vertices), 1.0, atol=2e-3)
    area = np.ones(len(faces))
    part = SitePart(np.arange(len(faces)), area, 200, 0.05)
    sites = place_sites(vertices, faces, [part], np.random.default_rng(7))
    for winding in (faces, faces[:, ::-1]):  # wound inwards: turned over
        at_sites = site_normals(vertices, winding, sites, np.zeros(3))
        np.testing.assert_allclose(np.linalg.norm(at_sites, axis=1), 1.0)
        radial = sites.points / np.linalg.norm(sites.points, axis=1, keepdims=True)
        assert np.einsum("kd,kd->k", at_sites, radial).min() > 0.98  # coarse near the poles


# -- the API ----------------------------------------------------------------------------------

PARAMS = {**SCALP, "units": "mm"}

pytestmark = pytest.mark.anyio


async def sites(client, params: dict, name: str = NAME, data: bytes | None = None):
    return await flatten(client, name, {**PARAMS, **params}, data=data, endpoint="/v1/sites")


def rectangle(name, x0, x1, y0, y1, density=None) -> dict:
    zone = {"name": name, "outer": {"x": [x0, x1, x1, x0], "y": [y0, y0, y1, y1]}}
    return zone if density is None else {**zone, "density_per_cm2": density}


async def scalp_map(client) -> tuple[np.ndarray, np.ndarray]:
    answer = await flatten(client, NAME, SCALP)
    x, y = (np.asarray(answer.json()["vertices"][k]) for k in "xy")
    return x, y


def check_on_the_mesh(answer: dict, vertices: np.ndarray, faces: np.ndarray) -> None:
    """Every site on its file triangle: weights in [0, 1] summing to 1, the position their
    combination of the triangle's corners, a unit normal."""
    found = answer["sites"]
    weights = np.asarray(found["barycentric"])
    assert (weights >= 0).all() and (weights <= 1).all()
    np.testing.assert_allclose(weights.sum(axis=1), 1.0, atol=1e-12)
    corners = vertices[faces[np.asarray(found["face"])]]
    expected = np.einsum("pk,pkd->pd", weights, corners)
    np.testing.assert_allclose(found["position"], expected, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(found["normal"], axis=1), 1.0, atol=1e-12)
    lengths = {len(values) for values in found.values()}
    assert lengths == {answer["count"]}


async def test_a_density_over_the_region_places_its_area_times_the_density(client):
    response = await sites(client, {"density_per_cm2": 30, "seed": 4})
    assert response.status_code == 200, response.text
    answer = response.json()
    (zone,) = answer["zones"]
    assert zone["name"] == "region" and answer["count"] == zone["sites"]
    assert zone["sites"] == round(30 * zone["open_area_cm2"])
    assert zone["achieved_density_per_cm2"] == pytest.approx(30, rel=0.01)
    vertices, faces = load_sample(NAME)
    check_on_the_mesh(answer, vertices, faces)
    # Spaced as promised, and the measured least distance is the true one.
    points = np.asarray(answer["sites"]["position"])
    assert answer["min_distance"] == pytest.approx(minimum_distance(points))
    assert answer["min_distance_mm"] >= zone["spacing_mm"]
    # The default rule at the density placed: 0.7 / sqrt(d) cm.
    assert zone["spacing_mm"] == pytest.approx(
        10 * default_spacing(zone["achieved_density_per_cm2"])
    )
    # theta and phi are the transform of the positions; x, y the map's (theta_phi: phi, theta).
    assert np.allclose(answer["sites"]["x"], answer["sites"]["phi"], atol=0.05)
    assert np.allclose(answer["sites"]["y"], answer["sites"]["theta"], atol=0.05)


async def test_zones_get_their_densities_within_five_percent_and_count_is_exact(client):
    x, y = await scalp_map(client)
    cx, cy = x.mean(), y.mean()
    zones = [
        rectangle("crown", cx - 0.3, cx, cy - 0.25, cy + 0.25, 40),
        rectangle("temple", cx + 0.05, cx + 0.3, cy - 0.25, cy + 0.1),  # the default density
        rectangle("speck", cx + 0.05, cx + 0.07, cy + 0.2, cy + 0.22, 30),  # below 1 cm²
    ]
    answer = (await sites(client, {"zones": zones, "density_per_cm2": 25})).json()
    by_name = {zone["name"]: zone for zone in answer["zones"]}
    assert by_name["temple"]["density_per_cm2"] == 25
    for zone in answer["zones"]:
        if zone["area_cm2"] >= 1:
            assert zone["achieved_density_per_cm2"] == pytest.approx(
                zone["density_per_cm2"], rel=0.05
            )
    # Inside their zones on the map, and spaced across the zones' borders.
    found = answer["sites"]
    on_map = np.column_stack([found["x"], found["y"]])
    polygons = [shapely.Polygon(np.column_stack([z["outer"]["x"], z["outer"]["y"]])) for z in zones]
    inside = np.zeros(len(on_map), dtype=int)
    for polygon in polygons:
        inside += shapely.contains_xy(polygon, on_map[:, 0], on_map[:, 1])
    assert (inside == 1).all()
    assert answer["min_distance_mm"] >= min(zone["spacing_mm"] for zone in answer["zones"])
    # An exact total: the zones keep their relative densities, the spacing adapts.
    counted = await sites(client, {"zones": zones[:2], "density_per_cm2": 25, "count": 777})
    counted = counted.json()
    assert counted["count"] == 777 == sum(zone["sites"] for zone in counted["zones"])
    crown, temple = counted["zones"]
    ratio = crown["achieved_density_per_cm2"] / temple["achieved_density_per_cm2"]
    assert ratio == pytest.approx(40 / 25, rel=0.02)


async def test_the_same_seed_gives_the_same_sites(client):
    first = (await sites(client, {"density_per_cm2": 5, "seed": 9})).json()
    again = (await sites(client, {"density_per_cm2": 5, "seed": 9})).json()
    other = (await sites(client, {"density_per_cm2": 5, "seed": 10})).json()
    assert first["sites"] == again["sites"]
    assert first["sites"]["face"] != other["sites"]["face"]


def posed(turn: Rotation, scale: float, shift: np.ndarray, units) -> tuple[bytes, dict]:
    """The sample head moved to ``scale * turn(p) + shift`` as an OBJ file, and the scalp's
    params moved with it: the cone's axis and apex, the centre, the pole and up, and the
    units (``None``: from a known distance between two of its vertices)."""
    vertices, faces = (np.array(array) for array in load_sample(NAME))
    centre = (vertices.min(axis=0) + vertices.max(axis=0)) / 2
    known = vertices[[0, 100]]

    def move(point):
        return (scale * turn.apply(np.asarray(point, float)) + shift).tolist()

    if units is None:
        units = {
            "between": [move(p) for p in known],
            "mm": float(np.linalg.norm(known[1] - known[0])),
        }
    params = {
        "region": {
            "cone": {
                "axis": turn.apply([0, 0, 1]).tolist(),
                "half_angle_deg": 70,
                "apex": move(centre),
            }
        },
        "center": move(centre),
        "rotation": {"pole": turn.apply([0, 0, -1]).tolist(), "up": turn.apply([0, 1, 0]).tolist()},
        "units": units,
    }
    return obj_of(scale * turn.apply(vertices) + shift, faces), params


#: Three similarities of the head and the units that keep it the same head.
POSES = ((0.1, "cm"), (0.001, "m"), (3.7, None))


def measured_mm(answer: dict) -> float:
    """The least distance between two of the answer's sites, by a k-d tree, in mm."""
    points = answer["sites"]["position"]
    distance, _ = cKDTree(points).query(points, k=2)
    return distance[:, 1].min() * answer["units"]["mm_per_unit"]


def check_the_same_sites(here: dict, there: dict, turn: Rotation, scale: float, shift) -> None:
    """``there`` is ``here``'s answer for the head moved: the same faces and weights, the
    positions moved, the normals turned, the same map; the measured least distance is the
    answer's and keeps every zone's spacing."""
    found = here["sites"]
    assert there["count"] == here["count"]
    assert [zone["sites"] for zone in there["zones"]] == [zone["sites"] for zone in here["zones"]]
    assert there["sites"]["face"] == found["face"]
    np.testing.assert_allclose(
        there["sites"]["barycentric"], found["barycentric"], rtol=0, atol=1e-9
    )
    size = scale * np.abs(load_sample(NAME)[0]).max()
    moved = scale * turn.apply(found["position"]) + shift
    np.testing.assert_allclose(there["sites"]["position"], moved, rtol=0, atol=1e-9 * size)
    np.testing.assert_allclose(there["sites"]["normal"], turn.apply(found["normal"]), atol=1e-9)
    for key in ("x", "y", "theta", "phi"):
        np.testing.assert_allclose(there["sites"][key], found[key], rtol=0, atol=1e-9)
    for answer in (here, there):
        assert measured_mm(answer) == pytest.approx(answer["min_distance_mm"], rel=1e-9)
        spacing = min(zone["spacing_mm"] for zone in answer["zones"] if zone["sites"])
        assert answer["min_distance_mm"] >= spacing * (1 - 1e-12)
    assert there["min_distance_mm"] == pytest.approx(here["min_distance_mm"], rel=1e-9)


async def test_a_mesh_moved_turned_and_scaled_with_its_params_gets_the_same_sites(client):
    """Move, turn and scale the mesh with its params and its units (the same head in cm, in
    m, and from a known distance): the same sites (:func:`check_the_same_sites`); the same
    seed, the same sites again. (Before the batches' sizes were settled, each of these poses
    gave other faces.)"""
    density = {"density_per_cm2": 5, "seed": 4}
    _, params = posed(Rotation.identity(), 1.0, np.zeros(3), "mm")
    here = (await sites(client, params | density)).json()
    assert here["count"] == 2904
    rng = np.random.default_rng(31)
    for scale, units in POSES:
        turn, shift = Rotation.random(random_state=rng), rng.normal(size=3) * 500 * scale
        moved, params = posed(turn, scale, shift, units)
        response = await sites(client, params | density, name="moved.obj", data=moved)
        assert response.status_code == 200, response.text
        check_the_same_sites(here, response.json(), turn, scale, shift)
    again = (await sites(client, params | density, name="moved.obj", data=moved)).json()
    assert again["sites"] == response.json()["sites"]


async def test_zones_and_a_count_get_the_same_sites_in_every_pose(client):
    """Zones drawn on the map cut triangles (candidates there kept by the zone's winding at
    their map point) and share an exact count by their areas times densities: the same sites
    for the head moved, turned and scaled with its params and units."""
    _, params = posed(Rotation.identity(), 1.0, np.zeros(3), "mm")
    plain = (await sites(client, params | {"density_per_cm2": 1})).json()["sites"]
    cx, cy = np.mean(plain["x"]), np.mean(plain["y"])
    zones = [
        rectangle("crown", cx - 0.3, cx, cy - 0.25, cy + 0.25, 12),
        rectangle("temple", cx + 0.05, cx + 0.3, cy - 0.25, cy + 0.1, 4),
    ]
    asked = {"zones": zones, "count": 1500, "seed": 6}
    here = (await sites(client, params | asked)).json()
    assert here["count"] == 1500 and all(zone["sites"] > 100 for zone in here["zones"])
    rng = np.random.default_rng(32)
    for scale, units in POSES[::2]:
        turn, shift = Rotation.random(random_state=rng), rng.normal(size=3) * 500 * scale
        moved, params = posed(turn, scale, shift, units)
        there = (await sites(client, params | asked, name="moved.obj", data=moved)).json()
        check_the_same_sites(here, there, turn, scale, shift)


async def test_a_density_map_gets_the_same_sites_in_every_pose(client):
    """A density map (a ramp from 0 to 40 sites per cm² across the map, a black stripe
    where triangles get no site): each triangle takes its own density and spacing from the
    pixel under its centroid on the map, the same map in every pose: the same sites for the
    head moved, turned and scaled with its params and units."""
    ramp = np.tile(np.linspace(0, 255, 480), (360, 1))
    ramp[:, 200:260] = 0
    picture = {"image_width": 480, "image_height": 360, "density_range": [0, 40], "seed": 2}

    async def placed(data: bytes | None, params: dict) -> dict:
        files = {"mesh": ("moved.obj", data) if data else (NAME, SAMPLES[NAME].path.read_bytes())}
        files["density_map"] = ("density.png", grey_png(ramp))
        body = {"params": json.dumps({**PARAMS, **params, **picture})}
        response = await client.post("/v1/sites", files=files, data=body)
        assert response.status_code == 200, response.text
        return response.json()

    here = await placed(None, posed(Rotation.identity(), 1.0, np.zeros(3), "mm")[1])
    assert here["count"] > 1000
    rng = np.random.default_rng(33)
    for scale, units in POSES[::2]:
        turn, shift = Rotation.random(random_state=rng), rng.normal(size=3) * 500 * scale
        moved, params = posed(turn, scale, shift, units)
        check_the_same_sites(here, await placed(moved, params), turn, scale, shift)


async def test_no_site_goes_on_a_flagged_face_unless_allowed(client):
    """The whole head: a closed mesh, so some triangles cross the seam or hold a singular
    point; sites avoid them, unless allow_flagged."""
    params = {"region": None, "density_per_cm2": 20}
    answer = (await sites(client, params)).json()
    validation = (
        await flatten(client, NAME, {"rotation": PARAMS["rotation"], "sigma": 0.3})
    ).json()["validation"]
    flagged = set()
    for key in ("singular_point_faces", "seam_faces", "folded_faces", "backfacing_faces"):
        flagged.update(validation[key])
    flagged.update(validation["degenerate_faces"])
    assert flagged
    assert not flagged & set(answer["sites"]["face"])
    (zone,) = answer["zones"]
    assert zone["open_area_cm2"] < zone["area_cm2"]
    allowed = (await sites(client, {**params, "allow_flagged": True})).json()
    assert flagged & set(allowed["sites"]["face"])
    assert allowed["zones"][0]["open_area_cm2"] == pytest.approx(allowed["zones"][0]["area_cm2"])


async def test_the_ply_answer_is_the_sites_with_normals_and_face_ids(client):
    params = {"density_per_cm2": 8, "seed": 2}
    answer = (await sites(client, params)).json()
    response = await sites(client, {**params, "output": "ply"})
    assert response.status_code == 200
    assert response.headers["content-type"] == "application/ply"
    header, _, body = response.content.partition(b"end_header\n")
    assert b"format binary_little_endian 1.0" in header
    assert f"element vertex {answer['count']}".encode() in header
    row = struct.Struct("<dddfffi")
    rows = [row.unpack_from(body, k * row.size) for k in range(answer["count"])]
    assert len(body) == row.size * answer["count"]
    np.testing.assert_allclose([r[:3] for r in rows], answer["sites"]["position"])
    np.testing.assert_allclose([r[3:6] for r in rows], answer["sites"]["normal"], atol=1e-6)
    assert [r[6] for r in rows] == answer["sites"]["face"]


async def test_the_glb_answer_adds_the_sites_as_points(client):
    response = await sites(client, {"density_per_cm2": 8, "output": "glb"})
    assert response.status_code == 200
    length = struct.unpack_from("<I", response.content, 12)[0]
    document = json.loads(response.content[20 : 20 + length])
    assert [node["name"] for node in document["nodes"]] == ["region", "sites"]
    (points,) = document["meshes"][1]["primitives"]
    assert points["mode"] == 0
    count = document["accessors"][points["attributes"]["POSITION"]]["count"]
    assert count == (await sites(client, {"density_per_cm2": 8})).json()["count"]


@pytest.mark.parametrize("output", ["svg", "png"])
async def test_the_picture_shows_the_sites_and_the_zones(client, output):
    x, y = await scalp_map(client)
    zone = rectangle("crown", x.mean() - 0.2, x.mean() + 0.2, y.mean() - 0.2, y.mean() + 0.2, 10)
    response = await sites(client, {"zones": [zone], "output": output})
    assert response.status_code == 200
    assert response.headers["content-type"] == f"image/{'svg+xml' if output == 'svg' else 'png'}"
    if output == "svg":
        text = response.text
        assert 'class="sites"' in text and "crown" in text and "sites: " in text


async def test_bad_requests_are_422s_naming_the_field(client):
    x, y = await scalp_map(client)
    cx, cy = x.mean(), y.mean()
    body = problem(await sites(client, {"units": None, "density_per_cm2": 5}), 422, "params.units")
    assert "length unit" in body["detail"]
    problem(await sites(client, {}), 422)
    zone = rectangle("bare", cx - 0.1, cx, cy - 0.1, cy)
    body = problem(await sites(client, {"zones": [zone]}), 422)
    assert "zones.0 ('bare'): give its density_per_cm2" in body["detail"]
    overlapping = [
        rectangle("a", cx - 0.2, cx + 0.1, cy - 0.2, cy + 0.1, 5),
        rectangle("b", cx, cx + 0.2, cy, cy + 0.2, 5),
    ]
    body = problem(await sites(client, {"zones": overlapping}), 422, "params.zones.1")
    assert "overlaps params.zones.0 ('a')" in body["detail"]
    body = await sites(client, {"density_per_cm2": 30, "min_spacing_mm": 3})
    body = problem(body, 422, "params.min_spacing_mm")
    assert "sites were placed within 200 candidates a site" in body["detail"]
    assert "at a spacing of 3 mm" in body["detail"]
    problem(await sites(client, {"density_per_cm2": 1e6}), 422)
    problem(await sites(client, {"density_per_cm2": 5, "count": 0}), 422)


async def test_too_many_sites_is_a_413():
    app = create_app(Settings(max_sites=1000))
    async with app.router.lifespan_context(app):
        transport = httpx.ASGITransport(app=app)
        async with httpx.AsyncClient(transport=transport, base_url="http://meshflat") as client:
            body = problem(await sites(client, {"density_per_cm2": 30}), 413, "sites")
            assert "the limit is 1,000 (MESHFLAT_MAX_SITES)" in body["detail"]


async def test_too_many_zone_points_is_a_413_naming_the_zones():
    """Each zone point costs some kilobytes to cover: they are bounded as /v1/measure's are
    (issue 32)."""
    async with started(Settings(max_drawn_points=10)) as client:
        t = np.linspace(0, 2 * np.pi, 11, endpoint=False)
        ring = {"x": (-1.5 + 0.1 * np.cos(t)).tolist(), "y": (1.5 + 0.1 * np.sin(t)).tolist()}
        zone = {"name": "many", "outer": ring, "density_per_cm2": 1}
        params = {"zones": [zone], "units": "mm"}
        body = problem(await sites(client, params), 413, "params.zones")
        assert "the limit is 10 (MESHFLAT_MAX_DRAWN_POINTS)" in body["detail"]


async def test_a_zones_points_are_charged_at_least_what_covering_them_allocates(monkeypatch):
    """What a ring of 5,000 points adds to a square's request (tracemalloc's peak: its
    pieces paired with the triangles, the cover kept) is within what it adds to the charge:
    it once took some 8 KB a point, charged nothing beyond its JSON (issue 32)."""
    charged = []
    charge = Ticket.charge
    monkeypatch.setattr(Ticket, "charge", lambda self, n: (charged.append(n), charge(self, n)))

    async def peak_and_charge(client, n: int) -> tuple[int, int]:
        t = np.linspace(0, 2 * np.pi, n, endpoint=False)
        ring = {"x": (-1.5 + 0.2 * np.cos(t)).tolist(), "y": (1.5 + 0.2 * np.sin(t)).tolist()}
        zone = {"name": "ring", "outer": ring, "density_per_cm2": 1}
        charged.clear()
        tracemalloc.start()
        try:
            response = await sites(client, {"zones": [zone], "units": "mm"})
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        assert response.status_code == 200, response.text
        return peak, sum(charged)

    app = create_app(Settings())
    async with app.router.lifespan_context(app):
        transport = httpx.ASGITransport(app=app)
        async with httpx.AsyncClient(transport=transport, base_url="http://meshflat") as client:
            few = await peak_and_charge(client, 4)
            many = await peak_and_charge(client, 5000)
    assert many[0] <= many[1]
    added, added_charge = many[0] - few[0], many[1] - few[1]
    assert added <= added_charge, (
        f"{added / 2**20:.0f} MiB more, {added_charge / 2**20:.0f} charged"
    )


async def test_the_command_line_places_sites_into_a_ply(client, tmp_path):
    x, y = await scalp_map(client)
    zone = rectangle("crown", x.mean() - 0.2, x.mean() + 0.2, y.mean() - 0.2, y.mean() + 0.2)
    path = tmp_path / "zones.json"
    path.write_text(json.dumps({"zones": [zone], "units": "mm"}))
    out = tmp_path / "sites.ply"
    frame = ["--region-cone", "0,0,1:70", "--pole", "0,0,-1", "--up", "0,1,0", "--sigma", "0.3"]
    mesh = str(SAMPLES[NAME].path)
    command = ["sites", mesh, *frame, "--density", "40", "--zones", str(path), "--out", str(out)]
    assert main(command) == 0
    expected = await sites(client, {"zones": [zone], "density_per_cm2": 40, "output": "ply"})
    assert out.read_bytes() == expected.content


def grey_png(grey: np.ndarray, mode: str = "L") -> bytes:
    from PIL import Image

    out = io.BytesIO()
    Image.fromarray(grey.astype(np.uint8)).convert(mode).save(out, format="PNG")
    return out.getvalue()


async def sites_with_map(client, params: dict, png: bytes | None):
    files = {"mesh": (NAME, SAMPLES[NAME].path.read_bytes())}
    if png is not None:
        files["density_map"] = ("density.png", png)
    data = {"params": json.dumps({**PARAMS, **params})}
    return await client.post("/v1/sites", files=files, data=data)


async def test_a_density_map_puts_each_triangle_at_its_pixels_density(client):
    """A grey PNG in the framing of the PNG answer: a band of 255 across the middle of the
    map, 0 elsewhere, for 0 to 20 sites per cm². The sites go onto the triangles whose
    centroid's pixel is in the band, as many as their area times 20 per cm²."""
    answer = (await flatten(client, NAME, SCALP)).json()
    x, y = np.asarray(answer["vertices"]["x"]), np.asarray(answer["vertices"]["y"])
    framing = Framing.of(x, y, Layout.THETA_PHI, 1200, 800)
    low, high = (int(framing.column(np.quantile(x, q))) for q in (0.3, 0.6))
    grey = np.zeros((800, 1200))
    grey[:, low:high] = 255
    placed = await sites_with_map(client, {"density_range": [0, 20]}, grey_png(grey))
    assert placed.status_code == 200, placed.text
    placed = placed.json()
    # The triangles in the band, by their centroids on the map.
    position = {vertex: k for k, vertex in enumerate(answer["vertices"]["ids"])}
    corners = np.vectorize(position.get)(np.asarray(answer["faces"]["vertices"]))
    centroids = np.column_stack([x[corners].mean(axis=1), y[corners].mean(axis=1)])
    column = np.floor(framing.pixels(centroids)[:, 0])
    band = np.asarray(answer["faces"]["ids"])[(column >= low) & (column < high)]
    vertices, faces = load_sample(NAME)
    p = vertices[faces[band]]
    area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1).sum()
    assert placed["count"] == round(20 * area / 100)
    assert set(placed["sites"]["face"]) <= set(band.tolist())
    (zone,) = placed["zones"]
    assert zone["name"] == "density map" and zone["density_per_cm2"] == pytest.approx(20)
    assert zone["open_area_cm2"] == pytest.approx(area / 100)
    check_on_the_mesh(placed, vertices, faces)


async def test_a_bad_density_map_is_a_422_naming_it(client):
    grey = np.full((800, 1200), 128)
    params = {"density_range": [0, 20]}
    body = problem(await sites_with_map(client, params, None), 422, "density_map")
    assert "a multipart part 'density_map'" in body["detail"]
    small = grey_png(np.full((400, 600), 128))
    body = problem(await sites_with_map(client, params, small), 422, "density_map")
    assert "600 x 400 pixels" in body["detail"] and "1200 x 800" in body["detail"]
    body = problem(await sites_with_map(client, params, grey_png(grey, "RGB")), 422)
    assert "mode RGB" in body["detail"]
    body = problem(await sites_with_map(client, params, b"not a png"), 422, "density_map")
    problem(await sites_with_map(client, {**params, "density_per_cm2": 5}, grey_png(grey)), 422)
    problem(await sites_with_map(client, {"density_range": [30, 20]}, grey_png(grey)), 422)


async def test_the_command_line_reads_a_density_map(client, tmp_path):
    grey = np.full((800, 1200), 200)
    path = tmp_path / "density.png"
    path.write_bytes(grey_png(grey))
    out = tmp_path / "sites.json"
    frame = ["--region-cone", "0,0,1:70", "--pole", "0,0,-1", "--up", "0,1,0", "--sigma", "0.3"]
    command = ["sites", str(SAMPLES[NAME].path), *frame, "--units", "mm"]
    command += ["--density-map", str(path), "--params", '{"density_range": [0, 30]}']
    assert main([*command, "--out", str(out)]) == 0
    expected = await sites_with_map(client, {"density_range": [0, 30]}, grey_png(grey))
    assert json.loads(out.read_bytes()) == expected.json()
    assert main([*command[:-4], "--density-map", str(tmp_path / "none.png")]) == 2


def test_triangles_a_zone_cuts_get_the_zones_density_too():
    """Big triangles, a zone that cuts most of them: the sites in the cut triangles are their
    share of the zone's area (candidates fall on the whole triangle, kept inside)."""
    triangles = jittered_mesh(n=4, seed=8)
    ring = [[0.13, 0.21], [0.86, 0.12], [0.79, 0.9], [0.22, 0.77]]
    part = zone_part(triangles, ring, 4000)
    part = SitePart(
        part.triangles, part.area, 4000, 0.2 * part.spacing, partial=part.partial,
        inside=part.inside, whole_area=part.whole_area,
    )  # fmt: skip
    sites = place_sites(triangles.surface_points, triangles.faces, [part], np.random.default_rng(9))
    cut = np.isin(sites.triangles, part.triangles[part.partial])
    share = part.area[part.partial].sum() / part.area.sum()
    assert cut.mean() == pytest.approx(share, abs=0.02), (cut.mean(), share)


async def test_a_sparse_zone_keeps_its_spacing_from_a_dense_one(client):
    """Zones are placed densest first, each keeping its own spacing: every site of the
    sparse zone is at least its spacing_mm from every other site, whatever the zones' order."""
    x, y = await scalp_map(client)
    cx, cy = x.mean(), y.mean()
    sparse = rectangle("sparse", cx - 0.3, cx, cy - 0.2, cy + 0.2, 5)
    dense = rectangle("dense", cx, cx + 0.3, cy - 0.2, cy + 0.2, 80)
    for zones in ([sparse, dense], [dense, sparse]):
        answer = (await sites(client, {"zones": zones, "seed": 2})).json()
        points = np.asarray(answer["sites"]["position"])
        name = {zone["name"]: zone for zone in answer["zones"]}
        on_map = np.column_stack([answer["sites"]["x"], answer["sites"]["y"]])
        in_sparse = on_map[:, 0] < cx
        distance, _ = cKDTree(points).query(points[in_sparse], k=2)
        assert distance[:, 1].min() >= name["sparse"]["spacing_mm"]
        assert name["sparse"]["spacing_mm"] > 3 * name["dense"]["spacing_mm"]


async def test_a_smaller_min_spacing_is_used_as_asked(client):
    answer = (await sites(client, {"density_per_cm2": 20, "min_spacing_mm": 0.5})).json()
    assert answer["zones"][0]["spacing_mm"] == pytest.approx(0.5)
    assert answer["min_distance_mm"] >= 0.5


@pytest.mark.filterwarnings("error::RuntimeWarning")
async def test_a_min_spacing_beyond_a_micron_to_a_kilometre_is_a_422(client):
    """1e-300 mm overflowed the sites a unit² the spacing allows, 1e300 mm its square."""
    for spacing in (1e-300, 1e-4, 2e6, 1e300):
        body = await sites(client, {"density_per_cm2": 5, "min_spacing_mm": spacing})
        problem(body, 422, "params.min_spacing_mm")
    answer = await sites(client, {"density_per_cm2": 5, "min_spacing_mm": 1e-3})
    assert answer.status_code == 200 and answer.json()["min_distance_mm"] >= 1e-3


async def test_edge_cases_answer_without_a_500(client):
    """No site at all (a tiny density): every form answers; a scale from a known distance
    far outside a micron to a kilometre per unit is a 422; a spacing far too wide for the
    count is refused after its tries."""
    for output in ("json", "glb", "ply", "svg", "png"):
        response = await sites(client, {"density_per_cm2": 1e-9, "output": output})
        assert response.status_code == 200, (output, response.text)
    answer = (await sites(client, {"density_per_cm2": 1e-9})).json()
    assert answer["count"] == 0 and answer["zones"][0]["spacing_mm"] is None
    assert answer["min_distance"] is None
    for mm in (1e200, 1e-300, 1e10):
        units = {"between": [[0, 0, 0], [1, 0, 0]], "mm": mm}
        body = problem(await sites(client, {"density_per_cm2": 5, "units": units}), 422)
        assert body["field"] == "params.units" and "mm per unit" in body["detail"]
    crowded = {"density_per_cm2": 1, "count": 500, "min_spacing_mm": 30}
    problem(await sites(client, crowded), 422, "params.min_spacing_mm")


async def test_a_density_map_without_its_range_is_a_422(client):
    grey = grey_png(np.full((800, 1200), 100))
    body = problem(await sites_with_map(client, {"density_per_cm2": 30}, grey), 422)
    assert body["field"] == "density_map" and "density_range" in body["detail"]
