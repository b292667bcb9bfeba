"""The kernel of a region and its deepest point (transforms.fit.kernel; docs/math.md, section 9)."""

from __future__ import annotations

import numpy as np

from transforms.fit.kernel import chebyshev_center, kernel_planes

from .conftest import sphere_mesh


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


def test_planes_are_the_same_whichever_way_the_faces_are_wound():
    """The planes point out of the region for either winding (the moments' winding turns
    them round), the closing plane of the hole included; the boundary's vertices are the
    rim's."""
    vertices, faces = sphere_mesh(24, 48)
    upper = faces[vertices[faces].mean(axis=1)[:, 2] > 0.0]
    outward, inward = kernel_planes(vertices, upper), kernel_planes(vertices, upper[:, ::-1])
    np.testing.assert_allclose(inward.normals, outward.normals, atol=1e-15)
    np.testing.assert_allclose(inward.offsets, outward.offsets, atol=1e-15)
    assert outward.normals[-1] @ [0, 0, -1] > 0.99  # the hole's plane, facing down
    lower = faces[vertices[faces].mean(axis=1)[:, 2] <= 0.0]
    rim = np.intersect1d(upper, lower)  # the ring the two halves share
    assert len(rim) == 48
    np.testing.assert_array_equal(outward.boundary_vertices, rim)


def test_the_depths_of_many_centres_are_each_centres_depth():
    vertices, faces = sphere_mesh(24, 48)
    planes = kernel_planes(vertices, faces)
    centers = np.random.default_rng(0).normal(size=(5, 3)) * 0.5
    expected = [planes.depth(center) for center in centers]
    np.testing.assert_allclose(planes.depths(centers), expected, rtol=0, atol=1e-15)
