"""Live AO: the bake re-evaluated on every frame change (viewport playback, F12 and headless
animation renders) for the analytic rungs (docs/DESIGN.md, 'Live and per-frame AO').

A live bake is a normal bake (BakeJob) with the option ``live``: its commit starts a Session
that keeps the plan's rung and τ and each item's role and tree; the persistent
frame_change_post handler then reads the frame's evaluated meshes from the depsgraph it is
given (the render's own during a render), refits the proxies (core/live.py), evaluates the
targets and writes their attribute under mesh_io's ownership rules. Blender's frame update
re-evaluates once more when a frame_change_post handler tagged data, so the frame renders
with its own AO.

What survives what:
- undo, redo and loading a file drop the sessions (they hold object names and arrays, never
  bpy references); the next frame change rebuilds one from the scene's ``canopy_ao_live``
  record (the rung, τ per tree, the objects and options of the first bake): re-armed on load.
- scene.canopy_ao.live off (the panel's toggle, or canopy_ao.live_stop) stops it; the
  attribute keeps the last frame's AO. Ticking it on without a bake bakes the current frame
  first (with the panel's options) and goes live from there.
- unregister removes the handlers.
"""

import json
import sys
import time

import bpy
import numpy as np
from bpy.app.handlers import persistent

from . import live_render, mesh_io
from .live_render import is_render
from .. import core
from ..core import live as core_live
from ..core.native import CanopyAOError

RECORD = "canopy_ao_live"  # the scene's custom property: JSON of what a rebuild needs
SHELLS = "canopy_ao_live_shells"  # ... and the shell partition per tree: {"0": int32 array}
_SESSIONS = {}  # scene name -> Session
_SUSPENDED = []  # non-empty while a frame-range bake steps the frames itself


class _Context:
    """What BakeJob reads of a context, for a depsgraph a handler was given (a render's: not
    the window's, whose depsgraph bpy.context would evaluate)."""

    def __init__(self, scene, depsgraph):
        self.scene, self._depsgraph = scene, depsgraph
        self.view_layer = depsgraph.view_layer
        self.selected_objects = []

    def evaluated_depsgraph_get(self):
        return self._depsgraph


def check_request(opts):
    """Refuse, before any work, a live bake that cannot run live: texels, a non-live rung."""
    if opts["mode"] != 'VERTEX':
        raise CanopyAOError("live AO and frame-range bakes write per-vertex attributes only "
                            "(a texel bake per frame would rasterise and write an image each "
                            "frame): set Output to Per Vertex")
    if opts["method"] != "auto":
        core_live.check_method(opts["method"])


def check_job(job):
    """Refuse, before its commit, a prepared live bake that cannot run live: what auto chose
    may be the grid or rays, and a frame cache's read-back would hide the live attribute."""
    core_live.check_method(job.plan.method, job.settings.method == "auto")
    from .frames import MODIFIER
    cached = [t.obj.name for t in job.targets if t.obj.modifiers.get(MODIFIER) is not None]
    if cached:
        raise CanopyAOError(f"{', '.join(cached)}: a frame cache ('{MODIFIER}' modifier) would "
                            "hide live AO; clear it first (Clear Frame Cache)")


class Session:
    """What one scene's live AO keeps between frames; built from a prepared BakeJob."""

    def __init__(self, job):
        core_live.check_method(job.plan.method, job.settings.method == "auto")
        self.scene_name = job.scene.name
        self.plan = job.plan
        self.template = core_live.template_items(job.items)
        self.targets = [t.item.name for t in job.targets]
        self.attribute = job.opts["attribute"]
        self.frames = 0
        self.timings = {}  # the last frame's seconds per stage
        self.shell_trees = sorted(job.plan.shell_labels)
        self.record = json.dumps({
            "objects": self.targets, "tau_by_tree": dict(job.plan.tau_by_tree),
            "role_scale": dict(job.plan.role_scale),
            "shell_trees": self.shell_trees,
            "opts": dict(job.opts, method=job.plan.method, tau=job.plan.tau, live=True)})

    def update(self, scene, depsgraph):
        """Refit and re-evaluate at the depsgraph's frame; write every target's attribute
        (all targets are checked before any is written). Returns seconds per stage."""
        aos, tm = self.evaluate(scene, depsgraph)
        t0 = time.perf_counter()
        objs = [scene.objects[name] for name in self.targets]
        for obj in objs:
            why = mesh_io.check_attribute(obj, self.attribute, False)
            if why:
                raise CanopyAOError(why)
        if is_render(depsgraph):
            live_render.write_frame(scene, depsgraph, objs, self.attribute, aos)
        else:
            for obj in objs:
                mesh_io.write_ao_attribute(obj, self.attribute, aos[obj.name], checked=True)
        tm["write"] = time.perf_counter() - t0
        tm["total"] += tm["write"]
        self.timings = tm
        self.frames += 1
        return tm

    def evaluate(self, scene, depsgraph):
        """The targets' AO at the depsgraph's frame, written nowhere: ({name: float32 (V,)},
        seconds per stage)."""
        tm = {}
        t0 = time.perf_counter()
        pos, nor = {}, {}
        for it in self.template:
            obj = scene.objects.get(it.name)
            if obj is None:
                raise CanopyAOError(f"{it.name} is no longer in scene '{scene.name}'")
            pos[it.name], nor[it.name], _t = mesh_io.evaluated_arrays(
                obj, depsgraph, same_count=it.name in self.targets, triangles=False)
        items = core_live.frame_items(self.template, pos, nor)
        t1 = time.perf_counter()
        tm["read"] = t1 - t0
        plan = core_live.refit(self.plan, items)
        t2 = time.perf_counter()
        tm["fit"] = t2 - t1
        aos = {it.name: core.evaluate_receivers(plan, it, it.positions, it.normals,
                                                vertices=slice(None))
               for it in items if it.name in self.targets}
        tm["evaluate"] = time.perf_counter() - t2
        tm["total"] = time.perf_counter() - t0
        return aos, tm


