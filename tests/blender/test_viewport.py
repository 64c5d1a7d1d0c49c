"""What the artist sees after and during a bake (blender/viewport.py): the panel's toggle on the
screen Blender has even in background mode, and the modal bake in a window under Xvfb
(ui_viewport.py): status percentage, "Cancelled" after Esc, the AO shown when it finishes."""
import os

import bpy


def _views():
    return [a.spaces.active for w in bpy.context.window_manager.windows
            for a in w.screen.areas if a.type == 'VIEW_3D']


def test_the_toggle_shows_the_baked_attribute_and_goes_back(tree_scene_objects):
    ground = tree_scene_objects["Ground"].data
    ground.color_attributes.new("UserPaint", 'BYTE_COLOR', 'POINT')
    ground.color_attributes.active_color = ground.color_attributes["UserPaint"]
    views = _views()
    assert views, "factory startup has a 3D view even in background mode"
    views[0].shading.color_type = 'OBJECT'  # the user's choice, put back by the toggle
    assert bpy.ops.canopy_ao.bake(objects="Ground,Leaves", method="sphere", tau=1.0) \
        == {'FINISHED'}
    # A scripted bake (not from the panel) leaves the views alone.
    assert views[0].shading.color_type == 'OBJECT'
    assert bpy.ops.canopy_ao.show_ao() == {'FINISHED'}
    assert all(v.shading.color_type == 'VERTEX' for v in views)
    assert ground.color_attributes.active_color.name == "CanopyAO"
    # Only meshes that have the attribute change: the trunk was not baked.
    trunk = tree_scene_objects["Trunk"].data
    assert "CanopyAO" not in trunk.attributes
    assert bpy.ops.canopy_ao.show_ao() == {'FINISHED'}
    assert views[0].shading.color_type == 'OBJECT'
    assert all(v.shading.color_type == 'MATERIAL' for v in views[1:])


def test_status_percentage_cancel_and_the_ao_shown_in_the_viewport(user_scripts):
    from ui_harness import run_in_window
    run_in_window(os.path.join(os.path.dirname(__file__), "ui_viewport.py"), user_scripts,
                  timeout=180)
