"""Distortion metrics (docs/math.md, section 7)."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from transforms import (
    Chart,
    Frame,
    PoleCap,
    distortion,
    face_distortion,
    flatten_region,
    measure_faces,
    weighted_quantile,
)

from .conftest import grid_mesh, load_sample


def stretched_layout(a: float, b: float, z: float = 1.0):
    """A planar grid whose layout is (phi, theta) = (a x, b y) + const: singular values a and
    b (the grid is small enough for theta to stay in [0, pi] and phi in [-pi, pi])."""
    vertices, faces = grid_mesh(np.linspace(-0.2, 0.2, 7), np.linspace(-0.2, 0.2, 5), z)
    return vertices, faces, b * vertices[:, 1] + 1.5, a * vertices[:, 0]


@pytest.mark.parametrize(("a", "b"), [(1.0, 1.0), (2.0, 1.0), (0.5, 3.0), (0.01, 0.01)])
def test_affine_layout_has_the_distortion_of_its_singular_values(a, b):
    vertices, faces, theta, phi = stretched_layout(a, b)
    d = distortion(measure_faces(vertices, faces, theta, phi, PoleCap.standard()))
    # After scaling to equal area the singular values are sqrt(a/b) and sqrt(b/a).
    ratio = max(a, b) / min(a, b)
    for summary, value in (
        (d.conformal, ratio),
        (d.area, 0.0),
        (d.isometric, (ratio + 1.0 / ratio) / 2.0),
    ):
        assert summary.mean == pytest.approx(value, abs=1e-12)
        assert summary.p50 == pytest.approx(value, abs=1e-12)
        assert summary.p95 == pytest.approx(value, abs=1e-12)
        assert summary.max == pytest.approx(value, abs=1e-12)
    assert d.layout_scale == pytest.approx(1.0 / np.sqrt(a * b))
    assert d.measured_faces == len(faces)


def test_area_distortion_sees_uneven_scaling():
    vertices, faces, theta, phi = stretched_layout(1.0, 1.0)
    phi = phi * np.where(vertices[:, 0] > 0, 2.0, 1.0)  # right half stretched twice
    per_face = face_distortion(measure_faces(vertices, faces, theta, phi, PoleCap.standard()))
    assert per_face.area.max() > 0.3
    assert per_face.conformal.max() == pytest.approx(2.0, rel=1e-9)


def test_rigid_motion_and_scale_of_the_mesh_change_nothing():
    vertices, faces, theta, phi = stretched_layout(1.5, 0.7)
    cap = PoleCap.standard()
    reference = distortion(measure_faces(vertices, faces, theta, phi, cap))
    rotation = Frame.from_pole_up([0.3, 0.2, 1.0], [1.0, 0.0, 0.0]).rotation
    moved = 37.0 * vertices @ rotation.T + [5.0, -2.0, 1.0]
    again = distortion(measure_faces(moved, faces, theta, phi, cap))
    for name in ("conformal", "area", "isometric"):
        for stat in ("mean", "p50", "p95", "max"):
            assert getattr(getattr(again, name), stat) == pytest.approx(
                getattr(getattr(reference, name), stat), abs=1e-12
            )


def reference_quantile(values, weights, q):
    order = np.argsort(values, kind="stable")
    cumulative = np.cumsum(weights[order])
    i = min(int(np.searchsorted(cumulative, q * weights.sum())), len(values) - 1)
    return values[order][i]


@given(
    hnp.arrays(np.float64, st.integers(1, 300), elements=st.floats(0, 1e6)),
    st.integers(0, 2**32 - 1),
    st.floats(0.0, 1.0),
)
def test_weighted_quantile_matches_sorting(values, seed, q):
    weights = np.random.default_rng(seed).integers(1, 50, len(values)).astype(float)
    assert weighted_quantile(values, weights, q) == reference_quantile(values, weights, q)


@pytest.mark.parametrize("kind", ["lognormal", "ties", "sorted", "two-spikes"])
def test_weighted_quantile_on_large_inputs(kind):
    rng = np.random.default_rng(16)
    n = 300_000
    values = {
        "lognormal": rng.lognormal(size=n),
        "ties": rng.integers(0, 4, n).astype(float),
        "sorted": np.sort(rng.random(n)),
        "two-spikes": np.where(rng.random(n) < 0.96, 1.0, 1e9),
    }[kind]
    weights = rng.integers(1, 1000, n).astype(float)
    for q in (0.05, 0.5, 0.95, 1.0):
        assert weighted_quantile(values, weights, q) == reference_quantile(values, weights, q)


def scalp_cap():
    """The brief's example (shared/spec/MATH.md): fsaverage, centre at the bounding-box
    centre, pole opposite a scalp cap of 1,558 faces (centroids within ~70.86 degrees of up,
    +Z in RAS)."""
    vertices, faces = load_sample("fsaverage-head.ply")
    centre = (vertices.min(axis=0) + vertices.max(axis=0)) / 2
    directions = vertices[faces].mean(axis=1) - centre
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    region = faces[np.degrees(np.arccos(directions[:, 2])) <= 70.86]
    assert len(region) == 1558
    return vertices, region, Frame.from_pole_up([0, 0, -1], [0, 1, 0], center=centre)


def test_isometric_energy_has_an_interior_minimum_over_sigma():
    vertices, region, frame = scalp_cap()
    d = {
        sigma: flatten_region(
            vertices, region, frame, Chart.distorted(PoleCap.from_sigma(sigma))
        ).distortion
        for sigma in (0.05, 0.5, 1.0)
    }
    assert d[0.05].isometric.mean == pytest.approx(1.080, abs=1e-3)  # the brief's figure
    assert d[0.5].isometric.mean < d[0.05].isometric.mean
    assert d[0.5].isometric.mean < d[1.0].isometric.mean
    # Conformal distortion keeps falling as sigma shrinks while area distortion rises.
    assert d[0.05].conformal.mean < d[0.5].conformal.mean < d[1.0].conformal.mean
    assert d[0.05].area.mean > d[0.5].area.mean > d[1.0].area.mean


def nefertiti_measures(extra_faces=()):
    """Face measurements of the Nefertiti scan (with ``extra_faces`` appended)."""
    vertices, faces = load_sample("nefertiti-lowres.obj")
    if len(extra_faces):
        faces = np.vstack([faces, extra_faces])
    centre = (vertices.min(axis=0) + vertices.max(axis=0)) / 2
    frame = Frame.from_pole_up([0.0, -1.0, 0.0], [0.0, 0.0, 1.0], center=centre)
    chart = Chart.distorted(PoleCap.from_sigma(0.4))
    local = frame.to_local(vertices)
    theta, phi, _ = chart.forward(local)
    return measure_faces(local, faces, theta, phi, chart.cap)


@pytest.mark.parametrize("degenerate", [False, True])
def test_summaries_agree_with_the_per_face_measures(degenerate):
    measures = nefertiti_measures([[0, 0, 1], [5, 6, 5]] if degenerate else [])
    faces = measures.faces
    summary = distortion(measures)
    per_face = face_distortion(measures)
    assert summary.measured_faces == len(per_face.faces) == len(faces) - 2 * degenerate
    for name in ("conformal", "area", "isometric"):
        values = getattr(per_face, name)
        got = getattr(summary, name)
        assert got.mean == pytest.approx(np.average(values, weights=per_face.weights), rel=1e-12)
        assert got.max == values.max()
        assert got.p95 == weighted_quantile(values, per_face.weights, 0.95)
        assert got.p50 == reference_quantile(values, per_face.weights, 0.5)


def test_a_misleading_sample_falls_back_to_the_exact_quantile():
    measures = nefertiti_measures()
    per_face = face_distortion(measures)
    got = distortion(measures, bracket=lambda sample, weights, q: (-2.0, -1.0))
    assert got.isometric.p95 == weighted_quantile(per_face.isometric, per_face.weights, 0.95)
    assert got.isometric.p50 == reference_quantile(per_face.isometric, per_face.weights, 0.5)


@pytest.mark.parametrize("seed", range(20))
def test_the_weighted_quickselect_finds_the_sorted_cumulative_quantile(seed):
    """Against the definition by a sort: the smallest value whose cumulative weight, in
    ascending order, reaches the target; ties, zero weights, and targets at and beyond the
    ends."""
    from transforms.metrics import _sorted_quantile

    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 300))
    values = rng.integers(0, 6, n).astype(float) if seed % 2 else rng.random(n)
    weights = rng.random(n)
    weights[rng.random(n) < 0.2] = 0.0
    order = np.argsort(values, kind="stable")
    cumulative = np.cumsum(weights[order])
    for share in (-0.5, 0.0, 0.05, 0.5, 0.95, 1.5):
        target = share * cumulative[-1]
        at = min(int(np.searchsorted(cumulative, target)), n - 1)
        assert _sorted_quantile(values, weights, target) == values[order[at]]
