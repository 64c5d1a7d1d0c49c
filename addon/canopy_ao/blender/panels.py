"""3D View → sidebar (N) → "Canopy AO"."""

import bpy

from . import viewport
from .gather import world_ao_distance
from .. import core
from ..core.native import core_status
from ..core.settings import OPTIONS


class _Sidebar:
    bl_space_type = 'VIEW_3D'
    bl_region_type = 'UI'
    bl_category = "Canopy AO"


class CANOPY_AO_PT_main(_Sidebar, bpy.types.Panel):
    bl_idname = "CANOPY_AO_PT_main"
    bl_label = "Canopy AO"

    def draw(self, context):
        layout = self.layout
        ok, msg = core_status()
        if not ok:
            box = layout.box()
            box.alert = True
            box.label(text="Native module not loaded", icon='ERROR')
            col = box.column(align=True)
            # Wrap the long message into lines the sidebar can show.
            words, line = msg.split(), ""
            for w in words:
                if len(line) + len(w) > 38:
                    col.label(text=line)
                    line = ""
                line += w + " "
            if line:
                col.label(text=line)
            return
        s = context.scene.canopy_ao
        # Blender's own layout: labels in a column of their own, so none is cut at the
        # sidebar's default width.
        layout.use_property_split = True
        layout.use_property_decorate = False
        col = layout.column()
        col.prop(s, "method")
        col.prop(s, "calibrate_tau")
        _sub(col, not s.calibrate_tau).prop(s, "tau")
        col.row(heading="Distance").prop(s, "use_world_distance", text="World")
        _sub(col, not s.use_world_distance).prop(s, "distance", text=" ")
        if s.use_world_distance:
            d = world_ao_distance(context.scene)
            col.label(text=(f"World AO distance: {d:g}" if context.scene.world and d > 0 else
                            f"No World: Cycles' {d:g}" if d > 0 else
                            "World AO distance 0: Cycles sees no AO"),
                      icon='NONE' if d > 0 else 'ERROR')
        rung = core.rung(s.method)
        if rung.uses_samples:  # auto: the most rays it may cast
            col.prop(s, "samples")
        if rung.chooses:
            col.prop(s, "time_budget", text=SHORT["time_budget"])
            col.prop(s, "target_rmse")
        col.separator()
        col.prop(s, "mode")
        col.prop(s, "attribute")
        col.prop(s, "overwrite")
        col.prop(s, "packing")
        sub = col.row()
        sub.enabled = s.packing == 'NONE'
        sub.prop(s, "channel")
        if s.mode == 'TEXEL':
            col.prop(s, "uv_map")
            col.prop(s, "resolution")
            col.prop(s, "texel_aa")
            col.prop(s, "margin")
            col.prop(s, "image_dir", text=SHORT["image_dir"])
            col.prop(s, "image_format")
            col.prop(s, "udim")
            col.prop(s, "atlas")
            _sub(col, s.channel != 'RGBA' or s.packing != 'NONE').prop(s, "pack_image")
        _checked_name(col, s, "thickness", "thickness_name", "Thickness")
        col.prop(s, "bent_normals", text="Bent")
        _sub(col, s.bent_normals != 'OFF').prop(s, "bent_normals_name", text="Name")
        col.separator()
        col.prop(s, "show_proxies")
        col.prop(s, "wire_material")
        col.prop(s, "gltf")
        _checked_name(col, s, "add_aov", "aov_name", "AOV", s.add_aov or s.wire_material)
        col.row(heading="Check").prop(s, "check_cycles", text="Cycles")
        _sub(col, s.check_cycles).prop(s, "cycles_samples", text="Samples")
        col.row(heading="Animation").prop(s, "live", text="Live")  # the Animation subpanel shows its state and the range bake
        col = layout.column()
        col.use_property_split = False
        col.separator()
        n_sel = sum(1 for o in context.selected_objects if o.type == 'MESH')
        label = f"Bake {n_sel} Selected" if n_sel else "Bake All Visible"
        col.operator("canopy_ao.bake", text=label, icon='RENDER_STILL')
        if context.screen is not None:
            col.operator("canopy_ao.show_ao", icon='SHADING_SOLID',
                         depress=viewport.shown(context),
                         text="Showing AO" if viewport.shown(context) else "Show AO")
        col.operator("canopy_ao.remove_wiring", icon='NODETREE')
        if viewport.STATUS["text"]:
            col.label(text=viewport.STATUS["text"], icon=viewport.STATUS["icon"])
        if s.last_report:
            col.label(text=f"Last: {s.last_report}", icon='INFO')


