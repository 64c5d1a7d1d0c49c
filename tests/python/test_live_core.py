"""Live and per-frame AO in the core (canopy_ao.core.live, no bpy): a frame refitted with the
first bake's rung and τ equals a full bake of that frame (the shells: with the first bake's
partition of the leaves, which keeps the AO smooth in time)."""
import os
import sys

import numpy as np
import pytest

HERE = os.path.dirname(__file__)
sys.path.insert(0, os.path.join(HERE, "..", "..", "addon"))
sys.path.insert(0, HERE)

from canopy_ao import core  # noqa: E402
from canopy_ao.core import live  # noqa: E402
from canopy_ao.core.native import CanopyAOError, _core  # noqa: E402
import tree_scene as ts  # noqa: E402

assert core.core_status()[0], core.core_status()[1]  # an unbuilt module fails, not skips

ROLE = {"Trunk": "TRUNK", "Leaves": "CANOPY", "Ground": "GROUND", "Grass": "GRASS"}


def scene_items(sway=0.0):
    """The tree scene, its crown bent sideways by ``sway`` h² at height h above its base."""
    out = []
    for name, (p, t) in ts.scene(True).items():
        p = p.copy()
        if name == "Leaves":
            p[:, 0] += np.float32(sway) * (p[:, 2] - 1.4) ** 2
        out.append(core.SceneItem(name, ROLE[name], "Oak" if name != "Ground" else "", p,
                                  ts.vertex_normals(p, t), t))
    return out


def frame_plan(first, sway):
    frame = scene_items(sway)
    return frame, live.refit(first, live.frame_items(
        live.template_items(frame), {i.name: i.positions for i in frame},
        {i.name: i.normals for i in frame}))


def leaves_ao(plan, items):
    (it,) = [i for i in items if i.name == "Leaves"]
    return core.evaluate_receivers(plan, it, it.positions, it.normals, vertices=slice(None))


@pytest.mark.parametrize("method", ["sphere", "ellipsoid", "reeves_blau"])
def test_a_refitted_frame_equals_a_full_bake_of_that_frame(method):
    first = core.prepare(scene_items(0.0), core.BakeSettings(method=method, tau=1.7))
    frame, plan = frame_plan(first, 0.15)
    full = core.prepare(scene_items(0.15), core.BakeSettings(method=method, tau=1.7))
    moved = False
    for it in frame:
        got = core.evaluate_receivers(plan, it, it.positions, it.normals, vertices=slice(None))
        want = core.evaluate_receivers(full, it, it.positions, it.normals, vertices=slice(None))
        np.testing.assert_allclose(got, want, atol=1e-6, err_msg=it.name)
        was = core.evaluate_receivers(first, it, it.positions, it.normals, vertices=slice(None))
        moved |= bool(np.abs(got - was).max() > 0.02)
    assert moved  # the proxies followed the leaves


@pytest.mark.parametrize("method", ["shells", "medium"])
def test_shells_keep_their_leaves_and_move_smoothly(method):
    settings = core.BakeSettings(method=method, tau=1.7)
    first = core.prepare(scene_items(0.0), settings)
    labels = first.shell_labels["Oak"]
    assert len(np.unique(labels)) == settings.shells
    # The first frame again: the refit of the same partition is the first bake's fit.
    frame, plan = frame_plan(first, 0.0)
    np.testing.assert_allclose(leaves_ao(plan, frame), leaves_ao(first, frame), atol=1e-6)
    # A later frame: each shell is the ellipsoid fitted to its own leaves, wherever they went.
    frame, plan = frame_plan(first, 0.15)
    (leaves,) = [i for i in frame if i.name == "Leaves"]
    for c, shell in zip(np.unique(labels), plan.fits["Oak"][2]):
        want = _core.fit_ellipsoid(np.ascontiguousarray(leaves.positions[labels == c]))
        np.testing.assert_allclose(shell.center, want.center, atol=1e-5)
        np.testing.assert_allclose(shell.radii, want.radii, atol=1e-5)
    # Smooth in time: over 12 steps of the sway no vertex changes by more than 0.25 in one step
    # (0.17 measured for shells, 0.08 for the medium; a point crossing into a second shell
    # steps), where clustering each frame afresh (a full bake per frame) jumps by 0.5-0.6 as
    # leaves change shells.
    live_steps, cold_steps, prev = [], [], None
    for sway in np.linspace(0.0, 0.3, 13):
        frame, plan = frame_plan(first, sway)
        now = (leaves_ao(plan, frame), leaves_ao(core.prepare(frame, settings), frame))
        if prev is not None:
            live_steps.append(np.abs(now[0] - prev[0]).max())
            cold_steps.append(np.abs(now[1] - prev[1]).max())
        prev = now
    assert max(live_steps) < 0.25, live_steps
    assert max(cold_steps) > 2 * max(live_steps), (cold_steps, live_steps)


