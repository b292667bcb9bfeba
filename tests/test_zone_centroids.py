"""The centroids of a zone's parts of the triangles its outline cuts (transforms.zones,
transforms.fans; docs/math.md, section 12): checked against shapely's clipping of each
triangle by the zone, for concave zones, zones with holes, outlines through vertices and along
edges, folded triangles and slivers."""

from __future__ import annotations

import numpy as np
import pytest
import shapely

from transforms.mapping import MapTriangles
from transforms.zones import ZoneCover, cover_zone

from .test_mapping import exact_mesh, folded_mesh, jittered_mesh
from .test_zones import (
    cut_into_tiles,
    random_zone,
    rectangle,
    star_with_hole,
    variants,
)

#: Pieces with a smaller share than this are slivers: the rounding of moments about a point
#: far from them, over their small area, is no longer below 1e-9 of the triangle's size.
SLIVER = 1e-6


def sizes(triangles: MapTriangles, faces: np.ndarray) -> np.ndarray:
    """(k,) float: each triangle's size on the map, the square root of twice its area."""
    return np.sqrt(2.0 * np.abs(triangles.signed_map_area[faces]))


def assert_in_triangles(triangles: MapTriangles, faces: np.ndarray, points: np.ndarray) -> None:
    """Every point is a number, in its triangle (weights not below -1e-12) and inside its
    box (to 1e-12 of its size)."""
    assert np.isfinite(points).all()
    assert (triangles.barycentric(faces, points) >= -1e-12).all()
    corners = triangles.corners(faces)
    slack = 1e-12 * sizes(triangles, faces)[:, None]
    assert (points >= corners.min(axis=1) - slack).all()
    assert (points <= corners.max(axis=1) + slack).all()


def assert_centroids_like_shapely(triangles: MapTriangles, rings) -> ZoneCover:
    """Each cut triangle's part inside the zone, by shapely: its share of the triangle, and
    its centroid to 1e-9 of the triangle's size unless it is a sliver; every centroid in its
    triangle."""
    zone = shapely.Polygon(rings[0], rings[1:])
    assert zone.is_valid
    cover = cover_zone(triangles, rings)
    assert cover.partial_centroid.shape == (len(cover.partial), 2)
    parts = shapely.intersection(shapely.polygons(triangles.corners(cover.partial)), zone)
    area = np.abs(triangles.signed_map_area[cover.partial])
    np.testing.assert_allclose(cover.share, shapely.area(parts) / area, atol=1e-9)
    expected = shapely.get_coordinates(shapely.centroid(parts))
    error = np.linalg.norm(cover.partial_centroid - expected, axis=1)
    error /= sizes(triangles, cover.partial)
    whole = cover.share > SLIVER
    assert error[whole].max(initial=0.0) <= 1e-9
    assert_in_triangles(triangles, cover.partial, cover.partial_centroid)
    return cover


def lattice_zones() -> list[list[np.ndarray]]:
    """Zones on the exact grid (``0..6``): corners at lattice points, edges along grid lines
    and along diagonal edges, across triangles corner to corner and through vertices, holes
    with corners at lattice points and between them."""
    notched = np.array([[0.0, 0.0], [3.0, 3.0], [6.0, 0.0], [6.0, 6.0], [0.0, 6.0]])
    return [
        [rectangle(1.0, 2.0, 5.0, 4.0), rectangle(2.0, 2.5, 3.0, 3.0)[::-1]],
        [np.array([[0.0, 1.0], [4.0, 3.0], [6.0, 6.0], [2.0, 5.0], [1.0, 3.5]])],
        [
            notched,
            np.array([[2.0, 4.0], [3.0, 5.0], [2.0, 5.0]]),
            np.array([[3.5, 4.5], [4.5, 4.5], [4.0, 5.5]]),
        ],
        # Along the diagonal x = y and grid lines (mesh edges), a point across triangles.
        [np.array([[1.0, 1.0], [5.0, 5.0], [1.0, 5.0], [1.5, 3.0]])],
        # Beside the other diagonal: across cells, corner to corner through vertices.
        [np.array([[0.0, 5.0], [5.0, 0.0], [6.0, 6.0]])],
        # An arrow whose sides run through lattice points across cells.
        [np.array([[0.5, 0.5], [5.5, 3.0], [0.5, 5.5], [2.0, 3.0]])],
    ]


