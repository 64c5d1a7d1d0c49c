"""Animated vegetation: live AO (a frame_change_post handler) and frame-range bakes, each
checked against full bakes made at the same frame with the same rung and τ."""

import os
import subprocess
import sys

import bpy
import numpy as np
import pytest

from conftest import _clear_scene, add_oak_scene, add_wind_key
from canopy_ao.blender import frames, live, live_session, mesh_io, properties
from canopy_ao.blender.job import run_bake
from canopy_ao.core.native import CanopyAOError

NAMES = ("Trunk", "Leaves", "Ground", "Grass")
ROLES = {"Trunk": 'TRUNK', "Leaves": 'CANOPY', "Ground": 'GROUND', "Grass": 'GRASS'}


def _animated_tree():
    """The tree scene with its leaves swaying: a shape key bending the crown sideways (0.15 h²
    at height h above its base; a bend, not a shear, which an ellipsoid fit would follow
    exactly), keyed 0 at frame 1 and 1 at frame 9."""
    _clear_scene()
    scene = bpy.context.scene
    add_oak_scene(ROLES)
    leaves = scene.objects["Leaves"]
    add_wind_key(leaves, 0.15, 9)
    scene.frame_start, scene.frame_end = 1, 9
    scene.frame_set(1)
    for ob in scene.objects:
        ob.select_set(False)
    return scene


@pytest.fixture
def animated():
    scene = _animated_tree()
    yield scene
    live.stop(bpy.context.scene)  # a test may have loaded a file: the scene it has now
    _clear_scene()


def opts(**kw):
    base = dict(properties.scene_options(bpy.context.scene), method="ellipsoid", tau=1.7,
                distance=0.0, show_proxies=False, live=False)
    base.update(kw)
    return base


def _ao(name, attribute="CanopyAO"):
    return mesh_io.read_ao_attribute(bpy.context.scene.objects[name], attribute)


def _drawn(name):
    """What the viewport draws of a live target at this frame: its evaluated mesh's AO (the
    original of a target this frame evaluated is written at a save, a stop, a render or an
    edit: live_render.write_viewport)."""
    return _evaluated_ao(bpy.context.scene.objects[name])


def held_ground(scene):
    """{name: float32 (V,)}: the live session's ground occlusion held from its first bake, as
    the scene stores it (live_session.HELD)."""
    held = scene.get(live_session.HELD) or {}
    return {n: np.asarray(held[n], np.float32) for n in held.keys()}


def _full(method, tau, attribute="Full", live_ground=False):
    """A full bake of the current frame; {name: AO}. live_ground: with live AO's rule for the
    GROUND surfaces (core/walls.py): a frame makes patches only where a wall is, and a ground
    alone's occlusion is the first bake's, held (core/live.held_ground)."""
    from canopy_ao.core import walls
    build = walls.build
    if live_ground:
        walls.build = lambda items: (lambda pt: pt if walls.has_wall(pt) else [])(build(items))
    try:
        _j, rep = run_bake(bpy.context, list(NAMES), opts(method=method, tau=tau,
                                                          attribute=attribute))
    finally:
        walls.build = build
    assert rep["method"] == method
    got = {n: _ao(n, attribute) for n in NAMES}
    held = held_ground(bpy.context.scene) if live_ground else {}
    return {n: got[n] * held[n] if n in held else got[n] for n in NAMES}


def _assert_equal(got, want, names=NAMES):
    for n in names:
        np.testing.assert_allclose(got[n], want[n], atol=2e-6, err_msg=n)


def _assert_within_the_fit(got, want, names=NAMES):
    """Equal within a bake's ellipsoid fit tolerance (1e-3): live fits solve to 1e-6
    (proxies.LIVE_TOLERANCE; tests/python/test_live_core.py measures the bound; up to 0.016
    on a vertex of this tree's eight small shells)."""
    for n in names:
        d = np.abs(got[n] - want[n])
        assert d.max() < 0.02 and d.mean() < 0.002, (n, d.max(), d.mean())


