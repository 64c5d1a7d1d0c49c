"""The user guide's screenshots, taken in a windowed Blender (docs/guide.md, 'The panel'): the
example tree (examples/make_scene.py's round_tree, quick size) baked per vertex from the panel,
the 3D View filling the window with the sidebar on the *Canopy AO* tab, saved as

    panel.png        the 3D View with its sidebar: the panel beside the baked tree in Solid shading
    viewport_ao.png  the 3D View alone, the AO the bake showed, in flat lighting

into $CANOPY_AO_SCREENSHOTS (default docs/images/). Regenerate the committed pictures with

    xvfb-run -a -s "-screen 0 1280x800x24" blender --factory-startup --enable-event-simulate \
        --python tests/blender/ui_screenshots.py

(the add-on found through BLENDER_USER_SCRIPTS, as in scripts/test.sh). Run by
test_screenshots.py into a temporary folder; prints "UI-OK" and exits 0, or exits 1 with the
failed check.
"""
import os
import sys

import bpy

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.join(REPO, "examples"))
from ui_harness import check, fail, run_steps  # noqa: E402

OUT = os.environ.get("CANOPY_AO_SCREENSHOTS") or os.path.join(REPO, "docs", "images")


def view3d():
    win = bpy.context.window_manager.windows[0]
    area = max((a for a in win.screen.areas if a.type == 'VIEW_3D'),
               key=lambda a: a.width * a.height)
    region = next(r for r in area.regions if r.type == 'WINDOW')
    return win, area, region


def show_our_tab(win, area, drawn):
    """Click down the sidebar's tab strip (its right edge) until the Canopy AO tab is the one
    drawn: Blender 3.4 has no API to choose a sidebar tab. Yields the seconds to wait."""
    region = next(r for r in area.regions if r.type == 'UI')
    x = region.x + region.width - max(4, region.width // 40)
    for y in range(region.y + region.height - 10, region.y, -20):
        win.event_simulate(type='MOUSEMOVE', value='NOTHING', x=x, y=y)
        win.event_simulate(type='LEFTMOUSE', value='PRESS', x=x, y=y)
        win.event_simulate(type='LEFTMOUSE', value='RELEASE', x=x, y=y)
        drawn.clear()
        yield 0.1
        if drawn:
            return
    fail("the Canopy AO tab never showed in the sidebar")


def steps():
    import addon_utils
    from mathutils import Euler

    import make_scene
    from canopy_ao.blender import viewport
    from canopy_scenes import make_scene as scene_named
    check(addon_utils.enable("canopy_ao", default_set=False, handle_error=None) is not None,
          "the add-on did not enable")
    from canopy_ao.blender import panels
    drawn, draw = [], panels.CANOPY_AO_PT_main.draw

    def recording(self, context):  # which sidebar tab is shown: ours when this runs
        drawn.append(True)
        return draw(self, context)
    panels.CANOPY_AO_PT_main.draw = recording
    for ob in list(bpy.data.objects):
        bpy.data.objects.remove(ob)
    make_scene.build(scene_named("round_tree", quick=True))
    os.makedirs(OUT, exist_ok=True)

    win, area, region = view3d()
    win.event_simulate(type='ESC', value='PRESS')  # the splash screen
    win.event_simulate(type='ESC', value='RELEASE')
    yield 0.5
    space = area.spaces.active
    space.show_region_ui = True
    space.overlay.show_floor = False
    space.overlay.show_axis_x = space.overlay.show_axis_y = False
    r3d = space.region_3d
    r3d.view_perspective = 'PERSP'
    r3d.view_rotation = Euler((1.35, 0.0, 0.75)).to_quaternion()
    yield from show_our_tab(win, area, drawn)
    with bpy.context.temp_override(window=win, area=area, region=region):
        bpy.ops.view3d.view_all()
    yield 0.5

    # The bake as an artist starts it: from the panel (modal), the panel's defaults.
    settings = bpy.context.scene.canopy_ao
    settings.show_proxies = False
    with bpy.context.temp_override(window=win, area=area, region=region):
        r = bpy.ops.canopy_ao.bake('INVOKE_DEFAULT')
    check(r == {'RUNNING_MODAL'}, f"invoke gave {r}, not a modal bake")
    ground = bpy.data.objects["ground"].data
    for _ in range(600):
        if "CanopyAO" in ground.attributes and not viewport.STATUS["text"]:
            break
        yield 0.05
    check("CanopyAO" in ground.attributes, "the bake did not finish in 30 s")
    check(space.shading.color_type == 'VERTEX', "the bake did not show the AO")
    yield 0.5  # let the window draw the baked colours and the panel's report

    shots = {"panel.png": None, "viewport_ao.png": area}
    for name, shot_area in shots.items():
        path = os.path.join(OUT, name)
        if os.path.exists(path):
            os.remove(path)
        if shot_area is None:
            # The 3D View with its sidebar (the whole window reads back black under Xvfb in
            # Blender 4.x: screen.screenshot there is taken before the window has drawn).
            with bpy.context.temp_override(window=win, area=area, region=region):
                bpy.ops.screen.screenshot_area(filepath=path)
        else:
            # The AO alone: flat lighting shows the attribute's colour as it is.
            space.show_region_ui = space.show_region_toolbar = False
            space.overlay.show_overlays = False
            space.shading.light = 'FLAT'
            yield 0.5
            with bpy.context.temp_override(window=win, area=area, region=region):
                bpy.ops.screen.screenshot_area(filepath=path)
        check(os.path.isfile(path), f"no screenshot at {path}")
        yield 0.2
    print("UI-OK", flush=True)
    os._exit(0)


run_steps(steps)
