"""Edge cases: exactness at extreme scales, degenerate configurations, and input that must be
refused with TransformInputError."""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from transforms import (
    RHO_MAX,
    Chart,
    Frame,
    PoleCap,
    TransformInputError,
    cartesian_to_spherical,
    flatten_region,
    measure_faces,
    orient3d_sign,
    pole_warp,
    region_edges,
    separable_forward,
    separable_inverse,
    separable_residual,
    validate,
    weighted_quantile,
)
from transforms.arrays import as_direction
from transforms.frames import check_rotation
from transforms.viewpoint import check_center_sees_area

from .conftest import exact_sign, grid_mesh


def test_an_edge_dipping_across_the_seam_is_a_seam_crossing():
    """All three corners lie outside the cap (phi span below pi), but edge 0-1 passes through
    the cap and crosses the seam twice."""
    cap = PoleCap.from_sigma(0.3)

    def direction(polar_deg, around_deg):
        p, a = math.radians(polar_deg), math.radians(around_deg)
        return np.array([-math.sin(p) * math.cos(a), math.cos(p), math.sin(p) * math.sin(a)])

    tip = np.array([-0.2, -1.0, 0.0]) / np.hypot(0.2, 1.0)
    vertices = np.array([direction(40, 60), direction(40, -60), tip]) * 2.0
    assert min(np.degrees(np.arccos(vertices[:, 1] / 2.0))) > cap.rho_deg
    v = flatten_region(vertices, [[0, 1, 2]], Frame.identity(), Chart.distorted(cap)).validation
    assert v.seam_faces.tolist() == [0]
    assert not v.seam_free and v.margin_deg_seam == 0.0


def test_an_edge_on_face_the_singular_ray_runs_through():
    """The face's plane holds the centre and +Z; the ray along +Z crosses its edge at z = 1."""
    vertices = np.array([[1.0, 1.0, 1.0], [-1.0, -1.0, 1.0], [0.2, 0.2, 3.0]])
    chart = Chart.standard()

    def check(corners):
        theta, phi, _ = chart.forward(corners)
        return validate(measure_faces(corners, [[0, 1, 2]], theta, phi, chart.cap))

    v = check(vertices)
    assert v.singular_point_faces.tolist() == [0]
    assert not v.seam_free and v.backfacing_faces.tolist() == [0]
    # Same plane, but the triangle lies beside the ray: no hit.
    assert (
        len(
            check(
                vertices * np.array([1.0, 1.0, 1.0]) + np.array([2.0, 2.0, 0.0])
            ).singular_point_faces
        )
        == 0
    )


def test_the_singular_test_does_not_depend_on_far_away_faces():
    vertices = np.array(
        [
            [1e-300, 0, 1],
            [1, 0.5, 1],
            [1, -0.5, 1],
            [1e100, 0, 1e100],
            [1e100, 1e100, 1e100],
            [1e100, 0, 5e99],
        ]
    )
    alone = flatten_region(vertices, [[0, 1, 2]], Frame.identity(), Chart.standard())
    both = flatten_region(vertices, [[0, 1, 2], [3, 4, 5]], Frame.identity(), Chart.standard())
    assert len(alone.validation.singular_point_faces) == 0
    assert len(both.validation.singular_point_faces) == 0


finite_floats = st.one_of(
    st.just(0.0),
    st.builds(
        lambda m, e: math.ldexp(m, e),
        st.floats(-1.0, 1.0, allow_nan=False),
        st.integers(-1074, 1023),
    ),
)


@given(st.lists(finite_floats, min_size=9, max_size=9))
def test_orientation_is_exact_over_the_whole_float_range(entries):
    a, b, c = np.array(entries[:3]), np.array(entries[3:6]), np.array(entries[6:])
    assert int(orient3d_sign(a, b, c)[0]) == exact_sign(a, b, c)


@pytest.mark.parametrize(
    ("a", "b", "c"),
    [
        ((2.0**1000, 0, 1), (1, 2.0**-537, 0), (0, -7 * 2.0**-76, 1.5 * 2.0**-537)),
        ((1e200, 1e200, 0), (1e200, 1e200, 1e-300), (0, 1, 1e200)),
    ],
)
def test_orientation_with_underflowing_or_overflowing_products(a, b, c):
    assert int(orient3d_sign(a, b, c)[0]) == exact_sign(a, b, c) == -1


