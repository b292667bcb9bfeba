"""Validation with answers known by construction (docs/math.md, section 6)."""

import math
from fractions import Fraction

import numpy as np
import pytest

from transforms import Chart, Frame, PoleCap, TransformInputError, flatten_region

from .conftest import grid_mesh, load_sample, sphere_mesh


def closed_triangle_contains_origin(corners_xy) -> bool:
    """Exact 2D test: the closed triangle holds (0, 0)."""
    (ax, ay), (bx, by), (cx, cy) = ([Fraction(float(v)) for v in p] for p in corners_xy)

    def side(px, py, qx, qy):
        return px * qy - py * qx  # orientation of (origin, p, q)

    s = [side(ax, ay, bx, by), side(bx, by, cx, cy), side(cx, cy, ax, ay)]
    return all(v >= 0 for v in s) or all(v <= 0 for v in s)


@pytest.mark.parametrize(
    "offset",
    [
        (0.25, 0.125),  # +Z hits the inside of one triangle
        (0.25, 0.25),  # on a cell diagonal: two triangles
        (0.5, 0.0),  # on a grid edge: two triangles
        (0.0, 0.0),  # on a vertex: all of its triangles
    ],
)
def test_region_over_a_singular_point_reports_exactly_the_triangles_holding_it(offset):
    # Standard chart: the north singular point is exactly +Z. A grid in the plane z = 1 whose
    # coordinates are exact binary fractions, shifted so the ray along +Z meets it at -offset.
    xs = np.arange(-2.0, 2.5, 0.5) - offset[0]
    ys = np.arange(-2.0, 2.5, 0.5) - offset[1]
    vertices, faces = grid_mesh(xs, ys, 1.0)
    flat = flatten_region(vertices, faces, Frame.identity(), Chart.standard())
    expected = [
        i for i, face in enumerate(faces) if closed_triangle_contains_origin(vertices[face, :2])
    ]
    assert len(expected) in (1, 2, 6)
    assert flat.validation.singular_point_faces.tolist() == expected
    assert flat.validation.margin_deg_north == 0.0
    assert flat.validation.margin_deg_south > 90.0  # the plane is on the +Z side
    assert not flat.validation.seam_free


def test_the_ray_is_a_ray_not_a_line():
    """The same grid below the centre holds the south singular point, not the north one."""
    vertices, faces = grid_mesh(np.arange(-2.0, 2.5, 0.5) - 0.25, np.arange(-2.0, 2.5, 0.5), -1.0)
    flat = flatten_region(vertices, faces, Frame.identity(), Chart.standard())
    hit = flat.validation.singular_point_faces
    assert len(hit) == 2
    assert flat.validation.margin_deg_south == 0.0 and flat.validation.margin_deg_north > 90.0


