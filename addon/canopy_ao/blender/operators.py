"""The operators: bake (modal in a window, blocking in the background), guess roles, remove
the material wiring. The bake itself is a BakeJob (job.py), shared with the command line."""

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, StringProperty

from . import mesh_io
from .gather import scene_settings_opts
from .job import BakeJob
from .properties import method_items
from ..core import roles
from ..core.native import CanopyAOError, core_status


# === The operator ============================================================================

class CANOPY_AO_OT_bake(bpy.types.Operator):
    """Bake approximate ambient occlusion into a color attribute of the selected objects (or
    every visible mesh), from proxies fitted to the canopies"""

    bl_idname = "canopy_ao.bake"
    bl_label = "Bake Canopy AO"
    bl_options = {'REGISTER', 'UNDO'}

    # Every setting can be given as an argument; one left unset takes the scene's panel value.
    objects: StringProperty(name="Objects", default="",
                            description="Comma-separated object names; empty = the selection, "
                                        "or every visible mesh")
    method: EnumProperty(name="Method", items=method_items)
    tau: FloatProperty(name="τ", default=0.0, min=0.0,
                       description="Optical depth; 0 = calibrate automatically")
    distance: FloatProperty(name="AO Distance", default=10.0, min=0.0)
    samples: IntProperty(name="Samples", default=64, min=1)
    attribute: StringProperty(name="Attribute", default="CanopyAO")
    overwrite: BoolProperty(name="Overwrite", default=False)
    show_proxies: BoolProperty(name="Show Proxies", default=True)
    wire_material: BoolProperty(name="Wire Material", default=False)
    add_aov: BoolProperty(name="Add AOV", default=False)
    aov_name: StringProperty(name="AOV Name", default="BakedAO")
    mode: EnumProperty(name="Output", items=[("VERTEX", "Per Vertex", ""),
                                             ("TEXEL", "Per Texel", "")], default="VERTEX")
    uv_map: StringProperty(name="UV Map", default="")
    resolution: IntProperty(name="Resolution", default=1024, min=16, max=16384)
    image_dir: StringProperty(name="Image Folder", default="//canopy_ao", subtype='DIR_PATH')
    check_cycles: BoolProperty(name="Check with Cycles", default=False)
    cycles_samples: IntProperty(name="Cycles Samples", default=64, min=1)

    _timer = None
    _job = None

    @classmethod
    def poll(cls, context):
        ok, _ = core_status()
        if not ok:
            cls.poll_message_set("The native module is not loaded: see the Canopy AO panel "
                                 "(N panel) for how to build it")
            return False
        if context.scene is None or not any(o.type == 'MESH' for o in context.scene.objects):
            cls.poll_message_set("The scene has no mesh objects to bake")
            return False
        return True

    def _opts(self, context):
        opts = scene_settings_opts(context.scene)
        keymap = {"attribute": "attribute", "method": "method", "distance": "distance",
                  "samples": "samples", "overwrite": "overwrite", "show_proxies": "show_proxies",
                  "wire_material": "wire_material", "add_aov": "add_aov",
                  "aov_name": "aov_name", "check_cycles": "check_cycles",
                  "cycles_samples": "cycles_samples", "mode": "mode", "uv_map": "uv_map",
                  "resolution": "resolution", "image_dir": "image_dir"}
        for prop, key in keymap.items():
            if self.properties.is_property_set(prop):
                opts[key] = getattr(self, prop)
        if self.properties.is_property_set("tau"):
            opts["tau"] = self.tau if self.tau > 0 else None
        return opts

    def _names(self):
        return [s.strip() for s in self.objects.split(",") if s.strip()]

    def _report_error(self, exc):
        self.report({'ERROR'}, str(exc))
        return {'CANCELLED'}

    def _finish(self, context, job, lines_reported=False):
        try:
            job.commit(context)
        except (CanopyAOError, mesh_io.MeshIOError, RuntimeError) as exc:
            return self._report_error(exc)
        rep = job.report_dict
        for line in job.lines if not lines_reported else ():
            self.report({'INFO'}, line)
        where = f"'{rep['attribute']}'" if rep["attribute"] else "images"
        self.report({'INFO'}, f"Canopy AO: {rep['method']}, τ {rep['tau']:.3g}, "
                              f"{len(job.results)} object(s) baked into {where}")
        for note in rep["notes"]:
            self.report({'WARNING'}, note)
        return {'FINISHED'}

    def execute(self, context):
        wm = context.window_manager
        try:
            job = BakeJob(context, self._names(), self._opts(context))
            wm.progress_begin(0, job.steps)
            try:
                job.prepare()
                while True:
                    wm.progress_update(job.index + 1)
                    line = job.step()
                    if line is None:
                        break
                    job.lines.append(line)
            finally:
                wm.progress_end()
        except CanopyAOError as exc:
            return self._report_error(exc)
        return self._finish(context, job)

    def invoke(self, context, event):
        if context.window is None or bpy.app.background:
            return self.execute(context)
        try:
            self._job = BakeJob(context, self._names(), self._opts(context))
        except CanopyAOError as exc:
            return self._report_error(exc)
        wm = context.window_manager
        wm.progress_begin(0, self._job.steps)
        self._timer = wm.event_timer_add(0.01, window=context.window)
        wm.modal_handler_add(self)
        context.workspace.status_text_set("Canopy AO: baking… (Esc to cancel)")
        return {'RUNNING_MODAL'}

    def _stop(self, context):
        wm = context.window_manager
        if self._timer is not None:
            wm.event_timer_remove(self._timer)
            self._timer = None
        wm.progress_end()
        context.workspace.status_text_set(None)

    def modal(self, context, event):
        if event.type == 'ESC' and event.value == 'PRESS':
            self._stop(context)
            self.report({'WARNING'}, "Canopy AO bake cancelled; nothing was changed")
            return {'CANCELLED'}
        if event.type != 'TIMER':
            return {'PASS_THROUGH'}
        job = self._job
        try:
            if job.plan is None:
                job.prepare()  # fitting and calibration: one tick
            else:
                line = job.step()
                if line is None:
                    self._stop(context)
                    return self._finish(context, job, lines_reported=True)
                job.lines.append(line)
                self.report({'INFO'}, line)
            context.window_manager.progress_update(job.index + 1)
        except CanopyAOError as exc:
            self._stop(context)
            return self._report_error(exc)
        return {'RUNNING_MODAL'}