def _sub(col, enabled):
    """A column under col whose properties are greyed out unless ``enabled``."""
    sub = col.column()
    sub.enabled = bool(enabled)
    return sub


def _checked_name(col, s, flag, name, heading, enabled=None):
    """A switch and the name it writes under, on one row headed ``heading``."""
    row = col.row(heading=heading)
    row.prop(s, flag, text="")
    _sub(row, getattr(s, flag) if enabled is None else enabled).prop(s, name, text="")


# Labels shortened in the sidebar (its default width cuts the options' own names); the
# tooltips keep the full names and descriptions.
SHORT = {"time_budget": "Budget", "image_dir": "Folder", "calibration_points": "Cal. Points",
         "calibration_samples": "Cal. Rays", "forest_epsilon": "Cut-off"}

# Options the main panel lays out by hand; every other one is in Advanced, so each option of
# core/settings.py is reachable from the panel.
MAIN = {"method", "calibrate_tau", "tau", "use_world_distance", "distance", "samples",
        "time_budget", "target_rmse", "mode", "attribute", "overwrite", "uv_map", "resolution",
        "texel_aa", "margin", "image_dir", "image_format", "udim", "atlas", "channel", "packing",
        "pack_image", "thickness", "thickness_name", "bent_normals", "bent_normals_name",
        "show_proxies", "wire_material", "gltf", "add_aov", "aov_name", "check_cycles",
        "cycles_samples",
        "live"}


class CANOPY_AO_PT_animation(_Sidebar, bpy.types.Panel):
    """Live AO and frame-range bakes (blender/live.py, blender/frames.py)."""

    bl_idname = "CANOPY_AO_PT_animation"
    bl_label = "Animation"
    bl_parent_id = "CANOPY_AO_PT_main"
    bl_options = {'DEFAULT_CLOSED'}

    def draw(self, context):
        from . import live
        col = self.layout.column()
        s, scene = context.scene.canopy_ao, context.scene
        col.label(text="Live AO: on" if s.live else "Live AO: off (tick Live above)")
        session = live.session_of(scene)
        if s.live and session is not None:
            ms = 1000.0 * session.timings.get("total", 0.0)
            col.label(text=f"{session.plan.method}, τ {session.plan.tau:.3g}, {ms:.0f} ms/frame",
                      icon='TIME')
        if s.live:
            col.operator("canopy_ao.live_stop", icon='PAUSE')
            if scene.render.use_lock_interface is False:
                col.label(text="Renders: tick Render > Lock Interface", icon='ERROR')
        col.separator()
        col.label(text=f"Frames {scene.frame_start}-{scene.frame_end}")
        col.operator("canopy_ao.bake_frames", icon='RENDER_ANIMATION')
        col.operator("canopy_ao.clear_frames", icon='TRASH')


class CANOPY_AO_PT_advanced(_Sidebar, bpy.types.Panel):
    bl_idname = "CANOPY_AO_PT_advanced"
    bl_label = "Advanced"
    bl_parent_id = "CANOPY_AO_PT_main"
    bl_options = {'DEFAULT_CLOSED'}

    def draw(self, context):
        self.layout.use_property_split = True
        self.layout.use_property_decorate = False
        col = self.layout.column()
        s = context.scene.canopy_ao
        for o in OPTIONS:
            if o.name not in MAIN:
                col.prop(s, o.name, **({"text": SHORT[o.name]} if o.name in SHORT else {}))


class CANOPY_AO_PT_object(_Sidebar, bpy.types.Panel):
    bl_idname = "CANOPY_AO_PT_object"
    bl_label = "Object Role"
    bl_parent_id = "CANOPY_AO_PT_main"

    @classmethod
    def poll(cls, context):
        return context.active_object is not None and context.active_object.type == 'MESH'

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        obj = context.active_object
        layout.label(text=obj.name, icon='OBJECT_DATA')
        layout.prop(obj.canopy_ao, "role")
        layout.prop(obj.canopy_ao, "tree")
        layout.operator("canopy_ao.guess_roles")
        if obj.canopy_ao.last_result:
            box = layout.box()
            for part in obj.canopy_ao.last_result.split(", "):
                box.label(text=part)


classes = (CANOPY_AO_PT_main, CANOPY_AO_PT_advanced, CANOPY_AO_PT_animation,
           CANOPY_AO_PT_object)

register, unregister = bpy.utils.register_classes_factory(classes)
