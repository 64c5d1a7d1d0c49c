"""canopy_ao.metrics: known answers (no bpy)."""
import importlib.util
import pathlib

import numpy as np
import pytest

# Load the module by path: importing the canopy_ao package is fine too, but this keeps the test
# independent of whether the compiled _core is built.
_PATH = pathlib.Path(__file__).resolve().parents[2] / "addon" / "canopy_ao" / "core" / "metrics.py"
_spec = importlib.util.spec_from_file_location("canopy_ao_metrics", _PATH)
metrics = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(metrics)
compare = metrics.compare


def _finite(d):
    return all(np.isfinite(v) for v in d.values())


def test_identical_arrays():
    x = np.linspace(0, 1, 101, dtype=np.float32)
    r = compare(x, x)
    assert r["mae"] == 0 and r["rmse"] == 0 and r["p95"] == 0 and r["bias"] == 0
    assert r["corr"] == pytest.approx(1.0)
    assert r["n"] == 101


def test_constant_offset():
    ref = np.linspace(0, 1, 1000)
    ours = ref + 0.1
    r = compare(ours, ref)
    assert r["mae"] == pytest.approx(0.1)
    assert r["rmse"] == pytest.approx(0.1)
    assert r["p95"] == pytest.approx(0.1)
    assert r["bias"] == pytest.approx(0.1)
    assert r["corr"] == pytest.approx(1.0)


def test_known_values():
    ref = np.array([0.0, 0.0, 0.0, 0.0])
    ours = np.array([0.1, -0.1, 0.3, -0.3])
    r = compare(ours, ref)
    assert r["mae"] == pytest.approx(0.2)
    assert r["rmse"] == pytest.approx(np.sqrt((0.01 + 0.01 + 0.09 + 0.09) / 4))
    assert r["bias"] == pytest.approx(0.0)
    # ref is constant and ours differs: corr is defined as 0, not NaN
    assert r["corr"] == 0.0
    assert _finite(r)


def test_p95():
    ref = np.zeros(100)
    ours = np.arange(100, dtype=float)  # |err| = 0..99
    assert compare(ours, ref)["p95"] == pytest.approx(np.percentile(np.arange(100.0), 95))


def test_anticorrelated():
    ref = np.linspace(0, 1, 50)
    r = compare(1 - ref, ref)
    assert r["corr"] == pytest.approx(-1.0)
    assert -1.0 <= r["corr"] <= 1.0


def test_constant_both_equal():
    r = compare(np.full(10, 0.5), np.full(10, 0.5))
    assert r["corr"] == 1.0 and r["mae"] == 0.0


def test_mask_and_nonfinite():
    ref = np.array([0.5, 0.5, 0.5, 0.5])
    ours = np.array([0.5, 1.0, np.nan, 0.6])
    r = compare(ours, ref, mask=np.array([True, False, True, True]))
    assert r["n"] == 2
    assert r["n_nonfinite"] == 1
    assert r["mae"] == pytest.approx(0.05)
    assert _finite(r)


def test_empty_is_finite():
    r = compare(np.array([]), np.array([]))
    assert r["n"] == 0 and _finite(r)


def test_2d_texels():
    ref = np.random.default_rng(0).random((8, 8))
    r = compare(ref + 0.01, ref)
    assert r["n"] == 64 and r["bias"] == pytest.approx(0.01)


def test_shape_mismatch_raises():
    with pytest.raises(ValueError, match="shape"):
        compare(np.zeros(3), np.zeros(4))
