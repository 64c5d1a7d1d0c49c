"""The operators: bake (modal in a window, blocking in the background), guess roles, remove
the material wiring. The bake itself is a BakeJob (job.py), shared with the command line."""

import time
import traceback

import bpy
from bpy.props import StringProperty

from . import gather, mesh_io, viewport
from .job import BakeJob
from .modal import start_modal
from .properties import option_properties, raw_values, resolve
from ..core import roles
from ..core.settings import OPTIONS
from ..core.native import CanopyAOError, core_status


# Seconds of work per modal tick: short enough for Esc and the progress bar to answer at once.
TICK = 0.05


def bake_status(job):
    """'Baking Ground: 37 %' (the share of the receivers evaluated), or the stage before."""
    stage, name, done, total = job.progress()
    if not total:
        return f"Baking: {stage}"
    return f"Baking {name}: {100.0 * done / total:.0f} %" if name else "Baking: writing"


# === The operator ============================================================================

class CANOPY_AO_OT_bake(bpy.types.Operator):
    """Bake approximate ambient occlusion into a color attribute of the selected objects (or
    every visible mesh), from proxies fitted to the canopies"""

    bl_idname = "canopy_ao.bake"
    bl_label = "Bake Canopy AO"
    bl_options = {'REGISTER', 'UNDO'}

    # Every option of core/settings.py is an argument (option_properties, added below); one
    # left unset takes the scene's panel value.
    objects: StringProperty(name="Objects", default="",
                            description="Comma-separated object names (or one object's exact "
                                        "name, commas and all); empty = the selection, or "
                                        "every visible mesh")

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
        is_set = self.properties.is_property_set
        values = raw_values(context.scene.canopy_ao)
        for name in values:
            if is_set(name):
                values[name] = getattr(self, name)
        # A number given without its switch means that number: tau=2 bakes with τ 2, whatever
        # the panel's Calibrate τ; distance=10 is used even when the panel follows the World.
        for o in OPTIONS:
            if o.none_prop and is_set(o.name) and not is_set(o.none_prop):
                values[o.none_prop] = False
        if is_set("distance") and not is_set("use_world_distance"):
            values["use_world_distance"] = False
        return resolve(values, context.scene)

    def _names(self):
        return gather.object_names(self.objects)

    def _report_error(self, exc):
        """CanopyAOError: its message. Anything else is a bug: the traceback goes to the
        console and the report says it is one."""
        if isinstance(exc, CanopyAOError):
            self.report({'ERROR'}, str(exc))
        else:
            traceback.print_exception(type(exc), exc, exc.__traceback__)
            self.report({'ERROR'}, f"Canopy AO internal error ({type(exc).__name__}: {exc}); "
                                   "the traceback is in the system console, please report it")
        return {'CANCELLED'}

    def _finish(self, context, job, lines_reported=False):
        try:
            job.commit(context)
        except Exception as exc:  # reported, never left to Blender half-handled
            return self._report_error(exc)
        rep = job.report_dict
        for line in job.lines if not lines_reported else ():
            self.report({'INFO'}, line)
        where = f"'{rep['attribute']}'" if rep["attribute"] else "images"
        if lines_reported and rep["attribute"] and rep["channel"] == "RGBA":
            # A bake from the panel: the artist sees the AO at once (the toggle goes back).
            try:
                viewport.show(context, [t.obj for t in job.targets], rep["attribute"])
            except Exception as exc:  # noqa: BLE001 - the bake stands; only the view lags
                self.report({'WARNING'}, f"Canopy AO: the viewport could not show the AO ({exc});"
                                         " set Viewport Shading > Color > Attribute")
        self.report({'INFO'}, f"Canopy AO: {rep['method']}, τ {rep['tau']:.3g}, "
                              f"{len(job.results)} object(s) baked into {where}")
        for note in rep["notes"]:
            self.report({'WARNING'}, note)
        return {'FINISHED'}

    def execute(self, context):
        wm = context.window_manager
        try:
            job = BakeJob(context, self._names(), self._opts(context), blocking=True)
            wm.progress_begin(0, job.steps)
            try:
                job.prepare()
                while True:
                    wm.progress_update(job.steps_done)
                    line = job.step()
                    if line is None:
                        break
                    if line:
                        job.lines.append(line)
            finally:
                wm.progress_end()
        except Exception as exc:
            return self._report_error(exc)
        return self._finish(context, job)

    def invoke(self, context, event):
        if context.window is None or bpy.app.background:
            return self.execute(context)
        try:
            self._job = BakeJob(context, self._names(), self._opts(context))
        except Exception as exc:
            return self._report_error(exc)
        return start_modal(self, context, self._job.steps, "Canopy AO: baking… (Esc to cancel)")

    def _stop(self, context):
        wm = context.window_manager
        if self._timer is not None:
            wm.event_timer_remove(self._timer)
            self._timer = None
        wm.progress_end()
        context.workspace.status_text_set(None)
        viewport.set_status(context, "")

    def modal(self, context, event):
        if event.type == 'ESC' and event.value == 'PRESS':
            self._stop(context)
            viewport.set_status(context, "Cancelled (Esc): nothing was changed", 'CANCEL')
            self.report({'WARNING'}, "Canopy AO bake cancelled; nothing was changed")
            return {'CANCELLED'}
        if event.type != 'TIMER':
            return {'PASS_THROUGH'}
        job = self._job
        try:
            if job.plan is None:
                job.prepare()  # fitting and calibration: one tick
            else:
                # Chunks for up to TICK seconds (at least one), then back to Blender (redraw,
                # Esc).
                t_end = time.perf_counter() + TICK
                while True:
                    line = job.step()
                    if line is None:
                        self._stop(context)
                        return self._finish(context, job, lines_reported=True)
                    if line:
                        job.lines.append(line)
                        self.report({'INFO'}, line)
                    if time.perf_counter() >= t_end:
                        break
            context.window_manager.progress_update(job.steps_done)
            text = bake_status(job)
            context.workspace.status_text_set(f"Canopy AO: {text} (Esc to cancel)")
            viewport.set_status(context, text, 'TIME')
        except Exception as exc:  # whatever it is, the timer and the status text go
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
            except CanopyAOError as exc:  # a mesh it cannot read, or no native module
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
            names = gather.object_names(self.objects)
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


CANOPY_AO_OT_bake.__annotations__.update(option_properties(hard=False))

classes = (CANOPY_AO_OT_bake, CANOPY_AO_OT_guess_roles, CANOPY_AO_OT_remove_wiring)

register, unregister = bpy.utils.register_classes_factory(classes)
