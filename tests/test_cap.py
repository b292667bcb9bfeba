"""Where the singular points and the seam go (docs/math.md, section 4), for every method."""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from transforms import Chart, Method, PoleCap, TransformInputError, pole_warp

from .conftest import directions, sigmas


def chart_for(method: Method, cap: PoleCap) -> Chart:
    return Chart.from_method(method, cap)


@given(sigmas)
def test_rho_is_two_atan_sigma(sigma):
    cap = PoleCap.from_sigma(sigma)
    assert cap.rho == pytest.approx(2 * math.atan(sigma), rel=1e-15)
    again = PoleCap.from_rho(cap.rho)
    # rho is stored to 2^-52 pi; sigma = tan(rho / 2) amplifies that by ~1 + sigma near 180.
    assert again.sigma == pytest.approx(sigma, rel=1e-15 * (2 + sigma))
    assert PoleCap.from_rho_deg(cap.rho_deg).rho == pytest.approx(cap.rho, rel=1e-15)


def test_sigma_1_is_90_degrees_and_the_standard_cap():
    assert PoleCap.from_sigma(1.0).rho_deg == pytest.approx(90.0)
    assert PoleCap.from_rho_deg(90.0).sigma == 1.0
    assert PoleCap.standard() == PoleCap.from_sigma(1.0) or PoleCap.standard().sigma == 1.0
    assert np.array_equal(PoleCap.standard().north, [0.0, 0.0, 1.0])


@given(st.floats(0.01, 100.0))
def test_warp_sends_the_singular_points_to_plus_and_minus_z(sigma):
    cap = PoleCap.from_sigma(sigma)
    warped = pole_warp(np.stack([cap.north, cap.south]), sigma)
    assert np.allclose(warped, [[0, 0, 1], [0, 0, -1]], atol=1e-12)


@pytest.mark.parametrize("method", list(Method))
@pytest.mark.parametrize("sigma", [0.05, 0.3, 1.0, 3.0])
def test_singular_points_get_theta_0_and_pi(method, sigma):
    chart = chart_for(method, PoleCap.from_sigma(sigma))
    theta, _, _ = chart.forward(np.stack([chart.cap.north, chart.cap.south]))
    assert theta == pytest.approx([0.0, np.pi], abs=1e-7)


@pytest.mark.parametrize("method", list(Method))
@pytest.mark.parametrize("sigma", [0.05, 0.3, 1.0, 3.0])
def test_the_seam_arc_is_where_phi_jumps(method, sigma):
    chart = chart_for(method, PoleCap.from_sigma(sigma))
    arc = chart.cap.seam_arc(41)[1:-1]
    assert np.allclose(np.linalg.norm(arc, axis=1), 1.0)
    assert (arc[:, 0] < 0).all()
    # Step off the circle of angle rho towards the pole and away from it, at the same azimuth
    # about +Y: phi is near +pi on one side and near -pi on the other.
    axis = np.array([0.0, 1.0, 0.0])
    towards = np.cross(np.cross(arc, axis), arc)  # tangent pointing to +Y
    towards /= np.linalg.norm(towards, axis=1, keepdims=True)
    _, phi_in, _ = chart.forward(arc + 1e-7 * towards)
    _, phi_out, _ = chart.forward(arc - 1e-7 * towards)
    assert (np.abs(np.abs(phi_in) - np.pi) < 1e-4).all()
    assert (np.abs(np.abs(phi_out) - np.pi) < 1e-4).all()
    assert (np.sign(phi_in) != np.sign(phi_out)).all()


@pytest.mark.parametrize("method", list(Method))
@given(u=directions, sigma=st.floats(1e-3, 1e3))
def test_outside_the_cap_phi_is_negative_and_theta_interior(method, u, sigma):
    chart = chart_for(method, PoleCap.from_sigma(sigma))  # standard keeps its 90 degrees
    outside = np.arccos(np.clip(u[:, 1], -1, 1)) > chart.cap.rho + 1e-9
    if not outside.any():
        return
    theta, phi, _ = chart.forward(u[outside])
    assert ((phi > -np.pi) & (phi < 0)).all()
    assert ((theta > 0) & (theta < np.pi)).all()


def test_seam_arc_lies_on_the_cap_boundary():
    cap = PoleCap.from_sigma(0.3)
    arc = cap.seam_arc(11)
    assert np.allclose(np.arccos(arc[:, 1]), cap.rho)
    assert np.allclose(arc[0], cap.north) and np.allclose(arc[-1], cap.south)


@pytest.mark.parametrize("rho_deg", [0.0, 180.0, -5.0, 200.0, np.nan, np.inf, 1e-5])
def test_bad_pole_angle(rho_deg):
    with pytest.raises(TransformInputError) as caught:
        PoleCap.from_rho_deg(rho_deg)
    assert caught.value.field == "pole_angle_deg"
    assert "inside (0, 180)" in str(caught.value)


@pytest.mark.parametrize("rho", [0.0, math.pi, -1.0, np.nan])
def test_bad_rho(rho):
    with pytest.raises(TransformInputError) as caught:
        PoleCap.from_rho(rho)
    assert caught.value.field == "rho"
