"""Windowed checks of animated AO that background mode cannot make: real undo around live AO,
and the modal frame-range bake (timer ticks, Esc).

    xvfb-run -a blender --factory-startup --enable-event-simulate --python tests/blender/ui_live.py

Run by test_live.py::test_live_and_frame_bakes_in_a_window when xvfb-run exists. Prints
"UI-OK" and exits 0, or exits 1 with the failed check.
"""
import os
import sys

import bpy
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "python"))
sys.path.insert(0, HERE)  # first: this folder's conftest and test_live

from ui_harness import check, run_steps, window_ctx  # noqa: E402


def leaves_ao():
    from canopy_ao.blender import mesh_io
    return mesh_io.read_ao_attribute(bpy.data.objects["Leaves"], "CanopyAO")


def leaves_drawn():
    """The leaves' AO as the viewport draws it (their evaluated mesh's)."""
    ob = bpy.data.objects["Leaves"]
    mesh = ob.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
    buf = np.empty(len(mesh.vertices) * 4, np.float32)
    mesh.attributes["CanopyAO"].data.foreach_get("color", buf)
    return buf.reshape(-1, 4)[:, 0].copy()


def steps():
    import addon_utils
    addon_utils.enable("canopy_ao", default_set=False, handle_error=None)
    from canopy_ao.blender import frames, live
    from test_live import _animated_tree
    scene = _animated_tree()
    ctx = window_ctx()
    with bpy.context.temp_override(**ctx):
        bpy.ops.ed.undo_push(message="animated tree built")
        r = bpy.ops.canopy_ao.bake(method="ellipsoid", tau=1.7, live=True, show_proxies=False)
        bpy.ops.ed.undo_push(message="live bake")  # a script's operator call pushes none
    check(r == {'FINISHED'}, f"the live bake gave {r}")
    scene = bpy.context.scene
    check(scene.canopy_ao.live and live.session_of(scene) is not None, "live did not start")
    # An unrelated edit undone: every datablock is replaced, the session is dropped and rebuilt
    # from the record at the next frame change (no stale reference, no crash).
    with bpy.context.temp_override(**ctx):
        bpy.ops.object.select_all(action='SELECT')
        bpy.ops.ed.undo_push(message="select")
        bpy.ops.ed.undo()
    yield 0.2
    scene = bpy.context.scene
    check(scene.canopy_ao.live and live.session_of(scene) is None, "undo kept the session")
    at1 = leaves_ao()
    scene.frame_set(6)
    check(live.session_of(scene) is not None, "the frame change did not rebuild the session")
    check(np.abs(leaves_drawn() - at1).max() > 0.02, "live AO did not follow the frame after undo")
    # Playback: each frame writes the swaying leaves' evaluated mesh alone. Their original is
    # written once at most as it starts (Blender then evaluates the keyed leaves again outside
    # a frame change: depsgraph_update_post), then not until something asks (here a stop).
    from canopy_ao.blender import live_session
    flushes, real_flush = [], live_session.Session.flush
    live_session.Session.flush = lambda self, *a, **kw: (flushes.append(1),
                                                        real_flush(self, *a, **kw))[1]
    try:
        frames_before = live.session_of(scene).frames
        with bpy.context.temp_override(**ctx):
            bpy.ops.screen.animation_play()
        yield 2.0
        with bpy.context.temp_override(**ctx):
            bpy.ops.screen.animation_cancel(restore_frame=False)
        yield 0.2
        played = live.session_of(scene).frames - frames_before
        check(played >= 4, f"playback ran {played} live frames in 2 s")
        check(len(flushes) <= 1, f"playback wrote the originals {len(flushes)} times in "
              f"{played} frames")
        drawn = leaves_drawn()
        live.stop(scene)
        check(np.array_equal(leaves_ao(), drawn), "the stop did not keep the last frame drawn")
    finally:
        live_session.Session.flush = real_flush
    scene.canopy_ao.live = True
    # The live bake itself undone: no attribute, no record, live off, frame changes inert.
    with bpy.context.temp_override(**ctx):
        bpy.ops.ed.undo()
    yield 0.2
    scene = bpy.context.scene
    check("CanopyAO" not in bpy.data.objects["Leaves"].data.attributes, "undo left the AO")
    check(not scene.canopy_ao.live and live.RECORD not in scene, "undo left live AO on")
    scene.frame_set(3)
    check("CanopyAO" not in bpy.data.objects["Leaves"].data.attributes, "a frame wrote AO")

    # The modal frame-range bake (the panel's options): Esc after a few frames leaves nothing.
    scene.frame_set(1)
    s = scene.canopy_ao
    s.method, s.calibrate_tau, s.tau, s.show_proxies = "ellipsoid", False, 1.7, False
    made = []
    real_step = frames.FrameBake.step

    def counting_step(self):
        made.append(self.steps_done)
        return real_step(self)

    frames.FrameBake.step = counting_step
    try:
        with bpy.context.temp_override(**window_ctx()):
            r = bpy.ops.canopy_ao.bake_frames('INVOKE_DEFAULT')
        check(r == {'RUNNING_MODAL'}, f"invoke gave {r}, not a modal frame bake")
        for _ in range(100):
            if len(made) >= 3:
                break
            yield 0.05
        check(len(made) >= 3, f"the modal frame bake made {len(made)} steps in 5 s")
        win = bpy.context.window_manager.windows[0]
        win.event_simulate(type='ESC', value='PRESS')
        win.event_simulate(type='ESC', value='RELEASE')
        yield 0.5
    finally:
        frames.FrameBake.step = real_step
    names = {a.name for a in bpy.data.objects["Leaves"].data.attributes}
    check(not any(n.startswith("CanopyAO") for n in names), f"Esc left attributes {names}")
    check(bpy.data.objects["Leaves"].modifiers.get(frames.MODIFIER) is None, "Esc left a modifier")
    check(scene.frame_current == 1, f"Esc left the scene at frame {scene.frame_current}")
    # And to the end: every frame of the scene's range cached.
    with bpy.context.temp_override(**window_ctx()):
        bpy.ops.canopy_ao.bake_frames('INVOKE_DEFAULT')
    for _ in range(200):
        if "CanopyAO_9" in bpy.data.objects["Leaves"].data.attributes:
            break
        yield 0.05
    names = {a.name for a in bpy.data.objects["Leaves"].data.attributes}
    check({f"CanopyAO_{f}" for f in range(1, 10)} <= names, f"the frame bake wrote {names}")
    print("UI-OK", flush=True)
    os._exit(0)


run_steps(steps)
