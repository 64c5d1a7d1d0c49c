"""Live AO: the bake re-evaluated on every frame change (viewport playback, F12 and headless
animation renders) for the analytic and ray-free rungs (docs/DESIGN.md, 'Live and per-frame
AO').

A live bake is a normal bake (BakeJob) with the option ``live``: its commit starts a Session
(live_session.py) that keeps the plan's rung and τ and each item's role and tree; the persistent
frame_change_post handler then reads the frame's evaluated meshes from the depsgraph it is
given (the render's own during a render), refits the proxies (core/live.py), evaluates the
targets and writes their attribute under mesh_io's ownership rules, where the frame draws it
(live_render.py: into the meshes this frame evaluated, untagged, so Blender evaluates the frame
once, their originals at a save, a stop, a render or an edit; a still target's original,
tagged).

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

import bpy
import numpy as np
from bpy.app.handlers import persistent

from . import live_session
from .job import BakeJob
from .live_render import is_render
# The session's state is live_session's; these names are the handlers' and the scripts'.
from .live_session import HELD, RECORD, SHELLS, Session, session_of, stop
from ..core.native import CanopyAOError


class _Context:
    """What BakeJob reads of a context, for a depsgraph a handler was given (a render's: not
    the window's, whose depsgraph bpy.context would evaluate)."""

    def __init__(self, scene, depsgraph):
        self.scene, self._depsgraph = scene, depsgraph
        self.view_layer = depsgraph.view_layer
        self.selected_objects = []

    def evaluated_depsgraph_get(self):
        return self._depsgraph


def _rebuild(scene, depsgraph):
    """The session of a scene whose live toggle is on but has none (after a load, undo, or the
    toggle ticked by hand): from its record, the first bake's rung and τ, refitted to this
    frame; without a record, a full bake of this frame with the panel's options."""
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
        # ... and its ground's occlusion, not this frame's: every frame shades the same
        # whichever frame the session was rebuilt at (a farm task's chunk, a reload).
        held = scene.get(HELD)
        if held is not None:
            held = {n: np.asarray(held[n], dtype=np.float32) for n in held.keys()}
        return live_session.keep(scene.name, Session(job, held))
    if is_render(depsgraph):
        raise CanopyAOError("live AO is on but was never baked in this file: bake once with "
                            "Live on (or the CLI's --live) before rendering")
    # Not the Cycles check: seconds of Cycles baking inside a frame change.
    job = BakeJob(ctx, [], dict(scene_options(scene), live=True, check_cycles=False))
    job.run()
    job.commit(ctx)  # commit begins the session (job.py)
    return session_of(scene)


def update_scene(scene, depsgraph):
    """One frame of a scene's live AO (the handler's work; the benchmark calls it too)."""
    session = session_of(scene)
    if session is None:
        session = _rebuild(scene, depsgraph)
    return session.update(scene, depsgraph)


@persistent
def _on_frame_change(scene, depsgraph=None):
    if live_session.suspended() or not getattr(scene, "canopy_ao", None):
        return
    if not scene.canopy_ao.live:  # unticked: originals left behind get the last frame, once
        session = session_of(scene)
        if session is not None and session.lagging:
            session.flush(scene, tag=True)
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
def _on_save(*_args):
    """A save keeps each target's last frame drawn (live_session.Session.flush)."""
    live_session.flush_all()


@persistent
def _on_depsgraph_update(scene, depsgraph=None):
    """An edit that evaluated a target again from its original (a modifier's setting, paused)
    drew the original's older AO: the last frame's written there and redrawn. A frame change
    calls frame_change_post, not this."""
    if depsgraph is None or is_render(depsgraph) or not live_session.any_lagging():
        return
    from .live_render import geometry_updated
    live_session.flush_all(geometry_updated(depsgraph))


@persistent
def _forget(*_args):
    """Undo, redo and file loads replace every datablock: drop what the sessions cached."""
    live_session.forget_all()


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


_HANDLERS = (("frame_change_post", _on_frame_change), ("save_pre", _on_save),
             ("depsgraph_update_post", _on_depsgraph_update), ("load_post", _forget),
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
    live_session.forget_all()
    bpy.utils.unregister_class(CANOPY_AO_OT_live_stop)
