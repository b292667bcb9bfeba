"""Eq. 1 and its true inverse (docs/math.md, section 2, slip 1)."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from transforms import TransformInputError, cartesian_to_spherical, spherical_to_cartesian

from .conftest import directions

radii = st.floats(1e-6, 1e6)


@given(directions, radii)
def test_eq1_round_trip(u, scale):
    points = u * scale
    theta, phi, r = cartesian_to_spherical(points)
    assert ((theta >= 0) & (theta <= np.pi)).all()
    assert ((phi > -np.pi) & (phi <= np.pi)).all()
    back = spherical_to_cartesian(theta, phi, r)
    assert np.allclose(back, points, rtol=0, atol=1e-14 * scale)


@given(
    hnp.arrays(np.float64, 20, elements=st.floats(0.0, np.pi)),
    hnp.arrays(np.float64, 20, elements=st.floats(-np.pi, np.pi)),
)
def test_inverse_then_forward(theta, phi):
    theta2, phi2, r = cartesian_to_spherical(spherical_to_cartesian(theta, phi))
    assert np.allclose(r, 1.0)
    assert np.allclose(theta2, theta, atol=1e-12)
    # phi is undefined at the poles and +-pi are the same azimuth
    away = np.sin(theta) > 1e-9
    wrapped = np.angle(np.exp(1j * (phi2 - phi)))
    assert np.allclose(wrapped[away], 0.0, atol=1e-9)


def test_the_printed_eq2_is_not_the_inverse():
    theta, phi, r = cartesian_to_spherical([[1.0, 2.0, 3.0]])
    printed = np.array(
        [r * np.cos(theta) * np.sin(phi), r * np.sin(theta) * np.sin(phi), r * np.cos(phi)]
    ).ravel()
    assert not np.allclose(printed, [1.0, 2.0, 3.0], atol=0.1)
    assert np.allclose(spherical_to_cartesian(theta, phi, r), [[1.0, 2.0, 3.0]])


def test_axes():
    theta, phi, _ = cartesian_to_spherical(np.eye(3))
    assert np.allclose(theta, [np.pi / 2, np.pi / 2, 0.0])
    assert np.allclose(phi[:2], [0.0, np.pi / 2])


@pytest.mark.parametrize(
    ("points", "field", "says", "rows"),
    [
        ([[1, 0, 0], [0, 0, 0]], "points", "at the centre", (1,)),
        ([[1, 0, np.nan]], "points", "NaN or Inf", (0,)),
        ([[1, 0, 0], [1, 0, 0], [np.inf, 0, 0]], "points", "NaN or Inf", (2,)),
        ([[1e101, 0, 0]], "points", "beyond", (0,)),
        ([[1, 0]], "points", "shape", ()),
    ],
)
def test_bad_points(points, field, says, rows):
    with pytest.raises(TransformInputError) as caught:
        cartesian_to_spherical(points)
    assert caught.value.field == field
    assert says in str(caught.value)
    assert caught.value.indices == rows


@pytest.mark.parametrize(
    ("theta", "phi", "r", "field"),
    [
        ([4.0], [0.0], 1.0, "theta"),
        ([-0.1], [0.0], 1.0, "theta"),
        ([1.0], [3.2], 1.0, "phi"),
        ([1.0], [np.nan], 1.0, "phi"),
        ([1.0], [0.0], -1.0, "r"),
        ([1.0, 2.0], [0.0], [1.0, 2.0, 3.0], "theta"),
    ],
)
def test_bad_angles(theta, phi, r, field):
    with pytest.raises(TransformInputError) as caught:
        spherical_to_cartesian(theta, phi, r)
    assert caught.value.field == field
