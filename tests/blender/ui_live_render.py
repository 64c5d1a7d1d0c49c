"""Windowed check of live AO in the renders a user starts from the UI: Ctrl+F12 (an animation
render job, Lock Interface on), F12 (a still render job, Lock Interface off) and Ctrl+F12 in
Eevee each show the frame's geometry and AO, pixel for pixel what a full bake of that frame
renders.

    xvfb-run -a blender --factory-startup --enable-event-simulate --python tests/blender/ui_live_render.py

Run by test_live_render.py::test_renders_started_in_a_window_follow_the_frame when xvfb-run
exists. Prints "UI-OK" and exits 0, or exits 1 with the failed check.
"""
import os
import sys
import tempfile

import bpy
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "python"))
sys.path.insert(0, HERE)

from ui_harness import check, run_steps, window_ctx  # noqa: E402

TMP = tempfile.mkdtemp(prefix="canopy_ao_ui_render_")


def wait_for_render(done):
    """Until the render job has finished: its render_complete handler has run and the job is
    gone (render_complete runs before the job ends; a render started then is cancelled)."""
    for _ in range(600):
        if done and not bpy.app.is_job_running('RENDER'):
            return True
        yield 0.1
    return False


def _set_eevee(scene):
    """Eevee's engine name: BLENDER_EEVEE_NEXT in 4.2-4.4, BLENDER_EEVEE before and after."""
    for name in ('BLENDER_EEVEE_NEXT', 'BLENDER_EEVEE'):
        try:
            scene.render.engine = name
            return name
        except TypeError:
            continue
    raise AssertionError("no Eevee engine")


def steps():
    import addon_utils
    addon_utils.enable("canopy_ao", default_set=False, handle_error=None)
    from canopy_ao.blender import live, properties
    from canopy_ao.blender.job import run_bake
    from test_live_render import (PIXEL_TOL, _deforming_tree, _pixels, bake_as_a_live_frame,
                                  held_at_first_frame)
    scene = _deforming_tree("simple_deform")
    done = []

    def complete(*_args):
        done.append(True)
    bpy.app.handlers.render_complete.append(complete)
    with bpy.context.temp_override(**window_ctx()):
        r = bpy.ops.canopy_ao.bake(method="ellipsoid", tau=1.7, live=True, show_proxies=False)
    check(r == {'FINISHED'}, f"the live bake gave {r}")
    # Ctrl+F12, Lock Interface on: frames 1-3 written by the render job.
    scene.render.use_lock_interface = True
    scene.render.filepath = os.path.join(TMP, "anim_")
    with bpy.context.temp_override(**window_ctx()):
        r = bpy.ops.render.render('INVOKE_DEFAULT', animation=True)
    check(r == {'RUNNING_MODAL'}, f"Ctrl+F12 gave {r}")
    ok = yield from wait_for_render(done)
    check(ok, "the animation render did not complete in 60 s")
    # F12 at frame 3, Lock Interface off.
    done.clear()
    scene.render.use_lock_interface = False
    scene.frame_set(3)
    with bpy.context.temp_override(**window_ctx()):
        r = bpy.ops.render.render('INVOKE_DEFAULT')
    check(r == {'RUNNING_MODAL'}, f"F12 gave {r}")
    ok = yield from wait_for_render(done)
    check(ok, "the still render did not complete in 60 s")
    yield 0.5
    still = os.path.join(TMP, "still_3.png")
    bpy.data.images["Render Result"].save_render(still)
    # Eevee (a GPU engine: it redraws a mesh only when the depsgraph updated it), Ctrl+F12.
    scene.frame_set(1)
    eevee = _set_eevee(scene)
    scene.render.filepath = os.path.join(TMP, "eevee_")
    done.clear()
    with bpy.context.temp_override(**window_ctx()):
        r = bpy.ops.render.render('INVOKE_DEFAULT', animation=True)
    ok = yield from wait_for_render(done)
    check(ok, "the Eevee animation render did not complete in 60 s")
    live.stop(scene)
    # The reference: each frame baked in full (same rung and τ, and a live frame's GROUND
    # rule, core/live.held_ground) and rendered in the foreground.
    opts = dict(properties.scene_options(scene), method="ellipsoid", tau=1.7,
                show_proxies=False, live=False)
    held = held_at_first_frame(scene, opts)
    for frame in (1, 2, 3):
        scene.frame_set(frame)
        bake_as_a_live_frame(opts, held)
        shots = {'CYCLES': [("Ctrl+F12", os.path.join(TMP, f"anim_{frame:04d}.png"))],
                 eevee: [("Eevee Ctrl+F12", os.path.join(TMP, f"eevee_{frame:04d}.png"))]}
        if frame == 3:
            shots['CYCLES'].append(("F12", still))
        for engine, pairs in shots.items():
            scene.render.engine = engine
            scene.render.filepath = os.path.join(TMP, f"full_{engine}_{frame}.png")
            bpy.ops.render.render(write_still=True)
            want = _pixels(scene.render.filepath)
            for what, path in pairs:
                err = np.abs(_pixels(path) - want).max()
                check(err <= PIXEL_TOL, f"{what} at frame {frame}: {err:.3f} from a full bake")
    print("UI-OK", flush=True)
    os._exit(0)


run_steps(steps)
