"""Angular distances from great-circle arcs to a point and to the seam, against dense
sampling."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from transforms import PoleCap, arcs_to_point, arcs_to_seam

from .conftest import directions, slow


def sample_arc(a, b, n=4001):
    t = np.linspace(0.0, 1.0, n)[:, None]
    # atan2, not arccos: arccos of a dot product near 1 loses a short arc's length, and the
    # samples then leave the arc (ends 1e-9 apart were sampled 1e-9 off).
    omega = angle(a, b)
    if omega < 1e-12:
        return np.repeat(a[None], n, axis=0)
    return (np.sin((1 - t) * omega) * a + np.sin(t * omega) * b) / np.sin(omega)


def angle(u, v):
    return np.arctan2(np.linalg.norm(np.cross(u, v), axis=-1), np.sum(u * v, axis=-1))


@given(directions, directions, directions)
def test_arc_to_point_matches_sampling(a, b, p):
    k = min(len(a), len(b))
    a, b = a[:k], b[:k]
    keep = np.sum(a * b, axis=1) > -0.999  # antipodal ends have no unique minor arc
    a, b = a[keep], b[keep]
    if not len(a):
        return
    got = arcs_to_point(a, b, p[0])
    for i in range(len(a)):
        sampled = angle(sample_arc(a[i], b[i]), p[0]).min()
        spacing = angle(a[i], b[i]) / 4000
        assert got[i] <= sampled + 1e-12
        assert got[i] >= sampled - spacing - 1e-12


def seam_points(cap: PoleCap, n=4001):
    return cap.seam_arc(n)


@slow
@settings(max_examples=25, deadline=None)
@given(directions, directions, st.floats(0.05, 5.0))
def test_arc_to_seam_matches_sampling(a, b, sigma):
    cap = PoleCap.from_sigma(sigma)
    k = min(len(a), len(b), 6)
    a, b = a[:k], b[:k]
    keep = np.sum(a * b, axis=1) > -0.999
    a, b = a[keep], b[keep]
    if not len(a):
        return
    got = arcs_to_seam(a, b, cap)
    seam = seam_points(cap, 801)
    seam_spacing = np.pi * np.sin(cap.rho) / 800
    for i in range(len(a)):
        arc = sample_arc(a[i], b[i], 801)
        sampled = angle(arc[:, None, :], seam[None, :, :]).min()
        spacing = angle(a[i], b[i]) / 800 + seam_spacing
        assert got[i] <= sampled + 1e-9
        assert got[i] >= sampled - spacing - 1e-12


def test_arc_crossing_the_seam_is_at_distance_zero():
    cap = PoleCap.from_rho_deg(60.0)
    # From inside the cap to outside it, on the seam's side (x < 0), through its middle.
    a = np.array([[-np.sin(0.5), np.cos(0.5), 0.0]])
    b = np.array([[-np.sin(1.6), np.cos(1.6), 0.0]])
    assert arcs_to_seam(a, b, cap)[0] == 0.0
    # The same arc on the other side (x > 0) only comes near the singular points.
    a[0, 0], b[0, 0] = -a[0, 0], -b[0, 0]
    assert arcs_to_seam(a, b, cap)[0] > np.radians(50.0)


def test_a_point_arc_measures_from_its_point_without_warnings():
    a = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    got = arcs_to_point(a, a.copy(), np.array([0.0, 1.0, 0.0]))  # RuntimeWarnings fail tests
    np.testing.assert_allclose(got, [np.pi / 2, np.pi / 2])
