"""Strands grown from sites (docs/math.md, section 20), checked against independent
computations: each leaves its root along the site's direction, keeps its length, and no
point of it lies inside the watertight bundled head (a generalised winding number over every
triangle) or, past its first 2 mm, nearer the surface than half the clearance (the distance
to every triangle)."""

from __future__ import annotations

import io
import json
import subprocess
from functools import cache

import numpy as np
import pytest
from PIL import Image
from scipy.spatial.transform import Rotation

from service.samples import SAMPLES
from transforms import MapTriangles, fit_region, lift_curve
from transforms.growth import growth_field, pushed_forward
from transforms.sites import SitePart, place_sites, site_normals, vertex_normals
from transforms.strands import (
    Curl,
    Roots,
    StrandShape,
    SurfaceGuard,
    grow_strands,
)

from .conftest import load_sample, real_servers, slow
from .test_api import flatten, problem
from .test_growth import (
    accessor,
    centre_of_map,
    glb_parts,
    hairline_and_crown,
    served_with_growth,
)
from .test_sites import PARAMS as SITES_PARAMS
from .test_sites import posed, sites
from .tools import node_tool

NAME = "fsaverage-head.ply"


@cache
def scalp():
    """The bundled head (watertight), its top fitted and mapped, a growth field of a
    hairline and a crown whorl, and 1,500 sites with their directions at 20 degrees."""
    vertices, faces = (np.array(a) for a in load_sample(NAME))
    fit = fit_region(vertices, faces[vertices[faces].mean(axis=1)[:, 2] > 0])
    flat = fit.region
    triangles = MapTriangles.of(flat.x, flat.y, vertices[flat.vertex_ids], flat.faces)
    low, high = triangles.map_points.min(axis=0), triangles.map_points.max(axis=0)
    middle, size = (low + high) / 2, float((high - low).max())
    hairline = np.array([[-0.3, -0.3], [0.3, -0.3]]) * size + middle
    crown = (middle + np.array([0.0, 0.1 * size]))[None, :]
    field = growth_field(triangles, [lift_curve(triangles, hairline)], crown, np.array([-1]))
    part = SitePart(np.arange(len(triangles)), triangles.surface_area, 1500, 2.0)
    sites = place_sites(triangles.surface_points, triangles.faces, [part], np.random.default_rng(1))
    normals = site_normals(triangles.surface_points, triangles.faces, sites, fit.frame.center)
    on_map = triangles.on_map(sites.triangles, sites.weights)
    directions = field.map_directions(on_map, sites.triangles)
    tangent, _ = pushed_forward(triangles, sites.triangles, directions, normals)
    rise = np.radians(20.0)
    roots = Roots(sites.points, np.cos(rise) * tangent + np.sin(rise) * normals, normals,
                  sites.triangles, on_map)  # fmt: skip
    outwards = _outwards(vertices, faces, fit.frame.center)
    region_normals = outwards * vertex_normals(triangles.surface_points, triangles.faces)
    guard = SurfaceGuard(vertices, faces, outwards)
    return vertices, faces, triangles, field, region_normals, roots, guard


def _outwards(vertices, faces, centre) -> int:
    """+1 when the faces' winding normals point away from ``centre`` on the whole, else -1."""
    cross = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]],
                     vertices[faces[:, 2]] - vertices[faces[:, 0]])  # fmt: skip
    return 1 if np.einsum("md,md->", cross, vertices[faces].mean(axis=1) - centre) > 0 else -1


def grown(length=60.0, points=16, clearance=1.0, curl=None, bend=None) -> np.ndarray:
    _, _, triangles, field, normals, roots, guard = scalp()
    lengths = np.full(len(roots.points), length)
    bend = 2.0 * clearance if bend is None else bend
    shape = StrandShape(points, clearance, bend, free=2.0, curl=curl)
    return grow_strands(triangles, field, normals, roots, lengths, shape, guard)