def test_warped_singular_point_in_a_tilted_plane():
    cap = PoleCap.from_sigma(0.3)
    north = cap.north
    e1 = np.cross(north, [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(north, e1)
    # A fan of triangles around the point where the ray meets the plane at distance 2.
    angles = np.linspace(0, 2 * np.pi, 9)[:-1] + 0.1
    ring = 2 * north + 0.3 * (np.cos(angles)[:, None] * e1 + np.sin(angles)[:, None] * e2)
    hub = 2 * north + 0.05 * e1 + 0.02 * e2  # off the ray, inside one fan triangle
    vertices = np.vstack([hub, ring])
    faces = np.array([[0, 1 + k, 1 + (k + 1) % 8] for k in range(8)])
    flat = flatten_region(vertices, faces, Frame.identity(), Chart.distorted(cap))
    # The ray leaves the hub at (-0.05, -0.02) in (e1, e2): angle ~ -158 degrees.
    along = np.degrees(np.arctan2(-0.02, -0.05)) % 360
    k = int(((along - np.degrees(0.1)) % 360) // 45)
    assert flat.validation.singular_point_faces.tolist() == [k]


def southern_cap(rings=36, segments=36, alpha0_deg=100.0):
    """Faces of a UV sphere around +Y with every vertex at least alpha0 from +Y."""
    vertices, faces = sphere_mesh(rings, segments)
    polar = np.degrees(np.arccos(np.clip(vertices[:, 1], -1, 1)))
    keep = (polar[faces] >= alpha0_deg - 1e-9).all(axis=1)
    return vertices, faces[keep]


def test_region_outside_the_cap_has_the_margin_computed_by_hand():
    # Rings every 5 degrees, so one sits at 100 degrees from +Y; rho = 60 degrees. Arcs
    # between points of a ring below the equator bulge away from +Y, so the region's nearest
    # points to the cap are the ring's vertices, among them ones at the longitudes of both
    # singular points (0 and 180 degrees): every margin is 100 - 60 = 40 degrees.
    vertices, faces = southern_cap(alpha0_deg=100.0)
    cap = PoleCap.from_rho_deg(60.0)
    for chart in (Chart.distorted(cap), Chart.separable(cap)):
        v = flatten_region(vertices, faces, Frame.identity(), chart).validation
        assert v.seam_free and v.star_shaped
        assert v.margin_deg_seam == pytest.approx(40.0, abs=1e-9)
        assert v.margin_deg_north == pytest.approx(40.0, abs=1e-9)
        assert v.margin_deg_south == pytest.approx(40.0, abs=1e-9)
        assert v.boundary_loops == 1
        assert len(v.folded_faces) == len(v.degenerate_faces) == 0


def test_margin_of_a_ring_above_the_equator_follows_the_bulge():
    # At 75 degrees from +Y (above the equator) the arc between ring points 10 degrees apart in
    # longitude comes closest to +Y at its middle, the normalised sum of its ends:
    # tan a = tan 75 cos 5.
    vertices, faces = southern_cap(alpha0_deg=75.0)
    cap = PoleCap.from_rho_deg(60.0)
    v = flatten_region(vertices, faces, Frame.identity(), Chart.distorted(cap)).validation
    bulge = math.degrees(math.atan(math.tan(math.radians(75.0)) * math.cos(math.radians(5.0))))
    assert v.seam_free
    assert v.margin_deg_seam == pytest.approx(bulge - 60.0, abs=1e-9)


def test_region_reaching_into_the_cap_on_the_seam_side_crosses_it():
    vertices, faces = southern_cap(alpha0_deg=40.0)  # rings reach 40 degrees from +Y
    v = flatten_region(
        vertices, faces, Frame.identity(), Chart.distorted(PoleCap.from_rho_deg(60.0))
    ).validation
    assert not v.seam_free
    assert len(v.seam_faces) > 0
    assert v.margin_deg_seam == 0.0


def test_nefertiti_is_not_star_shaped():
    vertices, faces = load_sample("nefertiti-lowres.obj")
    centre = (vertices.min(axis=0) + vertices.max(axis=0)) / 2
    frame = Frame.from_pole_up([0.0, -1.0, 0.0], [0.0, 0.0, 1.0], center=centre)
    v = flatten_region(vertices, faces, frame, Chart.distorted(PoleCap.from_sigma(0.3))).validation
    assert len(v.backfacing_faces) > 0
    assert not v.star_shaped
    assert v.winding == 1
    assert v.boundary_loops == 0  # watertight


def test_flat_disk_has_one_boundary_loop():
    angles = np.linspace(0, 2 * np.pi, 33)[:-1]
    radii = np.linspace(0.0, 1.0, 6)[1:]
    ring = [[r * np.cos(a), r * np.sin(a), 2.0] for r in radii for a in angles]
    vertices = np.vstack([[0.0, 0.0, 2.0], ring]) + np.array([0.0, -3.0, 0.0])
    faces = []
    n = len(angles)
    for k in range(n):
        faces.append([0, 1 + k, 1 + (k + 1) % n])
    for j in range(len(radii) - 1):
        for k in range(n):
            a, b = 1 + j * n + k, 1 + j * n + (k + 1) % n
            c, d = 1 + (j + 1) * n + k, 1 + (j + 1) * n + (k + 1) % n
            faces += [[a, c, d], [a, d, b]]
    flat = flatten_region(vertices, np.array(faces), Frame.identity(), Chart.standard())
    assert flat.validation.boundary_loops == 1
    assert flat.validation.star_shaped and flat.validation.seam_free


def test_flipped_and_degenerate_faces():
    vertices, faces = grid_mesh(np.arange(5.0) - 2.1, np.arange(5.0) + 1.0, 1.0)
    faces = faces.copy()
    faces[3] = faces[3][::-1]  # wound the other way: back-facing, and flipped in the layout
    faces = np.vstack([faces, [[0, 0, 1]]])  # a repeated vertex: no area
    v = flatten_region(vertices, faces, Frame.identity(), Chart.standard()).validation
    assert v.winding == 1
    assert v.backfacing_faces.tolist() == [3, len(faces) - 1]
    assert v.folded_faces.tolist() == [3]
    assert v.degenerate_faces.tolist() == [len(faces) - 1]
    assert not v.star_shaped


def test_inward_winding_is_detected_and_flipped():
    vertices, faces = southern_cap(alpha0_deg=100.0)
    cap = PoleCap.from_rho_deg(60.0)
    inward = np.ascontiguousarray(faces[:, ::-1])
    v = flatten_region(vertices, inward, Frame.identity(), Chart.distorted(cap)).validation
    assert v.winding == -1 and v.star_shaped
    forced = flatten_region(vertices, inward, Frame.identity(), Chart.distorted(cap), winding=1)
    assert len(forced.validation.backfacing_faces) == len(faces)


def test_seam_crossing_faces_are_the_ones_straddling_the_cut():
    # Standard chart: the seam is the half-plane y = 0, x < 0. A grid at x = -1 across it.
    xs = np.arange(-2.0, 2.5, 0.5) + 0.25  # no vertex on y = 0
    vertices, faces = grid_mesh(xs, np.arange(-2.0, 2.5, 0.5), 1.0)
    vertices = vertices[:, [2, 0, 1]] * [-1.0, 1.0, 1.0]  # plane x = -1, grid in (y, z)
    v = flatten_region(vertices, faces, Frame.identity(), Chart.standard()).validation
    y = vertices[faces, 1]
    straddling = np.flatnonzero((y.min(axis=1) < 0) & (y.max(axis=1) > 0))
    assert v.seam_faces.tolist() == straddling.tolist()
    assert v.margin_deg_seam == 0.0


def test_region_needs_a_face_with_area():
    vertices = np.array([[1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [3.0, 0.0, 0.0]])
    with pytest.raises(TransformInputError) as caught:
        flatten_region(vertices, [[0, 1, 2]], Frame.identity(), Chart.standard())
    assert "zero area" in str(caught.value)
    with pytest.raises(TransformInputError):
        flatten_region(vertices, np.zeros((0, 3), dtype=int), Frame.identity(), Chart.standard())


def test_a_region_vertex_at_the_centre_is_named_by_its_mesh_row():
    vertices, faces = sphere_mesh(12, 12)
    centre = vertices[40]
    away = ~(faces == 40).any(axis=1)
    flat = flatten_region(vertices, faces[away], Frame.identity(centre), Chart.standard())
    assert 40 not in flat.vertex_ids  # a vertex outside the region may sit at the centre
    with pytest.raises(TransformInputError) as caught:
        flatten_region(vertices, faces, Frame.identity(centre), Chart.standard())
    assert caught.value.field == "vertices"
    assert caught.value.indices == (40,)
    assert "vertex 40: at the centre" in str(caught.value)
