"""The ray-free regression rung and the near/far hybrid (canopy_ao.core), no bpy.

Against Embree on the small tree + ground scene of tree_scene.py: the regression of the traced
sample must beat the density grid it starts from; both rungs are deterministic and scale-free
(a scene 100x larger bakes the same AO), and the regression bakes a grass-only scene.
"""
import os
import sys

import numpy as np
import pytest

HERE = os.path.dirname(__file__)
sys.path.insert(0, os.path.join(HERE, "..", "..", "addon"))
sys.path.insert(0, HERE)

from canopy_ao import core  # noqa: E402
from canopy_ao.core import leaf_features, regression, regression_fit  # noqa: E402
from canopy_ao.core.native import _core  # noqa: E402
import tree_scene as ts  # noqa: E402

assert core.core_status()[0], core.core_status()[1]  # an unbuilt module fails, not skips

ROLE = ts.ROLE


def items(names=("Trunk", "Leaves", "Ground"), scale=1.0):
    out = []
    for name, (p, t) in ts.scene(with_grass=True).items():
        if name in names:
            p = (p * np.float32(scale)).astype(np.float32)
            out.append(core.SceneItem(name, ROLE[name], "T" if name in ("Trunk", "Leaves") else "",
                                      p, ts.vertex_normals(p, t), t))
    return out


def reference(its, samples=512):
    """Embree at every vertex, each skipping only its own triangles."""
    V = np.concatenate([it.positions for it in its])
    offs = np.cumsum([0] + [len(it.positions) for it in its])
    T = np.concatenate([it.triangles + o for it, o in zip(its, offs)]).astype(np.int32)
    N = np.concatenate([it.normals for it in its])
    ids = np.arange(len(V), dtype=np.int32)
    return np.asarray(_core.RayTracer(V, T).ao(V, N, samples=samples, seed=99, vertex_ids=ids))


def bake(its, method, **kw):
    res, rep = core.bake(its, core.BakeSettings(method=method, **kw))
    return np.concatenate([r.ao for r in res]), rep


@pytest.fixture(scope="module")
def scene():
    its = items()
    return its, reference(its)


def test_regression_beats_the_grid_it_starts_from(scene, monkeypatch):
    its, ref = scene
    got, rep = bake(its, "regression")
    grid, _ = bake(its, "grid")  # with the ground as an opaque patch (core/walls.py)
    mae, mae_grid = np.abs(got - ref).mean(), np.abs(grid - ref).mean()
    assert mae < mae_grid, (mae, mae_grid)
    # Its features are the density grid's, without the ground's patch: well beyond that grid.
    monkeypatch.setattr(core.walls, "build", lambda items: [])
    raw, _ = bake(its, "grid")
    mae_raw = np.abs(raw - ref).mean()
    assert mae < 0.7 * mae_raw, (mae, mae_raw)
    assert mae < 0.06 and np.corrcoef(got, ref)[0, 1] > 0.9
    assert rep["method"] == "regression"
    cal = rep["calibration"]
    assert cal["calibration_points"] <= regression.POINTS  # no rays beyond the sample
    assert set(cal["groups"]) == {"T/TRUNK", "T/CANOPY", "-/GROUND"}


@pytest.mark.parametrize("method", ["regression", "hybrid"])
def test_deterministic_and_scale_free(method):
    a, _ = bake(items(), method)
    b, _ = bake(items(), method)
    np.testing.assert_array_equal(a, b)
    big, _ = bake(items(scale=100.0), method)
    d = np.abs(big - a)
    assert d.mean() < 1e-3, d.mean()
    # Within one unit of the world origin Cycles' bake point (a move of 1e-4 × max(1, |x|)) and
    # its self-intersection offset (2^-16 × Ng within 1/32 of it) are absolute lengths, which
    # the exact rung reproduces: there a vertex's start is not scale-free (the vertex at the
    # origin, inside the trunk's base, reads 0 here and 0.12 at 100 ×).
    far = np.abs(np.concatenate([it.positions for it in items()])).max(axis=1) >= 1.0
    assert (~far).sum() < 0.05 * far.size
    # The hybrid's near rays, as the exact rung's, may flip one grazing ray of 64 at a few
    # vertices (1/64 = 0.016; raytrace alone: 0.016 at 16 of 8,000 vertices here).
    assert d[far].max() < (0.02 if method == "regression" else 1 / 64 + 0.01), d[far].max()