def _assert_same_fit(got, want, names=NAMES):
    """Equal to the live fits' precision (1e-6): the same frame, whichever frame its fits
    started from."""
    for n in names:
        np.testing.assert_allclose(got[n], want[n], atol=1e-4, err_msg=n)


@pytest.mark.parametrize("method", ["sphere", "ellipsoid", "shells", "medium"])
def test_live_ao_at_a_frame_equals_a_full_bake_of_that_frame(animated, method):
    _j, rep = run_bake(bpy.context, list(NAMES), opts(method=method, live=True))
    first = {n: _ao(n) for n in NAMES}
    assert animated.canopy_ao.live and live.session_of(animated) is not None
    if method == "sphere":
        # The first frame is lit as any bake, the flat ground's patch included, which the
        # frames then hold (held_ground): a live bake shows what a plain bake shows.
        assert held_ground(animated) and held_ground(animated)["Leaves"].min() < 0.99
        _assert_equal(first, _full(method, rep["tau"]))
    animated.frame_set(7)  # the handler re-evaluates
    now = {n: _drawn(n) for n in NAMES}
    assert np.abs(now["Leaves"] - first["Leaves"]).max() > 0.02  # the AO followed the wind
    assert np.abs(now["Ground"] - first["Ground"]).max() > 0.005  # and the shadow moved
    if method == "sphere":
        _assert_equal(now, _full(method, rep["tau"], live_ground=True))
    elif method == "ellipsoid":  # live fits solve to 1e-6, a bake's to 1e-3
        _assert_within_the_fit(now, _full(method, rep["tau"], live_ground=True))
        animated.frame_set(4)  # its fit starts from frame 7's
        _assert_within_the_fit({n: _drawn(n) for n in NAMES},
                               _full(method, rep["tau"], live_ground=True))
    else:
        # The shells keep the first bake's partition of the leaves (core/live.py): a full bake
        # clusters afresh, so the check is the first frame, reached again (the bake's fits
        # at 1e-3, the frame's at 1e-6), then frame 7 again, its fits started elsewhere.
        animated.frame_set(1)
        _assert_within_the_fit({n: _drawn(n) for n in NAMES}, first)
        animated.frame_set(7)
        _assert_same_fit({n: _drawn(n) for n in NAMES}, now)


