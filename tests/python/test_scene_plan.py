"""The native scene plan (_core.ScenePlan) against the Python composition it replaced
(lighting_reference.py): the same AO to ~1e-6 on scenes with several trees, interlocking crowns,
trunks, ground, grass, the grass layers over the ground, an instanced forest attached after the
plan, an AO distance and a τ per tree; built once per bake; bad input is a ValueError."""

import math
import os
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(__file__))

from canopy_ao import core  # noqa: E402
from canopy_ao.core import forest, grass_layer, lighting, ray_budget  # noqa: E402
from canopy_ao.core.native import _core  # noqa: E402
import lighting_reference  # noqa: E402
import tree_scene as ts  # noqa: E402

assert core.core_status()[0], core.core_status()[1]

# Three trees: A and B interlock (crowns 1.2 apart, radius 1.2), C stands alone; C has no
# trunk, D is a bare trunk (no leaves).
TREES = {"A": (-0.6, 0.0), "B": (0.6, 0.3), "C": (6.0, -2.0)}
TRUNKS = {"A": (-0.6, 0.0), "B": (0.6, 0.3), "D": (-5.0, 3.0)}


def forest_items():
    out = []
    for k, (name, (x, y)) in enumerate(TREES.items()):
        p, t = ts.leaves(count=600, center=(x, y, 2.6), seed=10 + k)
        out.append(core.SceneItem(f"Leaves{name}", "CANOPY", name, p, ts.vertex_normals(p, t), t))
    for name, (x, y) in TRUNKS.items():
        p, t = ts.cylinder()
        p = p + np.float32([x, y, 0.0])
        out.append(core.SceneItem(f"Trunk{name}", "TRUNK", name, p, ts.vertex_normals(p, t), t))
    p, t = ts.plane()
    out.append(core.SceneItem("Ground", "GROUND", "", p, ts.vertex_normals(p, t), t))
    p, t = ts.grass(region=(-2.0, 3.0))  # under the crowns, so the ground has a grass layer
    out.append(core.SceneItem("Grass", "GRASS", "", p, ts.vertex_normals(p, t), t))
    return out


@pytest.fixture(scope="module")
def items():
    return forest_items()


def plan_for(items, method, distance):
    return core.prepare(items, core.BakeSettings(method=method, tau=1.5, distance=distance,
                                                 shells=3))


def probe_points(n=2000, seed=5):
    """Points through the crowns, the trunks and over the ground, random unit normals."""
    rng = np.random.default_rng(seed)
    p = rng.uniform([-6, -4, 0], [7, 4, 4.5], size=(n, 3)).astype(np.float32)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return p, d.astype(np.float32)


@pytest.mark.parametrize("method", ["sphere", "ellipsoid", "reeves_blau", "shells", "medium"])
@pytest.mark.parametrize("distance", [0.0, 2.5])
def test_native_plan_equals_the_python_composition(items, method, distance):
    plan = plan_for(items, method, distance)
    assert set(plan.fits) == {"A", "B", "C"} and set(plan.trunks) == {"A", "B", "D"}
    assert plan.grass_layers, "the ground must have a grass layer over it"
    taus = {"A": 0.7, "B": 2.4, None: 1.5}  # C takes the scene-wide τ
    probe_p, probe_n = probe_points()
    worst, inside_two = 0.0, 0
    for it in items:
        for p, n in ((it.positions, it.normals), (probe_p, probe_n)):
            got = lighting.evaluate_points(plan, it.role, it.tree, it.name, p, n, method, taus)
            want = lighting_reference.evaluate(plan, it.role, it.tree, it.name, p, n, method,
                                               taus)
            assert got.dtype == np.float32 and got.shape == (len(p),)
            worst = max(worst, float(np.max(np.abs(got - want))))
    # The probes do reach into both interlocking crowns at once (the first one's model wins).
    a, b = (lighting.lights(plan).native.shells(lighting.lights(plan).index[t], method)
            for t in "AB")
    in_a = np.any([e.contains(probe_p) for e in a], axis=0)
    in_b = np.any([e.contains(probe_p) for e in b], axis=0)
    inside_two = int(np.sum(in_a & in_b))
    assert inside_two > 0
    assert worst <= 2e-6, worst


def test_one_plan_per_bake_reused_by_calibration(items, monkeypatch):
    built = []
    real = _core.ScenePlan

    def counting(*args, **kwargs):
        built.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(_core, "ScenePlan", counting)
    settings = core.BakeSettings(method="shells", tau=None, distance=0.0, shells=2,
                                 calibration_points=64, calibration_samples=16)
    results, report = core.bake(items, settings)
    assert report["calibration"], "τ must have been calibrated (many evaluations)"
    assert len(built) == 1
    assert all(np.all((r.ao >= 0) & (r.ao <= 1)) for r in results)