@pytest.mark.parametrize("sine", [1e-7, 3e-9, 2e-9])
def test_nearly_parallel_pole_and_up_still_give_a_rotation(sine):
    up = np.array([0.3, 0.4, 0.5])
    pole = up + sine * np.linalg.norm(up) * np.array([0.1, -0.7, 0.2])
    check_rotation(Frame.from_pole_up(pole, up).rotation)


@pytest.mark.parametrize("pole", [[1e-160, 0, 0], [1e-300, 1e-300, 0], [3e-320, 0, 1e-320]])
def test_tiny_pole_vectors(pole):
    frame = Frame.from_pole_up(pole, [0.0, 0.0, 1.0])
    check_rotation(frame.rotation)
    unit = np.array(pole) / np.abs(pole).max()
    assert np.allclose(frame.pole, unit / np.linalg.norm(unit))


@pytest.mark.parametrize("tiny", [1e-300, 1e-320])
def test_every_direction_follows_one_rule_however_small(tiny):
    """The cone's axis, the pole and up: the direction of any finite vector not all zero."""
    assert as_direction([tiny, 0.0, 0.0], "axis").tolist() == [1.0, 0.0, 0.0]
    assert np.allclose(as_direction([tiny, -tiny, 0.0], "up"), [0.5**0.5, -(0.5**0.5), 0.0])
    frame = Frame.from_pole_up([0.0, tiny, 0.0], [0.0, 0.0, tiny])
    assert np.array_equal(frame.rotation, np.eye(3))
    for field in ("region.cone.axis", "pole", "up"):
        with pytest.raises(TransformInputError, match="must be a non-zero direction") as caught:
            as_direction([0.0, -0.0, 0.0], field)
        assert caught.value.field == field


@pytest.mark.parametrize("seed", range(6))
def test_a_tilted_flat_grid_seen_from_its_own_plane_is_refused_despite_rounding(seed):
    """Rotated and moved, a flat grid is flat only to rounding, and its bounding-box centre in
    its plane only to rounding: still refused, naming the centre; a centre off the plane by a
    millionth of the grid's size is not."""
    rng = np.random.default_rng(seed)
    vertices, faces = grid_mesh(np.linspace(0, 1, 30), np.sort(rng.uniform(0, 1, 30)), 0.0)
    frame = Frame.from_pole_up(rng.normal(size=3), rng.normal(size=3))
    size = 10.0 ** rng.uniform(-4, 4)
    world = (vertices @ frame.rotation) * size + rng.normal(size=3) * size * 10
    center = (world.min(axis=0) + world.max(axis=0)) / 2
    with pytest.raises(TransformInputError, match="lies in the plane") as caught:
        check_center_sees_area(world, faces, center)
    assert caught.value.field == "center"
    check_center_sees_area(world, faces, center + frame.rotation[2] * size * 1e-6)


@pytest.mark.parametrize("rho_deg", [10.0, 33.4, 90.0, 150.0])
@pytest.mark.parametrize("theta0", [1e-12, 1e-8, 1e-5, np.pi - 1e-5, np.pi - 1e-8, np.pi - 1e-12])
def test_separable_theta_is_accurate_next_to_both_singular_points(rho_deg, theta0):
    rho = math.radians(rho_deg)
    phi = np.linspace(-3.1, 3.1, 41)
    points = separable_inverse(np.full(41, theta0), phi, 1.0, rho=rho)
    theta, phi2, r = separable_forward(points, rho)
    assert np.abs(theta - theta0).max() < 2e-14
    assert np.abs(separable_inverse(theta, phi2, r, rho=rho) - points).max() < 2e-14


def test_the_largest_pole_angle_still_inverts():
    cap = PoleCap.from_rho_deg(math.degrees(RHO_MAX))
    point = Chart.distorted(cap).inverse([1.0], [-1.0])
    assert np.isfinite(point).all()


