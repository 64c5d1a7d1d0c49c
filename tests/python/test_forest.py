"""Forests (canopy_ao.forest): instance transforms of shells, and instances as occluders.

Known answers: an identity instance is the prototype; a translated / rotated / scaled instance
is the exact image of the ellipsoid (checked on boundary points, to float32 precision); the
ground under an instance gets the AO it gets under the same tree placed there for real (to
1e-4: the two fits differ only by float rounding of the shifted points).
"""
import math
import os
import sys

import numpy as np
import pytest

HERE = os.path.dirname(__file__)
sys.path.insert(0, os.path.join(HERE, "..", "..", "addon"))
sys.path.insert(0, HERE)

from canopy_ao import core  # noqa: E402
from canopy_ao.core import forest  # noqa: E402
from canopy_ao.core.native import _core  # noqa: E402
import tree_scene as ts  # noqa: E402

assert core.core_status()[0], core.core_status()[1]  # an unbuilt module fails, not skips



def rot_z(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]], float)


def affine(a=np.eye(3), t=(0, 0, 0)):
    m = np.eye(4)
    m[:3, :3] = a
    m[:3, 3] = t
    return m


def proto_shell():
    q = rot_z(0.4) @ np.array([[1, 0, 0], [0, math.cos(0.3), -math.sin(0.3)],
                               [0, math.sin(0.3), math.cos(0.3)]])
    return _core.Ellipsoid(np.float32([0.5, -0.2, 2.6]), q.astype(np.float32),
                           np.float32([1.2, 0.8, 1.5]))


