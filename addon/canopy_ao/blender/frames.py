"""Frame-range bakes: the AO of every frame of a range cached on the mesh, read back by a
geometry-nodes modifier (frame_cache.py; docs/DESIGN.md, 'Live and per-frame AO').

Each frame is the bake loop of a live update (live_session.Session: the first frame's rung and
τ, the proxies refitted), so a range bake gives what live playback shows. Nothing is written
until every frame is evaluated: Esc or an error leaves the file as it was (the current frame
comes back too).
"""

import time

import bpy

from . import gather, live_session, mesh_io
from .commit import Transaction
# MODIFIER: re-exported for callers and tests.
from .frame_cache import (GROUP_TAG, MODIFIER, attach, cache_modifier,  # noqa: F401
                          cache_name, check_modifier, clear, node_group)
from .job import BakeJob
from .modal import start_modal
from ..core import texel_budget
from ..core.native import CanopyAOError

# Blender's last frame either way (MAXFRAME): frame_set stops there.
MAX_FRAME = 1048574


class FrameBake:
    """Bake frames start..end of the named objects (empty: every visible mesh)."""

    def __init__(self, context, object_names, opts, start, end):
        start, end = int(start), int(end)
        if end < start:
            raise CanopyAOError(f"the frame range {start}-{end} is empty (end before start)")
        if max(abs(start), abs(end)) > MAX_FRAME:
            raise CanopyAOError(f"the frame range {start}-{end} reaches past Blender's frames "
                                f"(-{MAX_FRAME} to {MAX_FRAME}), where every frame shows the "
                                "last one's scene; choose a range within them (nothing was "
                                "changed)")
        live_session.check_request(opts)
        if opts.get("gltf") or opts.get("packing", "NONE") != "NONE":
            raise CanopyAOError("a frame-range bake caches grey AO per frame, read back by a "
                                "modifier; For glTF and Packing are for single bakes: turn "
                                "them off (nothing was changed)")
        self.context, self.scene = context, context.scene
        self.names, self.opts = list(object_names), dict(opts, live=False)
        self.frames = list(range(start, end + 1))
        self.frame0 = self.scene.frame_current
        self.session = None
        self.results = {}  # frame -> {object name: AO float32 (V,)}
        self.seconds = []  # our work per frame (read, fit, evaluate)
        self.report = {}

    @property
    def steps(self):
        return len(self.frames)

    @property
    def steps_done(self):
        return len(self.results)

    def step(self):
        """Evaluate the next frame; False once every frame is done."""
        if len(self.results) == len(self.frames):
            return False
        f = self.frames[len(self.results)]
        live_session.suspend(True)
        try:
            self.scene.frame_set(f)
        finally:
            live_session.suspend(False)
        dg = self.context.evaluated_depsgraph_get()
        if self.session is None:  # the first frame: gather, fit, calibrate (as a bake does)
            job = BakeJob(self.context, self.names, dict(self.opts, frames=True))
            job.prepare()
            self.session = live_session.Session(job)
            self._check_names()
        aos, tm = self.session.evaluate(self.scene, dg)
        self.results[f] = aos
        self.seconds.append(tm["total"])
        return True

    def _check_names(self):
        o = self.opts
        # Every frame's AO is held until the commit writes it: twice the cache at the end.
        verts = sum(len(self.scene.objects[n].data.vertices) for n in self.session.targets)
        need, have = 8 * verts * len(self.frames), texel_budget.available_bytes()
        if have is not None and need > have:
            raise CanopyAOError(f"a frame cache of {len(self.frames):,} frames × {verts:,} "
                                f"vertices needs about {need:,} bytes but only {have:,} are "
                                "available; bake a shorter range (nothing was changed)")
        for name in self.session.targets:
            obj = self.scene.objects[name]
            why = check_modifier(obj)
            if why:
                raise CanopyAOError(why + " (nothing was changed)")
            for n in [o["attribute"]] + [cache_name(o["attribute"], f) for f in self.frames]:
                why = mesh_io.check_attribute(obj, n, o["overwrite"])
                if why:
                    raise CanopyAOError(why + " (nothing was changed)")

    def cancel(self):
        """Stop: nothing was written; the frame the bake started on comes back."""
        self.results.clear()
        self._restore_frame()

    def _restore_frame(self):
        if self.scene.frame_current != self.frame0:
            self.scene.frame_set(self.frame0)

    def commit(self):
        """Write every frame's attribute and the read-back modifier: all or, on failure, none.
        Returns the JSON-ready report."""
        o = self.opts
        attribute = o["attribute"]
        txn = Transaction()
        try:
            group = node_group(attribute, self.frames[0], self.frames[-1], txn)
            for name in self.session.targets:
                obj = self.scene.objects[name]
                for f in self.frames:
                    txn.attribute(obj, cache_name(attribute, f))
                    mesh_io.write_float_attribute(obj, cache_name(attribute, f),
                                                  self.results[f][name], o["overwrite"])
                attach(obj, group, txn)
        except BaseException:
            txn.rollback()
            self._restore_frame()
            raise
        txn.done()
        for ng in [g for g in bpy.data.node_groups if g.get(GROUP_TAG) and g.users == 0]:
            bpy.data.node_groups.remove(ng)  # an earlier range's read-back, replaced
        self._restore_frame()
        plan = self.session.plan
        ms = 1000.0 * sum(self.seconds) / max(len(self.seconds), 1)
        self.report = {"frames": [self.frames[0], self.frames[-1]], "method": plan.method,
                       "tau": plan.tau, "tau_by_tree": dict(plan.tau_by_tree),
                       "tau_role_scale": dict(plan.role_scale),
                       "objects": list(self.session.targets), "attribute": attribute,
                       "cache": [cache_name(attribute, f) for f in (self.frames[0],
                                                                      self.frames[-1])],
                       "ms_per_frame": ms}
        self.scene.canopy_ao.last_report = (
            f"frames {self.frames[0]}-{self.frames[-1]}: {plan.method}, τ {plan.tau:.3g}, "
            f"{ms:.0f} ms per frame")
        return self.report

    def run(self, progress=None):
        """Every frame, then the commit. progress(stage, name, done, total, unit=...) is called
        before each frame; it may raise to stop the bake with nothing written."""
        t0 = time.perf_counter()
        try:
            while True:
                if progress is not None:
                    progress("baking", "", len(self.results), len(self.frames), unit="frames")
                if not self.step():
                    break
        except BaseException:
            self.cancel()
            raise
        rep = self.commit()
        rep["seconds"] = time.perf_counter() - t0
        return rep