def test_tiny_vectors_keep_their_direction_in_the_warp():
    warped = pole_warp([[3e-162, 1e-170, 0.0], [1e-200, 0.0, 0.0]], 0.3)
    reference = pole_warp([[3.0, 1e-8, 0.0], [1.0, 0.0, 0.0]], 0.3)
    assert np.allclose(warped, reference, atol=1e-15)


def test_a_tiny_mesh_is_a_mesh():
    vertices = np.array([[1.0, 0, 1], [0, 1.0, 1], [-1.0, -1.0, 1]]) * 1e-120
    flat = flatten_region(vertices, [[0, 1, 2]], Frame.identity(), Chart.standard())
    assert flat.validation.singular_point_faces.tolist() == [0]


def test_a_face_repeating_a_vertex_adds_no_boundary_loop():
    faces = np.array([[0, 1, 2], [2, 1, 3], [3, 3, 4]])
    orientation = np.array([1, 1, 0], dtype=np.int8)
    # Edge 3-3 is no edge, and the face uses 3-4 both ways: only the pair's loop remains.
    assert region_edges(faces, orientation, 5).boundary_loops() == 1


@pytest.mark.parametrize(
    ("call", "field"),
    [
        (lambda: PoleCap.from_sigma(10**400), "sigma"),
        (lambda: PoleCap.from_sigma("0.3"), "sigma"),
        (lambda: PoleCap.from_sigma(True), "sigma"),
        (lambda: PoleCap.from_rho_deg(10**400), "pole_angle_deg"),
        (lambda: cartesian_to_spherical([[1, 2, 10**400]]), "points"),
        (lambda: cartesian_to_spherical([["1", "2", "3"]]), "points"),
        (lambda: cartesian_to_spherical([[True, False, True]]), "points"),
        (lambda: cartesian_to_spherical([[1 + 1j, 0, 0]]), "points"),
        (lambda: cartesian_to_spherical([[1, 2, 3], [1, 2]]), "points"),
        (lambda: Frame.from_pole_up([10**400, 0, 0], [0, 0, 1]), "pole"),
        (lambda: Frame.from_matrix([[10**400, 0, 0], [0, 1, 0], [0, 0, 1]]), "rotation"),
        (lambda: Chart.from_method("foo"), "method"),
        (lambda: Chart.from_method("distorted"), "sigma"),
        (lambda: weighted_quantile([], [], 0.95), "values"),
        (lambda: separable_residual([0.0], [[0.0, 0.0, 0.0]], 0.5), "points"),
        (lambda: separable_residual([0.0, 1.0], [[1.0, 0.0, 0.0]], 0.5), "f"),
        (
            lambda: measure_faces(
                np.eye(3), [[0, 1, 2], [0, 1]], [1.0, 1.0, 1.0], [0.0, 0.0, 0.0], PoleCap.standard()
            ),
            "faces",
        ),
        (
            lambda: measure_faces(
                np.eye(3), [[0, 1, 2]], [1.0, np.nan, 1.0], [0.0, 0.0, 0.0], PoleCap.standard()
            ),
            "theta",
        ),
        (
            lambda: measure_faces(
                np.eye(3), [[0.0, 1.0, 2.0]], [1.0, 1.0, 1.0], [0.0, 0.0, 0.0], PoleCap.standard()
            ),
            "faces",
        ),
    ],
)
def test_bad_input_is_a_transform_input_error(call, field):
    with pytest.raises(TransformInputError) as caught:
        call()
    assert caught.value.field == field


@pytest.mark.parametrize("winding", [0, 5, 1.5, True])
def test_winding_must_be_plus_or_minus_one(winding):
    measures = measure_faces(
        np.array([[1.0, 0, 1], [0, 1.0, 1], [-1.0, -1.0, 1]]),
        [[0, 1, 2]],
        [0.5, 0.6, 0.7],
        [0.1, 0.9, -2.0],
        PoleCap.standard(),
    )
    with pytest.raises(TransformInputError) as caught:
        validate(measures, winding)
    assert caught.value.field == "winding"


def test_weighted_quantile_with_zero_sampled_weights():
    values = np.arange(200_000, dtype=float)
    weights = np.zeros(200_000)
    weights[7] = 1.0
    assert weighted_quantile(values, weights, 0.95) == 7.0
