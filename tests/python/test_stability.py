"""Where methods fail (docs/DESIGN.md, 'How we check ourselves'): every method on every degenerate
case must give a finite result in [0, 1] of the right length, or raise a ValueError / RuntimeError
with a message. Never NaN, never out of range, never a crash. The cases and method adapters live in
bench/stability.py (which also tabulates the results: bench/out/stability.md).

Methods this build lacks are skipped, so the tests tighten as the core grows.
"""
import os
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "bench"))
stability = pytest.importorskip("stability")

if stability._core is None:
    pytest.skip("canopy_ao._core is not built", allow_module_level=True)


@pytest.fixture(scope="module")
def cases():
    return {name: make() for name, make in stability.CASES.items()}


@pytest.mark.parametrize("method", list(stability.METHODS))
@pytest.mark.parametrize("case", list(stability.CASES))
def test_finite_or_clear_error(cases, case, method):
    if not stability.available(method):
        pytest.skip(f"{method}: not in this build of canopy_ao._core")
    c = cases[case]
    fn = stability.METHODS[method][0]
    try:
        out = fn({k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in c.items()})
    except (ValueError, RuntimeError) as exc:
        assert str(exc).strip(), f"{method} on {case}: {type(exc).__name__} without a message"
        return
    status, text = stability.classify(out, n_points=len(c["points"]))
    assert status == "ok", f"{method} on {case} ({c['note']}): {text}"


def test_nan_input_is_rejected_by_the_reference():
    c = stability.case_nan_coords()
    if not stability.available("raytrace 64"):
        pytest.skip("no RayTracer")
    with pytest.raises(ValueError, match="non-finite"):
        stability.m_raytrace(c)


def test_classify():
    assert stability.classify(np.array([0.0, 1.0]), n_points=2)[0] == "ok"
    assert stability.classify(np.array([np.nan]), n_points=1)[0] == "bad"
    assert stability.classify(np.array([1.5]), n_points=1)[0] == "bad"
    assert stability.classify(np.array([0.5]), n_points=2)[0] == "bad"
    assert stability.classify(exc=ValueError("points is empty"))[0] == "error"
    assert stability.classify(exc=ValueError(""))[0] == "bad"
    assert stability.classify(exc=TypeError("x"))[0] == "bad"