def test_refit_proxies_rebuild_the_plan(items):
    plan = plan_for(items, "ellipsoid", 0.0)
    first = lighting.lights(plan)
    assert lighting.lights(plan) is first
    sphere, ell, shells = plan.fits["C"]
    plan.fits["C"] = (sphere, _core.Ellipsoid(ell.center, ell.axes, np.asarray(ell.radii) * 2),
                      shells)
    assert lighting.lights(plan) is not first


def test_bad_input_is_a_value_error():
    s = _core.Sphere((0, 0, 3), 1.0)
    e = _core.Ellipsoid.from_sphere(s)
    plan = _core.ScenePlan([(s, e, [e]), None], [[], [e]])
    p = np.zeros((4, 3), np.float32)
    n = np.tile(np.float32([0, 0, 1]), (4, 1))
    assert plan.trees == 2
    ok = plan.evaluate(p, n, "GROUND", -1, "shells", [1.0, 1.0])
    assert ok.shape == (4,) and np.all((ok >= 0) & (ok <= 1))
    bad = [
        dict(role="LEAF"),
        dict(method="grid"),
        dict(tau=[1.0]),
        dict(tau=[1.0, -1.0]),
        dict(tree=2),
        dict(tree=np.zeros(3, np.int32)),
        dict(tree=np.full(4, 5, np.int32)),
        dict(tree=np.zeros(4, np.int64)),
        dict(role="GRASS"),
        dict(grass=(0.0, 0.3)),
        dict(role="GRASS", grass=(0.0, 0.0)),
        dict(role="GRASS", grass="tall"),
    ]
    for change in bad:
        kw = dict(role="GROUND", tree=-1, method="shells", tau=[1.0, 1.0], grass=None)
        kw.update(change)
        with pytest.raises(ValueError):
            plan.evaluate(p, n, **kw)
    with pytest.raises(ValueError):
        plan.evaluate(p.astype(np.float64), n, "GROUND", -1, "shells", 1.0)
    for crowns, trunks in (([None], []), ([(s, e)], [[]]), ([(s, e, [])], [[]]),
                           (["oak"], [[]]), ([None], [["bark"]])):
        with pytest.raises(ValueError):
            _core.ScenePlan(crowns, trunks)
    with pytest.raises(ValueError):
        _core.ScenePlan([], [], distance=0.0)


def test_empty_receivers_and_no_trees():
    e0 = np.zeros((0, 3), np.float32)
    empty = _core.ScenePlan([], [])
    assert empty.evaluate(e0, e0, "CANOPY", -1, "sphere", []).shape == (0,)
    p = np.float32([[0, 0, 0.1], [1, 0, 0.2]])
    n = np.float32([[0, 0, 1], [1, 0, 0]])
    assert np.all(empty.evaluate(p, n, "GROUND", -1, "medium", 1.0) == 1.0)
    blades = empty.evaluate(p, n, "GRASS", -1, "medium", 1.0, grass=(0.0, 0.3))
    np.testing.assert_allclose(blades, _core.ao_grass(p, n, 0.0, 0.3), atol=1e-7)


@pytest.mark.parametrize("method", ["ellipsoid", "medium"])
def test_an_item_holding_several_trees_is_one_call_with_a_tree_per_receiver(method):
    """One mesh holding the trunks of A and B (a grove exported as one object): each vertex
    is lit with its own tree, its own trunk left out, as a per-tree evaluation would."""
    items = forest_items()
    ta, tb = (it for it in items if it.name in ("TrunkA", "TrunkB"))
    both = core.SceneItem("Trunks", "TRUNK", "A", np.concatenate([ta.positions, tb.positions]),
                          np.concatenate([ta.normals, tb.normals]),
                          np.concatenate([ta.triangles, tb.triangles + len(ta.positions)]),
                          tree_labels=np.repeat(np.int32([0, 1]), [len(ta.positions),
                                                                   len(tb.positions)]),
                          tree_names=("A", "B"))
    items = [it for it in items if it.name not in ("TrunkA", "TrunkB")] + [both]
    plan = core.prepare(items, core.BakeSettings(method=method, tau=1.5, distance=0.0))
    calls = []
    real = lighting.lights(plan).native.evaluate

    class Counting:
        def evaluate(self, *args, **kwargs):
            calls.append(1)
            return real(*args, **kwargs)

    lit = lighting.lights(plan)
    lit.native, saved = Counting(), lit.native
    try:
        got = core.evaluate_receivers(plan, both, both.positions, both.normals,
                                      vertices=slice(None))
    finally:
        lit.native = saved
    assert len(calls) == 1
    want = np.concatenate([
        lighting_reference.evaluate(plan, "TRUNK", t, "Trunks", it.positions, it.normals,
                                    method, plan.taus()) for t, it in (("A", ta), ("B", tb))])
    np.testing.assert_allclose(got, want, atol=2e-6)
    # The comparison tells the trees apart: every vertex lit as tree A's would differ.
    as_a = lighting.evaluate_points(plan, "TRUNK", "A", "Trunks", both.positions, both.normals,
                                    method, plan.taus())
    assert float(np.max(np.abs(as_a - want))) > 1e-5


