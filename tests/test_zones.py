"""Zones and curves drawn on the map, measured on the surface (transforms.zones; docs/math.md,
section 12): exact per triangle, whatever the outline's orientation, start, or passage through
vertices and along edges, checked against shapely clipping done triangle by triangle."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from transforms.mapping import MapTriangles
from transforms.zones import ZoneCover, cover_zone, lift_curve

from .test_mapping import exact_mesh, folded_mesh, jittered_mesh

UNIT_SQUARE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])


# -- helpers ------------------------------------------------------------------------------------


def shares_by_face(cover: ZoneCover, count: int) -> np.ndarray:
    """(count,) float: the share of every triangle inside the zone, 0 for those outside."""
    shares = np.zeros(count)
    shares[cover.inside] = 1.0
    shares[cover.partial] = cover.share
    return shares


def zone_area(triangles: MapTriangles, cover: ZoneCover) -> float:
    return cover.total(triangles.surface_area)


def region_area(triangles: MapTriangles) -> float:
    return math.fsum(triangles.surface_area)


def rectangle(x0: float, y0: float, x1: float, y1: float) -> np.ndarray:
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])


def star(centre, radii, turn: float = 0.0) -> np.ndarray:
    """A star-shaped ring round ``centre``: one point a radius, at even angles."""
    angles = turn + 2.0 * np.pi * np.arange(len(radii)) / len(radii)
    return (
        np.asarray(centre)
        + np.column_stack([np.cos(angles), np.sin(angles)]) * np.asarray(radii)[:, None]
    )


def shapely_shares(triangles: MapTriangles, zone: shapely.Geometry) -> np.ndarray:
    """(m,) float: each triangle's map area inside ``zone``, over its map area, by shapely."""
    polygons = shapely.polygons(triangles.corners(np.arange(len(triangles))))
    inside = shapely.area(shapely.intersection(polygons, zone))
    return inside / np.abs(triangles.signed_map_area)


def affine_lift(triangles: MapTriangles, face: int, points: np.ndarray) -> np.ndarray:
    """(n, 3) float: map points of triangle ``face`` on the surface, by the triangle's
    affine map solved afresh."""
    corners = triangles.map_points[triangles.faces[face]]
    surface = triangles.surface_points[triangles.faces[face]]
    edges = np.column_stack([corners[1] - corners[0], corners[2] - corners[0]])
    w = np.linalg.solve(edges, (points - corners[0]).T).T
    return surface[0] + w[:, :1] * (surface[1] - surface[0]) + w[:, 1:] * (surface[2] - surface[0])


def shapely_length(triangles: MapTriangles, line: shapely.Geometry) -> float:
    """The surface length of a map line: clipped to every triangle by shapely, each piece
    lifted by its triangle's affine map. (A line along a shared edge counts twice here.)"""
    polygons = shapely.polygons(triangles.corners(np.arange(len(triangles))))
    clipped = shapely.intersection(polygons, line)
    total = []
    for face in np.flatnonzero(~shapely.is_empty(clipped)):
        for part in shapely.get_parts(clipped[face]):
            if part.geom_type != "LineString":
                continue
            lifted = affine_lift(triangles, face, shapely.get_coordinates(part))
            total.append(np.linalg.norm(np.diff(lifted, axis=0), axis=1).sum())
    return math.fsum(total)


def ring_line(ring: np.ndarray) -> shapely.LineString:
    return shapely.LineString(np.concatenate([ring, ring[:1]]))


def split_convex(polygon: np.ndarray, point, direction) -> list[np.ndarray]:
    """The two sides of a convex ring cut by the line through ``point`` along ``direction``,
    sharing the cut's points exactly (either side dropped when empty)."""
    point, direction = np.asarray(point, float), np.asarray(direction, float)
    side = direction[0] * (polygon[:, 1] - point[1]) - direction[1] * (polygon[:, 0] - point[0])
    left, right = [], []
    for k in range(len(polygon)):
        a, b = polygon[k], polygon[(k + 1) % len(polygon)]
        fa, fb = side[k], side[(k + 1) % len(polygon)]
        if fa >= 0:
            left.append(a)
        if fa <= 0:
            right.append(a)
        if fa * fb < 0:
            cut = a + (b - a) * (fa / (fa - fb))
            left.append(cut)
            right.append(cut)
    return [np.array(half) for half in (left, right) if len(half) >= 3]


def cut_into_tiles(square: np.ndarray, lines) -> list[np.ndarray]:
    """The convex tiles of ``square`` cut by every line ``(point, direction)``."""
    tiles = [square]
    for point, direction in lines:
        tiles = [half for tile in tiles for half in split_convex(tile, point, direction)]
    return tiles


