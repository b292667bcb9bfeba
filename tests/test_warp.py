"""The pole warp W_sigma (paper eq. 3, docs/math.md stable form) and distorted-pole coordinates."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from transforms import (
    TransformInputError,
    cartesian_to_spherical,
    distorted_forward,
    distorted_inverse,
    pole_warp,
)

from .conftest import directions, sigmas


def printed_warp(u: np.ndarray, sigma: float) -> np.ndarray:
    """Paper eq. 3 exactly as printed (singular at y = 1)."""
    x, y, z = u.T
    xs, zs = sigma * x / (1 - y), sigma * z / (1 - y)
    d = 2 / (1 + xs**2 + zs**2)
    return np.stack([xs * d, 1 - d, zs * d], axis=1)


@given(directions, sigmas)
def test_warp_keeps_unit_length(u, sigma):
    assert np.allclose(np.linalg.norm(pole_warp(u, sigma), axis=1), 1.0, atol=1e-14)


@given(directions, sigmas)
def test_theorem_1_inverse_is_one_over_sigma(u, sigma):
    back = pole_warp(pole_warp(u, sigma), 1.0 / sigma)
    assert np.allclose(back, u, atol=1e-14)


@given(directions)
def test_w1_is_the_identity(u):
    assert np.allclose(pole_warp(u, 1.0), u, atol=1e-15)


@given(sigmas)
def test_poles_are_fixed(sigma):
    poles = np.array([[0.0, 1.0, 0.0], [0.0, -1.0, 0.0]])
    assert np.array_equal(pole_warp(poles, sigma), poles)


@given(directions, st.floats(0.01, 100.0))
def test_stable_form_equals_printed_form_away_from_y_1(u, sigma):
    away = u[:, 1] < 1 - 1e-3
    if away.any():
        assert np.allclose(pole_warp(u[away], sigma), printed_warp(u[away], sigma), atol=1e-12)


@given(sigmas)
def test_stable_form_is_finite_at_y_1(sigma):
    near = np.array([[0.0, 1.0, 0.0], [1e-9, 1.0, 0.0], [0.0, np.cos(1e-8), np.sin(1e-8)]])
    with np.errstate(divide="ignore", invalid="ignore"):
        assert not np.isfinite(printed_warp(near[:1], sigma)).all()
    assert np.isfinite(pole_warp(near, sigma)).all()


def test_small_sigma_pulls_towards_minus_y():
    rng = np.random.default_rng(1)
    u = rng.normal(size=(1000, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    interior = np.abs(u[:, 1]) < 0.999
    assert (pole_warp(u, 0.3)[interior, 1] < u[interior, 1]).all()
    assert (pole_warp(u, 3.0)[interior, 1] > u[interior, 1]).all()


def test_warp_is_conformal():
    """Moebius maps keep angles: the warp's Jacobian on the tangent plane is a similarity."""
    rng = np.random.default_rng(2)
    u = rng.normal(size=(200, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    u = u[np.abs(u[:, 1]) < 0.99]
    t1 = np.cross(u, [0.0, 0.0, 1.0])
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(u, t1)
    h = 1e-6
    w0 = pole_warp(u, 0.3)
    d1 = (pole_warp(u + h * t1, 0.3) - w0) / h
    d2 = (pole_warp(u + h * t2, 0.3) - w0) / h
    lengths = np.linalg.norm(d1, axis=1), np.linalg.norm(d2, axis=1)
    assert np.allclose(lengths[0], lengths[1], rtol=1e-4)
    assert np.allclose(np.sum(d1 * d2, axis=1) / (lengths[0] * lengths[1]), 0.0, atol=1e-4)


@given(directions, st.floats(1e-3, 1e3), sigmas)
def test_distorted_forward_is_eq1_of_the_warp(u, scale, sigma):
    theta, phi, r = distorted_forward(u * scale, sigma)
    theta_w, phi_w, _ = cartesian_to_spherical(pole_warp(u, sigma))
    assert np.allclose(r, scale)
    assert np.allclose(theta, theta_w, atol=1e-9)
    # Compare azimuths as points on the circle (+-pi are the same), away from the poles of
    # eq. 1 where the azimuth is undefined.
    defined = np.sin(theta) > 1e-6
    assert np.allclose(np.angle(np.exp(1j * (phi - phi_w)))[defined], 0.0, atol=1e-9)


@given(directions, st.floats(1e-3, 1e3), st.floats(0.01, 100.0))
def test_distorted_round_trip(u, scale, sigma):
    theta, phi, r = distorted_forward(u * scale, sigma)
    back = distorted_inverse(theta, phi, r, sigma=sigma)
    assert np.allclose(back, u * scale, atol=1e-12 * scale * max(sigma, 1 / sigma))


def test_sigma_1_is_exactly_eq1():
    rng = np.random.default_rng(3)
    p = rng.normal(size=(1000, 3))
    assert all(
        np.array_equal(a, b)
        for a, b in zip(distorted_forward(p, 1.0), cartesian_to_spherical(p), strict=True)
    )


@pytest.mark.parametrize("sigma", [0.0, -0.3, np.nan, np.inf, 1e-7, 2e6, "wide"])
def test_bad_sigma(sigma):
    with pytest.raises(TransformInputError) as caught:
        distorted_forward([[1.0, 0.0, 0.0]], sigma)
    assert caught.value.field == "sigma"
    assert "1e-06" in str(caught.value) or "number" in str(caught.value)


def test_zero_direction_is_refused():
    with pytest.raises(TransformInputError) as caught:
        pole_warp([[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]], 0.3)
    assert caught.value.indices == (1,)
