"""Choosing centre, rotation and sigma in the core (transforms.fit; docs/math.md, section 9).
The HTTP side, /v1/fit and "auto", is in test_api.py."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from transforms import (
    Chart,
    FitBounds,
    FitFixed,
    Frame,
    Layout,
    Method,
    PoleCap,
    TransformInputError,
    default_choice,
    fit_region,
    flatten_region,
)
from transforms.fit import SIGMA_SEARCH
from transforms.fit.emptycap import largest_empty_cap

from .conftest import grid_mesh, load_sample, scalp, sphere_mesh


@pytest.fixture(scope="module")
def fsaverage_fit():
    vertices, faces = scalp()
    return vertices, faces, fit_region(vertices, faces)


# -- the fit ---------------------------------------------------------------------------------


def test_auto_scalp_is_seam_free_and_star_shaped_with_the_margin(fsaverage_fit):
    _, _, fit = fsaverage_fit
    v, e = fit.region.validation, fit.explanation
    assert v.seam_free and v.star_shaped
    assert min(v.margin_deg_seam, v.margin_deg_north, v.margin_deg_south) >= 2.0
    assert e.margin_deg >= 2.0 and not e.kernel_empty and not e.notes
    assert e.energy_end <= e.energy_start
    assert e.center_depth >= 0.05 * e.kernel_inscribed_radius
    # The optimum of docs/math.md's section 7: better than either reported sigma.
    assert all(e.energy_end <= energy + 1e-9 for energy in e.energy_at_sigma.values())
    assert fit.region.distortion.isometric.mean == pytest.approx(e.energy_end)


@pytest.mark.parametrize(
    ("name", "up"),
    [
        ("fsaverage-head.ply", [0.3, 1.0, 0.2]),
        ("lee-perry-smith.obj", [0.3, 0.2, 1.0]),
        ("fsaverage-head.ply", None),  # the roll rule
        ("lee-perry-smith.obj", None),
    ],
)
def test_the_choice_turns_and_moves_with_the_mesh(name, up):
    vertices, faces = scalp(name)
    up = None if up is None else np.array(up)
    base = fit_region(vertices, faces, FitFixed(up=up))
    for seed in range(2):
        turn = Rotation.random(random_state=seed).as_matrix()
        shift = np.random.default_rng(seed).normal(size=3) * 50.0
        turned_up = None if up is None else turn @ up
        moved = fit_region(vertices @ turn.T + shift, faces, FitFixed(up=turned_up))
        np.testing.assert_allclose(moved.region.theta, base.region.theta, atol=1e-6, rtol=0)
        np.testing.assert_allclose(moved.region.phi, base.region.phi, atol=1e-6, rtol=0)
        np.testing.assert_allclose(moved.frame.center, turn @ base.frame.center + shift, atol=1e-6)


def test_fixed_parameters_are_kept(fsaverage_fit):
    vertices, faces, fit = fsaverage_fit
    frame = Frame.from_pole_up([0, 0, -1], [0, 1, 0])
    kept = fit_region(vertices, faces, FitFixed(center=fit.frame.center, rotation=frame, sigma=0.4))
    assert kept.chart.cap.sigma == 0.4
    np.testing.assert_array_equal(kept.frame.rotation, frame.rotation)
    np.testing.assert_array_equal(kept.frame.center, fit.frame.center)
    # Only sigma chosen: the answer is the best sigma for that centre and rotation.
    only_sigma = fit_region(vertices, faces, FitFixed(center=fit.frame.center, rotation=frame))
    energy = only_sigma.explanation.energy_end
    for sigma in (0.2, 0.4, 0.8):
        chart = Chart.distorted(PoleCap.from_sigma(sigma))
        moved = Frame.from_matrix(frame.rotation, fit.frame.center)
        other = flatten_region(vertices, faces, moved, chart).distortion.isometric.mean
        assert energy <= other + 1e-3


def test_an_empty_kernel_is_said_and_its_backfacing_faces_listed():
    vertices, faces = load_sample("nefertiti-lowres.obj")
    fit = fit_region(vertices, faces)
    e = fit.explanation
    assert e.kernel_empty and e.kernel_inscribed_radius == 0.0
    assert len(e.backfacing_faces) > 0
    np.testing.assert_array_equal(e.backfacing_faces, fit.region.validation.backfacing_faces)
    assert any("kernel is empty" in note for note in e.notes)


@pytest.mark.parametrize("shape", ["one triangle", "flat square"])
def test_small_and_flat_regions_get_a_centre_behind_them(shape):
    if shape == "one triangle":
        vertices, faces = np.array([[0, 0, 1.0], [1, 0, 1], [0, 1, 1]]), np.array([[0, 1, 2]])
    else:
        vertices, faces = grid_mesh(np.linspace(-1, 1, 12), np.linspace(-1, 1, 12), 0.0)
    fit = fit_region(vertices, faces)
    assert not fit.explanation.kernel_empty and fit.explanation.kernel_inscribed_radius > 0
    assert fit.region.validation.seam_free and fit.region.validation.star_shaped
    assert SIGMA_SEARCH[0] <= fit.chart.cap.sigma <= SIGMA_SEARCH[1]


def test_bad_bounds_are_refused():
    vertices, faces = sphere_mesh(6, 8)
    from transforms import TransformInputError

    with pytest.raises(TransformInputError, match="min_margin_deg"):
        fit_region(vertices, faces, bounds=FitBounds(min_margin_deg=95.0))
    with pytest.raises(TransformInputError, match="min_kernel_depth"):
        fit_region(vertices, faces, bounds=FitBounds(min_kernel_depth=float("nan")))
    with pytest.raises(TransformInputError, match="sigma"):
        fit_region(vertices, faces, FitFixed(sigma=0.3), method="standard")


# -- found by probing --------------------------------------------------------------------------


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_turned_flat_region_is_never_answered_worse_than_the_start(seed):
    vertices, faces = grid_mesh(np.arange(7.0), np.arange(4.0), 0.0)
    turned = vertices @ Rotation.random(random_state=seed).as_matrix().T
    fit = fit_region(turned, faces)
    e = fit.explanation
    assert e.energy_end <= e.energy_start + 1e-12
    assert fit.region.validation.seam_free and e.margin_deg >= 2.0


@pytest.mark.parametrize("scale", [1e90, 1e-100])
def test_huge_and_tiny_coordinates(scale):
    tetrahedron = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float) * scale
    faces = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    fit = fit_region(tetrahedron, faces)
    assert not fit.explanation.kernel_empty
    np.testing.assert_allclose(
        fit.explanation.kernel_inscribed_radius, scale / (3 + math.sqrt(3)), rtol=1e-9
    )
    assert np.isfinite(fit.region.theta).all() and np.isfinite(fit.explanation.energy_end)


def test_a_margin_larger_than_the_starting_cap_is_still_kept(fsaverage_fit):
    vertices, faces, _ = fsaverage_fit
    fit = fit_region(vertices, faces, bounds=FitBounds(min_margin_deg=60.0))
    assert fit.explanation.margin_deg >= 60.0 or any("below" in n for n in fit.explanation.notes)
    assert not any("closed" in note for note in fit.explanation.notes)


def test_a_closed_region_gets_the_sigma_of_least_energy():
    vertices, faces = sphere_mesh(8, 12)
    fit = fit_region(vertices * 3.0, faces, FitFixed(center=[0.0, 0.0, 0.0]))
    e = fit.explanation
    assert any("closed" in note for note in e.notes)
    assert e.energy_end <= min(e.energy_at_sigma.values()) + 1e-9


def test_an_up_hint_along_the_chosen_pole_falls_back_to_the_rule(fsaverage_fit):
    vertices, faces, fit = fsaverage_fit
    # The pole the search starts from, seen from that centre.
    directions = vertices[np.unique(faces)] - fit.frame.center
    pole, _ = largest_empty_cap(directions / np.linalg.norm(directions, axis=1)[:, None])
    hinted = fit_region(vertices, faces, FitFixed(center=fit.frame.center, up=pole))
    assert any("parallel" in note for note in hinted.explanation.notes)


# -- the default choice (no search) and the robust objective --------------------------------


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_default_choice_is_seam_free_in_any_pose(seed):
    """The scalp turned and moved at random, seen from its box centre, pole and sigma left to
    the default rule: seam-free with the margin, the map turning with the mesh."""
    vertices, faces = scalp()
    base_centre = (vertices[faces].min(axis=(0, 1)) + vertices[faces].max(axis=(0, 1))) / 2
    base = default_choice(vertices, faces, FitFixed(center=base_centre))
    turn = Rotation.random(random_state=seed).as_matrix()
    shift = np.random.default_rng(seed).normal(size=3) * 100.0
    moved = vertices @ turn.T + shift
    chosen = default_choice(moved, faces, FitFixed(center=turn @ base_centre + shift))
    v = chosen.region.validation
    assert v.seam_free and v.star_shaped
    assert min(v.margin_deg_seam, v.margin_deg_north, v.margin_deg_south) >= 2.0 - 1e-9
    assert chosen.explanation is None
    np.testing.assert_allclose(chosen.region.theta, base.region.theta, atol=1e-6)
    np.testing.assert_allclose(chosen.region.phi, base.region.phi, atol=1e-6)


def test_the_default_choice_keeps_what_is_fixed():
    vertices, faces = scalp()
    centre = np.array([1.0, -12.0, -30.0])
    frame = Frame.from_pole_up([0, 0, -1], [0, 1, 0])
    kept = default_choice(vertices, faces, FitFixed(center=centre, rotation=frame))
    np.testing.assert_array_equal(kept.frame.rotation, frame.rotation)
    np.testing.assert_array_equal(kept.frame.center, centre)
    sigma = default_choice(vertices, faces, FitFixed(center=centre, sigma=0.4))
    assert sigma.chart.cap.sigma == 0.4
    with pytest.raises(TransformInputError, match="needs a centre"):
        default_choice(vertices, faces, FitFixed())


def test_the_objective_judges_a_centre_by_what_it_sees_from_behind_then_the_rest():
    """Nefertiti's top seen from its box centre: some sampled faces are seen from behind (as
    validation judges it). The objective is their share of the sample's area (times the
    weight) plus the energy of the faces seen from the front measured alone, so their own
    energies play no part."""
    from transforms.fit.objective import BACKFACING_WEIGHT
    from transforms.fit.problem import _Candidate, _Problem

    vertices, faces = load_sample("nefertiti-lowres.obj")
    centre = (vertices.min(axis=0) + vertices.max(axis=0)) / 2
    directions = vertices[faces].mean(axis=1) - centre
    top = faces[directions[:, 2] / np.linalg.norm(directions, axis=1) > math.cos(1.0)]
    problem = _Problem(vertices, top, Method.DISTORTED, 1, Layout.THETA_PHI)
    rotation = Frame.from_pole_up([0, 0, -1], [0, 1, 0]).rotation
    frame, chart = Frame.from_matrix(rotation, centre), Chart.distorted(PoleCap.from_sigma(0.5))
    sample = flatten_region(problem.sample_points, problem.sample_faces, frame, chart)
    behind = np.zeros(len(problem.sample_faces), dtype=bool)
    behind[sample.validation.backfacing_faces] = True
    assert 0 < behind.sum() < len(behind)
    hidden = problem.sample_areas[behind].sum() / problem.sample_areas.sum()
    seen = flatten_region(problem.sample_points, problem.sample_faces[~behind], frame, chart)
    expected = seen.distortion.isometric.mean + BACKFACING_WEIGHT * hidden
    assert problem.energy(_Candidate(centre, rotation, 0.5)) == pytest.approx(expected, rel=1e-9)


def test_a_large_region_explains_with_energies_measured_on_runs_of_its_faces():
    """Beyond EXPLAIN_FACES the start's energy and the reported sigmas' are estimated on
    runs of consecutive faces; the answer's own energy stays exact."""
    vertices, faces = scalp()
    exact = fit_region(vertices, faces)
    estimated = fit_region(vertices, faces, explain_faces=400, explain_run=16)
    e, x = estimated.explanation, exact.explanation
    assert e.energy_end == x.energy_end
    assert e.energy_end == estimated.region.distortion.isometric.mean
    assert e.energy_start == pytest.approx(x.energy_start, rel=0.02)
    for sigma, energy in x.energy_at_sigma.items():
        assert e.energy_at_sigma[sigma] == pytest.approx(energy, rel=0.05)