@pytest.mark.parametrize("resolution", [32, 47, 56])
def test_features_scale_free_at_any_resolution(resolution):
    """A leaf vertex on the grid box's top face (the crown's highest point) reads the same
    features in a scene and the same ×1000: the swept field has an empty rim."""
    small, big = items(), items(scale=1000.0)
    a = regression.RegressionRung(small, resolution=resolution)
    b = regression.RegressionRung(big, resolution=resolution)
    for s_, b_ in zip(small, big):
        own = {"vertex_ids": np.arange(len(s_.positions))}
        fa = np.asarray(a._compute(s_.tree, s_.positions, s_.normals, s_.name, own))
        fb = np.asarray(b._compute(b_.tree, b_.positions, b_.normals, b_.name, own))
        assert np.abs(fa - fb).max() < 1e-2, (s_.name, np.abs(fa - fb).max())
        got = a.ao(s_.role, s_.tree, s_.positions, s_.normals, s_.name, own)
        assert np.abs(got - b.ao(b_.role, b_.tree, b_.positions, b_.normals, b_.name,
                                 own)).max() < 0.02


def test_calibration_is_sized_to_the_scene_and_shares_the_bvh(scene):
    its, _ = scene
    receivers = sum(len(it.positions) for it in its)
    _, rep = bake(its, "regression")
    cal = rep["calibration"]
    assert cal["receivers"] == receivers
    # No rays beyond the sample (and the bake's buried test), the sample at most
    # RAYS_PER_RECEIVER per receiver (or the floor of MIN_POINTS × MIN_SAMPLES rays).
    floor = regression.MIN_POINTS * regression.MIN_SAMPLES
    assert cal["calibration_rays"] <= max(regression.RAYS_PER_RECEIVER * receivers, floor)
    assert cal["calibration_points"] <= regression.POINTS
    assert cal["shared_tracer"]  # the bake's BVH, not a second one
    own, rep_own = regression.bake(its)  # the rung's own BVH: the same sample, the same AO
    assert not rep_own["shared_tracer"]
    got, rep_got = bake(its, "regression")
    # The same AO but where the bake's buried test set a receiver to 0 (bake._zero_buried).
    own = np.concatenate([own[it.name] for it in its])
    changed = np.abs(own - got) > 2e-3
    assert (got[changed] == 0).all()
    zeroed = sum(o["buried_set_to_0"] for o in rep_got["objects"].values())
    assert changed.sum() <= zeroed <= (got == 0).sum() and zeroed < 0.05 * len(got)
    assert regression.calibration_size(10 ** 6) == (regression.POINTS, 128)
    pts, spp = regression.calibration_size(2000)
    assert spp == regression.MIN_SAMPLES and pts * spp <= regression.RAYS_PER_RECEIVER * 2000
    assert regression.calibration_size(100) == (100, regression.MIN_SAMPLES)  # every point


def test_leaf_table_finds_each_leaf_and_places_points_on_it():
    # Two unit quads (two triangles each), the second 10 units off and twice the size.
    quad = np.array([[0, 0, 0], [1, 0, 0], [1, 0, 1], [0, 0, 1]], np.float64)
    P = np.concatenate([quad, quad * 2 + [10, 0, 0]]).astype(np.float32)
    T = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]], np.int32)
    leaves = leaf_features.LeafTable(P, T)
    assert len(leaves.size) == 2 and leaves.labels[0] != leaves.labels[4]
    np.testing.assert_allclose(leaves.size, [np.sqrt(0.5), 2 * np.sqrt(0.5)], rtol=1e-6)
    frame = (np.zeros(3, np.float32), 1.0, 0.0, 2.0)
    by_vertex = leaves.features(P, leaves.labels_of({"vertex_ids": np.arange(8)}, 8), frame)
    # Scale-free: the big leaf's corners sit where the small one's do, in its own size (up,
    # out of the axis and the length; toward the crown's middle depends on where a leaf is).
    np.testing.assert_allclose(by_vertex[:4, [0, 1, 3]], by_vertex[4:, [0, 1, 3]], atol=1e-6)
    h = np.sqrt(0.5)
    np.testing.assert_allclose(by_vertex[:, 0], [-h, -h, h, h] * 2, atol=1e-5)  # below / above
    np.testing.assert_allclose(by_vertex[:, 3], 1.0, atol=1e-5)  # every corner one radius out
    # A texel names its triangle: the same leaf, the same features at the same point.
    by_tri = leaves.features(P[[2, 6]], leaves.labels_of({"triangle_ids": [1, 3]}, 2), frame)
    np.testing.assert_allclose(by_tri, by_vertex[[2, 6]], atol=1e-6)
    # Unknown (-1) or no ids: the leaf's centre, all zero.
    assert not leaves.features(P[:2], leaves.labels_of({"vertex_ids": [-1, -1]}, 2), frame).any()
    assert not leaves.features(P[:2], leaves.labels_of(None, 2), frame).any()
    # Points all on leaves (no masked copy) read what they read beside an unknown one.
    some = leaves.labels_of({"vertex_ids": [0, 1, -1, 3, 4, 5, 6, 7]}, 8)
    mixed = leaves.features(P, some, frame)
    assert np.array_equal(mixed[[0, 1, 3, 4, 5, 6, 7]], by_vertex[[0, 1, 3, 4, 5, 6, 7]])
    assert not mixed[2].any()


