"""A small subset of the scan zoo (fixtures/zoo.py), measured as ``make bench-zoo`` measures
every case (benchmarks/zoo.py): turned and re-encoded scans, the region alone, seam-free with
the defaults, fold-free with untangling, and identical when the answer's params are sent
back."""

from __future__ import annotations

import pytest

from benchmarks.zoo import run_case
from fixtures.zoo import ALL_CASES, CASES, FS, UNITS, WRONG_UNITS


@pytest.mark.parametrize("name", ["fsaverage scalp, Y-up", "Lee Perry-Smith, PLY triangle strips"])
def test_a_zoo_case_is_seam_free_fold_free_and_identical_on_the_round_trip(name):
    (case,) = [c for c in CASES if c.name == name]
    row = run_case(case, poses=False)
    assert row["seam_free_alone"] and row["seam_free_auto"], row
    assert row["folded"] == 0 and row["identical"], row
    assert row["region"] > 500


@pytest.mark.parametrize(
    "name", ["fsaverage-head.ply, STL soup", "fsaverage-head.ply, OBJ with per-face normals"]
)
def test_a_soup_of_the_zoo_answers_as_its_welded_twin(name):
    (case,) = [c for c in ALL_CASES if c.name == name]
    row = run_case(case, poses=False)
    assert row["soup_equal"] and row["seam_free_auto"] and row["folded"] == 0, row


@pytest.mark.parametrize("stored, declared", WRONG_UNITS)
def test_a_scan_declared_in_the_wrong_unit_is_never_silent(stored, declared):
    (case,) = [c for c in UNITS if (c.scan, c.stored_in, c.declared) == (FS, stored, declared)]
    assert run_case(case)["units_named"]


def test_a_stray_box_is_said():
    (case,) = [c for c in ALL_CASES if c.stray and c.scan == FS]
    assert "region_pieces" in run_case(case)["warnings"]


def test_the_fit_in_three_random_poses_has_the_same_energy():
    (case,) = [c for c in CASES if c.name == "fsaverage scalp, Y-up"]
    assert run_case(case)["spread"] <= 1e-9
