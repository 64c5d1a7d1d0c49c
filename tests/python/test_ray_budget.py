"""The exact rung's rays at vertices spread evenly (core/ray_budget.py): the native per-point
counts (RayTracer.ao's point_samples), Cycles' number of rays, chunk-independence, and the
error at the same rays against Cycles' deal (S at every corner)."""
import os
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "addon"))
sys.path.insert(0, os.path.dirname(__file__))

from canopy_ao import core  # noqa: E402
from canopy_ao.core import lighting, ray_budget  # noqa: E402
import tree_scene  # noqa: E402


def _items():
    """The small tree scene (leaves, trunk, ground) as scene items."""
    return tree_scene.scene_items(core)


@pytest.fixture(scope="module")
def traced():
    """(items, tracer, vertex ids per item) of the small tree scene at Cycles' bake point."""
    items = _items()
    tracer = lighting.build_tracer(items)
    return items, tracer, _ids(items)


def _ids(items):
    """{name: int32 ids of its vertices in the tracer's mesh} (the items in order)."""
    bases = np.cumsum([0] + [len(it.positions) for it in items])
    return {it.name: np.arange(a, b, dtype=np.int32)
            for it, a, b in zip(items, bases[:-1], bases[1:])}


def test_each_point_casts_its_own_count(traced):
    """point_samples: each point as if alone at its own count (ray for ray)."""
    items, tracer, ids = traced
    it = items[0]
    kw = dict(distance=10.0, seed=5, vertex_ids=ids[it.name])
    counts = np.where(np.arange(len(it.positions)) % 3 == 0, 24, 6).astype(np.int32)
    for per_corner in (True, False):
        a = tracer.ao(it.positions, it.normals, samples=24, per_corner=per_corner, **kw)
        b = tracer.ao(it.positions, it.normals, samples=6, per_corner=per_corner, **kw)
        mixed = tracer.ao(it.positions, it.normals, samples=8, point_samples=counts,
                          per_corner=per_corner, **kw)
        np.testing.assert_array_equal(mixed, np.where(counts == 24, a, b))
        assert np.any(a != b)


@pytest.mark.parametrize("bad", [np.zeros(3, np.int32), np.full(2, 8, np.int32),
                                 np.full(3, 8, np.int64), [8, 8, 8]])
def test_bad_sample_counts_are_value_errors(traced, bad):
    items, tracer, _ids = traced
    p, n = items[0].positions[:3], items[0].normals[:3]
    with pytest.raises(ValueError, match="point_samples"):
        tracer.ao(p, n, samples=16, point_samples=bad)


def test_every_vertex_casts_cycles_mean_rays_whole_corners_each():
    corners = np.array([1, 1, 2, 3, 4, 6, 40])
    rays = ray_budget.vertex_rays(corners, 2.5 * 16)
    assert rays.dtype == np.int32
    np.testing.assert_array_equal(rays, [40, 40, 40, 39, 40, 42, 40])
    assert np.all(rays % corners == 0) and np.all(rays >= corners)
    np.testing.assert_array_equal(ray_budget.vertex_rays([5], 3.0), [5])  # one per corner


def test_the_bake_casts_cycles_rays_the_same_whole_or_in_chunks():
    items = _items()
    plan = core.prepare(items, core.BakeSettings(method="raytrace", samples=16, seed=3))
    assert ray_budget.spreads(plan)
    k = plan.tracer.corners_per_vertex  # every item a receiver: the tracer's whole mesh
    assert ray_budget.mean_corners(plan) == pytest.approx(k) and k > 1.2
    spent = sum(ray_budget.vertex_rays(ray_budget.corners_of(plan.tracer, ids), 16 * k).sum()
                for ids in _ids(items).values())
    assert spent == pytest.approx(plan.tracer.vertex_rays(0, plan.tracer.vertex_count, 16),
                                  rel=0.05)
    again = core.prepare(items, plan.settings)  # a new plan: the same rays
    for it in items:
        whole = core.evaluate_receivers(plan, it, it.positions, it.normals,
                                        vertices=slice(None))
        parts = np.concatenate([
            core.evaluate_receivers(plan, it, it.positions[a:a + 97], it.normals[a:a + 97],
                                    vertices=slice(a, min(a + 97, len(it.positions))))
            for a in range(0, len(it.positions), 97)])
        np.testing.assert_array_equal(whole, parts)
        np.testing.assert_array_equal(
            whole, core.evaluate_receivers(again, it, it.positions, it.normals,
                                           vertices=slice(None)))


def test_the_same_rays_spread_evenly_miss_less_than_cycles_deal(traced):
    """At 16 samples, as many rays in all, the even spread's MAE over the scene's vertices
    against a 1024-ray reference is below that of 16 at every corner (Cycles' deal)."""
    items, tracer, ids = traced
    everything = np.concatenate(list(ids.values()))
    p = np.concatenate([it.positions for it in items])
    n = np.concatenate([it.normals for it in items])
    ref = np.asarray(tracer.ao(p, n, samples=1024, distance=10.0, seed=99, vertex_ids=everything))
    per_vertex = 16 * tracer.corners_per_vertex
    err_c, err_e = [], []
    for seed in range(4):
        cycles_deal = tracer.ao(p, n, samples=16, distance=10.0, seed=seed,
                                vertex_ids=everything)
        even = ray_budget.trace_even(tracer, p, n, everything, 16, per_vertex, seed, 10.0)
        err_c.append(np.abs(cycles_deal - ref).mean())
        err_e.append(np.abs(even - ref).mean())
    assert np.mean(err_e) < 0.92 * np.mean(err_c), (np.mean(err_e), np.mean(err_c))


def test_vertex_corners_are_each_vertexs_rays_at_one_sample(traced):
    """RayTracer.vertex_corners: vertex_rays(v, 1, 1) for every vertex in one call."""
    _items_, tracer, _ids = traced
    got = tracer.vertex_corners(0, tracer.vertex_count)
    assert got.dtype == np.int32 and len(got) == tracer.vertex_count
    want = [tracer.vertex_rays(v, 1, 1) for v in range(tracer.vertex_count)]
    np.testing.assert_array_equal(got, want)
    assert got.min() >= 1 and got.max() > 1
    np.testing.assert_array_equal(tracer.vertex_corners(5, 3), want[5:8])
    with pytest.raises(ValueError, match="not in the tracer"):
        tracer.vertex_corners(tracer.vertex_count - 1, 2)
