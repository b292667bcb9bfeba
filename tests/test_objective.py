"""The fit's objective for many candidates at once (transforms.fit.objective; docs/math.md,
sections 7 and 9): it agrees with what a flatten measures, one candidate or many, and its
slope agrees with finite differences."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from transforms import Chart, Frame, Layout, Method, PoleCap, flatten_region
from transforms.fit import fused
from transforms.fit.objective import (
    Candidates,
    FaceEnergy,
    Motion,
    _energy_gradient,
    _Warped,
    region_energy,
)

from .conftest import scalp


@pytest.fixture(scope="module")
def region():
    vertices, faces = scalp()
    used, compact = np.unique(faces, return_inverse=True)
    return vertices[used], compact.reshape(-1, 3)


def _candidates(vertices: np.ndarray, count: int, seed: int = 0) -> Candidates:
    """Candidates around the middle of the head looking down at the scalp."""
    rng = np.random.default_rng(seed)
    middle = (vertices.min(axis=0) + vertices.max(axis=0)) / 2
    turn = Rotation.from_rotvec(rng.normal(size=(count, 3)) * 0.15).as_matrix()
    base = Frame.from_pole_up([0, -1, 0], [0, 0, 1]).rotation
    centers = middle + rng.normal(size=(count, 3)) * 5.0
    return Candidates.of(centers, base @ turn, np.exp(rng.normal(size=count) * 0.5) * 0.5)


@pytest.mark.parametrize("layout", list(Layout))
@pytest.mark.parametrize("method", [Method.DISTORTED, Method.SEPARABLE, Method.STANDARD])
def test_the_energy_of_every_face_is_what_a_flatten_reports(region, layout, method):
    vertices, faces = region
    batch = _candidates(vertices, 3)
    found = region_energy(vertices, faces, batch, method, layout, block=500)
    for i in range(3):
        frame = Frame.from_matrix(batch.rotations[i], batch.centers[i])
        cap = PoleCap.from_sigma(float(batch.sigmas[i]))
        chart = Chart.standard() if method is Method.STANDARD else Chart.from_method(method, cap)
        flat = flatten_region(vertices, faces, frame, chart, layout=layout)
        assert found[i] == pytest.approx(flat.distortion.isometric.mean, rel=1e-12)


def test_a_batch_scores_as_its_candidates_one_by_one(region):
    vertices, faces = region
    energy = FaceEnergy(vertices, faces, Method.DISTORTED, Layout.THETA_PHI)
    batch = _candidates(vertices, 40)
    together = energy.scores(batch)
    for i in (0, 17, 39):
        alone = energy.scores(batch[i : i + 1])
        assert alone.objective[0] == pytest.approx(together.objective[i], rel=1e-13)
        assert alone.cap_cosine[0] == together.cap_cosine[i]


def test_a_vertex_at_the_centre_scores_inf_and_does_not_spoil_the_batch(region):
    vertices, faces = region
    energy = FaceEnergy(vertices, faces, Method.DISTORTED, Layout.THETA_PHI)
    batch = _candidates(vertices, 2)
    on_vertex = Candidates(
        np.vstack([vertices[5], batch.centers[1]]), batch.rotations, batch.sigmas
    )
    scores = energy.scores(on_vertex)
    assert scores.objective[0] == np.inf and np.isfinite(scores.objective[1])


@pytest.mark.parametrize("layout", list(Layout))
@pytest.mark.parametrize("method", [Method.DISTORTED, Method.STANDARD])
def test_the_slope_is_the_derivative_of_the_energy(region, layout, method):
    """Moving the centre, turning the frame and changing sigma: the closed-form gradient
    against central differences of the scores themselves."""
    vertices, faces = region
    energy = FaceEnergy(vertices, faces, method, layout)
    start = _candidates(vertices, 1, seed=3)
    rng = np.random.default_rng(7)
    turns = [Rotation.from_rotvec(axis).as_matrix() for axis in rng.normal(size=(2, 3))]
    motion = Motion(
        rotation=np.array(
            [np.zeros((3, 3)), np.zeros((3, 3))]
            + [(t - np.eye(3)) @ start.rotations[0] for t in turns]  # any matrices will do
            + [np.zeros((3, 3))]
        ),
        center=np.vstack([rng.normal(size=(2, 3)), np.zeros((3, 3))]),
        log_sigma=np.array([0.0, 0.0, 0.0, 0.0, 1.0 if method is Method.DISTORTED else 0.0]),
    )
    slope = energy.slope(start, motion)
    step = 1e-6
    moved = []
    for sign in (1.0, -1.0):
        t = sign * step
        moved.append(
            Candidates(
                start.centers + t * motion.center,
                start.rotations + t * motion.rotation,
                start.sigmas * np.exp(t * motion.log_sigma),
            )
        )
    ahead, behind = energy.scores(moved[0]), energy.scores(moved[1])
    expected = (ahead.energy - behind.energy) / (2 * step)
    np.testing.assert_allclose(slope.energy, expected, rtol=1e-5, atol=1e-8)
    cap = (ahead.cap_cosine - behind.cap_cosine) / (2 * step)
    np.testing.assert_allclose(slope.cap_cosine, cap, rtol=1e-5, atol=1e-8)
    assert slope.scores.objective[0] == pytest.approx(energy.scores(start).objective[0])


@pytest.mark.parametrize("split", [True, False])
@pytest.mark.parametrize("layout", list(Layout))
@pytest.mark.parametrize("method", [Method.DISTORTED, Method.STANDARD])
def test_the_compiled_scores_are_numpys_to_rounding(region, layout, method, split):
    vertices, faces = region
    energy = FaceEnergy(vertices, faces, method, layout)
    batch = _candidates(vertices, 12, seed=3)
    fused = energy.scores(batch, split)
    plain = energy._chunk(batch, split)
    for name, expected in zip(("objective", "energy", "hidden", "cap_cosine"), plain, strict=True):
        np.testing.assert_allclose(getattr(fused, name), expected, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("layout", list(Layout))
def test_the_compiled_gradient_is_numpys_to_rounding(region, layout):
    vertices, faces = region
    energy = FaceEnergy(vertices, faces, Method.DISTORTED, layout)
    one = _candidates(vertices, 1, seed=4)
    center = one.centers[0] * energy.scale
    warped = _Warped.of(energy.points - center, one.rotations[0], float(one.sigmas[0]), layout)
    sums = energy.shapes.sums(warped.plane[None], center[None])
    expected = _energy_gradient(energy.shapes, warped.plane, center, sums)
    shapes = energy.shapes
    by_phi, by_second = fused.energy_gradient(
        *shapes.arrays,
        center,
        warped.plane.real.copy(),
        warped.plane.imag.copy(),
        len(warped.plane),
        *(float(v[0]) for v in sums[:5]),
    )
    scale = np.abs(expected).max()
    np.testing.assert_allclose(by_phi, expected.real, rtol=1e-9, atol=1e-12 * scale)
    np.testing.assert_allclose(by_second, expected.imag, rtol=1e-9, atol=1e-12 * scale)


@pytest.mark.parametrize("layout", list(Layout))
@pytest.mark.parametrize("method", [Method.DISTORTED, Method.STANDARD])
def test_the_compiled_slope_is_numpys_to_rounding(region, layout, method):
    """The slope's compiled contraction against numpy's: the vertices' moves
    (``_Warped.moves``) times the energy's gradient per vertex (``_energy_gradient``)."""
    vertices, faces = region
    energy = FaceEnergy(vertices, faces, method, layout)
    one = _candidates(vertices, 1, seed=6)
    rng = np.random.default_rng(8)
    motion = Motion(rng.normal(size=(6, 3, 3)), rng.normal(size=(6, 3)), rng.normal(size=6))
    slope = energy.slope(one, motion)
    center = one.centers[0] * energy.scale
    sigma = 1.0 if method is Method.STANDARD else float(one.sigmas[0])
    warped = _Warped.of(energy.points - center, one.rotations[0], sigma, layout)
    sums = energy.shapes.sums(warped.plane[None], center[None])
    toward = _energy_gradient(energy.shapes, warped.plane, center, sums)
    moves = warped.moves(motion, energy.scale, 0.0 if method is Method.STANDARD else 1.0)
    expected = moves.phi @ toward.real + moves.second @ toward.imag
    np.testing.assert_allclose(slope.energy, expected, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(slope.cap_cosine, moves.cap_cosine, rtol=1e-12, atol=1e-15)