class CANOPY_AO_OT_guess_roles(bpy.types.Operator):
    """Set each selected mesh's role to the one guessed from its geometry, so it can be
    reviewed and changed"""

    bl_idname = "canopy_ao.guess_roles"
    bl_label = "Guess Roles"
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def poll(cls, context):
        if not any(o.type == 'MESH' for o in context.selected_objects):
            cls.poll_message_set("Select mesh objects")
            return False
        return True

    def execute(self, context):
        depsgraph = context.evaluated_depsgraph_get()
        for obj in context.selected_objects:
            if obj.type != 'MESH':
                continue
            try:
                pos, _nor, tris = mesh_io.evaluated_arrays(obj, depsgraph)
            except mesh_io.MeshIOError as exc:
                self.report({'WARNING'}, str(exc))
                continue
            role, why = roles.guess_role(pos, tris)
            obj.canopy_ao.role = role
            self.report({'INFO'}, f"{obj.name}: {role} ({why})")
        return {'FINISHED'}


class CANOPY_AO_OT_remove_wiring(bpy.types.Operator):
    """Remove exactly the nodes Canopy AO added to the materials of the selected objects (or
    of the named ones) and restore the original links; the baked attributes stay"""

    bl_idname = "canopy_ao.remove_wiring"
    bl_label = "Remove Material Wiring"
    bl_options = {'REGISTER', 'UNDO'}

    objects: bpy.props.StringProperty(
        name="Objects", default="",
        description="Comma-separated object names (default: the selected objects)")

    def execute(self, context):
        from . import materials
        if self.objects.strip():
            names = [n.strip() for n in self.objects.split(",") if n.strip()]
            missing = [n for n in names if n not in bpy.data.objects]
            if missing:
                self.report({'ERROR'}, f"no object named {', '.join(map(repr, missing))}")
                return {'CANCELLED'}
            targets = [bpy.data.objects[n] for n in names]
        else:
            targets = [o for o in context.selected_objects if o.type == 'MESH']
            if not targets:
                self.report({'ERROR'}, "select the mesh objects whose wiring to remove, "
                                       "or name them with objects=")
                return {'CANCELLED'}
        removed = sum(materials.unwire(o) for o in targets)
        self.report({'INFO'}, f"removed {removed} Canopy AO node(s) from {len(targets)} object(s)")
        return {'FINISHED'}

    def invoke(self, context, event):
        return self.execute(context)


classes = (CANOPY_AO_OT_bake, CANOPY_AO_OT_guess_roles, CANOPY_AO_OT_remove_wiring)

register, unregister = bpy.utils.register_classes_factory(classes)