def assert_tiling(triangles: MapTriangles, tiles) -> list[ZoneCover]:
    """The tiles' areas sum to the region's and every triangle's shares to 1."""
    covers = [cover_zone(triangles, [tile]) for tile in tiles]
    total = math.fsum(zone_area(triangles, cover) for cover in covers)
    assert total == pytest.approx(region_area(triangles), rel=1e-9)
    shares = sum(shares_by_face(cover, len(triangles)) for cover in covers)
    np.testing.assert_allclose(shares, 1.0, atol=1e-9)
    return covers


def assert_like_shapely(triangles: MapTriangles, rings) -> ZoneCover:
    """The zone's shares, area, map areas and perimeter against shapely's."""
    zone = shapely.Polygon(rings[0], rings[1:])
    assert zone.is_valid
    cover = cover_zone(triangles, rings)
    expected = shapely_shares(triangles, zone)
    np.testing.assert_allclose(shares_by_face(cover, len(triangles)), expected, atol=1e-9)
    assert zone_area(triangles, cover) == pytest.approx(
        float(expected @ triangles.surface_area), rel=1e-9, abs=1e-12
    )
    assert cover.map_area == pytest.approx(zone.area, rel=1e-12)
    region = shapely.union_all(shapely.polygons(triangles.corners(np.arange(len(triangles)))))
    assert cover.covered_map_area == pytest.approx(zone.intersection(region).area, abs=1e-12)
    perimeter = math.fsum(shapely_length(triangles, ring_line(ring)) for ring in rings)
    assert cover.perimeter == pytest.approx(perimeter, rel=1e-9, abs=1e-12)
    return cover


def random_star(rng, centre, low: float, high: float, corners: int) -> np.ndarray:
    """A random ring, star-shaped round ``centre``: random radii, and angles jittered from
    even steps so that no gap reaches a half turn (the ring is simple)."""
    angles = (np.arange(corners) + rng.uniform(0.0, 0.5, corners)) * (2.0 * np.pi / corners)
    radii = rng.uniform(low, high, corners)
    return np.asarray(centre) + radii[:, None] * np.column_stack([np.cos(angles), np.sin(angles)])


def random_zone(rng) -> list[np.ndarray]:
    """A random star-shaped outer ring, and in half the cases a star-shaped hole well inside
    it."""
    centre = rng.uniform(0.1, 0.9, 2)
    outer = random_star(rng, centre, 0.05, rng.uniform(0.1, 0.7), int(rng.integers(3, 40)))
    if rng.uniform() < 0.5:
        return [outer]
    room = shapely.Point(centre).distance(shapely.LinearRing(outer))
    hole = random_star(rng, centre, 0.1 * room, 0.8 * room, int(rng.integers(3, 12)))
    return [outer, hole]


def star_with_hole() -> list[np.ndarray]:
    outer = star([0.52, 0.47], [0.42, 0.17] * 7, turn=0.1)
    hole = star([0.52, 0.47], [0.09, 0.06, 0.1, 0.07, 0.08], turn=0.4)
    return [outer, hole]


# -- areas ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("mesh", [jittered_mesh, exact_mesh])
def test_a_zone_over_the_whole_region_has_its_area(mesh):
    """A ring round the whole region, or along its very border, covers every triangle
    wholly: the region's surface area, to 1e-9 relative."""
    triangles = mesh()
    side = triangles.map_points.max()
    for ring in (rectangle(-0.3 * side, -0.2 * side, 1.4 * side, 1.1 * side), UNIT_SQUARE * side):
        cover = cover_zone(triangles, [ring])
        assert zone_area(triangles, cover) == pytest.approx(region_area(triangles), rel=1e-9)
        np.testing.assert_array_equal(np.sort(cover.inside), np.arange(len(triangles)))
        assert len(cover.partial) == 0
        assert cover.covered_map_area == pytest.approx(side * side, rel=1e-12)


def test_rectangles_along_grid_lines_tile_the_region_exactly():
    """A 3 x 3 tiling of the exact grid, its edges along mesh edges and through vertices:
    areas sum to the region's, each triangle wholly in the tile holding its centroid."""
    triangles = exact_mesh(6)
    tiles = [rectangle(2 * a, 2 * b, 2 * a + 2, 2 * b + 2) for a in range(3) for b in range(3)]
    covers = assert_tiling(triangles, tiles)
    centroids = triangles.map_points[triangles.faces].mean(axis=1)
    for tile, cover in zip(tiles, covers, strict=True):
        assert len(cover.partial) == 0
        within = (centroids >= tile[0]).all(axis=1) & (centroids <= tile[2]).all(axis=1)
        np.testing.assert_array_equal(np.sort(cover.inside), np.flatnonzero(within))