def test_live_ao_reaches_the_evaluated_meshes_the_viewport_draws(animated, tmp_path):
    """The swaying leaves are written into the mesh this frame evaluated (no second
    evaluation), their original left as it was; the still ground into its original, tagged.
    What is drawn is the frame's AO, and a save, an edit that evaluates the leaves again from
    their original and a stop each write the last frame drawn into it, owned."""
    run_bake(bpy.context, list(NAMES), opts(method="ellipsoid", live=True))
    first = {n: _ao(n) for n in NAMES}
    leaves = animated.objects["Leaves"]
    for frame in (7, 4):
        animated.frame_set(frame)
        drawn = {n: _drawn(n) for n in NAMES}
        assert np.abs(drawn["Leaves"] - first["Leaves"]).max() > 0.02
        assert np.abs(drawn["Ground"] - first["Ground"]).max() > 0.005
    # (the first frame evaluates every target the bake tagged; the second, the leaves alone)
    np.testing.assert_array_equal(_ao("Ground"), drawn["Ground"])  # still: the original
    np.testing.assert_array_equal(_ao("Leaves"), first["Leaves"])  # not written per frame
    # A save keeps the frame drawn: in the file, and ours to overwrite at the next frame.
    path = str(tmp_path / "saved.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path, copy=True)
    np.testing.assert_array_equal(_ao("Leaves"), drawn["Leaves"])
    assert mesh_io.ownership(leaves.data, "CanopyAO") == 'ours'
    # An edit evaluating the leaves again reads their original: the last frame is written
    # there first and drawn again, not an older one.
    animated.frame_set(7)
    at7 = _drawn("Leaves")
    np.testing.assert_array_equal(_ao("Leaves"), drawn["Leaves"])  # frame 4's, from the save
    leaves.data.update_tag()
    bpy.context.view_layer.update()
    np.testing.assert_array_equal(_drawn("Leaves"), at7)
    np.testing.assert_array_equal(_ao("Leaves"), at7)
    # A stop leaves the last frame drawn in the original, and frames after it show that.
    animated.frame_set(4)
    at4 = _drawn("Leaves")
    live.stop(animated)
    np.testing.assert_array_equal(_ao("Leaves"), at4)
    assert mesh_io.ownership(leaves.data, "CanopyAO") == 'ours'
    animated.frame_set(7)
    np.testing.assert_array_equal(_drawn("Leaves"), at4)
    bpy.ops.wm.open_mainfile(filepath=path)  # the saved file holds frame 4's AO, owned
    leaves = bpy.context.scene.objects["Leaves"]
    np.testing.assert_array_equal(mesh_io.read_ao_attribute(leaves, "CanopyAO"),
                                  drawn["Leaves"])
    assert mesh_io.ownership(leaves.data, "CanopyAO") == 'ours'


def test_unticking_live_leaves_the_last_frame_drawn(animated):
    """Live unticked by hand (no stop): the next frame change writes the last frame drawn into
    the originals left behind, and draws it again."""
    run_bake(bpy.context, list(NAMES), opts(method="ellipsoid", live=True))
    animated.frame_set(5)
    at5 = _drawn("Leaves")
    assert np.abs(_ao("Leaves") - at5).max() > 0.02  # left behind
    animated.canopy_ao.live = False
    animated.frame_set(7)
    np.testing.assert_array_equal(_ao("Leaves"), at5)
    np.testing.assert_array_equal(_drawn("Leaves"), at5)


def test_a_save_during_live_keeps_an_edit_or_a_bake_made_since(animated, tmp_path, capsys):
    """The original of a swaying target is written at a save only if it still holds what live
    AO last wrote there: an attribute painted since, or a static bake since, stays."""
    run_bake(bpy.context, list(NAMES), opts(method="ellipsoid", live=True))
    leaves = animated.objects["Leaves"]
    animated.frame_set(5)
    attr = leaves.data.attributes["CanopyAO"]
    attr.data.foreach_set("color", np.full(len(attr.data) * 4, 0.5, np.float32))  # painted
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "painted.blend"), copy=True)
    assert np.all(_ao("Leaves") == 0.5)
    assert mesh_io.ownership(leaves.data, "CanopyAO") == 'changed'
    assert "not kept in Leaves" in capsys.readouterr().err
    run_bake(bpy.context, list(NAMES), opts(method="ellipsoid", live=True, overwrite=True))
    animated.frame_set(6)
    run_bake(bpy.context, list(NAMES), opts(method="sphere", tau=1.0))  # live still on
    static = _ao("Leaves")
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "static.blend"), copy=True)
    np.testing.assert_array_equal(_ao("Leaves"), static)
    assert mesh_io.ownership(leaves.data, "CanopyAO") == 'ours'
    assert "written by another bake" in capsys.readouterr().err


def test_a_target_whose_modifier_drops_the_attribute_keeps_its_original_written(animated):
    """A geometry-nodes modifier removing the AO attribute from the evaluated leaves: nothing
    there to write, so live AO writes (and tags) the original, and keeps running."""
    leaves = animated.objects["Leaves"]
    ng = bpy.data.node_groups.new("Drop AO", 'GeometryNodeTree')
    for io in ('INPUT', 'OUTPUT'):
        if hasattr(ng, "interface"):  # 4.0+
            ng.interface.new_socket(name="Geometry", in_out=io, socket_type='NodeSocketGeometry')
        else:
            (ng.inputs if io == 'INPUT' else ng.outputs).new('NodeSocketGeometry', "Geometry")
    gin, gout = ng.nodes.new('NodeGroupInput'), ng.nodes.new('NodeGroupOutput')
    drop = ng.nodes.new('GeometryNodeRemoveAttribute')
    drop.inputs["Name"].default_value = "CanopyAO"
    ng.links.new(gin.outputs[0], drop.inputs[0])
    ng.links.new(drop.outputs[0], gout.inputs[0])
    leaves.modifiers.new("Drop", 'NODES').node_group = ng
    run_bake(bpy.context, list(NAMES), opts(method="ellipsoid", live=True))
    first = _ao("Leaves")
    animated.frame_set(7)
    assert animated.canopy_ao.live and live.session_of(animated).frames == 1
    assert np.abs(_ao("Leaves") - first).max() > 0.02