# -- against shapely -------------------------------------------------------------------------


def test_a_concave_zone_with_a_hole_has_its_parts_centroids():
    """A star-shaped zone with a star-shaped hole over a jittered grid: every cut triangle's
    part has shapely's centroid."""
    cover = assert_centroids_like_shapely(jittered_mesh(), star_with_hole())
    assert len(cover.partial) > 50


@pytest.mark.parametrize("seed", range(12))
def test_random_zones_parts_have_shapelys_centroids(seed):
    """Random star-shaped (concave) zones, half with a hole, some past the region's border,
    over jittered grids of several sizes."""
    rng = np.random.default_rng(300 + seed)
    assert_centroids_like_shapely(jittered_mesh(n=12 + seed, seed=seed), random_zone(rng))


@pytest.mark.parametrize("rings", lattice_zones())
def test_outlines_through_vertices_and_along_edges_have_shapelys_centroids(rings):
    """Zones on the exact grid whose edges run along mesh edges and through vertices: the
    parts that these outlines cut have shapely's centroids."""
    cover = assert_centroids_like_shapely(exact_mesh(6), rings)
    assert len(cover.partial) > 0


def test_random_lattice_polygons_have_shapelys_centroids():
    """Convex hulls of random lattice points (edges through vertices, along edges and from
    corner to corner of cells)."""
    rng = np.random.default_rng(4)
    checked = 0
    for _ in range(12):
        hull = shapely.convex_hull(shapely.MultiPoint(rng.integers(0, 7, (8, 2)).astype(float)))
        if hull.geom_type == "Polygon":
            assert_centroids_like_shapely(exact_mesh(6), [shapely.get_coordinates(hull)[:-1]])
            checked += 1
    assert checked >= 8


def test_a_folded_triangles_part_has_its_centroid():
    """A zone across a map with one triangle folded back (clockwise) over another: both
    parts have shapely's centroids."""
    cover = assert_centroids_like_shapely(folded_mesh(), [rectangle(0.5, 0.25, 1.7, 3.0)])
    np.testing.assert_array_equal(np.sort(cover.partial), [0, 1])


# -- slivers ---------------------------------------------------------------------------------


@pytest.mark.parametrize("slope", [0.3, -0.7, 2.1])
@pytest.mark.parametrize("gap", [1e-3, 1e-4, 1e-5, 3e-6, 1e-6, -1e-5, 0.0])
def test_slivers_cut_off_at_a_vertex_have_centroids_in_their_triangles(gap, slope):
    """An edge passing ``gap`` above a vertex (on the exact grid, at a slope through no
    other) cuts a corner sliver of share about ``gap**2`` off a triangle above it: every
    centroid is a number in its triangle, those of more than a sliver's share as shapely's.
    (At the smallest gaps, the rounding of the moments over the slivers' tiny areas would put
    some centroids outside.)"""
    line = 3.0 + gap + slope * (np.array([-1.0, 7.0]) - 3.0)  # y on the line at x = -1 and 7
    ring = np.array([[-1.0, -10.0], [7.0, -10.0], [7.0, line[1]], [-1.0, line[0]]])
    cover = assert_centroids_like_shapely(exact_mesh(6), [ring])
    if gap >= 1e-5:
        assert cover.share.min() < 2.0 * gap**2  # the sliver was made


def test_a_sliver_in_one_triangle_has_a_centroid_in_it():
    """A thin zone wholly inside one triangle, of shares from about 8e-3 down to 8e-9: its
    centroid is a number in the triangle, to 1e-9 of its size as shapely's above the sliver's
    share."""
    triangles = jittered_mesh()
    k = 100
    corners = triangles.map_points[triangles.faces[k]]
    centre = corners.mean(axis=0)
    for thin in (1e-2, 1e-4, 1e-6, 1e-8):
        ring = centre + np.array([[-0.2, -thin], [0.2, -thin], [0.2, thin], [-0.2, thin]]) * 0.02
        cover = assert_centroids_like_shapely(triangles, [ring])
        np.testing.assert_array_equal(cover.partial, [k])


# -- sums and means ------------------------------------------------------------------------


