"""The bake (canopy_ao.core) on a small tree + ground scene, no bpy.

Known answers are orderings a correct AO must show, with the margins stated: ground under the
crown darker than open ground, the crown's core darker than its rim, a denser canopy darker.
"""
import json
import os
import sys

import numpy as np
import pytest

HERE = os.path.dirname(__file__)
sys.path.insert(0, os.path.join(HERE, "..", "..", "addon"))
sys.path.insert(0, HERE)

from canopy_ao import core  # noqa: E402
from canopy_ao.core import native  # noqa: E402
from canopy_ao.core.native import _core  # noqa: E402
import tree_scene as ts  # noqa: E402

assert core.core_status()[0], core.core_status()[1]  # an unbuilt module fails, not skips

ROLE = ts.ROLE


def items(with_grass=True, offset=(0.0, 0.0, 0.0), tree="T", suffix=""):
    out = []
    for name, (p, t) in ts.scene(with_grass).items():
        if name == "Ground" and suffix:
            continue
        p = p + np.float32(offset)
        out.append(core.SceneItem(name + suffix, ROLE[name], tree if name != "Ground" else "",
                                    p, ts.vertex_normals(p, t), t))
    return out


def by_name(results):
    return {r.name: r.ao for r in results}


@pytest.fixture(scope="module")
def scene():
    return items()


@pytest.mark.parametrize("method", [m for m in core.available_methods()
                                    if m not in ("auto", "grid")])
def test_every_method_gives_valid_ao(scene, method):
    res, rep = core.bake(scene, core.BakeSettings(method=method, tau=2.0, distance=0.0,
                                                      samples=16))
    assert [r.name for r in res] == [it.name for it in scene]
    for r, it in zip(res, scene):
        assert r.ao.dtype == np.float32 and r.ao.shape == (len(it.positions),)
        assert np.all(np.isfinite(r.ao)) and r.ao.min() >= 0 and r.ao.max() <= 1, r.name
    json.dumps(rep)  # the report is plain data


@pytest.mark.parametrize("method", ["sphere", "ellipsoid", "shells", "raytrace"])
def test_physical_orderings(scene, method):
    res = by_name(core.bake(scene, core.BakeSettings(method=method, tau=2.0, distance=0.0,
                                                         samples=32))[0])
    g = {it.name: it for it in scene}
    r = np.linalg.norm(g["Ground"].positions[:, :2], axis=1)
    assert res["Ground"][r < 1.0].mean() < res["Ground"][r > 6.0].mean() - 0.05
    d = np.linalg.norm(g["Leaves"].positions - [0, 0, 2.6], axis=1)
    assert res["Leaves"][d < 0.5].mean() < res["Leaves"][d > 1.1].mean() - 0.1


def test_denser_canopy_is_darker(scene):
    lo = by_name(core.bake(scene, core.BakeSettings(method="ellipsoid", tau=0.5))[0])
    hi = by_name(core.bake(scene, core.BakeSettings(method="ellipsoid", tau=4.0))[0])
    assert hi["Leaves"].mean() < lo["Leaves"].mean() - 0.05
    assert hi["Ground"].mean() < lo["Ground"].mean()


def test_a_neighbour_tree_darkens(scene):
    alone = by_name(core.bake(scene, core.BakeSettings(method="ellipsoid", tau=2.0))[0])
    two = scene + items(with_grass=False, offset=(3.0, 0.0, 0.0), tree="U", suffix="_2")
    both = by_name(core.bake(two, core.BakeSettings(method="ellipsoid", tau=2.0))[0])
    assert both["Leaves"].mean() < alone["Leaves"].mean() - 0.005
    assert both["Ground"].mean() < alone["Ground"].mean()


def test_proxies_contain_the_canopy(scene):
    plan = core.prepare(scene, core.BakeSettings(method="ellipsoid", tau=2.0))
    leaves = next(it for it in scene if it.role == "CANOPY")
    (shell,) = plan.proxies["T"]
    assert np.asarray(shell.contains(leaves.positions)).all()
    d = core.proxy_dicts(plan)["T"][0]
    assert np.allclose(d["center"], [0, 0, 2.6], atol=0.3)


def test_auto_calibrates_and_says_why(scene):
    if not hasattr(_core, "RayTracer"):
        pytest.skip("no RayTracer in this build: auto falls back to the default tau")
    s = core.BakeSettings(method="auto", tau=None, distance=0.0, calibration_points=200)
    plan = core.prepare(scene, s)
    cal = plan.calibration
    assert plan.method in cal["candidates"] and cal["chosen"] == plan.method
    assert set(core.ANALYTIC_METHODS) <= set(cal["candidates"])
    assert cal["points"] >= 100 and "why" in cal
    # The fitted tau beats the default on the same samples.
    _m, _t, fixed = core.calibrate(plan, scene, ["ellipsoid"], tau_fixed=core.DEFAULT_TAU)
    fitted = cal["candidates"]["ellipsoid"]["rmse"]
    assert fitted <= fixed["candidates"]["ellipsoid"]["rmse"] + 1e-6
    assert cal["candidates"][plan.method]["rmse"] <= fitted + 1e-6  # the choice is no worse