def test_the_sample_never_exceeds_its_points():
    """Rounding each group's share up must not break the ray-free contract (<= 1024 points):
    nine similar groups each rounded up once gave 1026."""
    for sizes in ({i: 1000 + 37 * i for i in range(9)}, {"a": 3, "b": 10 ** 6},
                  {"a": 10 ** 5, "b": 5 * 10 ** 4, "c": 4096}):
        picks = regression._sample(sizes, regression.POINTS, 0)
        assert sum(len(v) for v in picks.values()) <= regression.POINTS
        assert all(len(v) >= 1 and len(set(v)) == len(v) for v in picks.values())


def test_regression_bakes_grass_without_a_tree_and_grass_shades_the_ground():
    its = items(("Grass", "Ground"))
    got, _ = bake(its, "regression")
    ref = reference(its)
    role = np.concatenate([np.full(len(it.positions), it.role) for it in its])
    ground = role == "GROUND"
    assert got[ground].min() < ref[ground].max() - 0.1  # blades shade the ground around them
    assert np.abs(got[ground] - ref[ground]).mean() < 0.03
    assert np.abs(got - ref).mean() < 0.08


def test_regression_refuses_a_scene_with_nothing_to_occlude():
    with pytest.raises(core.CanopyAOError, match="regression"):
        bake(items(("Ground",)), "regression")


def test_ridge_recovers_a_linear_law():
    rng = np.random.default_rng(0)
    X = np.c_[np.ones(400), rng.normal(size=(400, 3))]
    w = np.array([0.5, 0.1, -0.05, 0.02])
    y = X @ w + rng.normal(scale=1e-3, size=400)
    got, lam, cv = regression_fit.ridge(X, y)
    np.testing.assert_allclose(got, w, atol=5e-3)
    assert cv < 5e-3


def test_piece_columns_are_kept_only_where_they_cut_the_cv_error():
    """A fit reads its piece columns (LeafTable: where on its leaf or branch piece a point is)
    when the sample's AO depends on them, and drops them when they are noise (they cost more
    than they help on broadleaf limbs and on a grove's small per-tree samples)."""
    rng = np.random.default_rng(3)
    n, k = 600, regression_fit.NATIVE + leaf_features.LeafTable.COUNT
    F = rng.uniform(0.0, 1.0, (n, k)).astype(np.float32)
    base = 0.3 + 0.4 * F[:, 1]
    noise = rng.normal(scale=0.03, size=n)
    along = regression._fit(F, base + 0.25 * F[:, regression_fit.NATIVE] + noise)
    beside = regression._fit(F, base + noise)
    assert along.pieces and not beside.pieces
    assert along.predict(F).shape == (n,) and beside.predict(F[:, :regression_fit.NATIVE]).shape == (n,)
    # No piece columns at all (ground, grass): the one model, nothing chosen.
    G = F.copy()
    G[:, regression_fit.NATIVE:] = 0.0
    assert not regression._fit(G, base + noise).pieces


def test_the_rung_reports_which_fits_read_the_piece_columns(scene):
    its, _ref = scene
    plan = core.prepare(its, core.BakeSettings(method="regression"))
    fits = plan.regression.fits
    assert all(isinstance(f["piece_features"], bool) for f in fits.values())
    assert not any(f["piece_features"] for k, f in fits.items() if k.endswith("/GROUND"))
    ao = core.evaluate_item(plan, its[0]).ao
    assert np.isfinite(ao).all() and ((ao >= 0) & (ao <= 1)).all()


@pytest.mark.parametrize("method", ["hybrid", "regression"])
def test_command_line_offers_and_documents_the_rung(method):
    from canopy_ao import cli
    p = cli.build_parser()
    assert f"{method}:" in " ".join(p.format_help().split())  # its own line of --help
    opts = cli.options_from_args(p.parse_args(["--method", method]), world_distance=3.0)
    assert opts["method"] == method