def test_the_parts_of_a_tiling_recombine_into_each_triangles_centroid():
    """Tiles of random straight cuts over a jittered grid: over the tiles, the parts' shares
    sum to 1 and their share-weighted centroids to the triangle's centroid."""
    triangles = jittered_mesh(n=14, seed=5)
    rng = np.random.default_rng(9)
    lines = [(rng.uniform(0.0, 1.0, 2), rng.normal(size=2)) for _ in range(6)]
    total = np.zeros(len(triangles))
    moment = np.zeros((len(triangles), 2))
    for tile in cut_into_tiles(rectangle(-0.3, -0.3, 1.3, 1.3), lines):
        faces, share, centroid = cover_zone(triangles, [tile]).parts(triangles)
        np.add.at(total, faces, share)
        np.add.at(moment, faces, share[:, None] * centroid)
    np.testing.assert_allclose(total, 1.0, atol=1e-9)
    centres = triangles.corners(np.arange(len(triangles))).mean(axis=1)
    error = np.linalg.norm(moment - centres, axis=1) / sizes(triangles, np.arange(len(triangles)))
    assert error.max() <= 1e-9


@pytest.mark.parametrize("seed", range(4))
def test_the_mean_of_a_linear_function_over_a_zone_is_its_value_at_the_centroid(seed):
    """The parts (whole triangles and cut ones), each weighted by its map area and valued at
    its centroid, give the mean of a linear function over the zone's part of the map: its
    value at the centroid of that part (shapely)."""
    triangles = jittered_mesh(n=16, seed=seed)
    rng = np.random.default_rng(500 + seed)
    rings = random_zone(rng)
    faces, share, centroid = cover_zone(triangles, rings).parts(triangles)
    a, b, c = rng.normal(size=3)
    weight = share * np.abs(triangles.signed_map_area[faces])
    mean = np.dot(weight, a * centroid[:, 0] + b * centroid[:, 1] + c) / weight.sum()
    covered = shapely.Polygon(rings[0], rings[1:]).intersection(shapely.box(0.0, 0.0, 1.0, 1.0))
    x, y = shapely.get_coordinates(covered.centroid)[0]
    assert mean == pytest.approx(a * x + b * y + c, rel=1e-9, abs=1e-12)
    assert weight.sum() == pytest.approx(covered.area, rel=1e-9)


def test_whole_triangles_parts_are_the_triangles_with_their_centroids():
    """:meth:`ZoneCover.parts` lists the triangles wholly inside first, at share 1 and at
    their own centroids, then the cut ones with their shares and parts' centroids."""
    triangles = jittered_mesh()
    cover = cover_zone(triangles, star_with_hole())
    faces, share, centroid = cover.parts(triangles)
    held = len(cover.inside)
    np.testing.assert_array_equal(faces, np.concatenate([cover.inside, cover.partial]))
    np.testing.assert_array_equal(share, np.concatenate([np.ones(held), cover.share]))
    np.testing.assert_array_equal(centroid[held:], cover.partial_centroid)
    np.testing.assert_allclose(
        centroid[:held], triangles.corners(cover.inside).mean(axis=1), rtol=0, atol=1e-15
    )


def test_a_zone_off_the_region_has_no_parts():
    """A zone beside the region, or one whose hole holds it: no centroids, (0, 2) arrays."""
    triangles = jittered_mesh()
    for rings in (
        [rectangle(2.0, 2.0, 3.0, 3.5)],
        [rectangle(-2.0, -2.0, 3.0, 3.0), rectangle(-1.0, -1.0, 2.0, 2.0)],
    ):
        cover = cover_zone(triangles, rings)
        assert cover.partial_centroid.shape == (0, 2)
        faces, share, centroid = cover.parts(triangles)
        assert faces.shape == (0,) and share.shape == (0,) and centroid.shape == (0, 2)


def test_centroids_do_not_depend_on_orientation_or_start():
    """Rotating a ring's points or reversing them moves no centroid (beyond 1e-12 of its
    triangle's size)."""
    triangles = jittered_mesh()
    rings = star_with_hole()
    first = cover_zone(triangles, rings)
    order = np.argsort(first.partial)
    for moved in variants(rings):
        cover = cover_zone(triangles, moved)
        np.testing.assert_array_equal(np.sort(cover.partial), first.partial[order])
        shift = cover.partial_centroid[np.argsort(cover.partial)] - first.partial_centroid[order]
        size = sizes(triangles, first.partial[order])
        assert (np.linalg.norm(shift, axis=1) <= 1e-12 * size).all()
