"""Calibration with buried vertices (a leaf's base inside its twig), no bpy."""
import numpy as np
import pytest

from canopy_ao import core
from canopy_ao.core import ladder
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
    monkeypatch.setattr(ladder, "buried", lambda plan, it, p, n, own=None: np.zeros(len(p), bool))
    bias_all, rep_all = _bias_on_open(items, buried, s)
    assert bias_all < bias - 0.05, (bias_all, bias)
    assert rep_all["tau"] > rep["tau"]


def test_an_open_crevice_is_not_buried():
    """Every point inside a knot is found; an open point is found only when it is all but
    closed in (traced AO < 0.05: a leaf pressed against a neighbour's knot)."""
    items, buried = _scene()
    plan = core.prepare(items, core.BakeSettings(method="raytrace"))
    it = items[0]
    got = ladder.buried(plan, it, it.positions, it.normals)
    assert got[buried].all()
    ref = np.asarray(plan.tracer.ao(it.positions, it.normals, samples=256, seed=3))
    extra = got & ~buried
    assert extra.sum() < 0.005 * len(got) and (ref[extra] < 0.05).all()