def test_a_frame_keeps_the_first_bakes_tau_per_tree():
    first = core.prepare(scene_items(0.0), core.BakeSettings(method="ellipsoid", tau=1.7))
    first.tau_by_tree = {"Oak": 3.0}
    first.role_scale = {"GROUND": 0.4}  # the ground's factor (ladder.calibrate)
    frame = scene_items(0.2)
    plan = live.refit(first, live.frame_items(live.template_items(frame),
                                              {i.name: i.positions for i in frame},
                                              {i.name: i.normals for i in frame}))
    assert plan.tau == 1.7 and plan.tau_by_tree == {"Oak": 3.0} and plan.method == "ellipsoid"
    assert plan.role_scale == {"GROUND": 0.4}


@pytest.mark.parametrize("method", ["raytrace", "grid", "auto"])
def test_rungs_that_rebuild_from_triangles_are_refused(method):
    with pytest.raises(CanopyAOError, match="analytic rungs only"):
        live.check_method(method)


def test_a_changed_vertex_count_is_refused():
    its = scene_items()
    pos = {i.name: i.positions for i in its}
    nor = {i.name: i.normals for i in its}
    pos["Leaves"], nor["Leaves"] = pos["Leaves"][:-4], nor["Leaves"][:-4]
    with pytest.raises(CanopyAOError, match="Leaves: .*topology changed"):
        live.frame_items(live.template_items(its), pos, nor)


def _regression_frame(first, sway):
    frame = scene_items(sway)
    return frame, live.refit(first, live.frame_items(
        live.template_items(frame, "regression"), {i.name: i.positions for i in frame},
        {i.name: i.normals for i in frame}))


def test_the_ray_free_rung_runs_live_its_fit_kept_its_features_moved():
    """A regression frame: the first bake's fitted models, the frame's grid and leaf tables.
    At the first bake's own positions it is that bake (but for features held to the sample's
    range: test_a_frame_holds_the_features_to_the_calibration_sample); swayed, it follows the
    crown and agrees with a full regression bake of that frame (its own calibration rays) as
    closely as two calibrations of one scene agree."""
    settings = core.BakeSettings(method="regression", tau=1.7)
    first = core.prepare(scene_items(0.0), settings)
    still, same = _regression_frame(first, 0.0)
    assert same.regression is not first.regression
    assert same.regression._models is first.regression._models  # the fit is the first bake's
    for it in still:
        got = core.evaluate_receivers(same, it, it.positions, it.normals, vertices=slice(None))
        want = core.evaluate_receivers(first, it, it.positions, it.normals, vertices=slice(None))
        # equal but where a vertex's features leave the sample's range (held to it in a frame)
        assert np.mean(got == want) >= 0.95 and np.abs(got - want).mean() < 0.005, it.name
    frame, plan = _regression_frame(first, 0.15)
    full = core.prepare(scene_items(0.15), settings)
    reseeded = core.prepare(scene_items(0.15), core.BakeSettings(method="regression", tau=1.7,
                                                                 seed=5))
    got, want, was = leaves_ao(plan, frame), leaves_ao(full, frame), leaves_ao(first, frame)
    assert np.abs(got - was).max() > 0.02  # the features followed the leaves
    seeds = np.abs(leaves_ao(reseeded, frame) - want).mean()
    assert np.abs(got - want).mean() <= max(2 * seeds, 0.01)