def test_bad_input_is_refused():
    p = np.zeros((3, 3), np.float32)
    t = np.array([[0, 1, 2]], np.int32)
    with pytest.raises(core.CanopyAOError, match="unknown role"):
        core.SceneItem("x", "LEAVES", "", p, p, t)
    with pytest.raises(core.CanopyAOError, match="normals"):
        core.SceneItem("x", "GROUND", "", p, p[:2], t)
    with pytest.raises(core.CanopyAOError, match="method must be one of"):
        core.prepare([], core.BakeSettings(method="magic"))
    with pytest.raises(core.CanopyAOError, match="tau"):
        core.prepare([], core.BakeSettings(method="sphere", tau=-1.0))


def test_without_trees_ground_is_open_and_noted():
    p, t = ts.plane()
    it = core.SceneItem("Ground", "GROUND", "", p, ts.vertex_normals(p, t), t)
    res, rep = core.bake([it], core.BakeSettings(method="auto"))
    assert np.allclose(res[0].ao, 1.0)
    assert any("no CANOPY" in n for n in rep["notes"])


def test_ignored_items_stay_white(scene):
    p, t = ts.cylinder()
    ign = core.SceneItem("Rock", "IGNORE", "", p + np.float32([5, 5, 0]),
                           ts.vertex_normals(p, t), t)
    res = by_name(core.bake(scene + [ign], core.BakeSettings(method="sphere", tau=2.0))[0])
    assert np.all(res["Rock"] == 1.0)


def test_a_missing_native_function_says_rebuild(monkeypatch):
    class Partial:  # a module built from older sources
        Ellipsoid = _core.Ellipsoid

    assert "ao_canopy_sphere" in native.missing_functions(Partial)
    assert native.missing_functions(_core) == []
    # Reported as not loaded (with how to fix it) instead of failing mid-bake.
    monkeypatch.setattr(native, "_core", None)
    monkeypatch.setattr(native, "_CORE_ERROR", "it was built from older sources; rebuild it")
    ok, msg = core.core_status()
    assert not ok and "rebuild" in msg
    with pytest.raises(core.CanopyAOError, match="rebuild"):
        core.prepare([], core.BakeSettings(method="sphere", tau=1.0))
    assert core.available_methods() == ("auto",)


def test_triangles_needed_only_by_rays_grid_calibration_and_grass(scene):
    """The add-on skips Blender's loop triangulation when this says no: an analytic bake with a
    given τ then gives the same AO without any triangles but the grass's and the ground's (the
    GROUND surfaces occlude as patches: core/walls.py)."""
    need = core.triangles_needed
    # a bake's ground is a patch (a live bake's first too: its frames hold its occlusion)
    assert need("sphere", 1.5, "GROUND") is True and need("shells", 2.0, "GROUND") is True
    for role in ("CANOPY", "TRUNK", "GROUND"):
        assert role == "GROUND" or not need("sphere", 1.5, role) and not need("shells", 2.0, role)
        assert need("sphere", None, role) and need("auto", 1.5, role)
        assert need("raytrace", 1.5, role) and need("grid", 1.5, role)
    assert need("ellipsoid", 1.5, "GRASS") and not need("auto", None, "IGNORE")
    for method in ("sphere", "ellipsoid", "shells"):
        s = core.BakeSettings(method=method, tau=1.5)
        lean = [core.SceneItem(it.name, it.role, it.tree, it.positions, it.normals,
                                 it.triangles if need(method, 1.5, it.role)
                                 else np.zeros((0, 3), np.int32)) for it in scene]
        full, _ = core.bake(scene, s)
        got, _ = core.bake(lean, s)
        for a, b in zip(full, got):
            np.testing.assert_array_equal(a.ao, b.ao)


def test_sphere_method_fits_no_ellipsoid(scene, monkeypatch):
    calls = []
    real = _core.fit_ellipsoid
    monkeypatch.setattr(_core, "fit_ellipsoid",
                        lambda *a, **k: calls.append(1) or real(*a, **k))
    plan = core.prepare(scene, core.BakeSettings(method="sphere", tau=1.5))
    sphere, ell, shells = plan.fits["T"]
    assert np.allclose(ell.radii, sphere.radius) and shells == [ell]
    # trunks still get their solid (fit_ellipsoid on the bole, outside the sphere)
    assert len(calls) == len(plan.trunks.get("T", []))
