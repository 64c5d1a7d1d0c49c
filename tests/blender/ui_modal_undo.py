"""Windowed checks that background mode cannot make: the modal bake (timer ticks, Esc) and undo.

    xvfb-run -a blender --factory-startup --enable-event-simulate --python tests/blender/ui_modal_undo.py

Run by test_addon.py::test_modal_bake_escape_and_undo when xvfb-run exists. Steps run from a
timer once the window is up; prints "UI-OK" and exits 0, or exits 1 with the failed check.
"""
import os
import sys
import traceback

import bpy

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "python"))
import tree_scene  # noqa: E402


def fail(msg):
    print(f"UI-FAIL: {msg}", file=sys.stderr, flush=True)
    os._exit(1)


def check(cond, msg):
    if not cond:
        fail(msg)


def window_ctx():
    win = bpy.context.window_manager.windows[0]
    return dict(window=win, screen=win.screen, area=win.screen.areas[0])


def ground():
    return bpy.data.objects["Ground"].data.attributes


def steps():
    import addon_utils
    from canopy_ao.blender import mesh_io
    addon_utils.enable("canopy_ao", default_set=False, handle_error=None)
    for ob in list(bpy.data.objects):
        bpy.data.objects.remove(ob)
    for name, (p, t) in tree_scene.scene(True).items():
        me = bpy.data.meshes.new(name)
        me.from_pydata(p.tolist(), [], t.tolist())
        bpy.context.scene.collection.objects.link(bpy.data.objects.new(name, me))
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
    print("UI-OK", flush=True)
    os._exit(0)


_it = steps()


def tick():
    try:
        return next(_it)
    except StopIteration:
        return None
    except BaseException:
        traceback.print_exc()
        fail("exception")


bpy.app.timers.register(tick, first_interval=1.0)