def test_ray_free_auto_never_picks_rays_and_weighs_the_regression():
    from canopy_ao import cli
    assert "--ray-free" in cli.build_parser().format_help()
    its = items()
    _, free = bake(its, "auto", ray_free=True, time_budget=0.0)
    assert free["method"] not in ("raytrace", "hybrid")
    assert "regression" in free["calibration"]["candidates"]
    assert "raytrace" not in free["calibration"]["candidates"]
    _, full = bake(its, "auto", time_budget=0.0)
    assert "raytrace" in full["calibration"]["candidates"]


@pytest.mark.parametrize("pieces", [False, True])
def test_native_prediction_equals_the_expanded_model(pieces):
    """Model.predict's one native pass (held to the sample's range, expanded and weighted row
    by row, the leaf columns after the native ones) equals φ @ w on the expanded matrix, the
    fit's own terms (Model.expand), clipped to [0, 1]."""
    from canopy_ao.core.leaf_features import LeafTable
    from canopy_ao.core.regression_fit import NATIVE, Model
    rng = np.random.default_rng(7)
    F = rng.normal(size=(600, NATIVE + (LeafTable.COUNT if pieces else 0))).astype(np.float32)
    y = np.clip(0.5 + 0.1 * F[:, 0] - 0.05 * F[:, -1] + 0.02 * F[:, 1] * F[:, -1], 0, 1)
    m = Model(F, y)
    rows = rng.normal(scale=2.0, size=(300, F.shape[1])).astype(np.float32)
    for bounded in (False, True):
        x = np.clip(rows, m.lo, m.hi) if bounded else rows
        want = np.clip(m.expand(x).astype(np.float64) @ m.weights.astype(np.float64), 0, 1)
        np.testing.assert_allclose(m.predict(rows, bounded=bounded), want, atol=2e-5)
    assert np.abs(m.predict(rows, bounded=True) - m.predict(rows)).max() > 0.01


def test_the_trunk_sees_the_ground_patch_as_the_proxy_rungs_do():
    """The GROUND patches (core/walls.py) are multiplied into the ray-free rung too, its fit
    dividing them out of the traced sample: a stem standing on the ground (test_bole.py's
    tree) sees the ground fill the lower half of its hemisphere at its foot, which no feature
    of the leaf grid holds. Trunk MAE against rays 0.0050 (0.0087 without the patch)."""
    from test_bole import _items
    its = _items()
    ref = core.prepare(its, core.BakeSettings(method="raytrace", samples=512, distance=20.0))
    plan = core.prepare(its, core.BakeSettings(method="regression", distance=20.0))
    trunk = its[1]
    want = core.evaluate_item(ref, trunk).ao
    err = np.abs(core.evaluate_item(plan, trunk).ao - want)
    assert err.mean() < 0.0065, float(err.mean())
    assert plan.walls and plan.regression.patches == plan.walls
    own, _rep = regression.bake(its, 20.0)  # the one-off bake multiplies them in too
    assert np.abs(own["Trunk"] - want).mean() < 0.0065, float(np.abs(own["Trunk"] - want).mean())


def test_the_grids_thread_gives_the_serial_geometry_and_raises_its_errors_here():
    """regression_geometry.geometry sweeps the grid on a worker thread beside the leaf tables:
    its features are those of the grid built on this thread, and a bad occluder's error (a
    non-finite vertex) reaches the caller as the grid raised it."""
    from canopy_ao.core import regression_geometry
    its = items()
    occ = [it for it in its if it.role in regression.OCCLUDER_ROLES]
    features, leaves, scene_frame, frames = regression_geometry.geometry(its, occ, None, 32, 24)
    grid = _core.DensityGrid(*core.meshes.merged(occ), resolution=32)
    serial = _core.OcclusionFeatures(grid, directions=24)
    p = np.ascontiguousarray(its[1].positions, np.float32)
    n = np.ascontiguousarray(its[1].normals, np.float32)
    assert np.array_equal(np.asarray(features.compute(p, n, *scene_frame)),
                          np.asarray(serial.compute(p, n, *scene_frame)))
    assert set(leaves) == {it.name for it in its if it.role in ("CANOPY", "TRUNK")}
    bad = occ[0]
    pos = bad.positions.copy()
    pos[0, 0] = np.nan
    broken = [type(bad)(bad.name, bad.role, bad.tree, pos, bad.normals, bad.triangles)] + occ[1:]
    with pytest.raises(ValueError, match="non-finite"):
        regression_geometry.geometry(broken, broken, None, 32, 24)