def test_rectangles_across_a_jittered_grid_tile_the_region():
    """A 3 x 3 tiling of the unit square (edges cutting triangles anywhere) sums to the
    region's area, the shares of every triangle to 1."""
    thirds = [0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0]
    tiles = [
        rectangle(thirds[a], thirds[b], thirds[a + 1], thirds[b + 1])
        for a in range(3)
        for b in range(3)
    ]
    assert_tiling(jittered_mesh(), tiles)


@pytest.mark.parametrize("seed", range(4))
def test_random_straight_cuts_tile_the_region(seed):
    """Convex tiles from random straight cuts of a square larger than the region (some
    tiles wholly off it) sum to the region's area, the shares of every triangle to 1."""
    rng = np.random.default_rng(seed)
    lines = [(rng.uniform(0.0, 1.0, 2), rng.normal(size=2)) for _ in range(7)]
    tiles = cut_into_tiles(rectangle(-0.3, -0.3, 1.3, 1.3), lines)
    assert len(tiles) >= 8
    assert_tiling(jittered_mesh(n=20, seed=seed), tiles)


def test_cuts_through_vertices_and_along_edges_tile_the_region():
    """On the exact grid, cuts along grid lines and diagonals (along edges), and across
    triangles through lattice points, still tile it exactly."""
    lines = [
        ((0.0, 0.0), (1.0, 1.0)),  # along the diagonal edges
        ((3.0, 0.0), (0.0, 1.0)),  # along vertical edges
        ((0.0, 1.0), (2.0, 1.0)),  # through (2, 2), (4, 3): across cells at lattice points
        ((0.0, 5.0), (1.0, -1.0)),  # the other diagonal: corner to corner across triangles
        ((0.0, 4.0), (1.0, 0.0)),  # along horizontal edges
    ]
    tiles = cut_into_tiles(rectangle(-1.0, -1.0, 7.0, 7.0), lines)
    assert_tiling(exact_mesh(6), tiles)


