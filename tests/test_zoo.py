"""A small subset of the scan zoo (fixtures/zoo.py), measured as ``make bench-zoo`` measures
every case (benchmarks/zoo.py): turned and re-encoded scans, the region alone, seam-free with
the defaults, fold-free with untangling, and identical when the answer's params are sent
back."""

from __future__ import annotations

import pytest

from benchmarks.zoo import run_case
from fixtures.zoo import CASES


@pytest.mark.parametrize("name", ["fsaverage scalp, Y-up", "Lee Perry-Smith, PLY triangle strips"])
def test_a_zoo_case_is_seam_free_fold_free_and_identical_on_the_round_trip(name):
    (case,) = [c for c in CASES if c.name == name]
    row = run_case(case)
    assert row["seam_free"] and row["folded_after"] == 0 and row["identical"], row
    assert row["region"] > 500
