"""canopy_ao._core uniform-medium expectation (ao_medium_*) and leaf-density grid (DensityGrid):
known answers through the bindings, and the error messages a user sees.
"""
import math

import numpy as np
import pytest

from canopy_ao import _core as core  # conftest.py puts addon/ on sys.path


def f32(a):
    return np.ascontiguousarray(a, dtype=np.float32)


def random_ball(count, tau, seed=0):
    """Small randomly oriented triangles uniformly in the unit ball, sigma * R = tau."""
    rng = np.random.default_rng(seed)
    c = rng.normal(size=(count, 3))
    c *= (rng.random(count) ** (1 / 3) / np.linalg.norm(c, axis=1))[:, None]
    n = rng.normal(size=(count, 3))
    n /= np.linalg.norm(n, axis=1)[:, None]
    t1 = np.cross(n, [0.0, 0.0, 1.0]) + np.cross(n, [1.0, 0.0, 0.0]) * 1e-3
    t1 /= np.linalg.norm(t1, axis=1)[:, None]
    t2 = np.cross(n, t1)
    area_each = 2 * tau * (4 / 3 * math.pi) / count
    circ = math.sqrt(area_each / (3 * math.sqrt(3) / 4))
    angles = rng.random(count)[:, None] * 2 * math.pi + np.array([0, 2, 4]) * math.pi / 3
    v = c[:, None, :] + circ * (np.cos(angles)[..., None] * t1[:, None, :]
                                + np.sin(angles)[..., None] * t2[:, None, :])
    tris = np.arange(3 * count, dtype=np.int32).reshape(count, 3)
    return f32(v.reshape(-1, 3)), tris


def test_centre_is_exp_minus_tau_and_zero_tau_is_open():
    s = core.Sphere((1.0, 2.0, 3.0), 2.0)
    pos = f32([[1, 2, 3]] * 3)
    nrm = f32([[0, 0, 1], [1, 0, 0], [0, -1, 0]])
    np.testing.assert_allclose(core.ao_medium_sphere(pos, nrm, s, 1.5), math.exp(-1.5), rtol=1e-5)
    assert np.all(core.ao_medium_sphere(pos, nrm, s, 0.0) == 1.0)


def test_table_matches_quadrature_and_surface_facing_out_is_open():
    for r, c, tau in [(0.3, 0.2, 1.0), (0.9, -0.7, 4.0), (2.5, -1.0, 3.0)]:
        assert abs(core.medium_ao(r, c, tau) - core.medium_ao_quadrature(r, c, tau)) < 1e-3
    s = core.Sphere((0.0, 0.0, 0.0), 1.0)
    ao = core.ao_medium_sphere(f32([[0, 0, 1]]), f32([[0, 0, 1]]), s, 5.0)
    assert ao[0] == pytest.approx(1.0, abs=1e-5)


def test_ellipsoid_and_shells_reduce_to_the_sphere():
    s = core.Sphere((0.5, 0.0, 0.0), 1.5)
    e = core.Ellipsoid.from_sphere(s)
    rng = np.random.default_rng(1)
    pos, nrm = f32(rng.normal(size=(100, 3))), f32(rng.normal(size=(100, 3)))
    a = core.ao_medium_sphere(pos, nrm, s, 2.0)
    np.testing.assert_allclose(core.ao_medium_ellipsoid(pos, nrm, e, 2.0), a, atol=1e-5)
    np.testing.assert_allclose(core.ao_medium_shells(pos, nrm, [e], 2.0), a, atol=1e-5)
    np.testing.assert_allclose(core.ao_medium_shells(pos, nrm, [e, e], [2.0, 0.0]), a, atol=1e-5)
    np.testing.assert_allclose(core.ao_medium_shells(pos, nrm, [e], 2.0, combine="nearest"), a,
                               atol=1e-5)
    assert a.dtype == np.float32 and a.shape == (100,)
    assert np.all((a >= 0) & (a <= 1))


def test_medium_bad_input():
    s = core.Sphere((0.0, 0.0, 0.0), 1.0)
    e = core.Ellipsoid.from_sphere(s)
    ok = f32([[0, 0, 0]])
    with pytest.raises(ValueError, match="tau"):
        core.ao_medium_sphere(ok, ok, s, -1.0)
    with pytest.raises(ValueError, match="positions"):
        core.ao_medium_sphere(f32([[0, 0, np.nan]]), ok, s, 1.0)
    with pytest.raises(ValueError, match="dtype float32"):
        core.ao_medium_sphere(np.zeros((1, 3)), ok, s, 1.0)
    with pytest.raises(ValueError, match="combine"):
        core.ao_medium_shells(ok, ok, [e], 1.0, combine="max")
    with pytest.raises(ValueError, match="one per shell"):
        core.ao_medium_shells(ok, ok, [e, e], [1.0, 2.0, 3.0])