def winding_numbers(points: np.ndarray, vertices, faces, chunk: int = 1000) -> np.ndarray:
    """(p,) float: the generalised winding number of a closed triangle mesh at ``points``
    (the sum of the triangles' signed solid angles over 4 pi: 1 inside, 0 outside)."""
    a_all, b_all, c_all = (vertices[faces[:, k]] for k in range(3))
    out = np.empty(len(points))
    for start in range(0, len(points), chunk):
        p = points[start : start + chunk, None, :]
        a, b, c = a_all[None] - p, b_all[None] - p, c_all[None] - p
        la, lb, lc = (np.linalg.norm(x, axis=2) for x in (a, b, c))
        det = np.einsum("pfd,pfd->pf", a, np.cross(b, c))
        dots = (np.einsum("pfd,pfd->pf", a, b) * lc + np.einsum("pfd,pfd->pf", b, c) * la
                + np.einsum("pfd,pfd->pf", c, a) * lb)  # fmt: skip
        out[start : start + chunk] = 2 * np.arctan2(det, la * lb * lc + dots).sum(axis=1)
    return out / (4 * np.pi)


def distances_to_surface(points: np.ndarray, vertices, faces) -> np.ndarray:
    """(p,) float: each point's distance to the nearest of every triangle."""
    best = np.full(len(points), np.inf)
    for start in range(0, len(faces), 256):
        corners = vertices[faces[start : start + 256]]
        repeated = np.repeat(points, len(corners), axis=0)
        nearest = closest_on_triangles(repeated, np.tile(corners, (len(points), 1, 1)))
        gaps = np.linalg.norm(nearest - repeated, axis=1).reshape(len(points), len(corners))
        best = np.minimum(best, gaps.min(axis=1))
    return best


