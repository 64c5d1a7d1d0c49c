"""One user-facing error type (CanopyAOError) for bad input and scene problems, distinct from
bugs, which keep their own type and traceback (no bpy)."""
import os
import sys

import numpy as np
import pytest

HERE = os.path.dirname(__file__)
sys.path.insert(0, os.path.join(HERE, "..", "..", "addon"))
sys.path.insert(0, HERE)

from canopy_ao import core  # noqa: E402
from canopy_ao.core import lighting  # noqa: E402
import tree_scene as ts  # noqa: E402

assert core.core_status()[0], core.core_status()[1]  # an unbuilt module fails, not skips


def scene():
    out = []
    for name, (p, t) in ts.scene(False).items():
        role = {"Trunk": "TRUNK", "Leaves": "CANOPY", "Ground": "GROUND"}[name]
        out.append(core.SceneItem(name, role, "" if role == "GROUND" else "T", p,
                                  ts.vertex_normals(p, t), t))
    return out


def test_the_user_error_is_a_value_error_not_a_runtime_error():
    assert issubclass(core.CanopyAOError, ValueError)
    assert not issubclass(core.CanopyAOError, RuntimeError)


def test_a_native_refusal_reaches_the_user_as_canopy_ao_error():
    items = scene()
    leaves = next(it for it in items if it.role == "CANOPY")
    leaves.positions[5] = np.nan  # a mesh with a NaN vertex: bad input, not a bug
    with pytest.raises(core.CanopyAOError) as exc:
        core.prepare(items, core.BakeSettings(method="ellipsoid", tau=2.0))
    assert isinstance(exc.value.__cause__, ValueError) and str(exc.value)


def test_a_bug_keeps_its_type(monkeypatch):
    items = scene()
    plan = core.prepare(items, core.BakeSettings(method="ellipsoid", tau=2.0))

    def broken(*a, **k):
        raise RuntimeError("boom")

    monkeypatch.setattr(lighting, "evaluate_points", broken)
    with pytest.raises(RuntimeError, match="boom") as exc:
        core.evaluate_item(plan, items[0])
    assert not isinstance(exc.value, core.CanopyAOError)