def test_density_grid_recovers_sigma_and_matches_the_medium():
    v, t = random_ball(40000, 2.0, seed=3)
    g = core.DensityGrid(v, t, resolution=32)
    assert g.shape[0] == 32 and g.total_area == pytest.approx(2 * 2.0 * 4 / 3 * math.pi, rel=1e-4)
    sig = g.sigma()
    assert sig.shape == g.shape and sig.dtype == np.float32
    h = g.voxel_size
    idx = np.indices(g.shape).reshape(3, -1).T
    centres = np.asarray(g.origin) + (idx + 0.5) * h
    inner = np.linalg.norm(centres, axis=1) < 0.8
    assert sig.reshape(-1)[inner].mean() == pytest.approx(2.0, rel=0.04)  # sigma = A / (2V)

    rng = np.random.default_rng(4)
    p = rng.normal(size=(100, 3))
    p *= (0.5 * rng.random(100) ** (1 / 3) / np.linalg.norm(p, axis=1))[:, None]
    n = rng.normal(size=(100, 3))
    pos, nrm = f32(p), f32(n)
    ref = core.ao_medium_sphere(pos, nrm, core.Sphere((0.0, 0.0, 0.0), 1.0), 2.0)
    got = g.ao(pos, nrm, directions=128)
    assert np.abs(got - ref).mean() < 0.015
    assert np.abs(got - ref).max() < 0.04
    np.testing.assert_array_equal(got, g.ao(pos, nrm, directions=128))  # deterministic


def test_density_grid_empty_and_cutoff_and_errors():
    empty = core.DensityGrid(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int32))
    pos, nrm = f32([[0, 0, 0]]), f32([[0, 0, 1]])
    assert empty.ao(pos, nrm)[0] == 1.0 and empty.total_area == 0.0
    # a dense slab above the receiver, cut off by the AO distance
    quads = []
    for z in np.linspace(0.05, 0.95, 30):
        quads.append([[-5, -5, z], [5, -5, z], [5, 5, z], [-5, 5, z]])
    v = f32(np.array(quads).reshape(-1, 3))
    base = np.arange(0, len(v), 4, dtype=np.int32)[:, None]
    t = np.ascontiguousarray(np.concatenate([base + [0, 1, 2], base + [0, 2, 3]]), np.int32)
    g = core.DensityGrid(v, t, resolution=40)
    below = f32([[0, 0, -0.2]])
    assert g.ao(below, nrm)[0] < 0.05
    assert g.ao(below, nrm, distance=0.1)[0] == 1.0
    assert g.ao(below, nrm, sigma_scale=0.0)[0] == 1.0
    with pytest.raises(ValueError, match="resolution"):
        core.DensityGrid(v, t, resolution=0)
    bad = v.copy()
    bad[0, 0] = np.nan
    with pytest.raises(ValueError, match="vertices"):
        core.DensityGrid(bad, t)
    with pytest.raises(ValueError, match="directions"):
        g.ao(below, nrm, directions=0)
    with pytest.raises(ValueError, match="distance"):
        g.ao(below, nrm, distance=0.0)
    assert "DensityGrid" in repr(g)


@pytest.mark.skipif(core is None or not hasattr(core, "RayTracer"), reason="no RayTracer")
def test_near_far_limits():
    v, t = random_ball(5000, 1.5, seed=5)
    g = core.DensityGrid(v, t, resolution=24)
    rt = core.RayTracer(v, t)
    rng = np.random.default_rng(6)
    pos, nrm = f32(rng.normal(size=(50, 3)) * 0.3), f32(rng.normal(size=(50, 3)))
    assert np.all(g.ao(pos, nrm, start=5.0) == 1.0)
    np.testing.assert_array_equal(core.ao_near_far(rt, g, pos, nrm, near=5.0, samples=32),
                                  rt.ao(pos, nrm, samples=32))
    mixed = core.ao_near_far(rt, g, pos, nrm, near=4 * g.voxel_size, samples=32)
    assert mixed.shape == (50,) and np.all((mixed >= 0) & (mixed <= 1))
    with pytest.raises(ValueError, match="near"):
        core.ao_near_far(rt, g, pos, nrm, near=0.0)


@pytest.mark.skipif(core is None or not hasattr(core, "RayTracer"), reason="no RayTracer")
def test_near_far_starts_named_vertices_as_the_exact_rung():
    """ao_near_far takes the receivers' own primitives as RayTracer.ao does: a vertex named by
    its id starts at Cycles' bake point and casts its samples at every face corner, so the
    hybrid's near rays are the exact rung's cut at `near` (the add-on's hybrid, whose receivers
    are vertices, passes them; before, its rays started at the bare points)."""
    v, t = random_ball(3000, 1.5, seed=8)
    n = f32(np.random.default_rng(9).normal(size=v.shape))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    g = core.DensityGrid(v, t, resolution=24)
    rt = core.RayTracer(v, t, normals=n)
    ids = np.arange(200, dtype=np.int32)
    p, q = v[:200], n[:200]
    near = 4 * g.voxel_size
    got = core.ao_near_far(rt, g, p, q, near, samples=16, seed=3, vertex_ids=ids)
    want = (rt.ao(p, q, samples=16, seed=3, distance=near, vertex_ids=ids)
            * g.ao(p, q, start=near, seed=3, self_skip=0.0))
    np.testing.assert_array_equal(got, want)
    free = core.ao_near_far(rt, g, p, q, near, samples=16, seed=3)
    assert not np.array_equal(got, free)  # the bake point is not the bare point
    with pytest.raises(ValueError, match="vertex_ids"):
        core.ao_near_far(rt, g, p, q, near, vertex_ids=ids[:5])
