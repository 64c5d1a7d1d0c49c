"""A short seeded run of the CLI fuzz (bench/fuzz_cli.py; the long run is in
docs/studies/robustness.md, "The fuzz runs"): random argument lists through canopy_ao.cli.main,
batched in worker Blenders with a time limit per run."""
import os
import sys

import bpy
import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "bench"))
import fuzz_cli  # noqa: E402


@pytest.fixture(scope="module")
def short_run():
    return fuzz_cli.cli_fuzz(cases=60, seed=5, timeout=120, blender=bpy.app.binary_path)


def test_no_crash_hang_traceback_or_bad_ao(short_run):
    by_name, kinds, failures = short_run
    assert sum(r[0] for r in by_name.values()) == 60
    assert kinds.get("ok", 0) >= 5  # some runs bake, not only refuse
    hard = [f for f in failures if f[2] != "wrong_exit"]
    assert hard == []


def test_bad_numbers_exit_2(short_run):
    assert [f for f in short_run[2] if f[2] == "wrong_exit"] == []