def test_a_ray_free_frame_fits_no_proxy_and_needs_none():
    """The ray-free rung reads no proxy (Rung.reads_proxies), so its frames skip their fits
    (an ellipsoid at the live tolerance costs as much as the rung's grid): no fit in the frame's
    plan, and the AO of every item equal to the bit to that of the same frame with them fitted."""
    from canopy_ao.core import proxies
    first = core.prepare(scene_items(0.0), core.BakeSettings(method="regression", tau=1.7))
    frame, plan = _regression_frame(first, 0.15)
    assert plan.fits == {} and plan.trunks == {} and plan.proxies == {}
    proxies.fit_scene(plan, live.split_trees(frame))  # the fits a proxy rung's frame makes
    assert plan.fits
    for it in frame:
        got = core.evaluate_receivers(plan, it, it.positions, it.normals, vertices=slice(None))
        _f, again = _regression_frame(first, 0.15)
        want = core.evaluate_receivers(again, it, it.positions, it.normals, vertices=slice(None))
        assert np.array_equal(got, want), it.name


def test_a_frame_holds_the_features_to_the_calibration_sample():
    """A feature all but constant in the first frame's sample (a ground point's shape feature
    under an unbent crown) that a later frame moves far outside it: held to the sample's range,
    the fit predicts as at the range's edge instead of extrapolating thousands of standard
    deviations (the swayed benchmark crown's ground went from AO 0.98 to 0.32)."""
    from canopy_ao.core.regression_fit import NATIVE, Model
    rng = np.random.default_rng(3)
    F = rng.normal(size=(400, NATIVE)).astype(np.float32)
    F[:, 8] = 1.0 + 1e-5 * rng.normal(size=400)
    y = np.clip(0.5 + 0.1 * F[:, 0] + 0.05 * F[:, 8], 0, 1)
    m = Model(F, y)
    far = F[:50].copy()
    far[:, 8] = 50.0
    near = m.predict(F[:50])
    assert np.abs(m.predict(far, bounded=True) - near).max() < 0.02
    assert np.abs(m.predict(far) - near).max() > 0.2  # what the bound prevents
    np.testing.assert_array_equal(m.predict(F[:50], bounded=True), near)  # inside: unchanged


def test_a_live_bake_holds_a_ground_alones_occlusion_from_its_first_bake():
    """A bake makes the flat ground a patch (core/walls.py: it darkens the trunk's foot and the
    leaves facing down), a live bake's first too; its frames evaluate no patch for a ground
    alone (tens of times a rung's own cost) but multiply in what it occluded at the first bake
    (held_ground): at the first frame's geometry that is the bake, and a swayed frame stays
    near a full bake of it, much nearer than without the ground. A frame-range bake's frames
    (not live) make the patch as their bake."""
    items = scene_items(0.0)
    settings = core.BakeSettings(method="sphere", tau=1.7)
    baked = core.prepare(items, settings)
    first = core.prepare(items, settings, live=True)
    assert len(baked.walls) == 1 and len(first.walls) == 1
    held = live.held_ground(first, items, {"Leaves", "Trunk"})
    assert set(held) == {"Leaves", "Trunk"} and held["Leaves"].min() < 0.9
    assert live.held_ground(baked, items, {"Leaves"}) == {}  # frames make their own
    frame, plan = frame_plan(first, 0.15)
    assert plan.walls == [] and len(frame_plan(baked, 0.15)[1].walls) == 1
    np.testing.assert_allclose(leaves_ao(frame_plan(first, 0.0)[1], items) * held["Leaves"],
                               leaves_ao(baked, items), atol=2e-6)
    full = leaves_ao(core.prepare(frame, settings), frame)
    bare = leaves_ao(plan, frame)
    assert np.abs(bare * held["Leaves"] - full).mean() < 0.3 * np.abs(bare - full).mean()