def test_the_ray_free_rung_runs_live_as_close_to_rays_as_its_static_bake(animated):
    """The regression rung live (its fit from frame 1's calibration rays, its features from
    each frame): on the swayed crown its error against that frame's rays stays within 0.01 of
    a static regression bake of that frame (calibrated on that frame's own rays)."""
    _j, rep = run_bake(bpy.context, list(NAMES), opts(method="regression", live=True))
    assert rep["method"] == "regression" and live.session_of(animated) is not None
    first = {n: _ao(n) for n in NAMES}
    animated.frame_set(7)
    assert live.session_of(animated).frames == 1
    now = {n: _drawn(n) for n in NAMES}
    assert np.abs(now["Leaves"] - first["Leaves"]).max() > 0.02  # the AO followed the wind
    rays = _full("raytrace", rep["tau"], attribute="Rays")
    static = _full("regression", rep["tau"], attribute="Static")

    def mae(got):
        return np.mean(np.concatenate([np.abs(got[n] - rays[n]) for n in NAMES]))
    assert mae(now) <= mae(static) + 0.01, (mae(now), mae(static))  # 0.042, 0.040 here
    assert mae(now) < mae(first)  # closer than frame 1's AO left in place (0.045)


def test_live_keeps_the_first_bakes_calibrated_tau(animated):
    _j, rep = run_bake(bpy.context, list(NAMES), opts(method="ellipsoid", tau=None, live=True))
    assert rep["calibration"]  # τ was calibrated at frame 1 ...
    animated.frame_set(5)
    session = live.session_of(animated)
    assert session.frames == 1 and session.plan.tau == rep["tau"]  # ... and kept at frame 5
    assert session.plan.role_scale == rep["tau_role_scale"]  # the ground's own factor too
    taus = set(rep["tau_by_tree"].values()) | {rep["tau"]}
    if len(taus) == 1:  # one τ for every tree: a full bake given it is the same bake ...
        want = _full("ellipsoid", rep["tau"], live_ground=True)
        # ... but for the receivers frame 1's buried test set to 0 (a given τ traces nothing)
        for name, mask in session.plan.buried.items():
            want[name][mask] = 0.0
        # ... and the ground, grass and trunk, lit with τ × their factor (a given τ has none)
        scaled = {n for n in NAMES if ROLES[n] in rep["tau_role_scale"]}
        _assert_within_the_fit({n: _drawn(n) for n in NAMES}, want,
                               [n for n in NAMES if n not in scaled])


@pytest.mark.parametrize("kw, words", [
    (dict(method="raytrace"), "analytic rungs"), (dict(method="grid"), "analytic rungs"),
    (dict(mode='TEXEL'), "per-vertex attributes only")])
def test_live_refuses_what_cannot_run_live_and_changes_nothing(animated, kw, words):
    with pytest.raises(CanopyAOError, match=words):
        run_bake(bpy.context, list(NAMES), opts(live=True, **kw))
    assert "CanopyAO" not in animated.objects["Leaves"].data.attributes
    assert not animated.canopy_ao.live and live.session_of(animated) is None