def test_calibration_batches_equal_per_item_evaluation(items):
    """Calibration evaluates its sample in one scene-plan call per role (ladder._batches),
    which must give each point what its own item's evaluation gives."""
    from canopy_ao.core import ladder
    plan = plan_for(items, "shells", 2.0)
    split = core.scene.split_trees(items)
    groups = []
    for it, idx in ladder.sample_receivers(split, 300, seed=3):
        groups.append((it, np.ascontiguousarray(it.positions[idx]),
                       np.ascontiguousarray(it.normals[idx]), None))
    taus = {"A": 0.5, "B": 3.0, "C": 1.1, None: 1.5}
    batches = ladder._batches(groups)
    assert {role for role, _key in batches} == {"CANOPY", "TRUNK", "GROUND", "GRASS"}
    assert len(batches) < len(groups)
    for method in ("ellipsoid", "medium"):
        want = np.concatenate([lighting.evaluate_points(plan, it.role, it.tree, it.name, p, n,
                                                        method, taus)
                               for it, p, n, _own in groups])
        got = np.full(len(want), np.nan, np.float32)
        for (role, key), (trees, p, n, where) in batches.items():
            got[where] = lighting.evaluate_points(plan, role, trees, key, p, n, method, taus)
        np.testing.assert_allclose(got, want, atol=1e-6)


# --- The forest and the grass layers, in the same native call ---------------------------------

def _affine(angle, scale, t):
    c, s = np.cos(angle), np.sin(angle)
    m = np.eye(4)
    m[:3, :3] = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ np.diag(scale)
    m[:3, 3] = t
    return m


def prototypes(mesh=False):
    """Two prototypes, each a few instances around (and one inside) the scene's trees: one
    with two crown shells and a trunk, rotated, scaled non-uniformly, one instance mirrored;
    one with a single shell of another τ and no trunk."""
    crown = [_core.Ellipsoid((0.3, 0.0, 2.4), np.eye(3, dtype=np.float32), (1.0, 0.8, 0.9)),
             _core.Ellipsoid((-0.4, 0.2, 2.8), np.eye(3, dtype=np.float32), (0.7, 0.7, 0.6))]
    trunk = [_core.Ellipsoid((0.0, 0.0, 1.0), np.eye(3, dtype=np.float32), (0.15, 0.15, 1.0))]
    oaks = np.stack([_affine(0.3, (1, 1, 1), (-3.0, 2.5, 0)),
                     _affine(1.2, (1.3, 0.8, 1.1), (3.0, -3.0, 0)),
                     _affine(-0.7, (-1, 1, 1), (2.5, 2.8, 0)),  # mirrored
                     _affine(0.0, (0.9, 0.9, 0.9), (0.0, 0.2, 0.4))])  # in the grove's crowns
    pines = np.stack([_affine(0.5, (1, 1, 1.6), (-4.5, -2.5, 0)),
                      _affine(2.0, (1, 1, 1.2), (5.0, 2.0, 0))])
    pine = [_core.Ellipsoid((0, 0, 3.0), np.eye(3, dtype=np.float32), (0.6, 0.6, 1.4))]
    tri = None
    if mesh:
        p, t = ts.leaves(count=300, center=(0.0, 0.0, 2.6), seed=4)
        tri = (np.ascontiguousarray(p, np.float32), np.ascontiguousarray(t, np.int32))
    return [forest.Prototype("Oak", crown, 1.3, oaks, trunk, tri),
            forest.Prototype("Pine", pine, 2.6, pines, [], tri)]