def test_warm_started_frames_match_a_full_bake_and_not_their_history():
    """A live session's frames start each ellipsoid's fit from the previous frame's support
    (plan.fit_warm, proxies.fit_tree) and solve it to LIVE_TOLERANCE: over a sway in 8 steps
    every frame's AO stays within a bake's own fit tolerance of a full bake of that frame
    (0.012, 0.002 on average: a bake fits to 1e-3), and the last frame is the same reached
    step by step or at once (a farm task starting there, a reloaded file): the fit no longer
    depends on where it started."""
    settings = core.BakeSettings(method="ellipsoid", tau=1.7)
    first = core.prepare(scene_items(0.0), settings)
    first.fit_warm = {}
    worst, mean = 0.0, []
    for sway in np.linspace(0.0, 0.2, 8):
        frame, plan = frame_plan(first, sway)
        full = core.prepare(scene_items(sway), settings)
        for it in frame:
            got = core.evaluate_receivers(plan, it, it.positions, it.normals,
                                          vertices=slice(None))
            want = core.evaluate_receivers(full, it, it.positions, it.normals,
                                           vertices=slice(None))
            worst = max(worst, float(np.abs(got - want).max()))
            mean.append(float(np.abs(got - want).mean()))
    assert worst < 0.012 and max(mean) < 0.002, (worst, mean)
    assert first.fit_warm["Oak"][-1].support >= 4  # a 3-D fit's support: at least d + 1
    stepped = leaves_ao(plan, frame)
    first.fit_warm = {}  # a new session, its first frame the last one
    frame, at_once = frame_plan(first, 0.2)
    np.testing.assert_allclose(leaves_ao(at_once, frame), stepped, atol=1e-5)
    assert np.abs(stepped - leaves_ao(full, frame)).max() > 1e-4  # not the bake's 1e-3 fit


def test_a_warm_state_of_other_points_is_ignored():
    """What a fit keeps for the next frame applies only to as many points (the same mesh
    moved): a state from another count (the topology changed, another object) gives exactly
    a fresh fit, and an empty state the fresh fit too (a bake's fits are unchanged)."""
    pts = {i.name: np.ascontiguousarray(i.positions) for i in scene_items(0.0)}
    leaves, trunk = pts["Leaves"], pts["Trunk"]

    def same(a, b):
        return (np.array_equal(a.center, b.center) and np.array_equal(a.radii, b.radii)
                and np.array_equal(a.axes, b.axes))

    state = _core.EllipsoidWarmStart()
    assert same(_core.fit_ellipsoid(leaves, warm=state), _core.fit_ellipsoid(leaves))
    assert state.support >= 4
    assert same(_core.fit_ellipsoid(trunk, warm=state), _core.fit_ellipsoid(trunk))
    assert same(_core.fit_ellipsoid(leaves[:-7], warm=state), _core.fit_ellipsoid(leaves[:-7]))
    # Refilled by the last fit (of leaves[:-7]): the leaves again start afresh, then moved
    # they start from that fit's support, within its tolerance of a fresh fit.
    assert same(_core.fit_ellipsoid(leaves, warm=state), _core.fit_ellipsoid(leaves))
    moved = leaves + np.float32(0.01) * leaves[:, [2, 0, 1]]
    warm = _core.fit_ellipsoid(moved, warm=state)
    cold = _core.fit_ellipsoid(moved)
    vol = float(np.prod(np.asarray(warm.radii, np.float64) / np.asarray(cold.radii)))
    assert abs(vol - 1.0) < 5e-3 and not same(warm, cold)


def test_the_ray_free_rung_holds_the_ground_as_the_proxy_rungs_do():
    """The ray-free rung multiplies the GROUND patches in (Rung.ground_patches): a live bake's
    frames hold a ground alone's occlusion from the first bake as the proxy rungs' do, so the
    first frame shows the bake; without it the leaves facing down read too bright."""
    items = scene_items(0.0)
    settings = core.BakeSettings(method="regression", tau=1.7)
    baked = core.prepare(items, settings)
    first = core.prepare(items, settings, live=True)
    held = live.held_ground(first, items, {"Leaves", "Trunk"})
    assert set(held) == {"Leaves", "Trunk"} and held["Leaves"].min() < 0.9
    still, same = _regression_frame(first, 0.0)
    assert same.walls == []
    want, bare = leaves_ao(baked, items), leaves_ao(same, still)
    assert np.abs(bare * held["Leaves"] - want).mean() < 0.005
    assert np.abs(bare - want).mean() > 0.01
