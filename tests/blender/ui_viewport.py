"""Windowed checks of what the artist sees (blender/viewport.py): a modal bake's status line
in the panel gives a percentage and says "Cancelled" after Esc; a finished per-vertex bake
shows its attribute in the 3D views' Solid shading; the panel's toggle goes back and forth.

    xvfb-run -a blender --factory-startup --enable-event-simulate --python tests/blender/ui_viewport.py

Run by test_viewport.py when xvfb-run exists; prints "UI-OK" and exits 0, or exits 1 with the
failed check.
"""
import os
import sys

import bpy

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "python"))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from ui_harness import build_tree_scene, check, run_steps, window_ctx  # noqa: E402


def views():
    return [a.spaces.active for w in bpy.context.window_manager.windows
            for a in w.screen.areas if a.type == 'VIEW_3D']


def steps():
    import addon_utils
    addon_utils.enable("canopy_ao", default_set=False, handle_error=None)
    from canopy_ao.blender import job as job_mod, operators, viewport
    build_tree_scene()
    ground = bpy.data.objects["Ground"].data
    # A colour attribute of the user's, active: the bake's must take its place in the view.
    ground.color_attributes.new("UserPaint", 'BYTE_COLOR', 'POINT')
    ground.color_attributes.active_color = ground.color_attributes["UserPaint"]
    check(views() and all(v.shading.color_type == 'MATERIAL' for v in views()),
          f"factory shading is not MATERIAL: {[v.shading.color_type for v in views()]}")

    statuses, real_set = [], viewport.set_status

    def recording(context, text, icon='NONE'):
        statuses.append(text)
        return real_set(context, text, icon)

    saved = job_mod.CHUNK, operators.TICK, viewport.set_status
    job_mod.CHUNK, operators.TICK, viewport.set_status = 64, 0.0, recording
    try:
        with bpy.context.temp_override(**window_ctx()):
            r = bpy.ops.canopy_ao.bake('INVOKE_DEFAULT', objects="Ground,Leaves",
                                       method="ellipsoid", tau=2.0)
        check(r == {'RUNNING_MODAL'}, f"invoke gave {r}, not a modal bake")
        for _ in range(200):
            if "CanopyAO" in ground.attributes and not viewport.STATUS["text"]:
                break
            yield 0.05
        check("CanopyAO" in ground.attributes, "the modal bake did not finish in 10 s")
        pct = [s for s in statuses if s.endswith(" %")]
        check(len(pct) >= 3 and any(s.startswith("Baking Ground: ") for s in pct),
              f"the panel's status gave no percentages: {statuses[:10]}")
        nums = [int(s.rsplit(" ", 2)[1]) for s in pct]
        check(all(0 <= n <= 100 for n in nums), f"percentages out of range: {nums}")
        # The finished bake shows: every 3D view in Attribute colours, the AO active.
        check(all(v.shading.color_type == 'VERTEX' for v in views()),
              f"the views do not show the attribute: {[v.shading.color_type for v in views()]}")
        check(ground.color_attributes.active_color.name == "CanopyAO",
              f"active color is {ground.color_attributes.active_color.name}")
        check(viewport.shown(bpy.context), "the panel's toggle does not read as shown")
        # The toggle goes back to what the views showed before, and shows again.
        with bpy.context.temp_override(**window_ctx()):
            bpy.ops.canopy_ao.show_ao()
        check(all(v.shading.color_type == 'MATERIAL' for v in views()), "toggle did not hide")
        with bpy.context.temp_override(**window_ctx()):
            bpy.ops.canopy_ao.show_ao()
        check(all(v.shading.color_type == 'VERTEX' for v in views()), "toggle did not show")

        # Esc: the status says so, nothing is written.
        statuses.clear()
        with bpy.context.temp_override(**window_ctx()):
            bpy.ops.canopy_ao.bake('INVOKE_DEFAULT', objects="Ground,Leaves",
                                   method="ellipsoid", tau=2.0, attribute="Cancelled")
        yield 0.2
        win = bpy.context.window_manager.windows[0]
        win.event_simulate(type='ESC', value='PRESS')
        win.event_simulate(type='ESC', value='RELEASE')
        yield 1.0
    finally:
        job_mod.CHUNK, operators.TICK, viewport.set_status = saved
    check("Cancelled" not in ground.attributes, "Esc did not cancel the bake")
    check(viewport.STATUS["text"].startswith("Cancelled"),
          f"the panel's status after Esc: {viewport.STATUS['text']!r} ({statuses[-3:]})")
    print("UI-OK", flush=True)
    os._exit(0)


run_steps(steps)
