"""The fit's objective for many candidates at once (transforms.fit.objective; docs/math.md,
sections 7 and 9): it agrees with what a flatten measures, one candidate or many, and its
slope agrees with finite differences."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from transforms import Chart, Frame, Layout, Method, PoleCap, flatten_region
from transforms.fit.objective import Candidates, FaceEnergy, Motion, region_energy

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
