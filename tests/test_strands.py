"""Strands grown from sites (docs/math.md, section 20), checked against independent
computations: each leaves its root along the site's direction, keeps its length, and no
point of it lies inside the watertight bundled head (a generalised winding number over every
triangle) or, past its first 2 mm, nearer the surface than half the clearance (the distance
to every triangle)."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest

from transforms import MapTriangles, fit_region, lift_curve
from transforms.growth import growth_field, pushed_forward
from transforms.sites import SitePart, place_sites, site_normals, vertex_normals
from transforms.strands import (
    Roots,
    StrandShape,
    SurfaceGuard,
    _closest_on_triangles,
    grow_strands,
)

from .conftest import load_sample

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


def grown(length: float = 60.0, points: int = 16, clearance: float = 1.0) -> np.ndarray:
    _, _, triangles, field, normals, roots, guard = scalp()
    lengths = np.full(len(roots.points), length)
    shape = StrandShape(points, clearance, 2.0 * clearance, free=2.0)
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
        nearest = _closest_on_triangles(repeated, np.tile(corners, (len(points), 1, 1)))
        gaps = np.linalg.norm(nearest - repeated, axis=1).reshape(len(points), len(corners))
        best = np.minimum(best, gaps.min(axis=1))
    return best


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
