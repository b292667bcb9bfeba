"""Frames: q = R (p - c) and back; rotations from (pole, up); refusing non-rotations."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from transforms import Frame, TransformInputError

from .conftest import directions

points = hnp.arrays(
    np.float64, st.tuples(st.integers(1, 30), st.just(3)), elements=st.floats(-1e3, 1e3)
)
vectors = hnp.arrays(np.float64, (3,), elements=st.floats(-10.0, 10.0))


@given(directions, directions, points, vectors)
def test_world_local_round_trip(poles, ups, world, center):
    pole, up = poles[0], ups[0]
    if np.linalg.norm(np.cross(pole, up)) < 1e-3:
        up = np.roll(pole, 1) + np.array([0.5, -0.25, 0.125])
    frame = Frame.from_pole_up(pole, up, center)
    back = frame.to_world(frame.to_local(world))
    assert np.allclose(back, world, rtol=0, atol=1e-12 * (1 + np.abs(world).max()))


@given(directions, directions)
def test_pole_goes_to_plus_y_and_up_to_the_plus_z_side(poles, ups):
    pole, up = poles[0], ups[0]
    if np.linalg.norm(np.cross(pole, up)) < 1e-3:
        return
    frame = Frame.from_pole_up(pole * 7.0, up * 0.5)
    r = frame.rotation
    assert np.allclose(r @ r.T, np.eye(3), atol=1e-12)
    assert np.isclose(np.linalg.det(r), 1.0, atol=1e-12)
    assert np.allclose(frame.to_local([pole]), [[0.0, 1.0, 0.0]], atol=1e-12)
    local_up = frame.to_local([up])[0]
    assert abs(local_up[0]) < 1e-12 and local_up[2] > 0
    assert np.allclose(frame.pole, pole, atol=1e-12)


def test_translation_only():
    frame = Frame.identity(center=[1.0, 2.0, 3.0])
    assert np.array_equal(frame.to_local([[1.0, 2.0, 4.0]]), [[0.0, 0.0, 1.0]])


@pytest.mark.parametrize(
    ("pole", "up", "field"),
    [
        ([0, 0, 0], [0, 1, 0], "pole"),
        ([0, 1, 0], [0, 0, 0], "up"),
        ([0, 1, 0], [0, -3, 0], "up"),
        ([1, 1, 0], [2, 2, 0], "up"),
        ([np.nan, 1, 0], [0, 0, 1], "pole"),
    ],
)
def test_pole_up_refuses_zero_or_parallel(pole, up, field):
    with pytest.raises(TransformInputError) as caught:
        Frame.from_pole_up(pole, up)
    assert caught.value.field == field


def test_from_matrix_accepts_rotations():
    angle = 0.3
    r = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]])
    frame = Frame.from_matrix(r, center=[1, 0, 0])
    assert np.allclose(frame.to_local([[1, 0, 0]]), 0.0)
    assert np.allclose(frame.to_local([[2, 0, 0]]), [[np.cos(angle), np.sin(angle), 0]])


@pytest.mark.parametrize(
    ("matrix", "says"),
    [
        (np.diag([1.0, 1.0, -1.0]), "reflection"),
        (np.eye(3) * 1.001, "magnitude 1.001"),
        (np.diag([1.0, 1.0, 1e154]), "magnitude 1e+154"),  # R R^T would overflow
        (np.diag([1.0, 1.0, 0.5]), "not orthonormal"),
        (np.eye(3) + 1e-8, "magnitude 1.00000001"),
        (np.full((3, 3), 0.5), "not orthonormal"),
        (np.eye(2), "3x3"),
        ([[1, 0, 0], [0, 1, 0], [0, 0, np.inf]], "NaN or Inf"),
        ("identity", "3x3"),
    ],
)
def test_from_matrix_refuses_non_rotations(matrix, says):
    with pytest.raises(TransformInputError) as caught:
        Frame.from_matrix(matrix)
    assert caught.value.field == "rotation"
    assert says in str(caught.value)


def test_tolerance_is_1e9():
    """Off by e in one entry, R R^T differs from I by e (and e^2, lost to rounding) with the
    determinant still 1: accepted up to 1e-9, refused beyond it."""
    for off in (4e-10, 9e-10):  # within 1e-9: accepted as given
        nearly = np.eye(3)
        nearly[0, 1] = off
        frame = Frame.from_matrix(nearly)
        np.testing.assert_array_equal(frame.rotation, nearly)
        assert np.abs(frame.rotation @ frame.rotation.T - np.eye(3)).max() <= 1e-9
    for off in (1.1e-9, 4e-9):  # beyond 1e-9: refused
        beyond = np.eye(3)
        beyond[0, 1] = off
        with pytest.raises(TransformInputError, match="not orthonormal") as caught:
            Frame.from_matrix(beyond)
        assert caught.value.field == "rotation"


def test_frames_are_immutable():
    frame = Frame.identity()
    with pytest.raises(ValueError):
        frame.rotation[0, 0] = 2.0
