"""Trees told apart by where they stand (canopy_ao.core.trees) inside the bake, no bpy."""
import numpy as np
import pytest

from canopy_ao import core
from canopy_ao.core import scene as core_scene
from real_shapes import bent_tubes, join, leaves, stem

pytest.importorskip("canopy_scenes")


def _normals(p, t):
    import canopy_scenes as cs
    return cs.vertex_normals(p, t)


def _item(name, role, mesh, tree, source):
    p, t = mesh
    return core.SceneItem(name, role, tree, p, _normals(p, t), t, tree_source=source)


def _grove(source, tree_a="Collection", tree_b="Collection", joined=False):
    """A dense crown and a sparse one 12 m apart, with their boles, on a ground."""
    rng = np.random.default_rng(5)
    la = leaves(rng, n=3000, centre=(0, 0, 5), radius=2.0)
    lb = leaves(rng, n=150, centre=(12, 0, 5), radius=2.0)
    ba = join(stem((0, 0), 4.0), bent_tubes(rng, 12, base=(0, 0)))
    bb = join(stem((12, 0), 4.0), bent_tubes(rng, 12, base=(12, 0)))
    xs = np.linspace(-6, 18, 25)
    gx, gy = np.meshgrid(xs, np.linspace(-6, 6, 13))
    gp = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], 1).astype(np.float32)
    i, j = np.meshgrid(np.arange(12), np.arange(24), indexing="ij")
    a = (i * 25 + j).ravel()
    gt = np.concatenate([np.stack([a, a + 1, a + 26], 1), np.stack([a, a + 26, a + 25], 1)])
    ground = core.SceneItem("Ground", "GROUND", "Collection", gp,
                            np.tile(np.float32([0, 0, 1]), (len(gp), 1)), gt.astype(np.int32),
                            tree_source=source)
    if joined:
        return [_item("Leaves", "CANOPY", join(la, lb), tree_a, source),
                _item("Wood", "TRUNK", join(ba, bb), tree_a, source), ground], len(la[0])
    return [_item("LeavesA", "CANOPY", la, tree_a, source),
            _item("LeavesB", "CANOPY", lb, tree_b, source),
            _item("WoodA", "TRUNK", ba, tree_a, source),
            _item("WoodB", "TRUNK", bb, tree_b, source), ground], len(la[0])


SETTINGS = dict(method="ellipsoid", tau=1.5)


def test_one_collection_bakes_as_two_trees():
    """Loose in one collection the two trees were fitted as one ellipsoid spanning both (the
    gap between them inside a crown); now they bake as if the user had named them."""
    named, _ = _grove("set", "A", "B")
    want, _rep = core.bake(named, core.BakeSettings(**SETTINGS))
    one, _ = _grove("set")  # what grouping by collection alone gave: one tree
    one, _rep = core.bake(one, core.BakeSettings(**SETTINGS))
    assert abs(one[-1].ao.mean() - want[-1].ao.mean()) > 0.05  # the ground: 0.72 vs 0.80
    items, _ = _grove("collection")
    got, rep = core.bake(items, core.BakeSettings(**SETTINGS))
    assert len(rep["proxies"]) == 2
    objs = rep["objects"]
    assert objs["LeavesA"]["tree"] == objs["WoodA"]["tree"] != objs["LeavesB"]["tree"]
    assert objs["LeavesB"]["tree"] == objs["WoodB"]["tree"]
    assert objs["LeavesA"]["tree_source"] == "collection" and objs["LeavesA"]["tree_why"]
    assert objs["LeavesA"]["predicted_seconds"] > 0  # the cost model's, per object
    for w, g in zip(want, got):
        assert np.abs(w.ao - g.ao).max() < 1e-5, w.name


def test_one_mesh_holding_two_trees_is_split():
    """All leaves joined into one mesh (and all wood into another): each vertex gets its own
    tree's lighting, as with separate objects."""
    named, _ = _grove("set", "A", "B")
    want, _ = core.bake(named, core.BakeSettings(**SETTINGS))
    items, n_a = _grove("collection", joined=True)
    got, rep = core.bake(items, core.BakeSettings(**SETTINGS))
    assert len(rep["proxies"]) == 2
    assert len(items[0].tree_names) == 2
    leaves_ao = got[0].ao
    assert np.abs(leaves_ao[:n_a] - want[0].ao).max() < 1e-5
    assert np.abs(leaves_ao[n_a:] - want[1].ao).max() < 1e-5
    parts = core_scene.parts(items[0])
    assert sum(len(idx) for _p, idx in parts) == len(items[0].positions)
    # Receivers that are not the item's vertices (texels) take the nearest crown's tree.
    plan = core.prepare(items, core.BakeSettings(**SETTINGS))
    it = items[0]
    as_texels = core.evaluate_receivers(plan, it, it.positions, it.normals)
    assert np.abs(as_texels - leaves_ao).max() < 1e-5


def test_tau_per_tree_lightens_the_sparse_tree(monkeypatch):
    """A dense crown and a sparse one: the scene-wide τ (what calibration gave before) darkens
    the sparse tree's leaves by ~0.3 against rays; τ per tree takes most of that away."""
    from canopy_ao.core import ladder, lighting
    items, _ = _grove("set", "A", "B")
    tracer = lighting.build_tracer(items)
    ref = {it.name: np.asarray(tracer.ao(it.positions, it.normals, samples=256, seed=9))
           for it in items}

    def bias(name):
        res, rep = core.bake(items, core.BakeSettings(method="ellipsoid", tau=None))
        return float(np.mean(next(r.ao for r in res if r.name == name) - ref[name])), rep
    per_tree, rep = bias("LeavesB")
    assert rep["tau_by_tree"]["B"] < 0.7 * rep["tau_by_tree"]["A"]
    monkeypatch.setattr(ladder, "tau_per_tree", lambda plan, m, tau, err: tau)
    one, rep_one = bias("LeavesB")
    assert rep_one["tau_by_tree"] == {}
    assert one < -0.2 and abs(per_tree) < abs(one) - 0.1, (one, per_tree)


def test_a_texels_sub_samples_stay_one_group_across_two_crowns():
    """A texel of a mesh holding two trees whose anti-aliasing sub-samples lie nearest to
    different crowns is still traced as one group (its rays dealt over its sub-samples), not
    split into the two trees' calls."""
    from canopy_ao.core import lighting
    items, n_a = _grove("collection", joined=True)
    plan = core.prepare(items, core.BakeSettings(method="raytrace", samples=16))
    it = items[0]
    idx = [0, n_a, 1, n_a + 1, n_a + 2, 2, n_a + 3, 3]  # two texels, each 2 + 2 across crowns
    p, n = it.positions[idx], it.normals[idx]
    got = core.evaluate_receivers(plan, it, p, n, group=4)
    # each texel as its own call (its tree's: the first sub-sample's): keyed as group 0
    want = np.concatenate([lighting.trace(plan, p[k:k + 4], n[k:k + 4],
                                          **lighting.ray_args(plan, 4)) for k in (0, 4)])
    np.testing.assert_array_equal(got, want)
