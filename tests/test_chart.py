"""Charts: dispatch by method, world frame handling, and layout orientation."""

import numpy as np
import pytest

from transforms import (
    LAYOUT_ORIENTATION,
    Chart,
    Frame,
    Method,
    PoleCap,
    TransformInputError,
    angles_to_world,
    distorted_forward,
    separable_forward,
    world_to_angles,
)


@pytest.mark.parametrize("method", list(Method))
@pytest.mark.parametrize("sigma", [0.1, 0.3, 1.0, 2.5])
def test_layout_orientation_is_the_same_for_every_method(method, sigma):
    """Small triangles counter-clockwise seen from outside come out clockwise in (phi, theta):
    the sign of LAYOUT_ORIENTATION, everywhere outside the cap."""
    chart = Chart.from_method(method, PoleCap.from_sigma(sigma))
    rng = np.random.default_rng(11)
    centres = rng.normal(size=(3000, 3))
    centres /= np.linalg.norm(centres, axis=1, keepdims=True)
    centres = centres[np.arccos(centres[:, 1]) > chart.cap.rho + 0.05]
    # A tiny triangle in the tangent plane, counter-clockwise about the outward normal.
    t1 = np.cross(centres, rng.normal(size=3))
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(centres, t1)
    h = 1e-4
    corners = [centres, centres + h * t1, centres + h * t2]
    layout = [chart.forward(c)[:2] for c in corners]  # (theta, phi) per corner
    f1 = [layout[1][1] - layout[0][1], layout[1][0] - layout[0][0]]  # (phi, theta) edges
    f2 = [layout[2][1] - layout[0][1], layout[2][0] - layout[0][0]]
    signed = f1[0] * f2[1] - f1[1] * f2[0]
    assert (np.sign(signed) == LAYOUT_ORIENTATION).all()


def test_dispatch_matches_the_functions():
    rng = np.random.default_rng(12)
    p = rng.normal(size=(100, 3))
    cap = PoleCap.from_sigma(0.3)
    for got, want in zip(Chart.distorted(cap).forward(p), distorted_forward(p, 0.3), strict=True):
        assert np.allclose(got, want, atol=1e-15)
    for got, want in zip(
        Chart.separable(cap).forward(p), separable_forward(p, cap.rho), strict=True
    ):
        assert np.allclose(got, want, atol=1e-15)
    assert Chart.standard().cap.rho_deg == pytest.approx(90.0)
    assert Chart.from_method("standard", cap) == Chart.standard()


@pytest.mark.parametrize("method", list(Method))
@pytest.mark.parametrize("threads", [1, 2])
def test_world_round_trip_through_a_frame(method, threads):
    rng = np.random.default_rng(13)
    p = rng.normal(size=(70_000, 3)) * 50.0 + [10.0, -4.0, 3.0]
    frame = Frame.from_pole_up([0.2, -1.0, 0.1], [0.0, 0.0, 1.0], center=[10.0, -4.0, 3.0])
    chart = Chart.from_method(method, PoleCap.from_sigma(0.4))
    theta, phi, r = world_to_angles(p, frame, chart, threads=threads)
    local = frame.to_local(p)
    assert all(
        np.array_equal(a, b) for a, b in zip((theta, phi, r), chart.forward(local), strict=True)
    )
    back = angles_to_world(theta, phi, r, frame, chart)
    assert np.allclose(back, p, atol=1e-9)


def test_a_point_at_the_centre_is_named_by_its_row():
    p = np.ones((70_000, 3))
    p[40_000] = [1.0, 2.0, 3.0]
    frame = Frame.identity(center=[1.0, 2.0, 3.0])
    with pytest.raises(TransformInputError) as caught:
        world_to_angles(p, frame, Chart.standard())
    assert caught.value.indices == (40_000,)
    assert "at the centre" in str(caught.value)