def closest_on_triangles(points: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """(p, 3): the closest point of each triangle (p, 3, 3) to each point (p, 3), by its
    barycentric region (Ericson, Real-Time Collision Detection, 5.1.5), vectorised: the
    brute force the service's guard (libigl's tree) is checked against."""
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    ab, ac, ap = b - a, c - a, points - a
    d1, d2 = dot(ab, ap), dot(ac, ap)
    bp = points - b
    d3, d4 = dot(ab, bp), dot(ac, bp)
    cp = points - c
    d5, d6 = dot(ab, cp), dot(ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        total = va + vb + vc
        v, w = vb / total, vc / total
        inside = a + v[:, None] * ab + w[:, None] * ac
        t_ab = d1 / (d1 - d3)
        t_ac = d2 / (d2 - d6)
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
    # Ericson's tests in reverse, so that the first of his that holds is the one kept.
    out = inside
    out = where_chosen(
        out, (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0), b + t_bc[:, None] * (c - b)
    )
    out = where_chosen(out, (vb <= 0) & (d2 >= 0) & (d6 <= 0), a + t_ac[:, None] * ac)
    out = where_chosen(out, (d6 >= 0) & (d5 <= d6), c)
    out = where_chosen(out, (vc <= 0) & (d1 >= 0) & (d3 <= 0), a + t_ab[:, None] * ab)
    out = where_chosen(out, (d3 >= 0) & (d4 <= d3), b)
    out = where_chosen(out, (d1 <= 0) & (d2 <= 0), a)
    bad = ~np.isfinite(out).all(axis=1)  # a triangle of no area: its nearest corner
    if bad.any():
        gaps = np.linalg.norm(corners[bad] - points[bad, None, :], axis=2)
        out[bad] = corners[bad][np.arange(bad.sum()), np.argmin(gaps, axis=1)]
    return out


def dot(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return np.einsum("pd,pd->p", u, v)


def where_chosen(current: np.ndarray, chosen: np.ndarray, value: np.ndarray) -> np.ndarray:
    return np.where(chosen[:, None], value, current)


def test_a_strand_leaves_along_its_sites_direction_and_keeps_its_length():
    _, _, _, _, _, roots, _ = scalp()
    strands = grown(length=60.0, points=16)
    assert strands.shape == (len(roots.points), 16, 3)
    np.testing.assert_array_equal(strands[:, 0], roots.points)
    first = strands[:, 1] - strands[:, 0]
    cosine = np.einsum("pd,pd->p", first / np.linalg.norm(first, axis=1)[:, None], roots.directions)
    assert np.degrees(np.arccos(np.clip(cosine, -1, 1))).max() < 1.0
    arcs = np.linalg.norm(np.diff(strands, axis=1), axis=2).sum(axis=1)
    np.testing.assert_allclose(arcs, 60.0, rtol=0.01)


@slow
@pytest.mark.parametrize("clearance", [1.0, 3.0])
def test_no_strand_point_is_inside_the_head_or_near_its_surface_past_2_mm(clearance):
    vertices, faces, *_ = scalp()
    strands = grown(length=40.0, points=12, clearance=clearance)
    points = strands[:, 1:].reshape(-1, 3)
    assert np.abs(winding_numbers(points[::3], vertices, faces)).max() < 0.5
    steps = np.linalg.norm(np.diff(strands, axis=1), axis=2)
    arc = np.cumsum(steps, axis=1).reshape(-1)
    sample = np.arange(0, len(points), 7)  # every triangle for every 7th point
    gaps = distances_to_surface(points[sample], vertices, faces)
    assert gaps[arc[sample] > 2.0 + 1e-9].min() >= 0.5 * clearance - 1e-9
    assert gaps.min() > 0.0


def distances_to_polyline(points: np.ndarray, polyline: np.ndarray) -> np.ndarray:
    """(p,) float: each point's distance to the nearest segment of ``polyline`` ((k, 3))."""
    a, b = polyline[:-1], polyline[1:]
    ab = b - a
    t = np.einsum("pkd,kd->pk", points[:, None, :] - a[None], ab) / np.einsum("kd,kd->k", ab, ab)
    nearest = a[None] + np.clip(t, 0.0, 1.0)[..., None] * ab[None]
    return np.linalg.norm(nearest - points[:, None, :], axis=2).min(axis=1)


@slow
@pytest.mark.parametrize(
    ("points", "radius", "period", "spread"),
    # Fewer points, a coarser axis: a point's distance to its chords strays further.
    [(64, 1.0, 10.0, 0.1), (24, 2.0, 20.0, 0.2)],
)
def test_a_curled_strand_turns_at_its_radius_about_its_path_and_keeps_its_length(
    points, radius, period, spread
):
    vertices, faces, *_ = scalp()
    curled = grown(length=60.0, points=points, curl=Curl(radius, period))
    # The helix's axis: the strand grown without curl a radius higher, its bend as much longer.
    axis = grown(length=60.0, points=points, clearance=1.0 + radius, bend=2.0 * (1.0 + radius))
    np.testing.assert_array_equal(curled[:, :2], axis[:, :2])  # the same first segment
    steps = np.linalg.norm(np.diff(curled, axis=1), axis=2)
    np.testing.assert_allclose(steps.sum(axis=1), 60.0, rtol=0.01)
    arc = np.cumsum(steps, axis=1)
    rows = np.arange(0, len(curled), 25)
    # Past the bend (the radius grows as 1 - exp(-s / 2)), each point is a radius off the axis.
    off = np.concatenate([distances_to_polyline(curled[i, 1:][arc[i] > 14.0], axis[i])
                          for i in rows])  # fmt: skip
    assert np.percentile(off, 50) == pytest.approx(radius, rel=0.02)
    assert np.percentile(off, 5) > (1 - spread) * radius and off.max() < (1 + spread) * radius
    sample = curled[:, 1:].reshape(-1, 3)
    assert np.abs(winding_numbers(sample[::5], vertices, faces)).max() < 0.5
    gaps = distances_to_surface(sample[::11], vertices, faces)
    assert gaps[arc.reshape(-1)[::11] > 2.0 + 1e-9].min() >= 0.5 - 1e-9


def some_roots(rows) -> Roots:
    _, _, _, _, _, roots, _ = scalp()
    return Roots(*(getattr(roots, name)[rows] for name in
                   ("points", "directions", "normals", "triangles", "map_points")))  # fmt: skip


@pytest.mark.parametrize(("points", "radius", "period"), [(100, 50.0, 50.0), (64, 10.0, 20.0)])
def test_a_wide_curl_whose_axis_rises_steeply_still_keeps_its_length(points, radius, period):
    vertices, faces, triangles, field, normals, _, guard = scalp()
    roots = some_roots(slice(0, 1500, 10))
    shape = StrandShape(points, 1.0, 2.0, 2.0, Curl(radius, period))
    strands = grow_strands(triangles, field, normals, roots, np.full(150, 40.0), shape, guard)
    arcs = np.linalg.norm(np.diff(strands, axis=1), axis=2).sum(axis=1)
    np.testing.assert_allclose(arcs, 40.0, rtol=0.01)
    inside = winding_numbers(strands[:, 1:].reshape(-1, 3)[::4], vertices, faces)
    assert np.abs(inside).max() < 0.5


def test_a_curled_strand_is_the_same_grown_alone_or_with_others():
    _, _, triangles, field, normals, _, guard = scalp()
    shape = StrandShape(48, 1.0, 2.0, 2.0, Curl(1.5, 10.0))
    together = grow_strands(triangles, field, normals, some_roots(slice(0, 200)),
                            np.full(200, 50.0), shape, guard)  # fmt: skip
    alone = grow_strands(triangles, field, normals, some_roots(slice(7, 8)), np.full(1, 50.0),
                         shape, guard)  # fmt: skip
    np.testing.assert_array_equal(alone[0], together[7])
    empty = grow_strands(triangles, field, normals, some_roots(slice(0, 0)), np.zeros(0), shape,
                         guard)  # fmt: skip
    assert empty.shape == (0, 48, 3)


def test_the_guard_tells_the_side_behind_a_crease_sharper_than_a_right_angle():
    # A valley z = 2 |x| (its walls 53 degrees apart), outside above: a face's normal alone
    # calls the points under the crease outside of the other wall.
    corners = np.array([[0, -2, 0], [2, -2, 4], [2, 2, 4], [0, 2, 0], [-2, -2, 4], [-2, 2, 4]],
                       dtype=float)  # fmt: skip
    guard = SurfaceGuard(corners, np.array([[0, 1, 2], [0, 2, 3], [0, 3, 5], [0, 5, 4]]), +1)
    rng = np.random.default_rng(5)
    points = rng.uniform([-1.5, -1.5, -1.5], [1.5, 1.5, 2.5], (4000, 3))
    _, _, height = guard.nearest(points)
    below = points[:, 2] < 2 * np.abs(points[:, 0])
    np.testing.assert_array_equal(height < 0, below)
    # Its magnitude is the distance to the nearer wall: in the xz plane, each wall is the
    # segment from the crease (0, 0) to (+-2, 4).
    xz = points[:, [0, 2]]
    gaps = []
    for way in (np.array([1.0, 2.0]), np.array([-1.0, 2.0])):
        way /= np.linalg.norm(way)
        along = np.clip(xz @ way, 0.0, 2.0 * np.sqrt(5.0))
        gaps.append(np.linalg.norm(xz - along[:, None] * way, axis=1))
    np.testing.assert_allclose(np.abs(height), np.minimum(*gaps), atol=1e-9)


# -- through the API ------------------------------------------------------------------------


async def strands_of(client, params: dict, data: bytes | None = None, name: str = NAME):
    return await flatten(client, name, {**SITES_PARAMS, **params}, data=data,
                         endpoint="/v1/strands")  # fmt: skip


async def growth_of(client) -> dict:
    cx, cy, size = await centre_of_map(client)
    return hairline_and_crown(cx, cy, size)


@pytest.mark.anyio
async def test_strands_start_at_the_sites_along_their_directions_and_keep_their_lengths(client):
    growth = await growth_of(client)
    asked = {"density_per_cm2": 3, "seed": 4, "growth": growth}
    placed = (await sites(client, asked)).json()
    response = await strands_of(client, asked | {"length_mm": 50, "points": 12})
    assert response.status_code == 200, response.text
    answer = response.json()
    points = np.asarray(answer["points"])
    assert points.shape == (placed["count"], 12, 3) and answer["count"] == placed["count"]
    assert answer["root_site"] == list(range(placed["count"]))
    np.testing.assert_allclose(points[:, 0], placed["sites"]["position"], rtol=0, atol=1e-9)
    first = points[:, 1] - points[:, 0]
    angles = np.degrees(np.arccos(np.clip(np.einsum(
        "pd,pd->p", first / np.linalg.norm(first, axis=1)[:, None],
        placed["sites"]["direction"]), -1, 1)))  # fmt: skip
    assert angles.max() < 1.0
    arcs = np.linalg.norm(np.diff(points, axis=1), axis=2).sum(axis=1)
    np.testing.assert_allclose(arcs, 50.0, rtol=0.01)
    np.testing.assert_allclose(answer["length_mm"], 50.0)
    vertices, faces = (np.array(a) for a in load_sample(NAME))
    sample = points[:, 1:].reshape(-1, 3)[::5]
    assert np.abs(winding_numbers(sample, vertices, faces)).max() < 0.5
    again = (await strands_of(client, asked | {"length_mm": 50, "points": 12})).json()
    assert again["points"] == answer["points"]  # same seed, same strands


@pytest.mark.anyio
async def test_zones_and_a_length_map_give_the_lengths_asked(client):
    growth = await growth_of(client)
    cx, cy, size = await centre_of_map(client)
    zones = [
        {"name": "front", "outer": {"x": [cx - size, cx + size, cx + size, cx - size],
                                    "y": [cy - size, cy - size, cy, cy]},
         "density_per_cm2": 2, "length_mm": 30},
        {"name": "back", "outer": {"x": [cx - size, cx + size, cx + size, cx - size],
                                   "y": [cy, cy, cy + size, cy + size]},
         "density_per_cm2": 2, "length_mm": 70},
    ]  # fmt: skip
    answer = (await strands_of(client, {"zones": zones, "growth": growth})).json()
    plain = [{k: v for k, v in zone.items() if k != "length_mm"} for zone in zones]
    placed = (await sites(client, {"zones": plain, "growth": growth})).json()
    front = np.asarray(placed["sites"]["y"]) < cy
    expected = np.where(front, 30.0, 70.0)
    np.testing.assert_allclose(answer["length_mm"], expected)
    arcs = np.linalg.norm(np.diff(np.asarray(answer["points"]), axis=1), axis=2).sum(axis=1)
    np.testing.assert_allclose(arcs, expected, rtol=0.01)
    grey = Image.new("L", (1200, 800), 128)  # the PNG answer's default size
    png = io.BytesIO()
    grey.save(png, format="PNG")
    files = {
        "mesh": (NAME, SAMPLES[NAME].path.read_bytes()),
        "length_map": ("l.png", png.getvalue()),
    }
    params = {**SITES_PARAMS, "density_per_cm2": 2, "growth": growth, "length_range": [20, 60]}
    mapped = await client.post("/v1/strands", files=files, data={"params": json.dumps(params)})
    assert mapped.status_code == 200, mapped.text
    np.testing.assert_allclose(mapped.json()["length_mm"], 20 + 40 * 128 / 255)


@pytest.mark.anyio
async def test_strands_are_the_same_turned_for_the_head_moved_and_turned(client):
    _, params = posed(Rotation.identity(), 1.0, np.zeros(3), "mm")
    plain = (await sites(client, params | {"density_per_cm2": 5})).json()["sites"]
    x, y = np.asarray(plain["x"]), np.asarray(plain["y"])
    growth = hairline_and_crown((x.min() + x.max()) / 2, (y.min() + y.max()) / 2,
                                max(np.ptp(x), np.ptp(y)))  # fmt: skip
    asked = {"density_per_cm2": 2, "seed": 3, "growth": growth, "length_mm": 40}
    here = (await strands_of(client, params | asked)).json()
    rng = np.random.default_rng(43)
    turn, shift = Rotation.random(random_state=rng), rng.normal(size=3) * 300
    moved, params = posed(turn, 1.0, shift, "mm")
    there = (await strands_of(client, params | asked, data=moved, name="moved.obj")).json()
    expected = turn.apply(np.asarray(here["points"]).reshape(-1, 3)) + shift
    np.testing.assert_allclose(np.asarray(there["points"]).reshape(-1, 3), expected, atol=1e-6)


@pytest.mark.anyio
async def test_strands_need_growth_and_a_length(client):
    growth = await growth_of(client)
    problem(await strands_of(client, {"density_per_cm2": 1, "length_mm": 40}), 422,
            "params.growth")  # fmt: skip
    body = problem(await strands_of(client, {"density_per_cm2": 1, "growth": growth}), 422)
    assert body["detail"].startswith("params: length_mm: the strands' length")


@slow
@pytest.mark.anyio
async def test_curled_strands_keep_their_length_and_too_few_points_a_turn_are_refused(client):
    growth = await growth_of(client)
    asked = {"density_per_cm2": 2, "seed": 5, "growth": growth, "length_mm": 40}
    curl = {"radius_mm": 1.5, "period_mm": 8}
    straight = (await strands_of(client, asked | {"points": 48})).json()
    response = await strands_of(client, asked | {"points": 48, "curl": curl})
    assert response.status_code == 200, response.text
    points = np.asarray(response.json()["points"])
    arcs = np.linalg.norm(np.diff(points, axis=1), axis=2).sum(axis=1)
    np.testing.assert_allclose(arcs, 40.0, rtol=0.01)
    np.testing.assert_allclose(points[:, :2], np.asarray(straight["points"])[:, :2])
    vertices, faces = (np.array(a) for a in load_sample(NAME))
    assert np.abs(winding_numbers(points[:, 1:].reshape(-1, 3)[::7], vertices, faces)).max() < 0.5
    # 40 mm of helix of radius 1.5 mm winds 40 / hypot(1, 2 pi 1.5 / 5) = 18.7 mm of its path:
    # 3.75 turns of 5 mm, which 14 points past the first segment draw at under 4 a turn.
    tight = {"radius_mm": 1.5, "period_mm": 5}
    body = problem(await strands_of(client, asked | {"curl": tight}), 422, "params.curl.period_mm")
    assert "give points >= 17" in body["detail"]
    # A strand of two points is one segment: it cannot turn, and is not silently straight.
    problem(await strands_of(client, asked | {"points": 2, "curl": curl}), 422,
            "params.curl.period_mm")  # fmt: skip


@pytest.mark.anyio
async def test_the_ply_and_the_glb_hold_every_strand(client):
    growth = await growth_of(client)
    asked = {"density_per_cm2": 2, "growth": growth, "length_mm": 40, "points": 8}
    answer = (await strands_of(client, asked)).json()
    count = answer["count"]
    data = (await strands_of(client, asked | {"output": "ply"})).content
    header, _, body = data.partition(b"end_header\n")
    assert f"element vertex {count * 8}\n".encode() in header
    assert f"element edge {count * 7}\n".encode() in header
    points = np.frombuffer(body[: count * 8 * 24], dtype="<f8").reshape(count, 8, 3)
    np.testing.assert_allclose(points, answer["points"])
    document, binary = glb_parts((await strands_of(client, asked | {"output": "glb"})).content)
    (node,) = [mesh for mesh in document["meshes"] if mesh["name"] == "strands"]
    ends = accessor(document, binary, node["primitives"][0]["attributes"]["POSITION"])
    assert node["primitives"][0]["mode"] == 1 and ends.shape == (count * 7 * 2, 3)
    np.testing.assert_allclose(ends[0::2].reshape(count, 7, 3), points[:, :-1], atol=1e-3)


@pytest.mark.anyio
async def test_the_usd_stage_opens_with_usd_core_and_holds_the_strands(client, tmp_path):
    """The .usda answer, opened with Pixar's usd-core: one BasisCurves of as many curves as
    strands, each of ``points`` points, its width and each root's st and face id; a Mesh whose
    st is the GLB's UVs."""
    usd = pytest.importorskip("pxr.Usd", reason="usd-core (the test extra) opens the stage")
    geom = pytest.importorskip("pxr.UsdGeom")
    growth = await growth_of(client)
    asked = {"density_per_cm2": 2, "growth": growth, "length_mm": 40, "points": 8}
    answer = (await strands_of(client, asked)).json()
    placed = (await sites(client, {"density_per_cm2": 2, "growth": growth})).json()
    response = await strands_of(client, asked | {"output": "usd"})
    assert response.headers["content-type"] == "model/vnd.usda"
    path = tmp_path / "hair.usda"
    path.write_bytes(response.content)
    stage = usd.Stage.Open(str(path))
    curves = [prim for prim in stage.Traverse() if prim.GetTypeName() == "BasisCurves"]
    assert len(curves) == 1
    strands = geom.BasisCurves(curves[0])
    assert strands.GetTypeAttr().Get() == "linear"
    assert list(strands.GetCurveVertexCountsAttr().Get()) == [8] * answer["count"]
    points = np.asarray(strands.GetPointsAttr().Get())
    np.testing.assert_allclose(points, np.asarray(answer["points"]).reshape(-1, 3), atol=1e-4)
    assert strands.GetWidthsAttr().Get()[0] == pytest.approx(0.08, rel=1e-6)  # mm units
    api = geom.PrimvarsAPI(curves[0])
    assert list(api.GetPrimvar("faceId").Get()) == placed["sites"]["face"]
    root_st = np.asarray(api.GetPrimvar("st").Get())
    assert root_st.shape == (answer["count"], 2) and (root_st >= 0).all() and (root_st <= 1).all()
    mesh = geom.Mesh(stage.GetPrimAtPath("/meshflat/region"))
    st = np.asarray(geom.PrimvarsAPI(mesh).GetPrimvar("st").Get(), dtype=np.float32)
    document, binary = glb_parts((await strands_of(client, asked | {"output": "glb"})).content)
    region = next(m for m in document["meshes"] if m["name"] == "region")
    uv = accessor(document, binary, region["primitives"][0]["attributes"]["TEXCOORD_0"])
    np.testing.assert_array_equal(st, uv)


@pytest.mark.anyio
@pytest.mark.parametrize("route", ["/v1/strands", "/v1/sites"])
async def test_the_strands_and_growth_glbs_pass_the_khronos_validator(client, tmp_path, route):
    growth = await growth_of(client)
    asked = {"density_per_cm2": 2, "growth": growth, "output": "glb"}
    if route == "/v1/strands":
        asked |= {"length_mm": 40, "points": 8}
    response = await flatten(client, NAME, {**SITES_PARAMS, **asked}, endpoint=route)
    assert response.status_code == 200, response.text
    path = tmp_path / "answer.glb"
    path.write_bytes(response.content)
    run = subprocess.run([*node_tool("validate-gltf.mjs"), str(path)], capture_output=True,
                         text=True, check=True)  # fmt: skip
    (report,) = json.loads(run.stdout)
    assert report["issues"]["numErrors"] == 0, report
    assert report["issues"]["numWarnings"] == 0, report


@real_servers
def test_a_real_server_grows_strands():
    """``meshflat serve`` (the command `make serve` runs), over HTTP: strands of the bundled
    head's sites about a crown whorl."""
    params = {**SITES_PARAMS, "density_per_cm2": 2, "length_mm": 30}
    response = served_with_growth("/v1/strands", params)
    assert response.status_code == 200, response.text
    points = np.asarray(response.json()["points"])
    assert points.shape == (response.json()["count"], 16, 3) and len(points) > 100
    arcs = np.linalg.norm(np.diff(points, axis=1), axis=2).sum(axis=1)
    np.testing.assert_allclose(arcs, 30.0, rtol=0.01)