@pytest.mark.parametrize("mesh", [jittered_mesh, exact_mesh])
def test_a_triangles_own_image_is_that_triangle(mesh):
    """A zone that is one triangle's image on the map holds that triangle wholly and
    nothing else: its surface area, no partial triangle."""
    triangles = mesh()
    for k in (0, 7, len(triangles) // 2 + 3, len(triangles) - 1):
        cover = cover_zone(triangles, [triangles.map_points[triangles.faces[k]]])
        np.testing.assert_array_equal(cover.inside, [k])
        assert len(cover.partial) == 0
        assert zone_area(triangles, cover) == pytest.approx(triangles.surface_area[k], rel=1e-12)
        assert cover.map_area == pytest.approx(triangles.signed_map_area[k], rel=1e-12)


@pytest.mark.parametrize("mesh", [jittered_mesh, exact_mesh])
def test_a_quad_of_two_triangles_is_those_two(mesh):
    """A zone that is the quad of two triangles sharing an edge holds just those two."""
    triangles = mesh()
    faces = triangles.faces
    for k in (0, 9, len(triangles) // 2 + 5):
        pair = k + 1 if k % 2 == 0 else k - 1  # the other triangle of the grid cell
        shared = [v for v in faces[k] if v in faces[pair]]
        assert len(shared) == 2
        (apex,) = [v for v in faces[k] if v not in shared]
        (other,) = [v for v in faces[pair] if v not in shared]
        # Walk the quad: apex, one end of the shared edge, the other apex, the other end.
        quad = triangles.map_points[[apex, shared[0], other, shared[1]]]
        cover = cover_zone(triangles, [quad])
        np.testing.assert_array_equal(np.sort(cover.inside), sorted([k, pair]))
        assert len(cover.partial) == 0
        expected = triangles.surface_area[k] + triangles.surface_area[pair]
        assert zone_area(triangles, cover) == pytest.approx(expected, rel=1e-12)


def test_a_zone_inside_one_triangle_is_its_share_of_it():
    """A small polygon strictly inside one triangle (no edge crossed) cuts only it, by the
    polygon's share of its map area."""
    triangles = jittered_mesh()
    k = 100
    corners = triangles.map_points[triangles.faces[k]]
    weights = np.array([[0.6, 0.2, 0.2], [0.2, 0.6, 0.2], [0.2, 0.2, 0.6], [0.3, 0.3, 0.4]])
    ring = weights[[0, 1, 3, 2]] @ corners
    cover = cover_zone(triangles, [ring])
    assert len(cover.inside) == 0
    np.testing.assert_array_equal(cover.partial, [k])
    expected = shapely.Polygon(ring).area / triangles.signed_map_area[k]
    np.testing.assert_allclose(cover.share, [expected], rtol=1e-12)


# -- orientation and start ----------------------------------------------------------------


def variants(rings):
    """The same zone with every ring started elsewhere, reversed, or both."""
    for shift in (0, 1, 2, 5):
        for reverse in (False, True):
            moved = [np.roll(ring, -shift, axis=0) for ring in rings]
            yield [ring[::-1] for ring in moved] if reverse else moved
    yield [rings[0], *(ring[::-1] for ring in rings[1:])]


@pytest.mark.parametrize(
    ("mesh", "rings"),
    [
        (jittered_mesh, star_with_hole()),
        (exact_mesh, [rectangle(1.0, 2.0, 5.0, 4.0), rectangle(2.0, 2.5, 3.0, 3.0)[::-1]]),
        (exact_mesh, [np.array([[0.0, 1.0], [4.0, 3.0], [6.0, 6.0], [2.0, 5.0], [1.0, 3.5]])]),
    ],
)
def test_results_do_not_depend_on_orientation_or_start(mesh, rings):
    """Rotating a ring's points or reversing them changes neither the triangles, the shares,
    the areas nor the perimeter."""
    triangles = mesh()
    first = cover_zone(triangles, rings)
    shares = shares_by_face(first, len(triangles))
    for moved in variants(rings):
        cover = cover_zone(triangles, moved)
        np.testing.assert_array_equal(np.sort(cover.inside), np.sort(first.inside))
        np.testing.assert_array_equal(np.sort(cover.partial), np.sort(first.partial))
        np.testing.assert_allclose(shares_by_face(cover, len(triangles)), shares, atol=1e-12)
        assert zone_area(triangles, cover) == pytest.approx(zone_area(triangles, first), rel=1e-12)
        assert cover.map_area == pytest.approx(first.map_area, rel=1e-12)
        assert cover.covered_map_area == pytest.approx(first.covered_map_area, rel=1e-12)
        assert cover.perimeter == pytest.approx(first.perimeter, rel=1e-12)


# -- against shapely -------------------------------------------------------------------------


def test_a_star_with_a_hole_matches_shapely():
    """A star-shaped zone with a hole: every triangle's share, the area and the perimeter
    as shapely's clipping triangle by triangle gives them."""
    triangles = jittered_mesh()
    cover = assert_like_shapely(triangles, star_with_hole())
    assert len(cover.partial) > 50 and len(cover.inside) > 50
    assert len(cover.outline) == 2


@pytest.mark.parametrize("seed", range(8))
def test_random_polygons_match_shapely(seed):
    """Random star-shaped zones, with or without a hole, some past the region's border."""
    rng = np.random.default_rng(100 + seed)
    assert_like_shapely(jittered_mesh(n=16, seed=seed), random_zone(rng))


def test_lattice_polygons_match_shapely_in_area():
    """Zones whose corners are grid vertices and whose edges run along or across mesh
    edges: shares and area as shapely gives them."""
    triangles = exact_mesh(6)
    rng = np.random.default_rng(4)
    for _ in range(6):
        ring = np.unique(rng.integers(0, 7, (8, 2)).astype(float), axis=0)
        hull = shapely.convex_hull(shapely.MultiPoint(ring))
        if hull.geom_type != "Polygon":
            continue
        outer = shapely.get_coordinates(hull.exterior)[:-1]
        cover = cover_zone(triangles, [outer])
        expected = shapely_shares(triangles, hull)
        np.testing.assert_allclose(shares_by_face(cover, len(triangles)), expected, atol=1e-9)
        assert zone_area(triangles, cover) == pytest.approx(
            float(expected @ triangles.surface_area), rel=1e-9
        )


def test_a_zone_off_the_region_covers_nothing():
    """A zone wholly beside the region: no triangle, no area, no outline on the surface,
    and its own map area all the same; so for a zone whose hole holds the region."""
    triangles = jittered_mesh()
    for rings, area in (
        ([rectangle(2.0, 2.0, 3.0, 3.5)], 1.5),
        ([rectangle(-2.0, -2.0, 3.0, 3.0), rectangle(-1.0, -1.0, 2.0, 2.0)], 16.0),
    ):
        cover = cover_zone(triangles, rings)
        assert len(cover.inside) == 0 and len(cover.partial) == 0
        assert zone_area(triangles, cover) == 0.0
        assert cover.map_area == pytest.approx(area, rel=1e-12)
        assert cover.covered_map_area == 0.0
        assert cover.perimeter == 0.0
        assert all(len(ring.faces) == 0 for ring in cover.outline)


#: A far coordinate: 10**e off the unit square's map, from just beyond it to 1e15.
far_exponents = st.floats(0.2, 15.0)
#: A coordinate on the square's map, clear of its sides.
on_map = st.floats(0.05, 0.95)


def assert_same_cover(triangles: MapTriangles, far: ZoneCover, near: ZoneCover) -> None:
    """Two covers of zones with the same part of the map: the same numbers to 1e-9."""
    np.testing.assert_allclose(
        shares_by_face(far, len(triangles)), shares_by_face(near, len(triangles)), atol=1e-9
    )
    assert zone_area(triangles, far) == pytest.approx(zone_area(triangles, near), rel=1e-9)
    assert far.perimeter == pytest.approx(near.perimeter, rel=1e-9, abs=1e-12)
    assert far.covered_map_area == pytest.approx(near.covered_map_area, rel=1e-9, abs=1e-12)


@settings(max_examples=12, deadline=None)
@given(
    sides=st.lists(st.one_of(on_map, far_exponents.map(lambda e: -(10.0**e))), min_size=4,
                   max_size=4),
)  # fmt: skip
def test_a_rectangles_numbers_do_not_depend_on_how_far_off_the_map_its_sides_lie(sides):
    """A rectangle with each side on the map or up to 1e15 off it: the numbers of the same
    rectangle with its far sides just beyond the map (checked against shapely)."""
    triangles = jittered_mesh(n=12)
    # A negative side is that far beyond the map, on the side it bounds.
    x0, y0 = sides[:2]
    x1, y1 = (side if side >= 0 else 1.0 - side for side in sides[2:])
    x0, x1 = sorted((x0, x1)) if min(sides[0], sides[2]) >= 0 else (x0, x1)
    y0, y1 = sorted((y0, y1)) if min(sides[1], sides[3]) >= 0 else (y0, y1)
    assume(x1 - x0 > 1e-3 and y1 - y0 > 1e-3)
    near = np.clip(rectangle(x0, y0, x1, y1), -0.5, 1.5)
    assert_same_cover(
        triangles,
        cover_zone(triangles, [rectangle(x0, y0, x1, y1)]),
        assert_like_shapely(triangles, [near]),
    )


@settings(max_examples=12, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    reaches=st.lists(far_exponents, min_size=1, max_size=4),
)
def test_a_polygons_numbers_do_not_depend_on_far_off_vertices_added_beyond_the_map(seed, reaches):
    """A random convex polygon over the map, some of its corners off the map (no two
    neighbours) each moved up to 1e15 away along one of their edges' lines (the edge keeps
    its line and its part of the map, and the polygon gains a triangle off the map, beside
    the next edge): the polygon's numbers (checked against shapely)."""
    triangles = jittered_mesh(n=12)
    rng = np.random.default_rng(seed)
    near = shapely.get_coordinates(shapely.MultiPoint(rng.uniform(-0.5, 1.5, (8, 2))).convex_hull)
    near = near[:-1]
    square = shapely.box(0.0, 0.0, 1.0, 1.0)
    ring, moved, taken = near.copy(), 0, np.zeros(len(near), dtype=bool)
    for k, corner in enumerate(near):
        # Along the edge from the corner before (or after) it; the triangle gained lies
        # between the new corner and the corner after (or before) it. Never two neighbours:
        # the edge between two corners moved far away could cross the map anywhere.
        along, other = (near[k - 1], near[(k + 1) % len(near)])[:: rng.choice([1, -1])]
        out = (corner - along) / np.linalg.norm(corner - along)
        strip = shapely.Polygon([corner, other, other + 100.0 * out, corner + 100.0 * out])
        beside = taken[k - 1] or taken[(k + 1) % len(near)]
        if moved < len(reaches) and not beside and not strip.intersects(square):
            ring[k] = corner + 10.0 ** reaches[moved] * out
            moved, taken[k] = moved + 1, True
    assume(moved > 0 and shapely.Polygon(ring).is_valid)
    assert_same_cover(
        triangles, cover_zone(triangles, [ring]), assert_like_shapely(triangles, [near])
    )


# -- curves and perimeters ---------------------------------------------------------------


def assert_polyline_on_its_triangles(triangles: MapTriangles, polyline):
    """Each piece of the polyline lies in its triangle's map image, and its surface points
    are its map points lifted by that triangle."""
    assert len(polyline.faces) == len(polyline.map_points) - 1
    for end in (0, 1):
        on = np.flatnonzero(polyline.faces >= 0)
        faces = polyline.faces[on]
        weights = triangles.barycentric(faces, polyline.map_points[on + end])
        assert (weights >= -1e-9).all()
        np.testing.assert_allclose(
            triangles.lift(faces, weights), polyline.surface_points[on + end], atol=1e-12
        )


@pytest.mark.parametrize("seed", range(5))
def test_a_curves_length_matches_shapely(seed):
    """A random polyline on the region: its surface length as shapely's clipping, each
    piece lifted by its triangle's affine map; the polyline passes through the curve's own
    points, each lifted where ``locate`` says."""
    rng = np.random.default_rng(200 + seed)
    triangles = jittered_mesh(n=16, seed=seed)
    points = rng.uniform(0.02, 0.98, (int(rng.integers(2, 12)), 2))
    polyline = lift_curve(triangles, points)
    expected = shapely_length(triangles, shapely.LineString(points))
    assert polyline.length == pytest.approx(expected, rel=1e-9)
    assert (polyline.faces >= 0).all()
    assert_polyline_on_its_triangles(triangles, polyline)
    np.testing.assert_allclose(polyline.map_points[[0, -1]], points[[0, -1]], atol=1e-12)
    found, weights = triangles.locate(points)
    lifted = triangles.lift(found, weights)
    for point, surface in zip(points, lifted, strict=True):
        at = np.argmin(np.linalg.norm(polyline.map_points - point, axis=1))
        np.testing.assert_allclose(polyline.map_points[at], point, atol=1e-12)
        np.testing.assert_allclose(polyline.surface_points[at], surface, atol=1e-12)


def lattice_walk_length(triangles: MapTriangles, lattice) -> float:
    """The surface length through consecutive grid vertices ``(i, j)`` of the exact grid."""
    n = round(float(triangles.map_points.max()))
    ids = [j * (n + 1) + i for i, j in lattice]
    steps = np.diff(triangles.surface_points[ids], axis=0)
    return math.fsum(np.linalg.norm(steps, axis=1))


@pytest.mark.parametrize(
    ("start", "stop", "steps"),
    [((1, 1), (1, 5), (0, 1)), ((0, 0), (6, 6), (1, 1)), ((6, 2), (0, 2), (-1, 0))],
)
def test_a_curve_along_shared_edges_is_counted_once(start, stop, steps):
    """A straight curve along a grid line or the diagonal runs along edges two triangles
    share: one piece per edge, through the vertices, its length the lifted edges' sum."""
    triangles = exact_mesh(6)
    count = max(abs(stop[0] - start[0]), abs(stop[1] - start[1]))
    lattice = [(start[0] + k * steps[0], start[1] + k * steps[1]) for k in range(count + 1)]
    polyline = lift_curve(triangles, np.array([start, stop], dtype=float))
    assert polyline.length == pytest.approx(lattice_walk_length(triangles, lattice), rel=1e-12)
    np.testing.assert_allclose(polyline.map_points, np.array(lattice, dtype=float), atol=1e-12)
    assert len(polyline.faces) == count and (polyline.faces >= 0).all()
    assert_polyline_on_its_triangles(triangles, polyline)


def test_a_perimeter_along_edges_is_counted_once():
    """A rectangle whose sides run along mesh edges: its perimeter is the lifted edges'
    sum, each edge once."""
    triangles = exact_mesh(6)
    cover = cover_zone(triangles, [rectangle(1.0, 2.0, 5.0, 4.0)])
    walk = [(i, 2) for i in range(1, 6)] + [(5, 3), (5, 4)]
    walk += [(i, 4) for i in range(4, 0, -1)] + [(1, 3), (1, 2)]
    assert cover.perimeter == pytest.approx(lattice_walk_length(triangles, walk), rel=1e-12)
    assert len(cover.outline[0].faces) == 12


def test_a_curve_leaving_the_region_has_a_gap():
    """A curve that leaves the square and comes back: the piece off the region is one
    gap (face -1) from where it leaves to where it re-enters, and only the pieces on the
    region count in the length."""
    triangles = jittered_mesh(n=16)
    points = np.array([[0.25, 0.5], [1.5, 0.5], [1.5, 0.8], [0.25, 0.8]])
    polyline = lift_curve(triangles, points)
    gaps = np.flatnonzero(polyline.faces == -1)
    assert len(gaps) == 1
    (gap,) = gaps
    np.testing.assert_allclose(polyline.map_points[gap], [1.0, 0.5], atol=1e-12)
    np.testing.assert_allclose(polyline.map_points[gap + 1], [1.0, 0.8], atol=1e-12)
    np.testing.assert_allclose(polyline.map_points[[0, -1]], points[[0, -1]], atol=1e-12)
    expected = shapely_length(triangles, shapely.LineString(points))
    assert polyline.length == pytest.approx(expected, rel=1e-9)
    assert_polyline_on_its_triangles(triangles, polyline)


def test_a_curve_entering_the_region_starts_at_its_border():
    """A curve from off the region starts where it enters; one wholly off it is empty."""
    triangles = jittered_mesh(n=16)
    polyline = lift_curve(triangles, [[-0.5, 0.3], [0.5, 0.3]])
    np.testing.assert_allclose(polyline.map_points[[0, -1]], [[0.0, 0.3], [0.5, 0.3]], atol=1e-12)
    assert (polyline.faces >= 0).all()
    outside = lift_curve(triangles, [[1.5, 0.3], [2.5, 0.3], [2.0, 1.0]])
    assert outside.length == 0.0 and len(outside.faces) == 0 and len(outside.map_points) == 0


@pytest.mark.parametrize("far", [1e3, 1e9, 1e12, 1e15])
@pytest.mark.parametrize("both", [False, True])
def test_a_curve_with_a_point_far_off_the_map_keeps_its_length_on_the_region(far, both):
    """A straight curve across the square from a point ``far`` off it (and to one, with
    ``both``): the same length and the same points on the region as the curve cut at the
    square's sides, however far the points."""
    triangles = jittered_mesh(n=16)
    y = 0.4375  # between rows of vertices, so that both curves cross the same edges
    points = [[-far, y], [0.5, y], [far if both else 0.9, y]]
    near = [[0.0, y], [0.5, y], [1.0 if both else 0.9, y]]
    polyline, cut = lift_curve(triangles, points), lift_curve(triangles, near)
    assert polyline.length == pytest.approx(cut.length, rel=1e-12)
    assert cut.length > 0.9
    np.testing.assert_allclose(polyline.map_points, cut.map_points, atol=1e-12)
    np.testing.assert_array_equal(polyline.faces, cut.faces)
    # A segment wholly off the map, far away, leaves a gap, not an error.
    beyond = lift_curve(triangles, [[0.5, y], [0.5, 2.0], [far, 2.0], [far, y + 1.0]])
    assert beyond.length == pytest.approx(lift_curve(triangles, [[0.5, y], [0.5, 1.0]]).length)


# -- a folded map ---------------------------------------------------------------------------


def test_a_folded_triangle_counts_negative_in_the_covered_map_area():
    """Two triangles, one folded back over the other: a zone over both covers map area 2 - 1,
    yet both triangles' surface areas; a zone that is the folded one's image covers 1 - 1."""
    triangles = folded_mesh()
    cover = cover_zone(triangles, [rectangle(-1.0, -1.0, 3.0, 3.0)])
    np.testing.assert_array_equal(np.sort(cover.inside), [0, 1])
    assert cover.covered_map_area == pytest.approx(1.0, rel=1e-12)
    assert cover.map_area == pytest.approx(16.0)
    assert zone_area(triangles, cover) == pytest.approx(3.0, rel=1e-12)
    folded = cover_zone(triangles, [triangles.map_points[[1, 0, 3]]])
    assert folded.covered_map_area == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_allclose(shares_by_face(folded, 2), [0.5, 1.0], atol=1e-12)
    assert zone_area(triangles, folded) == pytest.approx(2.0 * 0.5 + 1.0, rel=1e-12)


# -- outlines along the region's border and through vertices ----------------------------------


def grow_patch(triangles: MapTriangles, rng, steps: int) -> np.ndarray:
    """A random connected set of triangles (neighbours across edges) off the region's
    border, grown from one in the middle."""
    faces = triangles.faces
    side = triangles.map_points.max()
    corners = triangles.map_points[faces]
    clear = ((corners > 0) & (corners < side)).all(axis=(1, 2))
    chosen = [int(np.argmin(np.linalg.norm(corners.mean(axis=1) - side / 2, axis=1)))]
    for _ in range(steps):
        seed = chosen[int(rng.integers(len(chosen)))]
        neighbours = np.flatnonzero((np.isin(faces, faces[seed]).sum(axis=1) == 2) & clear)
        chosen.append(int(rng.choice(neighbours)))
    return np.unique(chosen)


def border_edges(faces: np.ndarray) -> np.ndarray:
    """(b, 2) int: the edges of ``faces`` that only one of them has."""
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    keys, counts = np.unique(edges, axis=0, return_counts=True)
    return keys[counts == 1]


@pytest.mark.parametrize("seed", range(6))
def test_a_patch_of_whole_triangles_has_their_area_and_border_length(seed):
    """A zone that is the outline of a patch of whole triangles of the jittered grid (along
    shared edges, through vertices): those triangles wholly, their surface area, and a
    perimeter that counts each border edge of the patch once."""
    triangles = jittered_mesh(n=12, seed=seed)
    rng = np.random.default_rng(seed)
    chosen = grow_patch(triangles, rng, int(rng.integers(5, 60)))
    patch = shapely.union_all(shapely.polygons(triangles.corners(chosen)))
    rings = [patch.exterior, *patch.interiors]
    if not (patch.geom_type == "Polygon" and all(ring.is_simple for ring in rings)):
        pytest.skip("the patch pinches at a vertex")  # no seed in range(6) does
    cover = cover_zone(triangles, [shapely.get_coordinates(ring)[:-1] for ring in rings])
    np.testing.assert_array_equal(np.sort(cover.inside), chosen)
    assert len(cover.partial) == 0
    assert zone_area(triangles, cover) == pytest.approx(
        math.fsum(triangles.surface_area[chosen]), rel=1e-12
    )
    edges = border_edges(triangles.faces[chosen])
    lengths = np.linalg.norm(np.diff(triangles.surface_points[edges], axis=1)[:, 0], axis=1)
    assert cover.perimeter == pytest.approx(math.fsum(lengths), rel=1e-12)
    assert sum(len(ring.faces) for ring in cover.outline) == len(edges)
    assert all((ring.faces >= 0).all() for ring in cover.outline)


SIDES = {
    "bottom": [(i, 0) for i in range(7)],
    "right": [(6, j) for j in range(7)],
    "top": [(i, 6) for i in range(6, -1, -1)],
    "left": [(0, j) for j in range(6, -1, -1)],
}


@pytest.mark.parametrize("reverse", [False, True])
@pytest.mark.parametrize("side", SIDES)
def test_a_curve_along_the_regions_border_has_its_length(side, reverse):
    """A curve along a side of the region runs over its border triangles, whichever side
    and direction: one piece per border edge, the lifted edges' length."""
    triangles = exact_mesh(6)
    lattice = SIDES[side][::-1] if reverse else SIDES[side]
    polyline = lift_curve(triangles, np.array([lattice[0], lattice[-1]], dtype=float))
    assert polyline.length == pytest.approx(lattice_walk_length(triangles, lattice), rel=1e-12)
    np.testing.assert_allclose(polyline.map_points, np.array(lattice, dtype=float), atol=1e-12)
    assert (polyline.faces >= 0).all()


def test_a_zone_along_the_regions_border_has_its_perimeter():
    """A zone whose ring is the region's own border: a perimeter of every border edge, on
    each of the four sides."""
    triangles = exact_mesh(6)
    cover = cover_zone(triangles, [UNIT_SQUARE * 6.0])
    walk = SIDES["bottom"] + SIDES["right"][1:] + SIDES["top"][1:] + SIDES["left"][1:]
    assert cover.perimeter == pytest.approx(lattice_walk_length(triangles, walk), rel=1e-12)
    assert (cover.outline[0].faces >= 0).all() and len(cover.outline[0].faces) == 24


def test_curves_through_mesh_vertices_run_on_without_gaps():
    """Straight curves through interior vertices of the jittered grid, inside the region:
    their polylines run from the curve's start to its end, forward along it, without a gap
    (face -1), and have the length shapely's clipping gives."""
    triangles = jittered_mesh(n=12, seed=25)
    rng = np.random.default_rng(25)
    failures, tried = [], 0
    for vertex in range(len(triangles.map_points)):
        point = triangles.map_points[vertex]
        if not ((point > 0) & (point < 1)).all():
            continue
        tried += 1
        direction = rng.normal(size=2)
        direction *= 0.05 / np.linalg.norm(direction)
        curve = np.array([point - direction, point + 0.8 * direction])
        polyline = lift_curve(triangles, curve)
        along = (polyline.map_points - curve[0]) @ (curve[1] - curve[0])
        ends = np.abs(polyline.map_points[[0, -1]] - curve).max()
        if (polyline.faces < 0).any() or (np.diff(along) < -1e-15).any() or ends > 1e-12:
            failures.append((vertex, curve.tolist(), polyline.faces.tolist()))
        expected = shapely_length(triangles, shapely.LineString(curve))
        assert polyline.length == pytest.approx(expected, rel=1e-9)
    assert not failures, f"{len(failures)} of {tried} curves, first: {failures[0]}"
