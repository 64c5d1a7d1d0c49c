"""Calibration with buried vertices (a leaf's base inside its twig), no bpy."""
import numpy as np
import pytest

from canopy_ao import core
from canopy_ao.core import buried as buried_test, cost, ladder, live
from real_shapes import cubes

cs = pytest.importorskip("canopy_scenes")


def _scene():
    """A crown of kite-shaped leaves whose two base corners (1 cm apart) sit inside a small
    closed knot (a twig): half the leaf vertices are buried, as on Sapling conifers (their
    needle bases: up to 47 %)."""
    rng = np.random.default_rng(7)
    n = 2000
    kite = np.array([[0, 0, 0], [0.01, 0, 0], [0.12, 0.2, 0], [-0.1, 0.2, 0]], float)
    rot = np.linalg.qr(rng.normal(size=(n, 3, 3)))[0]
    base = np.array([0, 0, 5.0]) + rng.normal(0, 1.0, (n, 3))
    lp = (base[:, None, :] + np.einsum("nij,kj->nki", rot, kite)).reshape(-1, 3)
    lp = lp.astype(np.float32)
    lt = (np.arange(n)[:, None, None] * 4 + np.array([[0, 1, 2], [0, 2, 3]])[None])
    lt = lt.reshape(-1, 3).astype(np.int32)
    kp, kt = cubes(lp.reshape(-1, 4, 3)[:, :2].mean(axis=1), 0.012)
    buried = np.zeros(len(lp), bool)
    buried.reshape(-1, 4)[:, :2] = True
    return [core.SceneItem("Leaves", "CANOPY", "T", lp, cs.vertex_normals(lp, lt), lt),
            core.SceneItem("Twigs", "TRUNK", "T", kp, cs.vertex_normals(kp, kt), kt)], buried


def _bias_on_open(items, buried, settings):
    res, rep = core.bake(items, settings)
    tracer = core.lighting.build_tracer(items)
    it = items[0]
    ref = np.asarray(tracer.ao(it.positions, it.normals, samples=256, seed=3))
    assert ref[buried].max() < 0.01  # the knots bury them: traced AO 0 (a ray may leak)
    return float(np.mean(res[0].ao[~buried] - ref[~buried])), rep


def test_buried_points_are_kept_out_of_the_fit(monkeypatch):
    items, buried = _scene()
    s = core.BakeSettings(method="ellipsoid", tau=None, calibration_points=1000)
    bias, rep = _bias_on_open(items, buried, s)
    cal = rep["calibration"]
    # a third of the sample points are a leaf's (the knots have more vertices), half buried
    assert cal["buried_points_left_out"] >= 100, cal
    assert abs(bias) < 0.08, bias
    # Fitted to them too (what calibration did before), τ darkens every open leaf.
    monkeypatch.setattr(ladder, "buried",
                        lambda plan, it, p, n, own=None, **kw: np.zeros(len(p), bool))
    bias_all, rep_all = _bias_on_open(items, buried, s)
    assert bias_all < bias - 0.05, (bias_all, bias)
    assert rep_all["tau"] > rep["tau"]


def test_an_open_crevice_is_not_buried():
    """Every point inside a knot is found; an open point is found only when it is all but
    closed in (traced AO < 0.05: a leaf pressed against a neighbour's knot)."""
    items, buried = _scene()
    plan = core.prepare(items, core.BakeSettings(method="raytrace"))
    it = items[0]
    got = buried_test.buried(plan, it, it.positions, it.normals)
    assert got[buried].all()
    ref = np.asarray(plan.tracer.ao(it.positions, it.normals, samples=256, seed=3))
    extra = got & ~buried
    assert extra.sum() < 0.005 * len(got) and (ref[extra] < 0.05).all()


@pytest.mark.parametrize("method", ["sphere", "shells", "medium", "grid", "regression"])
def test_buried_receivers_read_0_under_every_approximate_rung(method):
    """The approximate rungs model a buried leaf base like any point; the bake's own test sets
    it to 0, as rays and Cycles read it, and leaves the open points alone."""
    items, buried = _scene()
    res, rep = core.bake(items, core.BakeSettings(method=method, calibration_points=1000))
    ao = res[0].ao
    assert (ao[buried] == 0).all(), (ao[buried] > 0).sum()
    zeroed = (ao == 0) & ~buried
    assert zeroed.sum() < 0.005 * len(ao), zeroed.sum()
    assert ao[~buried].mean() > 0.2
    assert buried.sum() <= rep["objects"]["Leaves"]["buried_set_to_0"] <= (ao == 0).sum()


def test_a_given_tau_traces_nothing_and_live_frames_keep_what_the_bake_found():
    """A given τ builds no tracer, so nothing is tested (the documented fallback: no rays at
    all); a live frame (no tracer either) keeps the buried vertices its first bake found."""
    items, buried = _scene()
    res, rep = core.bake(items, core.BakeSettings(method="sphere", tau=1.0))
    assert (res[0].ao[buried] > 0).all() and rep["objects"]["Leaves"]["buried_set_to_0"] == 0
    plan = core.prepare(items, core.BakeSettings(method="sphere", calibration_points=1000))
    first = core.evaluate_item(plan, items[0]).ao
    frame = live.refit(plan, items)
    assert frame.tracer is None
    again = core.evaluate_receivers(frame, items[0], items[0].positions, items[0].normals,
                                    vertices=slice(None))
    assert (again[buried] == 0).all()
    np.testing.assert_array_equal(again == 0, first == 0)


def test_the_cost_model_counts_the_buried_test():
    """8 rays per leaf or branch receiver, log2(triangles) BVH steps each, in the rung's unit;
    none for the exact rung (its rays find them) or without a tracer."""
    items, _ = _scene()
    plan = core.prepare(items, core.BakeSettings(method="sphere", calibration_points=1000))
    n = len(items[0].positions) + len(items[1].positions)
    unit, with_test = cost.work(plan, "sphere", n)
    _u, without = cost._work(plan, "sphere", n)
    depth = np.log2(plan.tracer.triangle_count)
    rays = n * buried_test.BURIED_RECEIVER_RAYS  # both items are leaves or branches
    expect = rays * depth * cost.SECONDS_PER_UNIT["bvh_step"] / cost.SECONDS_PER_UNIT[unit]
    assert with_test - without == pytest.approx(expect, rel=1e-9)
    assert cost.work(plan, "raytrace", n) == cost._work(plan, "raytrace", n)
    plan.tracer = None
    assert cost.buried_test_rays(plan, n) == 0.0
