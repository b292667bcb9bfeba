"""Exact orientation signs."""

import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from transforms import orient3d_sign

from .conftest import exact_sign


def test_nearly_coplanar_triples_match_exact_rationals():
    rng = np.random.default_rng(14)
    a = rng.normal(size=(3000, 3))
    b = rng.normal(size=(3000, 3))
    t = rng.random((3000, 1))
    c = a * t + b * (1 - t)  # coplanar with the origin up to rounding
    c[::3] += rng.normal(size=(1000, 3)) * 1e-17
    c[1::3] = a[1::3] * 0.5  # exactly coplanar: c is a multiple of a
    signs = orient3d_sign(a, b, c)
    want = [exact_sign(a[i], b[i], c[i]) for i in range(len(a))]
    assert np.array_equal(signs, want)
    assert (signs[1::3] == 0).all()


@given(
    hnp.arrays(np.float64, (5, 3), elements=st.floats(-1e30, 1e30)),
    hnp.arrays(np.float64, (5, 3), elements=st.floats(-1e30, 1e30)),
    hnp.arrays(np.float64, (5, 3), elements=st.floats(-1e30, 1e30)),
)
def test_any_finite_input_matches_exact_rationals(a, b, c):
    signs = orient3d_sign(a, b, c)
    assert [int(s) for s in signs] == [exact_sign(*rows) for rows in zip(a, b, c, strict=True)]


def test_tiny_and_subnormal_entries():
    a = np.array([[5e-324, 0.0, 0.0], [1e-300, 1e-300, 0.0]])
    b = np.array([[0.0, 5e-324, 0.0], [1e-300, -1e-300, 0.0]])
    c = np.array([[0.0, 0.0, 5e-324], [0.0, 0.0, 1e-300]])
    assert list(orient3d_sign(a, b, c)) == [1, -1]


def test_antisymmetric():
    rng = np.random.default_rng(15)
    a, b, c = rng.normal(size=(3, 100, 3))
    assert np.array_equal(orient3d_sign(a, b, c), -orient3d_sign(b, a, c))
    assert np.array_equal(orient3d_sign(a, b, c), orient3d_sign(b, c, a))