@pytest.mark.parametrize("method", ["sphere", "ellipsoid", "reeves_blau", "shells", "medium"])
@pytest.mark.parametrize("distance", [0.0, 2.5])
def test_forest_and_grass_layers_are_in_the_one_native_call(items, method, distance):
    """The plan built first, the forest attached after it (attach_forest): the same ScenePlan
    (its trees' grids not rebuilt) now multiplies every receiver by the instances, and the
    ground by the grass layer, as the Python multipliers it replaced did."""
    plan = plan_for(items, method, distance)
    lit = lighting.lights(plan)
    native = lit.native
    probe_p, probe_n = probe_points(seed=8)
    taus = {"A": 0.7, "B": 2.4, None: 1.5}
    before = lighting.evaluate_points(plan, "GROUND", "", "Ground", probe_p, probe_n, method,
                                      taus)
    core.attach_forest(plan, prototypes())
    assert lighting.lights(plan) is lit and lit.native is native
    assert native.forest is plan.forest.native and native.grass_covers == len(plan.grass_layers)
    calls = []
    real_ao = plan.forest.native

    class Watch:  # the other rungs' multiplier must not run for an analytic rung
        def ao(self, *a):
            calls.append(1)
            return real_ao.ao(*a)

    plan.forest.native = Watch()
    worst = 0.0
    try:
        for it in items:
            for p, n in ((it.positions, it.normals), (probe_p, probe_n)):
                got = lighting.evaluate_points(plan, it.role, it.tree, it.name, p, n, method,
                                               taus)
                want = lighting_reference.evaluate(plan, it.role, it.tree, it.name, p, n,
                                                   method, taus)
                assert got.dtype == np.float32 and got.shape == (len(p),)
                worst = max(worst, float(np.max(np.abs(got - want))))
    finally:
        plan.forest.native = real_ao
    assert not calls
    assert worst <= 2e-6, worst
    after = lighting.evaluate_points(plan, "GROUND", "", "Ground", probe_p, probe_n, method,
                                     taus)
    assert float(np.max(before - after)) > 0.05  # the instances do shade the probes
    assert np.all(after <= before + 1e-6)


def test_a_forest_given_to_prepare_is_in_the_plan_too(items):
    protos = prototypes()
    settings = core.BakeSettings(method="medium", tau=1.5, distance=0.0, shells=3)
    plan = core.prepare(items, settings, prototypes=protos)
    assert lighting.lights(plan).native.forest is plan.forest.native
    for it in items:
        got = core.evaluate_item(plan, it).ao
        want = lighting_reference.evaluate(plan, it.role, it.tree, it.name, it.positions,
                                           it.normals, "medium", plan.taus())
        np.testing.assert_allclose(got, want, atol=2e-6)


@pytest.mark.parametrize("mesh", [False, True])
def test_the_exact_rung_multiplies_the_forest_only_when_its_rays_miss_the_instances(items,
                                                                                   mesh):
    settings = core.BakeSettings(method="raytrace", samples=16, seed=2, distance=0.0)
    plan = core.prepare(items, settings, prototypes=prototypes(mesh=mesh))
    assert lighting.traces_instances(plan) == mesh
    ground = next(it for it in items if it.role == "GROUND")
    got = core.evaluate_item(plan, ground).ao
    own = {"vertex_ids": np.arange(len(ground.positions), dtype=np.int32)}
    own = lighting.own_ids(plan, ground.name, own)
    assert ray_budget.applies(plan, ground.name, own)  # the exact rung's rays at vertices
    rays = ray_budget.trace(plan, ground.name, ground.positions, ground.normals, own)
    want = rays if mesh else np.clip(rays * lighting_reference.forest_ao(
        plan.forest, ground.positions, ground.normals), 0, 1)
    np.testing.assert_allclose(got, want, atol=1e-6)


def test_grass_cover_equals_the_numpy_disc_count():
    """The core's per-point grass law (GrassCover) against the numpy formula it replaced, for
    footprints whose disc spans one cell or several (blade heights against the cell size)."""
    rng = np.random.default_rng(3)
    discs = set()
    for blade, count in ((0.3, 300), (0.3, 3000), (1.5, 400)):
        p, t = ts.grass(count=count, height=blade, region=(-2.0, 3.0), seed=count)
        layer = grass_layer.grass_layer("g", p, t, 0.0, blade)
        discs.add(int(np.ceil(layer.blade / layer.cells.h)))
        q = np.column_stack([rng.uniform(-3.0, 4.0, 5000), rng.uniform(-3.0, 3.0, 5000),
                             rng.uniform(-1.3 * blade, 1.3 * blade, 5000)]).astype(np.float32)
        got = layer.ground_visibility(q)
        want = lighting_reference.ground_visibility(layer, q)
        assert got.dtype == np.float32
        np.testing.assert_array_equal(got, want)
        # Every case: inside (a disc smaller than the field), at the edge, away.
        if blade < 1.0:
            assert np.sum(got == np.float32(layer.visibility)) > 100
        assert np.sum((got > layer.visibility + 1e-3) & (got < 1)) > 100
        assert np.sum(got == 1) > 100
    assert len(discs) == 3, discs  # discs of different radii, in cells