def test_live_stops_resumes_after_undo_and_reload_and_respects_the_users_attribute(
        animated, tmp_path):
    run_bake(bpy.context, list(NAMES), opts(live=True))
    animated.frame_set(4)
    at4 = _drawn("Leaves")
    assert bpy.ops.canopy_ao.live_stop() == {'FINISHED'}
    animated.frame_set(8)
    np.testing.assert_array_equal(_ao("Leaves"), at4)  # stopped: the last frame's AO stays
    # Undo and redo replace every datablock: the session goes and is rebuilt from the record.
    animated.canopy_ao.live = True
    live._forget()
    animated.frame_set(9)
    _assert_within_the_fit({n: _drawn(n) for n in NAMES},
                           _full("ellipsoid", 1.7, live_ground=True))
    # Saved and loaded: re-armed from the file's record by the persistent handler.
    path = str(tmp_path / "live.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    scene = bpy.context.scene
    assert scene.canopy_ao.live and live.session_of(scene) is None
    scene.frame_set(3)
    _assert_within_the_fit({n: _drawn(n) for n in NAMES},
                           _full("ellipsoid", 1.7, live_ground=True))
    # The user's own attribute of that name is never overwritten: live AO stops instead.
    leaves = scene.objects["Leaves"]
    mesh_io.remove_owned_attribute(leaves, "CanopyAO")
    theirs = leaves.data.attributes.new("CanopyAO", 'FLOAT', 'POINT')
    theirs.data.foreach_set("value", np.full(len(theirs.data), 0.25, np.float32))
    scene.frame_set(6)
    assert not scene.canopy_ao.live and "did not make" in scene.canopy_ao.last_report
    vals = np.empty(len(leaves.data.vertices), np.float32)
    leaves.data.attributes["CanopyAO"].data.foreach_get("value", vals)
    assert np.all(vals == 0.25)


def test_unregister_removes_the_handlers():
    assert live._on_frame_change in bpy.app.handlers.frame_change_post
    live.unregister()
    try:
        assert live._on_frame_change not in bpy.app.handlers.frame_change_post
        assert live._forget not in bpy.app.handlers.load_post
        assert not hasattr(bpy.types, "CANOPY_AO_OT_live_stop")
    finally:
        live.register()
    assert live._on_frame_change in bpy.app.handlers.frame_change_post


def _evaluated_ao(obj):
    mesh = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
    buf = np.empty(len(mesh.vertices) * 4, np.float32)
    mesh.attributes["CanopyAO"].data.foreach_get("color", buf)
    return buf.reshape(-1, 4)[:, 0].copy()


def test_a_frame_range_bake_matches_per_frame_full_bakes_and_is_read_back(animated):
    want = {}
    for f in (2, 4, 6):
        animated.frame_set(f)
        want[f] = _full("ellipsoid", 1.7)
    animated.frame_set(1)
    rep = frames.FrameBake(bpy.context, list(NAMES), opts(method="ellipsoid"), 2, 6).run()
    assert rep["frames"] == [2, 6] and rep["cache"] == ["CanopyAO_2", "CanopyAO_6"]
    assert animated.frame_current == 1  # the frame the bake started on
    for f, full in want.items():
        for n in NAMES:
            attr = animated.objects[n].data.attributes[f"CanopyAO_{f}"]
            vals = np.empty(len(attr.data), np.float32)
            attr.data.foreach_get("value", vals)
            d = np.abs(vals - full[n])  # live fits solve to 1e-6, a bake's to 1e-3
            assert d.max() < 0.012 and d.mean() < 0.002, (n, f, d.max(), d.mean())
    # The geometry-nodes read-back: the frame's cache, clamped to the baked range.
    leaves = animated.objects["Leaves"]
    for frame, cached in ((4, 4), (6, 6), (1, 2), (40, 6)):
        animated.frame_set(frame)
        attr = leaves.data.attributes[f"CanopyAO_{cached}"]
        vals = np.empty(len(attr.data), np.float32)
        attr.data.foreach_get("value", vals)
        np.testing.assert_allclose(_evaluated_ao(leaves), vals, atol=2e-6)
    # Clearing removes the modifier, the cache and the node group.
    assert bpy.ops.canopy_ao.clear_frames() == {'FINISHED'}
    assert not any(a.name.startswith("CanopyAO_") for a in leaves.data.attributes)
    assert leaves.modifiers.get(frames.MODIFIER) is None
    assert not [g for g in bpy.data.node_groups if g.get(frames.GROUP_TAG)]


def test_a_frame_range_bake_of_the_ray_free_rung_caches_what_live_shows(animated):
    """Both fit the ray-free rung on the first frame's rays and move its features after. The
    GROUND patches it multiplies in (Rung.ground_patches) a frame-range bake makes at each
    frame, as its bake does, and live holds from its first bake (core/live.held_ground), as for
    the proxy rungs: what does not move is equal, the swayed leaves near."""
    rep = frames.FrameBake(bpy.context, list(NAMES), opts(method="regression"), 1, 5).run()
    assert rep["frames"] == [1, 5]
    cached = {}
    for n in NAMES:
        attr = animated.objects[n].data.attributes["CanopyAO_5"]
        cached[n] = np.empty(len(attr.data), np.float32)
        attr.data.foreach_get("value", cached[n])
    assert bpy.ops.canopy_ao.clear_frames() == {'FINISHED'}
    animated.frame_set(1)
    run_bake(bpy.context, list(NAMES), opts(method="regression", live=True))
    at1 = _ao("Leaves")
    animated.frame_set(5)
    assert np.abs(_drawn("Leaves") - at1).max() > 0.02
    still = [n for n in NAMES if n != "Leaves"]
    _assert_equal({n: _drawn(n) for n in still}, cached, still)
    d = np.abs(_drawn("Leaves") - cached["Leaves"])
    assert d.mean() < 0.5 * np.abs(cached["Leaves"] - at1).mean(), d.mean()


def test_a_cancelled_frame_range_bake_leaves_nothing_behind(animated):
    before = {n: sorted(a.name for a in animated.objects[n].data.attributes) for n in NAMES}
    groups = len(bpy.data.node_groups)
    bake = frames.FrameBake(bpy.context, list(NAMES), opts(), 1, 9)
    assert bake.step() and bake.step() and bake.steps_done == 2 and bake.steps == 9
    assert animated.frame_current == 2
    bake.cancel()
    assert animated.frame_current == 1
    assert {n: sorted(a.name for a in animated.objects[n].data.attributes)
            for n in NAMES} == before
    assert len(bpy.data.node_groups) == groups
    assert all(not o.modifiers for o in animated.objects)
    with pytest.raises(CanopyAOError, match="analytic rungs"):
        frames.FrameBake(bpy.context, [], opts(method="raytrace"), 1, 3)
    with pytest.raises(CanopyAOError, match="empty"):
        frames.FrameBake(bpy.context, [], opts(), 5, 3)


def test_frames_blender_cannot_show_or_a_cache_that_would_not_fit_are_refused(animated,
                                                                             monkeypatch):
    """Frames past Blender's ±1048574 (frame_set stops there: each would cache that frame's AO
    under another frame's name), and a cache whose frames would not fit in memory (it was
    evaluated frame by frame until the machine ran out): refused, nothing written."""
    before = {n: sorted(a.name for a in animated.objects[n].data.attributes) for n in NAMES}
    with pytest.raises(CanopyAOError, match="1048574"):
        frames.FrameBake(bpy.context, list(NAMES), opts(), 1048570, 1048580)
    with pytest.raises(CanopyAOError, match="1048574"):
        frames.FrameBake(bpy.context, list(NAMES), opts(), -1048580, -1048570)
    from canopy_ao.core import texel_budget
    monkeypatch.setattr(texel_budget, "available_bytes", lambda: 10_000)
    with pytest.raises(CanopyAOError, match="frame cache .* needs about"):
        frames.FrameBake(bpy.context, list(NAMES), opts(), 1, 9).run()
    assert {n: sorted(a.name for a in animated.objects[n].data.attributes)
            for n in NAMES} == before
    assert all(not o.modifiers for o in animated.objects)


def test_a_users_modifier_named_like_the_frame_cache_is_left_alone(animated):
    """A geometry-nodes modifier of the user's called "Canopy AO Frames": a frame-range bake
    is refused (it repointed the modifier at its own group), Clear Frame Cache keeps it (it
    removed it), and live AO is not blocked by it."""
    ground = animated.objects["Ground"]
    group = bpy.data.node_groups.new("UserNodes", "GeometryNodeTree")
    mod = ground.modifiers.new(frames.MODIFIER, 'NODES')
    mod.node_group = group
    mod.show_viewport = mod.show_render = False  # an empty group: the mesh as it is
    with pytest.raises(CanopyAOError, match="not Canopy AO's frame cache"):
        frames.FrameBake(bpy.context, list(NAMES), opts(), 1, 3).run()
    assert mod.node_group == group
    assert all(not any(a.name.startswith("CanopyAO_") for a in animated.objects[n].data.attributes)
               for n in NAMES)
    ground.select_set(True)
    assert bpy.ops.canopy_ao.clear_frames() == {'FINISHED'}
    assert ground.modifiers.get(mod.name) is not None and mod.node_group == group
    ground.modifiers.remove(mod)


def test_the_command_line_bakes_frames_and_renders_with_live_ao(animated, tmp_path,
                                                                 user_scripts):
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    animated.collection.objects.link(cam)
    cam.location, cam.rotation_euler = (0.0, -12.0, 3.0), (1.45, 0.0, 0.0)
    animated.camera = cam
    animated.render.engine = 'CYCLES'
    animated.cycles.samples, animated.cycles.use_denoising = 1, False  # no OIDN in Debian
    animated.render.resolution_x = animated.render.resolution_y = 8
    animated.render.filepath = str(tmp_path / "frame_")
    animated.frame_start, animated.frame_end = 3, 4
    path = str(tmp_path / "cli.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path, copy=True)
    probe = ("import bpy, numpy as np; o = bpy.context.scene.objects['Leaves']; "
             "a = o.data.attributes['CanopyAO']; v = np.empty(len(a.data) * 4, np.float32); "
             "a.data.foreach_get('color', v); np.save(r'%s', v[::4]); "
             "print('frame', bpy.context.scene.frame_current)") % (tmp_path / "ao.npy")
    env = dict(os.environ, BLENDER_USER_SCRIPTS=user_scripts)
    cmd = ["blender", "-b", "--factory-startup", path, "--python-expr",
           "import canopy_ao.cli; canopy_ao.cli.main()", "-a", "--python-expr", probe, "--",
           "--live", "--method", "ellipsoid", "--tau", "1.7", "--no-proxies",
           "--distance", "0"]  # opts()'s: the ground's patch reaches the leaves by distance
    out = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "canopy_ao: error" not in out.stderr, out.stderr
    # The leaves are keyed (a shape key): a render writes their AO into its own evaluated
    # mesh (test_live_render.py checks the frames), the file's keeps the frame the CLI baked,
    # a plain bake of it (a live bake's first frame is lit as any bake, its ground included).
    kept = np.load(tmp_path / "ao.npy")
    np.testing.assert_allclose(kept, _full("ellipsoid", 1.7)["Leaves"], atol=2e-6)
    assert os.path.exists(str(tmp_path / "frame_0004.png"))
    # --frames: the cache written and saved.
    cmd = ["blender", "-b", "--factory-startup", path, "--python-expr",
           "import canopy_ao.cli; canopy_ao.cli.main()", "--", "--frames", "3", "4",
           "--method", "sphere", "--tau", "1.7", "--no-proxies", "--save"]
    out = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "canopy_ao: frames 3-4, sphere" in out.stdout
    # Its progress, per frame, on stderr (core/progress.py).
    assert "canopy_ao: progress: baking, 0/2 frames (0 %), time left unknown" in out.stderr
    bpy.ops.wm.open_mainfile(filepath=path)
    names = {a.name for a in bpy.context.scene.objects["Leaves"].data.attributes}
    assert {"CanopyAO_3", "CanopyAO_4"} <= names
    assert sys.modules["canopy_ao.blender.frames"].MODIFIER in \
        bpy.context.scene.objects["Leaves"].modifiers


def test_live_and_frame_bakes_in_a_window(user_scripts):
    """In a real window (Xvfb): undo around live AO (an unrelated edit undone: the session is
    rebuilt at the next frame; the live bake undone: live AO off, nothing written), and the
    modal frame-range bake (Esc leaves nothing; run to the end, every frame cached). Skipped
    without xvfb-run."""
    from ui_harness import run_in_window
    run_in_window(os.path.join(os.path.dirname(__file__), "ui_live.py"), user_scripts)


def test_auto_choosing_a_rung_that_cannot_run_live_is_refused_unwritten(animated,
                                                                        monkeypatch):
    from canopy_ao.core import ladder
    real = ladder.choose

    def choose_rays(plan, items, grass_only_auto):
        real(plan, items, grass_only_auto)
        plan.method = "raytrace"  # as auto does on a small scene its rays bake within budget
    monkeypatch.setattr(ladder, "choose", choose_rays)
    with pytest.raises(CanopyAOError, match="auto chose the raytrace rung"):
        run_bake(bpy.context, list(NAMES), opts(method="auto", tau=None, live=True))
    assert "CanopyAO" not in animated.objects["Leaves"].data.attributes
    assert not animated.canopy_ao.live
    with pytest.raises(CanopyAOError, match="auto chose the raytrace rung"):
        frames.FrameBake(bpy.context, list(NAMES), opts(method="auto", tau=None), 1, 3).run()
    assert not any(a.name.startswith("CanopyAO") for a in
                   animated.objects["Leaves"].data.attributes)
    assert animated.frame_current == 1


def test_the_animation_panel_shows_live_state_and_the_frame_bakes(animated):
    from types import SimpleNamespace
    from test_addon import FakeLayout
    from canopy_ao.blender import panels

    def drawn():
        log = []
        panels.CANOPY_AO_PT_animation.draw(SimpleNamespace(layout=FakeLayout(log)), bpy.context)
        return log
    off = drawn()
    assert {("operator", "canopy_ao.bake_frames"), ("operator", "canopy_ao.clear_frames")} \
        <= set(off)
    assert ("operator", "canopy_ao.live_stop") not in off
    run_bake(bpy.context, list(NAMES), opts(live=True))
    animated.frame_set(2)
    on = drawn()
    assert ("operator", "canopy_ao.live_stop") in on
    assert any(kind == "label" and text.startswith("ellipsoid, τ 1.7") for kind, text in on)


def test_live_refuses_targets_a_frame_cache_would_hide(animated):
    frames.FrameBake(bpy.context, list(NAMES), opts(), 1, 2).run()
    frames.FrameBake(bpy.context, list(NAMES), opts(), 1, 3).run()  # a range baked again
    assert "CanopyAO_3" in animated.objects["Leaves"].data.attributes
    assert len([g for g in bpy.data.node_groups if g.get(frames.GROUP_TAG)]) == 1
    with pytest.raises(CanopyAOError, match="frame cache .* would hide live AO"):
        run_bake(bpy.context, list(NAMES), opts(live=True))
    assert not animated.canopy_ao.live


def test_a_reloaded_file_keeps_the_shell_partition_of_the_session_that_saved_it(animated,
                                                                                 tmp_path):
    run_bake(bpy.context, list(NAMES), opts(method="shells", live=True))
    animated.frame_set(5)
    at5 = {n: _drawn(n) for n in NAMES}
    path = str(tmp_path / "shells.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)  # re-armed at frame 5, a frame the bake was not at
    scene = bpy.context.scene
    scene.frame_set(6)
    scene.frame_set(5)
    _assert_same_fit({n: _drawn(n) for n in NAMES}, at5)
