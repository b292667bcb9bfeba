"""The separable method (docs/math.md, section 5)."""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from transforms import (
    Chart,
    PoleCap,
    TransformInputError,
    cartesian_to_spherical,
    distorted_forward,
    separable_forward,
    separable_inverse,
    separable_residual,
)
from transforms.separable import MAX_ITERATIONS

from .conftest import directions

rhos = st.floats(math.radians(0.5), math.radians(179.5))


@given(directions, rhos)
def test_root_residual_below_1e_12(u, rho):
    theta, _, _ = separable_forward(u, rho)
    f = np.pi / 2 - theta
    assert ((f >= -np.pi / 2) & (f <= np.pi / 2)).all()
    assert np.abs(separable_residual(f, u, rho)).max() < 1e-12


@given(directions, rhos)
def test_root_is_the_only_sign_change(u, rho):
    """F(-pi/2) >= 0 >= F(pi/2) and F changes sign once on a fine grid, at our root."""
    theta, _, _ = separable_forward(u, rho)
    grid = np.linspace(-np.pi / 2, np.pi / 2, 2001)
    for row, root in zip(u, np.pi / 2 - theta, strict=True):
        values = separable_residual(grid, np.repeat(row[None], grid.size, axis=0), rho)
        assert values[0] >= -1e-15 and values[-1] <= 1e-15
        strict = np.sign(values[np.abs(values) > 1e-12])
        changes = np.flatnonzero(np.diff(strict) != 0)
        assert len(changes) <= 1
        if len(changes) == 1:
            kept = grid[np.abs(values) > 1e-12]
            assert kept[changes[0]] <= root + 1e-12 and root - 1e-12 <= kept[changes[0] + 1]


def test_many_directions_converge_and_round_trip():
    rng = np.random.default_rng(7)
    u = rng.normal(size=(200_000, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    for rho_deg in (1.0, 20.0, 33.4, 90.0, 150.0, 179.0):
        rho = math.radians(rho_deg)
        theta, phi, r = separable_forward(u * 3.0, rho)
        assert np.isfinite(theta).all() and np.isfinite(phi).all()
        assert np.abs(separable_residual(np.pi / 2 - theta, u, rho)).max() < 1e-12
        back = separable_inverse(theta, phi, r, rho=rho)
        assert np.abs(back - u * 3.0).max() < 1e-11


@given(directions, rhos, st.floats(1e-3, 1e3))
def test_inverse_round_trip(u, rho, scale):
    theta, phi, r = separable_forward(u * scale, rho)
    back = separable_inverse(theta, phi, r, rho=rho)
    assert np.allclose(back, u * scale, atol=1e-11 * scale)


def test_azimuth_formula():
    rho = math.radians(40.0)
    u = np.array([[0.3, -0.5, 0.2]])
    u /= np.linalg.norm(u)
    _, phi, _ = separable_forward(u, rho)
    assert phi[0] == pytest.approx(math.atan2(u[0, 1] - math.cos(rho), u[0, 0]), abs=1e-15)


def test_at_90_degrees_it_is_eq1():
    rng = np.random.default_rng(8)
    p = rng.normal(size=(10_000, 3))
    theta, phi, r = separable_forward(p, math.pi / 2)
    theta1, phi1, r1 = cartesian_to_spherical(p)
    assert np.allclose(theta, theta1, atol=1e-12)
    assert np.allclose(phi, phi1, atol=1e-15) and np.allclose(r, r1)


def test_a_different_system_from_the_warp():
    """docs/math.md, section 5: at rho = 33.4 degrees the two differ by about 11 degrees
    (median) per angle."""
    rng = np.random.default_rng(9)
    u = rng.normal(size=(100_000, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    cap = PoleCap.from_rho_deg(33.4)
    ts, ps, _ = separable_forward(u, cap.rho)
    tw, pw, _ = distorted_forward(u, cap.sigma)
    d_theta = np.degrees(np.median(np.abs(ts - tw)))
    d_phi = np.degrees(np.median(np.abs(np.angle(np.exp(1j * (ps - pw))))))
    assert 8.0 < d_theta < 14.0 and 8.0 < d_phi < 14.0


def test_theta_is_the_polar_angle_not_the_azimuth():
    """Slip 2: the paper's section calls the azimuth theta; meshflat keeps eq. 1's names."""
    chart = Chart.separable(PoleCap.from_rho_deg(90.0))
    theta, phi, _ = chart.forward([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    assert theta[0] == pytest.approx(0.0, abs=1e-12)  # +Z: polar angle 0
    assert phi[1] == pytest.approx(0.0) and theta[1] == pytest.approx(np.pi / 2)


def test_solver_has_headroom():
    assert MAX_ITERATIONS >= 110  # two steps per halving of [0, pi] down to 1e-15


def test_bad_rho():
    with pytest.raises(TransformInputError) as caught:
        separable_forward([[1.0, 0.0, 0.0]], 0.0)
    assert caught.value.field == "rho"


@pytest.mark.parametrize("guess", [0.0, np.pi, "random"])
def test_converges_from_any_start(guess):
    """The bracket and bisection fallback converge even from a useless starting guess."""
    rng = np.random.default_rng(10)

    def bad_guess(gamma, s, k):
        if guess == "random":
            return rng.uniform(0, np.pi, gamma.shape)
        return np.full_like(gamma, guess)

    u = rng.normal(size=(5000, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    rho = math.radians(25.0)
    theta, _, _ = separable_forward(u, rho, starting_guess=bad_guess)
    assert np.abs(separable_residual(np.pi / 2 - theta, u, rho)).max() < 1e-12
