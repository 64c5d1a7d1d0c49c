"""Windowed checks that background mode cannot make: the modal bake (timer ticks, Esc) and undo.

    xvfb-run -a blender --factory-startup --enable-event-simulate --python tests/blender/ui_modal_undo.py

Run by test_addon.py::test_modal_bake_escape_and_undo when xvfb-run exists. Steps run from a
timer once the window is up; prints "UI-OK" and exits 0, or exits 1 with the failed check.
"""
import os
import sys

import bpy

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "python"))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from ui_harness import build_tree_scene, check, run_steps, window_ctx  # noqa: E402


def ground():
    return bpy.data.objects["Ground"].data.attributes


def steps():
    import addon_utils
    from canopy_ao.blender import mesh_io
    addon_utils.enable("canopy_ao", default_set=False, handle_error=None)
    build_tree_scene()
    with bpy.context.temp_override(**window_ctx()):
        bpy.ops.ed.undo_push(message="scene built")
        r = bpy.ops.canopy_ao.bake('INVOKE_DEFAULT', objects="Ground,Leaves", method="ellipsoid",
                                   tau=2.0)
    check(r == {'RUNNING_MODAL'}, f"invoke gave {r}, not a modal bake")
    for _ in range(80):  # one object per timer tick
        if "CanopyAO" in ground():
            break
        yield 0.1
    check("CanopyAO" in ground(), "the modal bake did not finish in 8 s")
    check(mesh_io.owned_attributes(bpy.data.objects["Ground"]) == ["CanopyAO"], "not marked ours")
    with bpy.context.temp_override(**window_ctx()):
        bpy.ops.ed.undo()
    yield 0.2
    check("CanopyAO" not in ground(), "undo left the attribute")
    check(not mesh_io.owned_attributes(bpy.data.objects["Ground"]), "undo left the mark")
    check("Canopy AO Proxies" not in bpy.data.collections, "undo left the proxies")
    with bpy.context.temp_override(**window_ctx()):
        bpy.ops.canopy_ao.bake('INVOKE_DEFAULT', objects="Ground,Leaves", method="ellipsoid",
                               tau=2.0, attribute="Cancelled")
    win = bpy.context.window_manager.windows[0]
    win.event_simulate(type='ESC', value='PRESS')
    win.event_simulate(type='ESC', value='RELEASE')
    yield 2.0
    check("Cancelled" not in ground(), "Esc did not cancel the bake (or it wrote anyway)")

    # A bug in the middle of a modal bake: the modal ends, its timer and status text go
    # (_stop), and nothing is written.
    from canopy_ao.blender import operators
    from canopy_ao.core import lighting
    stops, real_stop, real_eval = [], operators.CANOPY_AO_OT_bake._stop, lighting.evaluate_points

    def counting_stop(self, context):
        stops.append(1)
        return real_stop(self, context)

    def broken(*a, **k):
        raise RuntimeError("a bug in the evaluation")

    operators.CANOPY_AO_OT_bake._stop, lighting.evaluate_points = counting_stop, broken
    try:
        with bpy.context.temp_override(**window_ctx()):
            r = bpy.ops.canopy_ao.bake('INVOKE_DEFAULT', objects="Ground,Leaves",
                                       method="ellipsoid", tau=2.0, attribute="Broken")
        check(r == {'RUNNING_MODAL'}, f"invoke gave {r}")
        for _ in range(40):
            if stops:
                break
            yield 0.1
    finally:
        operators.CANOPY_AO_OT_bake._stop, lighting.evaluate_points = real_stop, real_eval
    check(stops == [1], f"the modal did not clean up after a bug (stop called {len(stops)}x)")
    check("Broken" not in ground(), "a failed bake wrote its attribute")

    # A texel bake: its texels are evaluated chunk by chunk across timer ticks (progress moves),
    # and Esc stops it with no image or file written.
    from canopy_ao.blender import job as job_mod
    import tempfile
    bpy.ops.mesh.primitive_plane_add(size=20.0)
    plane = bpy.context.object
    plane.name = "TexelGround"
    image_dir = tempfile.mkdtemp(prefix="canopy_ao_ui_")
    seen, real_step = [], job_mod.BakeJob.step

    def recording_step(self):
        seen.append((self.steps_done, self.steps))
        return real_step(self)

    saved = job_mod.CHUNK, operators.TICK, job_mod.BakeJob.step
    job_mod.CHUNK, operators.TICK, job_mod.BakeJob.step = 64, 0.0, recording_step
    try:
        with bpy.context.temp_override(**window_ctx()):
            r = bpy.ops.canopy_ao.bake('INVOKE_DEFAULT', objects="TexelGround",
                                       method="ellipsoid", tau=2.0, mode='TEXEL',
                                       resolution=128, image_dir=image_dir)
        check(r == {'RUNNING_MODAL'}, f"texel invoke gave {r}")
        for _ in range(100):
            if len(seen) >= 10:
                break
            yield 0.05
        check(len(seen) >= 10, f"the texel bake made {len(seen)} steps in 5 s")
        win.event_simulate(type='ESC', value='PRESS')
        win.event_simulate(type='ESC', value='RELEASE')
        yield 0.5
        n_at_esc = len(seen)
        yield 0.5
    finally:
        job_mod.CHUNK, operators.TICK, job_mod.BakeJob.step = saved
    done = [d for d, _total in seen]
    total = seen[0][1]
    check(total > 100, f"a 128² texel bake in chunks of 64 has {total} steps")
    check(done == sorted(done) and done[-1] > done[0], f"progress did not move: {done[:20]}")
    check(len(seen) == n_at_esc and done[-1] < total - 1, "Esc did not stop the texel bake")
    check(not os.listdir(image_dir), "a cancelled texel bake wrote a file")
    check(not any(img.get("canopy_ao_object") == "TexelGround" for img in bpy.data.images),
          "a cancelled texel bake made an image")
    print("UI-OK", flush=True)
    os._exit(0)


run_steps(steps)