# === Operators ==============================================================================

class CANOPY_AO_OT_bake_frames(bpy.types.Operator):
    """Bake the AO of every frame of a range into per-frame attributes, read back at render
    time by a geometry-nodes modifier (Esc cancels: nothing is written)"""

    bl_idname = "canopy_ao.bake_frames"
    bl_label = "Bake Frame Range"
    bl_options = {'REGISTER', 'UNDO'}

    objects: bpy.props.StringProperty(name="Objects", default="",
                                      description="Comma-separated object names; empty = the "
                                                  "selection, or every visible mesh")
    use_scene_range: bpy.props.BoolProperty(name="Scene Range", default=True,
                                            description="Bake the scene's frame range")
    frame_start: bpy.props.IntProperty(name="Start", default=1)
    frame_end: bpy.props.IntProperty(name="End", default=250)

    _bake = None
    _timer = None

    def _make(self, context):
        from .properties import scene_options
        s = context.scene
        start, end = ((s.frame_start, s.frame_end) if self.use_scene_range
                      else (self.frame_start, self.frame_end))
        names = gather.object_names(self.objects)
        return FrameBake(context, names, scene_options(s), start, end)

    def _done(self, rep):
        self.report({'INFO'}, f"Canopy AO: frames {rep['frames'][0]}-{rep['frames'][1]} baked "
                              f"({rep['method']}, τ {rep['tau']:.3g}, "
                              f"{rep['ms_per_frame']:.0f} ms per frame)")
        return {'FINISHED'}

    def execute(self, context):
        try:
            return self._done(self._make(context).run())
        except CanopyAOError as exc:
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}

    def invoke(self, context, event):
        if context.window is None or bpy.app.background:
            return self.execute(context)
        try:
            self._bake = self._make(context)
        except CanopyAOError as exc:
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}
        return start_modal(self, context, self._bake.steps,
                           "Canopy AO: baking frames… (Esc to cancel)")

    def _stop(self, context):
        wm = context.window_manager
        wm.event_timer_remove(self._timer)
        wm.progress_end()
        context.workspace.status_text_set(None)

    def modal(self, context, event):
        if event.type == 'ESC' and event.value == 'PRESS':
            self._stop(context)
            self._bake.cancel()
            self.report({'WARNING'}, "Canopy AO frame bake cancelled; nothing was changed")
            return {'CANCELLED'}
        if event.type != 'TIMER':
            return {'PASS_THROUGH'}
        self._bake.context = context  # a context is valid for the call it is given to
        try:
            if not self._bake.step():
                self._stop(context)
                return self._done(self._bake.commit())
            context.window_manager.progress_update(self._bake.steps_done)
        except Exception as exc:  # noqa: BLE001 - the timer and status text must go
            self._stop(context)
            self._bake.cancel()
            if not isinstance(exc, CanopyAOError):
                raise
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}
        return {'RUNNING_MODAL'}


class CANOPY_AO_OT_clear_frames(bpy.types.Operator):
    """Remove the frame cache (per-frame attributes and the read-back modifier) from the
    selected objects, or from every object that has one"""

    bl_idname = "canopy_ao.clear_frames"
    bl_label = "Clear Frame Cache"
    bl_options = {'REGISTER', 'UNDO'}

    def execute(self, context):
        obs = [o for o in (context.selected_objects or context.scene.objects)
               if o.type == 'MESH' and cache_modifier(o) is not None]
        removed = sum(clear(o) for o in obs)
        self.report({'INFO'}, f"Canopy AO: removed {removed} cached frame(s) from "
                              f"{len(obs)} object(s)")
        return {'FINISHED'}


classes = (CANOPY_AO_OT_bake_frames, CANOPY_AO_OT_clear_frames)

register, unregister = bpy.utils.register_classes_factory(classes)
