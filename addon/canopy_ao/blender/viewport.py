"""What the artist sees: the baked attribute in the 3D viewports' Solid shading, and the status
of the bake running or last stopped in the panel.

Solid shading shows a mesh's *active* color attribute when its colour type is 'VERTEX' (called
"Attribute" in the UI from 3.2 on; the identifier is 'VERTEX' in every version this add-on
supports). Showing the AO makes the baked attribute active on each mesh that has it (mesh data:
undone with the bake's or the toggle's undo step) and sets the colour type of every 3D view in
the open windows, remembering the one before; hiding puts those back. A viewport's shading is
screen data, which Blender's undo does not cover: the toggle is how to go back.
"""

import bpy

# The text the panel shows under the bake button while a modal bake runs or after it was
# stopped: runtime only, never saved in the .blend.
STATUS = {"text": "", "icon": 'NONE'}
# Colour type of each 3D view before show() set it, by the space's pointer.
_BEFORE = {}
COLOR_TYPE = 'VERTEX'


def set_status(context, text, icon='NONE'):
    """The panel's status line (and a redraw of the sidebars showing it)."""
    STATUS["text"], STATUS["icon"] = text, icon
    screen = getattr(context, "screen", None)
    for area in screen.areas if screen is not None else ():
        if area.type == 'VIEW_3D':
            area.tag_redraw()


def _views(context):
    """Every 3D view's space in the open windows."""
    wm = context.window_manager
    for win in wm.windows if wm is not None else ():
        for area in win.screen.areas:
            if area.type == 'VIEW_3D':
                yield area, area.spaces.active


def shown(context):
    """Whether the 3D views show color attributes in Solid shading (all of them, one at least)."""
    views = [space.shading.color_type for _area, space in _views(context)]
    return bool(views) and all(t == COLOR_TYPE for t in views)


def _color_attribute(obj, name):
    if obj.type != 'MESH' or obj.data is None:
        return None
    ca = getattr(obj.data, "color_attributes", None)
    return ca.get(name) if ca is not None else None


def show(context, objects, name):
    """Make ``name`` the active color attribute of each of ``objects`` that has it and switch
    every 3D view's Solid shading to show it. Returns how many objects show it."""
    count = 0
    for obj in objects:
        attr = _color_attribute(obj, name)
        if attr is None or obj.library is not None or obj.data.library is not None:
            continue
        if obj.data.color_attributes.active_color != attr:
            obj.data.color_attributes.active_color = attr
        count += 1
    for area, space in _views(context):
        if space.shading.color_type != COLOR_TYPE:
            _BEFORE[space.as_pointer()] = space.shading.color_type
            space.shading.color_type = COLOR_TYPE
        area.tag_redraw()
    return count


def hide(context):
    """Put back each 3D view's colour type from before show() ('MATERIAL', Blender's default,
    for a view it did not set)."""
    for area, space in _views(context):
        if space.shading.color_type == COLOR_TYPE:
            space.shading.color_type = _BEFORE.pop(space.as_pointer(), 'MATERIAL')
        area.tag_redraw()


class CANOPY_AO_OT_show_ao(bpy.types.Operator):
    """Show the baked AO in the 3D viewports' Solid shading (the attribute made active on the
    selected meshes, or on every mesh that has it), or go back to the colours shown before"""

    bl_idname = "canopy_ao.show_ao"
    bl_label = "Show AO in Viewport"
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def poll(cls, context):
        if not any(True for _ in _views(context)):
            cls.poll_message_set("No 3D viewport is open")
            return False
        return True

    def execute(self, context):
        if shown(context):
            hide(context)
            self.report({'INFO'}, "Canopy AO: viewports show their colours from before")
            return {'FINISHED'}
        name = context.scene.canopy_ao.attribute
        selected = [o for o in context.selected_objects if o.type == 'MESH']
        n = show(context, selected or context.scene.objects, name)
        if n == 0:
            self.report({'WARNING'}, f"no {'selected ' if selected else ''}mesh has a color "
                                     f"attribute '{name}': bake first")
        else:
            self.report({'INFO'}, f"Canopy AO: '{name}' shown on {n} object(s)")
        return {'FINISHED'}


classes = (CANOPY_AO_OT_show_ao,)

register, unregister = bpy.utils.register_classes_factory(classes)
