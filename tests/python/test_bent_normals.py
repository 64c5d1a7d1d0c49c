"""Bent normals (docs/DESIGN.md, 'Bent normals'): the native tracer's and grid's output through
Python, the tangent-space conversion and encoding (core/maps.py), a baked tree through
prepare(), and the command line's option."""

import numpy as np
import pytest

from canopy_ao import _core, core
from canopy_ao.core import maps

import tree_scene


def _unit(a):
    a = np.asarray(a, np.float64)
    return a / np.linalg.norm(a, axis=-1, keepdims=True)


def _degrees(a, b):
    return np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", _unit(a), _unit(b)), -1, 1)))


def _wall_and_ground():
    """A ground square and a tall wall standing on it along x = 0 (the wall covers x < 0's
    view for receivers just beside it)."""
    v = np.float32([[-20, -20, 0], [20, -20, 0], [20, 20, 0], [-20, 20, 0],
                    [0, -20, 0], [0, 20, 0], [0, 20, 40], [0, -20, 40]])
    t = np.int32([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    return v, t


def test_the_tracer_returns_bent_normals_leaning_away_from_a_wall():
    v, t = _wall_and_ground()
    tracer = _core.RayTracer(v, t)
    p = np.float32([[0.05, 0.0, 0.01], [0.05, 3.0, 0.01], [15.0, 0.0, 0.01]])
    n = np.float32([[0, 0, 1]] * 3)
    ao, bent = tracer.ao(p, n, samples=1024, bent_normals=True)
    assert bent.shape == (3, 3) and bent.dtype == np.float32
    assert np.allclose(np.linalg.norm(bent, axis=1), 1.0, atol=1e-5)
    # Beside the wall the open half-hemisphere's cosine-weighted mean direction: with Malley's
    # x = √u cos φ, z = √(1 − u), E[x | x > 0] = (2/3)(2/π) = 4/(3π) and E[z] = 2/3, so the
    # bent normal leans atan(2/π) = 32.5° towards +x; ±2° (1024 rays).
    want = np.degrees(np.arctan2(4.0 / (3.0 * np.pi), 2.0 / 3.0))
    tilt = np.degrees(np.arctan2(bent[:2, 0], bent[:2, 2]))
    assert tilt == pytest.approx([want, want], abs=2.0)
    assert np.abs(bent[:2, 1]).max() < 0.03
    # The wall beyond the AO distance: open sky, the bent normal is the normal (the lattice's
    # residual at 1024 rays is far below 1°).
    _ao, far = tracer.ao(p[2:], n[2:], samples=1024, distance=5.0, bent_normals=True)
    assert _degrees(far, n[2:])[0] < 1.0
    assert np.array_equal(ao, tracer.ao(p, n, samples=1024))  # the AO is unchanged
    # The plain call still returns the AO alone.
    assert isinstance(tracer.ao(p, n), np.ndarray)


def test_grid_bent_normals_lean_the_same_way():
    v, t = _wall_and_ground()
    grid = _core.DensityGrid(v[4:], t[2:] - 4, resolution=32)  # the wall alone, as a medium
    p = np.float32([[0.8, 0.0, 0.5], [0.8, 5.0, 0.5]])
    n = np.float32([[0, 0, 1]] * 2)
    ao, bent = grid.ao(p, n, directions=256, bent_normals=True)
    assert np.array_equal(ao, grid.ao(p, n, directions=256))
    # Away from the wall; less than the rays' 32.5° (tan = 0.64): voxelised, the sheet is a
    # partly transparent slab.
    assert np.all(bent[:, 0] > 0.1)
    assert np.allclose(np.linalg.norm(bent, axis=1), 1.0, atol=1e-5)


def test_tangent_space_of_the_normal_is_z_and_the_frame_is_right_handed():
    rng = np.random.default_rng(2)
    n = _unit(rng.normal(size=(50, 3)))
    t = rng.normal(size=(50, 3))  # not orthogonal to n: made so
    signs = np.where(rng.uniform(size=50) < 0.5, -1.0, 1.0)
    assert np.allclose(maps.to_tangent(n, n, t, signs), [0, 0, 1], atol=1e-6)
    t_orth = _unit(t - n * np.einsum("ij,ij->i", t, n)[:, None])
    b = signs[:, None] * np.cross(n, t_orth)
    assert np.allclose(maps.to_tangent(t_orth, n, t, signs), [1, 0, 0], atol=1e-6)
    assert np.allclose(maps.to_tangent(b, n, t, signs), [0, 1, 0], atol=1e-6)
    # A random unit vector keeps its length (an orthonormal frame), and a zero one stays zero.
    d = _unit(rng.normal(size=(50, 3)))
    assert np.allclose(np.linalg.norm(maps.to_tangent(d, n, t, signs), axis=1), 1, atol=1e-6)
    assert np.all(maps.to_tangent(np.zeros((50, 3)), n, t, signs) == 0)
    # A tangent along the normal or zero: some frame orthogonal to n, the normal still z.
    bad = maps.to_tangent(n[:2], n[:2], np.stack([n[0], np.zeros(3)]), [1, 1])
    assert np.allclose(bad, [0, 0, 1], atol=1e-6)


def test_encoding_is_half_plus_half():
    assert np.allclose(maps.encode([[0, 0, 1], [-1, 0, 0], [0, 0, 0]]),
                       [[0.5, 0.5, 1.0], [0.0, 0.5, 0.5], [0.5, 0.5, 0.5]])


def test_bent_normals_of_a_baked_tree_whatever_the_rung():
    """Through prepare() with a rung that traces no rays: ensure_tracer builds the tracer, and
    the bent normals are the same as under the ray-traced rung (the same rays); unit, in the
    normal's hemisphere; the ground under the crown leans off its normal more than the open
    ground far from it."""
    items = _tree_items()
    got = {}
    for method in ("ellipsoid", "raytrace"):
        plan = core.prepare(items, core.BakeSettings(method=method, tau=2.0, samples=64))
        maps.ensure_tracer(plan, items)
        got[method] = {it.name: maps.bent_normals(plan, it, it.positions, it.normals,
                                                  vertices=slice(None)) for it in items}
    for it in items:
        a, b = got["ellipsoid"][it.name], got["raytrace"][it.name]
        assert np.array_equal(a, b)
        assert np.allclose(np.linalg.norm(a, axis=1), 1.0, atol=1e-5)
        assert np.all(np.einsum("ij,ij->i", a, it.normals) > -1e-6)
    ground = next(i for i in items if i.name == "Ground")
    g = got["raytrace"]["Ground"]
    r = np.linalg.norm(ground.positions[:, :2], axis=1)
    tilt = _degrees(g, ground.normals)
    assert tilt[r > 0.8 * r.max()].mean() < tilt[r < 0.2 * r.max()].mean()



def _tree_items():
    """The small tree scene (leaves, trunk, ground) as scene items."""
    return tree_scene.scene_items(core)


def test_under_the_exact_rung_one_trace_gives_the_ao_and_the_bent_normals():
    """The bake takes the exact rung's AO from the bent normals' trace (rung_is_the_trace):
    it is the AO evaluate_receivers gives, bit for bit, for whole items and for a chunk."""
    tree_items = _tree_items()
    plan = core.prepare(tree_items, core.BakeSettings(method="raytrace", samples=16))
    for it in tree_items:
        assert maps.rung_is_the_trace(plan, it)
        for sel in (slice(None), slice(3, 40)):
            ao, _bent = maps.bent_normals(plan, it, it.positions[sel], it.normals[sel],
                                          vertices=sel, with_ao=True)
            want = core.evaluate_receivers(plan, it, it.positions[sel], it.normals[sel],
                                           vertices=sel)
            assert np.array_equal(ao, want)
    plan = core.prepare(tree_items, core.BakeSettings(method="ellipsoid", tau=2.0))
    assert not any(maps.rung_is_the_trace(plan, it) for it in tree_items)


def test_command_line_takes_the_bent_normals():
    from canopy_ao import cli
    opts = cli.options_from_args(cli.build_parser().parse_args(
        ["--bent-normals", "tangent", "--bent-normals-name", "Bent"]), 0.0)
    assert (opts["bent_normals"], opts["bent_normals_name"]) == ("TANGENT", "Bent")
    assert cli.options_from_args(cli.build_parser().parse_args([]), 0.0)["bent_normals"] == "OFF"
    with pytest.raises(SystemExit) as exc:
        cli.build_parser().parse_args(["--bent-normals", "object"])
    assert exc.value.code == 2