def boundary(e, count=200, seed=0):
    """Points on the ellipsoid's surface."""
    u = np.random.default_rng(seed).normal(size=(count, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    q, r, c = (np.asarray(e.axes, float), np.asarray(e.radii, float),
               np.asarray(e.center, float))
    return c + (u * r) @ q.T


def implicit(e, x):
    """|diag(1/r) Qᵀ (x − c)| (1 on the surface)."""
    q, r, c = (np.asarray(e.axes, float), np.asarray(e.radii, float),
               np.asarray(e.center, float))
    return np.linalg.norm(((x - c) @ q) / r, axis=1)


def test_identity_instance_is_the_prototype():
    e = proto_shell()
    (w,) = forest.instance_shells([e], np.eye(4)[None])
    np.testing.assert_allclose(w.center, e.center, atol=1e-6)
    np.testing.assert_allclose(w.radii, np.sort(e.radii)[::-1], atol=1e-6)  # SVD order
    x = boundary(e)
    np.testing.assert_allclose(implicit(w, x), 1.0, atol=1e-5)


@pytest.mark.parametrize("name, a, t", [
    ("translated", np.eye(3), (10, -4, 0.5)),
    ("rotated", rot_z(1.1), (0, 0, 0)),
    ("uniform scale", 2.5 * np.eye(3), (3, 3, 0)),
    ("non-uniform scale + rotation", rot_z(0.7) @ np.diag([2.0, 0.5, 1.3]), (1, 2, 3)),
    ("mirrored, sheared", np.array([[-1.0, 0.3, 0], [0, 1, 0], [0, 0, 0.8]]), (5, 0, 0)),
])
def test_instance_is_the_exact_image(name, a, t):
    e = proto_shell()
    m = affine(a, t)
    (w,) = forest.instance_shells([e], m[None])
    q = np.asarray(w.axes, float)
    np.testing.assert_allclose(q.T @ q, np.eye(3), atol=1e-5, err_msg=name)
    assert np.linalg.det(q) > 0, name
    x = boundary(e) @ a.T + np.asarray(t, float)  # image of the surface is the surface
    np.testing.assert_allclose(implicit(w, x), 1.0, atol=2e-5, err_msg=name)
    np.testing.assert_allclose(w.center, a @ np.asarray(e.center, float) + t, atol=1e-4)
    vol = np.prod(np.asarray(w.radii, float))
    assert vol == pytest.approx(np.prod(np.asarray(e.radii, float)) * abs(np.linalg.det(a)),
                                rel=1e-5)


def test_many_instances_order_and_degenerate_scale():
    shells = [proto_shell(), _core.Ellipsoid.from_sphere(_core.Sphere(np.float32([0, 0, 1]), 0.5))]
    mats = np.stack([affine(t=(i, 0, 0)) for i in range(3)] + [affine(np.zeros((3, 3)))])
    out = forest.instance_shells(shells, mats)
    assert len(out) == 6  # the zero-scaled instance is dropped
    np.testing.assert_allclose(out[3].center, [1, 0, 1], atol=1e-6)  # instance-major
    u = forest.unique_matrices(np.concatenate([mats, mats[:2]]))
    assert len(u) == 4


def items(offset=(0.0, 0.0, 0.0), ground=True, tree=True):
    role = {"Trunk": "TRUNK", "Leaves": "CANOPY", "Ground": "GROUND"}
    out = []
    for name, (p, t) in ts.scene(False).items():
        if (name == "Ground" and not ground) or (name != "Ground" and not tree):
            continue
        if name != "Ground":
            p = p + np.float32(offset)
        out.append(core.SceneItem(name, role[name], "" if name == "Ground" else "T", p,
                                    ts.vertex_normals(p, t), t))
    return out


def test_ground_under_an_instance_equals_a_real_tree():
    settings = core.BakeSettings(method="ellipsoid", tau=2.0)
    offset = (3.0, 1.5, 0.0)
    real = core.bake(items(offset), settings)[0]
    want = {r.name: r.ao for r in real}["Ground"]
    proto = core.prepare(items(ground=False), settings)  # the tree at the origin, baked once
    plan = core.prepare(items(tree=False), settings)
    # ε as the scene's own occluders use it (the core's default), to compare one law.
    core.attach_forest(plan, [forest.prototype_from_plan(proto, "T", affine(t=offset)[None])],
                         epsilon=forest.DEFAULT_EPSILON)
    (ground,) = [it for it in items(tree=False)]
    got = core.evaluate_item(plan, ground).ao
    assert want.min() < 0.8  # the tree does shade the ground
    np.testing.assert_allclose(got, want, atol=1e-4)
    assert any("forest: 1 instance" in n for n in plan.notes)


def test_forest_cost_is_bounded_by_the_cut_off():
    """400 instances on a lattice: a receiver tests at most the occluders in reach, and the
    cut-off changes the AO by < ε per occluder in reach (stated bound: 0.05 here)."""
    sh = [_core.Ellipsoid.from_sphere(_core.Sphere(np.float32([0, 0, 3]), 1.0))]
    mats = np.stack([affine(t=(6.0 * i, 6.0 * j, 0)) for i in range(20) for j in range(20)])
    cut = forest.Forest([forest.Prototype("T", sh, 1.0, mats)], epsilon=1e-2)
    full = forest.Forest([forest.Prototype("T", sh, 1.0, mats)], epsilon=0.0)
    assert cut.instances == 400 and cut.max_candidates < 100 and full.max_candidates == 400
    rng = np.random.default_rng(1)
    p = np.c_[rng.uniform(0, 114, (2000, 2)), np.zeros(2000)].astype(np.float32)
    n = np.tile(np.float32([0, 0, 1]), (2000, 1))
    a, b = cut.ao(p, n), full.ao(p, n)
    assert np.all(a >= b - 1e-6) and (a - b).max() < 0.05


# --- Instanced trees under the exact rung and auto (docs/DESIGN.md, 'How each role is lit')
FOREST = [affine(rot_z(0.3), (-4.0, -3.0, 0.0)), affine(rot_z(1.9) * 1.1, (3.5, -2.5, 0.0)),
          affine(rot_z(-0.8) * 0.9, (0.5, 4.0, 0.0))]


def small_forest(settings):
    """Three instances of the test tree (its own plan, baked once at the origin) and the
    ground under them: (prototypes, ground item, the same trees realised as real triangles)."""
    tree = items(ground=False)
    proto = core.prepare(tree, settings)
    protos = [forest.prototype_from_plan(proto, "T", np.stack(FOREST), items=tree)]
    (ground,) = items(tree=False)
    v, t = forest.prototype_mesh(tree)
    real_v, real_t = [ground.positions], [ground.triangles]
    base = len(ground.positions)
    for m in FOREST:
        real_v.append((v.astype(np.float64) @ m[:3, :3].T + m[:3, 3]).astype(np.float32))
        real_t.append(t + base)
        base += len(v)
    rv = np.ascontiguousarray(np.concatenate(real_v))
    rt = np.ascontiguousarray(np.concatenate(real_t), np.int32)
    # The add-on's tracer starts the ground's vertices at Cycles' bake point with its faces;
    # so does this one (the trees' rows only occlude: any normal, each triangle a face).
    normals = np.zeros_like(rv)
    normals[:len(ground.positions)] = ground.normals
    faces = (ground.polygons if ground.polygons is not None
             else np.arange(len(ground.triangles)))
    first = int(faces.max()) + 1 if len(faces) else 0
    polygons = np.concatenate([faces, first + np.arange(len(rt) - len(ground.triangles))])
    realised = (rv, rt, {"normals": normals, "polygons": np.ascontiguousarray(polygons, np.int32)})
    return protos, ground, realised


def test_raytrace_ground_sees_instances_as_their_triangles():
    """The exact rung's ground AO under instanced trees is the AO of a tracer over the same
    triangles realised (un-instanced), to noise: rays hit the instances, no shell law."""
    settings = core.BakeSettings(method="raytrace", samples=64, seed=3)
    protos, ground, (rv, rt, shading) = small_forest(settings)
    plan = core.prepare([ground], settings, prototypes=protos)
    assert plan.tracer.instance_count == len(FOREST)
    got = core.evaluate_item(plan, ground).ao
    ids = np.arange(len(ground.positions), dtype=np.int32)
    want = np.asarray(_core.RayTracer(rv, rt, **shading).ao(
        ground.positions, ground.normals, samples=1024, seed=11, vertex_ids=ids))
    shaded = want < 0.95
    assert shaded.sum() > 50  # the trees do shade the ground
    # 64 rays against 1024: per-vertex noise ≤ sqrt(a(1−a)/64) ≤ 0.063, so the mean of |Δ|
    # over the shaded vertices stays well below 0.03 and its bias below 0.01.
    assert np.abs(got - want)[shaded].mean() < 0.03
    assert abs(float(np.mean(got[shaded] - want[shaded]))) < 0.01
    # The same rays (same seed) through the realised mesh: equal but for float rounding of
    # the instance transforms.
    same = np.asarray(_core.RayTracer(rv, rt, **shading).ao(
        ground.positions, ground.normals, samples=64, seed=3, vertex_ids=ids))
    assert np.abs(got - same).max() <= 2.0 / 64


def test_attach_forest_after_prepare_traces_instances():
    """attach_forest on an exact-rung plan rebuilds its tracer with the instances."""
    settings = core.BakeSettings(method="raytrace", samples=32, seed=3)
    protos, ground, (rv, rt, shading) = small_forest(settings)
    plan = core.prepare([ground], settings)
    before = core.evaluate_item(plan, ground).ao
    core.attach_forest(plan, protos)
    assert plan.tracer.instance_count == len(FOREST)
    got = core.evaluate_item(plan, ground).ao
    ids = np.arange(len(ground.positions), dtype=np.int32)
    same = np.asarray(_core.RayTracer(rv, rt, **shading).ao(
        ground.positions, ground.normals, samples=32, seed=3, vertex_ids=ids))
    assert np.abs(got - same).max() <= 2.0 / 32
    assert before.min() > 0.99 and got.min() < 0.8


def test_auto_on_a_forest_is_checked_against_traced_instances():
    """Auto's calibration on a ground under instanced trees traces the instances: its
    reference rays see them (the exact rung's sample error is its own noise only), and the
    proxy candidate's error is the instances' shell law against those rays."""
    settings = core.BakeSettings(method="auto", samples=64, seed=3, calibration_points=200)
    protos, ground, (rv, rt, shading) = small_forest(settings)
    plan = core.prepare([ground], settings, prototypes=protos)
    cal = plan.calibration
    assert cal and cal["instances_traced"]
    cands = cal["candidates"]
    assert set(cands) == {"ellipsoid", "raytrace"}
    # Reference (128 rays) and candidate (64 rays, another seed) both see the trees: noise only.
    assert cands["raytrace"]["rmse"] < 0.06
    # The shells' law is not the traced trees: a real error, measured against traced rays.
    assert cands["ellipsoid"]["rmse"] > cands["raytrace"]["rmse"]
    got = core.evaluate_item(plan, ground).ao
    ids = np.arange(len(ground.positions), dtype=np.int32)
    want = np.asarray(_core.RayTracer(rv, rt, **shading).ao(
        ground.positions, ground.normals, samples=256, seed=11, vertex_ids=ids))
    # Whatever auto chose, it was scored against these rays: its ground error stays near the
    # sample RMSE it reported.
    rmse = float(np.sqrt(np.mean((got - want) ** 2)))
    assert rmse < 1.5 * cands[plan.method]["rmse"] + 0.02
    assert not any("do not see the instanced trees" in n for n in plan.notes)


def test_auto_with_own_tree_and_instances_scores_against_traced_instances():
    """A real tree beside instanced ones: every candidate of auto's ladder (the proxies with
    the instances' shells as occluders, the exact rung with their triangles) is scored against
    reference rays that hit the instances."""
    settings = core.BakeSettings(method="auto", samples=64, seed=3, calibration_points=300)
    protos, _ground, _realised = small_forest(settings)
    plan = core.prepare(items(), settings, prototypes=protos)
    cal = plan.calibration
    assert cal["instances_traced"] and plan.forest is not None
    assert {"sphere", "ellipsoid", "raytrace"} <= set(cal["candidates"])
    assert cal["candidates"]["raytrace"]["rmse"] < 0.06  # both see the same triangles
    assert plan.tracer.instance_count == len(FOREST)


def _ground_error(method, **kw):
    """(MAE of the ground under small_forest against 512 rays through the realised trees,
    the plan) for a bake with ``method``."""
    settings = core.BakeSettings(method=method, samples=64, seed=3, calibration_points=200, **kw)
    protos, ground, (rv, rt, shading) = small_forest(settings)
    plan = core.prepare([ground], settings, prototypes=protos)
    got = core.evaluate_item(plan, ground).ao
    ids = np.arange(len(ground.positions), dtype=np.int32)
    want = np.asarray(_core.RayTracer(rv, rt, **shading).ao(
        ground.positions, ground.normals, samples=512, seed=11, vertex_ids=ids))
    return float(np.abs(got - want).mean()), plan


def test_the_forests_tau_is_fitted_on_the_ground_it_shades():
    """A prototype's τ comes from its own leaves (inside its crown); the ground sees the crowns
    from outside. With τ calibrated, one factor on every prototype's τ is fitted to the
    ground's sample against rays that trace the instances (core/forest_tau.py). Before, the
    shells' ground read 0.029 off here (bias -0.029); now 0.004."""
    err, plan = _ground_error("shells")
    fit = plan.calibration["forest"]
    assert 0.1 < fit["tau_scale"] < 0.9 and fit["rmse_after"] < fit["rmse_before"]
    assert plan.forest.tau_scale == fit["tau_scale"]
    assert any(n.startswith("forest τ × ") for n in plan.notes)
    assert err < 0.01, err
    # A τ the user gives is the forest's too: nothing fitted.
    _err, fixed = _ground_error("shells", tau=2.0)
    assert "forest" not in (fixed.calibration or {}) and fixed.forest.tau_scale == 1.0


def test_regression_bakes_a_ground_under_instanced_trees_alone():
    """The ray-free rung has no occluder of the scene's own to voxelise there: the ground takes
    the instances' shells, as under the density grid (before: 'needs a CANOPY, TRUNK or GRASS
    object'), with the forest's τ fitted as above."""
    err, plan = _ground_error("regression")
    grid_err, _grid = _ground_error("grid")
    assert plan.method == "regression" and "forest" in plan.calibration
    assert any("only occluders are instanced trees" in n for n in plan.notes)
    assert err < 0.01 and abs(err - grid_err) < 1e-6


def _blade_item(name="Blade"):
    p = np.float32([[-0.01, 0, 0], [0.01, 0, 0], [-0.005, 0, 0.2], [0.005, 0, 0.2]])
    n = np.tile(np.float32([0, -1, 0]), (4, 1))
    return core.SceneItem(name, "TRUNK", "proto", p, n, np.int32([[0, 1, 3], [0, 3, 2]]),
                          polygons=np.int32([0, 0]))


def test_realize_is_every_instance_moved_exactly():
    """Positions by each matrix, normals by its inverse transpose (unit), a mirrored copy's
    triangles wound the other way, polygon ids per copy, a zero-scaled instance dropped, and
    spans that find each copy again."""
    it = _blade_item()
    a = rot_z(0.7) @ np.diag([2.0, 1.0, 0.5])
    mats = np.stack([affine(), affine(a, (3, 1, 0)), affine(np.diag([-1.0, 1, 1]), (0, 5, 0)),
                     affine(np.zeros((3, 3)), (9, 9, 9))])
    real = forest.realize([it], [mats], "field", "GRASS", "proto")
    r = real.item
    assert (r.name, r.role) == ("field", "GRASS")
    assert len(r.positions) == 12 and len(r.triangles) == 6  # the singular one is gone
    assert real.spans == [("Blade", 0, 3, 4)]
    for k, m in enumerate(mats[:3]):
        np.testing.assert_allclose(r.positions[4 * k:4 * k + 4],
                                   it.positions @ m[:3, :3].T + m[:3, 3], atol=1e-6)
        want = it.normals @ np.linalg.inv(m[:3, :3])  # (A⁻ᵀ n)ᵀ = nᵀ A⁻¹
        want /= np.linalg.norm(want, axis=1, keepdims=True)
        np.testing.assert_allclose(r.normals[4 * k:4 * k + 4], want, atol=1e-6)
    # Each copy's face normal agrees with its vertex normals, the mirrored one's too.
    t = r.triangles
    face = np.cross(r.positions[t[:, 1]] - r.positions[t[:, 0]],
                    r.positions[t[:, 2]] - r.positions[t[:, 0]])
    assert np.all(np.einsum("ij,ij->i", face, r.normals[t[:, 0]]) > 0)
    assert list(r.polygons) == [0, 0, 1, 1, 2, 2]
    assert forest.realize([it], [mats[3:]], "none", "GRASS", "proto") is None


def test_sample_vertices_spreads_over_the_instances():
    it = _blade_item()
    mats = np.stack([affine(t=(i, 0, 0)) for i in range(10)])
    real = forest.realize([it], [mats], "field", "GRASS", "proto")
    [(name, idx, k, v)] = real.sample_vertices(4)
    assert (name, k, v) == ("Blade", 4, 4)
    # instances 0, 3, 6, 9: their vertices, instance-major
    np.testing.assert_allclose(real.item.positions[idx][::4, 0], [-0.01 + i for i in (0, 3, 6, 9)],
                               atol=1e-6)
    [(_n, idx_all, k_all, _v)] = real.sample_vertices(100)
    assert k_all == 10 and list(idx_all) == list(range(40))
    assert real.sample_vertices(4, names={"Other"}) == []


@pytest.mark.parametrize("tau", [None, 2.5])
def test_a_prototype_nobody_bakes_is_fitted_without_calibrating(tau):
    """forest_fit.fit_only: under auto, the fit of a prototype whose own AO is not baked is
    auto's fallback rung at the given τ (else the default), the same shells, trunks and τ as
    prepare gives at that rung, and no tracer or calibration; other methods are left to
    prepare (None)."""
    from canopy_ao.core import forest_fit
    from canopy_ao.core.ladder import DEFAULT_TAU
    tree = items(ground=False)
    plan = forest_fit.fit_only(tree, core.BakeSettings(method="auto", tau=tau, seed=3))
    want = core.prepare(tree, core.BakeSettings(method="ellipsoid", tau=tau or DEFAULT_TAU,
                                                seed=3))
    assert plan.method == want.method == "ellipsoid"
    assert plan.tau == want.tau == (tau or DEFAULT_TAU)
    assert plan.tracer is None and not plan.calibration and plan.lights is None
    got = forest.prototype_from_plan(plan, "T", affine()[None])
    ref = forest.prototype_from_plan(want, "T", affine()[None])
    assert got.tau == ref.tau and len(got.shells) == len(ref.shells) == 1
    assert len(got.solids) == len(ref.solids) >= 1  # the trunk occludes as a solid
    for a, b in zip(got.shells + got.solids, ref.shells + ref.solids):
        np.testing.assert_array_equal(a.center, b.center)
        np.testing.assert_array_equal(a.radii, b.radii)
    for method in ("ellipsoid", "raytrace", "shells"):
        assert forest_fit.fit_only(tree, core.BakeSettings(method=method, tau=tau)) is None