def begin(job):
    """After a live bake's commit: the scene's session and its record (saved with the file)."""
    session = Session(job)
    _SESSIONS[job.scene.name] = session
    live_render.forget()
    job.scene[RECORD] = session.record
    # ID property arrays take and give numpy buffers (1M labels in < 1 ms); keys are indices,
    # as tree names may be longer than an ID property key.
    job.scene[SHELLS] = {str(i): np.ascontiguousarray(job.plan.shell_labels[t], np.int32)
                         for i, t in enumerate(session.shell_trees)}
    job.scene.canopy_ao.live = True
    return session


def _rebuild(scene, depsgraph):
    """The session of a scene whose live toggle is on but has none (after a load, undo, or the
    toggle ticked by hand): from its record, the first bake's rung and τ, refitted to this
    frame; without a record, a full bake of this frame with the panel's options."""
    from .job import BakeJob
    from .properties import scene_options
    ctx = _Context(scene, depsgraph)
    raw = scene.get(RECORD)
    if isinstance(raw, str) and raw:
        rec = json.loads(raw)
        job = BakeJob(ctx, rec["objects"], dict(rec["opts"], live=True))
        job.prepare()
        job.plan.tau_by_tree = {k: float(v) for k, v in rec["tau_by_tree"].items()}
        job.plan.role_scale = {k: float(v) for k, v in rec.get("role_scale", {}).items()}
        # The first bake's partition, not this frame's clustering: a file re-armed on load (a
        # farm task's first frame) shades as the session that saved it did.
        stored = scene.get(SHELLS) or {}
        job.plan.shell_labels = {t: np.asarray(stored[str(i)], dtype=np.int32)
                                 for i, t in enumerate(rec.get("shell_trees", []))
                                 if str(i) in stored}
        _SESSIONS[scene.name] = session = Session(job)
        return session
    if is_render(depsgraph):
        raise CanopyAOError("live AO is on but was never baked in this file: bake once with "
                            "Live on (or the CLI's --live) before rendering")
    # Not the Cycles check: seconds of Cycles baking inside a frame change.
    job = BakeJob(ctx, [], dict(scene_options(scene), live=True, check_cycles=False))
    job.run()
    job.commit(ctx)  # commit begins the session (job.py)
    return _SESSIONS[scene.name]


def suspend(on):
    """While on (nested), frame changes do not update live AO (a frame-range bake steps the
    frames and evaluates them itself)."""
    if on:
        _SUSPENDED.append(True)
    elif _SUSPENDED:
        _SUSPENDED.pop()


def session_of(scene):
    return _SESSIONS.get(scene.name)


def stop(scene):
    """Stop a scene's live AO: the toggle off, the session gone (the record stays, so ticking
    the toggle on again resumes with the same rung and τ)."""
    _SESSIONS.pop(scene.name, None)
    if scene.canopy_ao.live:
        scene.canopy_ao.live = False


def update_scene(scene, depsgraph):
    """One frame of a scene's live AO (the handler's work; the benchmark calls it too)."""
    session = _SESSIONS.get(scene.name)
    if session is None:
        session = _rebuild(scene, depsgraph)
    return session.update(scene, depsgraph)


@persistent
def _on_frame_change(scene, depsgraph=None):
    if _SUSPENDED or not getattr(scene, "canopy_ao", None) or not scene.canopy_ao.live:
        return
    if depsgraph is None:
        depsgraph = bpy.context.evaluated_depsgraph_get()
    try:
        update_scene(scene, depsgraph)
    except Exception as exc:  # noqa: BLE001 - a handler must not raise into Blender's frame
        import traceback
        if not isinstance(exc, CanopyAOError):
            traceback.print_exc()
        msg = f"live AO stopped at frame {scene.frame_current}: {exc}"
        print(f"canopy_ao: error: {msg}", file=sys.stderr, flush=True)
        stop(scene)
        scene.canopy_ao.last_report = msg


@persistent
def _forget(*_args):
    """Undo, redo and file loads replace every datablock: drop what the sessions cached."""
    _SESSIONS.clear()
    live_render.forget()


class CANOPY_AO_OT_live_stop(bpy.types.Operator):
    """Stop live AO in this scene: frame changes no longer re-evaluate it (the attribute keeps
    the last frame's AO); tick Live again to resume with the same method and τ"""

    bl_idname = "canopy_ao.live_stop"
    bl_label = "Stop Live AO"
    bl_options = {'REGISTER', 'UNDO'}

    def execute(self, context):
        stop(context.scene)
        self.report({'INFO'}, "Canopy AO: live AO stopped")
        return {'FINISHED'}


_HANDLERS = (("frame_change_post", _on_frame_change), ("load_post", _forget),
             ("undo_post", _forget), ("redo_post", _forget))


def register():
    bpy.utils.register_class(CANOPY_AO_OT_live_stop)
    for name, fn in _HANDLERS:
        lst = getattr(bpy.app.handlers, name)
        if fn not in lst:
            lst.append(fn)


def unregister():
    for name, fn in _HANDLERS:
        lst = getattr(bpy.app.handlers, name)
        while fn in lst:
            lst.remove(fn)
    _SESSIONS.clear()
    bpy.utils.unregister_class(CANOPY_AO_OT_live_stop)