def test_forest_and_cover_bad_input_is_a_value_error():
    e = _core.Ellipsoid((0, 0, 3), np.eye(3, dtype=np.float32), (1, 1, 1))
    keys = np.array([41, 42, 83], np.int64)
    ok = _core.GrassCover(0.0, 0.3, 0.4, 0.2, (0.0, 0.0), 40, keys)
    assert ok.ground_visibility(np.zeros((0, 3), np.float32)).shape == (0,)
    for args in ((0.0, 0.0, 0.4, 0.2, (0, 0), 40, keys), (0.0, 0.3, 1.4, 0.2, (0, 0), 40, keys),
                 (math.nan, 0.3, 0.4, 0.2, (0, 0), 40, keys),
                 (0.0, 0.3, 0.4, 0.2, (0, 0, 0), 40, keys), (0.0, 0.3, 0.4, 0.2, (0, 0), 0, keys),
                 (0.0, 0.3, 0.4, 0.2, (0, 0), 40, keys[::-1].copy()),
                 (0.0, 0.3, 0.4, 0.2, (0, 0), 40, keys.astype(np.int32)),
                 (0.0, 0.3, 0.4, 1e-9, (0, 0), 40, keys)):
        with pytest.raises(ValueError):
            _core.GrassCover(*args)
    with pytest.raises(ValueError):
        ok.ground_visibility(np.zeros((2, 3), np.float64))
    for crowns, solids, kw in (([([e], -1.0)], [], {}), ([([e],)], [], {}), ([("oak", 1.0)], [], {}),
                               ([([e], 1.0)], ["bark"], {}), ([], [], {"epsilon": 1.0}),
                               ([], [], {"distance": 0.0})):
        with pytest.raises(ValueError):
            _core.ForestOccluders(crowns, solids, **kw)
    plan = _core.ScenePlan([], [], grass_covers=[ok])
    for bad in ("forest", ok, 3):
        with pytest.raises(ValueError):
            plan.set_forest(bad)
    with pytest.raises(ValueError):
        _core.ScenePlan([], [], grass_covers=["lawn"])
    f = _core.ForestOccluders([([e], 1.0)], [])
    plan.set_forest(f)
    assert plan.forest is f
    plan.set_forest(None)
    assert plan.forest is None


def test_plan_methods_are_the_tau_rungs():
    from canopy_ao.core import ladder
    from canopy_ao.core.rungs import base as rungs
    plan_rungs = [r for r in rungs.ladder() if r.scene_plan]
    assert {r.name for r in plan_rungs} == set(ladder.TAU_METHODS)
    # Each names its own native PlanMethod, and the module reads a name as the same method.
    if hasattr(_core, "PlanMethod"):
        assert [rungs.plan_method(r) for r in plan_rungs] == [_core.PlanMethod(r.name)
                                                              for r in plan_rungs]
        empty = _core.ScenePlan([], [])
        assert empty.max_candidates(_core.PlanMethod.shells) == empty.max_candidates("shells")
        for bad in ("grid", 3, None):  # not a scene-plan rung: a ValueError naming the choices
            with pytest.raises(ValueError, match="method must be a PlanMethod"):
                empty.max_candidates(bad)


def test_one_tree_under_a_forest_gets_the_instances_on_its_own_leaves():
    """A single tree (its leaves all inside its own crown: the trees' part is its in-shell
    kernel alone) beside instanced trees: its leaves and the ground still get the forest."""
    one = [it for it in forest_items() if it.name in ("LeavesC", "Ground")]
    plan = core.prepare(one, core.BakeSettings(method="ellipsoid", tau=1.5, distance=0.0),
                        prototypes=prototypes())
    for it in one:
        got = core.evaluate_item(plan, it).ao
        want = lighting_reference.evaluate(plan, it.role, it.tree, it.name, it.positions,
                                           it.normals, "ellipsoid", plan.taus())
        np.testing.assert_allclose(got, want, atol=2e-6)
        alone = lighting_reference.forest_ao(plan.forest, it.positions, it.normals)
        assert float(alone.min()) < 0.95, it.name  # the instances do reach this item
