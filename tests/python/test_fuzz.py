"""A short seeded run of the module fuzz (bench/fuzz.py; the long run is in
docs/studies/robustness.md, "The fuzz runs"): every public function of canopy_ao._core, each
call in a worker child with a time limit. And the harness itself: a hang and a crash are caught
and attributed."""
import os
import sys

import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "bench"))
import fuzz  # noqa: E402


def test_short_fuzz_run_finds_no_failure():
    by_name, kinds, failures = fuzz.fuzz(cases=1500, seed=11, timeout=30)
    assert set(by_name) == set(fuzz.CASES)  # every function was called
    assert sum(r[0] for r in by_name.values()) == 1500
    assert kinds.get("ok", 0) > 500  # most calls compute, not only refuse
    assert failures == []


@pytest.mark.parametrize("only, outcome", [("selftest_hang", "hang"),
                                           ("selftest_crash", "crash")])
def test_the_harness_attributes_hangs_and_crashes_to_their_case(only, outcome):
    by_name, kinds, failures = fuzz.fuzz(cases=2, seed=1, timeout=1, only=only)
    assert kinds == {outcome: 2}
    assert [(c, n, o) for c, n, o, _ in failures] == [(0, only, outcome), (1, only, outcome)]
