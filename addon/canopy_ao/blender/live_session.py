"""What live AO keeps between frames (docs/DESIGN.md, 'Live and per-frame AO'): one Session
per scene, made from a prepared bake (job.BakeJob), that runs the bake loop (loop.py) on each
frame's meshes with the first bake's rung and τ, its fit cached and refitted (core/live.py).
The frame-change handlers and the rebuild after a load or an undo are live.py's; a
frame-range bake (frames.py) runs a Session per frame without writing."""

import json
import sys
import time

import numpy as np

from . import live_render, mesh_io
from .frame_cache import MODIFIER, cache_modifier
from .live_render import is_render
from .loop import Loop
from .vertex_target import VertexTarget
from .. import core
from ..core import live as core_live
from ..core.native import CanopyAOError

RECORD = "canopy_ao_live"  # the scene's custom property: JSON of what a rebuild needs
SHELLS = "canopy_ao_live_shells"  # ... and the shell partition per tree: {"0": int32 array}
HELD = "canopy_ao_live_held"  # a ground alone's occlusion at the first bake: {target: float}
_SESSIONS = {}  # scene name -> Session
_SUSPENDED = []  # non-empty while a frame-range bake steps the frames itself


def check_request(opts):
    """Refuse, before any work, a live bake that cannot run live: texels, a non-live rung."""
    if opts["mode"] != 'VERTEX':
        raise CanopyAOError("live AO and frame-range bakes write per-vertex attributes only "
                            "(a texel bake per frame would rasterise and write an image each "
                            "frame): set Output to Per Vertex")
    if not core.rung(opts["method"]).chooses:
        core_live.check_method(opts["method"])


def check_job(job):
    """Refuse, before its commit, a prepared live bake that cannot run live: what auto chose
    may be the grid or rays, and a frame cache's read-back would hide the live attribute."""
    core_live.check_method(job.plan.method, core.rung(job.settings.method).chooses)
    cached = [t.obj.name for t in job.targets if cache_modifier(t.obj) is not None]
    if cached:
        raise CanopyAOError(f"{', '.join(cached)}: a frame cache ('{MODIFIER}' modifier) would "
                            "hide live AO; clear it first (Clear Frame Cache)")


class Session:
    """What one scene's live AO keeps between frames; built from a prepared BakeJob."""

    def __init__(self, job, held=None):
        core_live.check_method(job.plan.method, core.rung(job.settings.method).chooses)
        self.scene_name = job.scene.name
        self.plan = job.plan
        self.plan.fit_warm = {}  # the frames' ellipsoid fits start from the previous frame's
        self.template = core_live.template_items(job.items, job.plan.method)
        self.targets = [t.item.name for t in job.targets]
        # a ground alone's occlusion at the first bake, multiplied into every frame (held: the
        # scene's stored one, when a session is rebuilt at a later frame)
        self.held = held if held is not None else core_live.held_ground(
            job.plan, job.items, set(self.targets))
        self.attribute = job.opts["attribute"]
        self.frames = 0
        self.timings = {}  # the last frame's seconds per stage
        self.written = {}  # {target name: the AO last written in the viewport}
        # {target name: (its AO drawn, the ownership record of its original then)}: the
        # targets whose original is behind the frame drawn (live_render.write_viewport)
        self.lagging = {}
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
            self.flush(scene)  # a render copies the originals: the viewport's last frame first
            live_render.write_frame(scene, depsgraph, objs, self.attribute, aos)
        else:
            live_render.write_viewport(depsgraph, objs, self.attribute, aos, self.written,
                                       self.lagging)
        tm["write"] = time.perf_counter() - t0
        tm["total"] += tm["write"]
        self.timings = tm
        self.frames += 1
        return tm

    def flush(self, scene, tag=False):
        """Write into the originals the AO drawn of the targets whose original is behind (a
        save, a stop, a render, an edit that evaluates them again from the original: tag).
        A target whose attribute was changed or written by another since (its record is not
        the one it had, or its content not its record's: painted, a bake) keeps that, and the
        console says so; nothing is lost either way (what it skips is only drawn)."""
        from .ownership import recorded
        lagging, self.lagging = self.lagging, {}
        for name, (ao, record) in lagging.items():
            obj = scene.objects.get(name)
            if obj is None or obj.type != 'MESH':
                continue
            why = mesh_io.check_attribute(obj, self.attribute, False)
            if not why and recorded(obj.data, self.attribute) != record:
                why = f"{name}: '{self.attribute}' was written by another bake since"
            if why:
                print(f"canopy_ao: warning: live AO's last frame not kept in {name}: {why}",
                      file=sys.stderr, flush=True)
                continue
            mesh_io.write_ao_attribute(obj, self.attribute, ao, checked=True, tag=tag)

    def evaluate(self, scene, depsgraph):
        """The targets' AO at the depsgraph's frame, written nowhere: ({name: float32 (V,)},
        seconds per stage). The bake loop over the frame's targets, one step per target."""
        tm = {}
        t0 = time.perf_counter()
        pos, nor, objs = {}, {}, {}
        for it in self.template:
            obj = objs[it.name] = scene.objects.get(it.name)
            if obj is None:
                raise CanopyAOError(f"{it.name} is no longer in scene '{scene.name}'")
            pos[it.name], nor[it.name], _t = mesh_io.evaluated_arrays(
                obj, depsgraph, same_count=it.name in self.targets, triangles=False,
                shared=True)
        items = core_live.frame_items(self.template, pos, nor)
        t1 = time.perf_counter()
        tm["read"] = t1 - t0
        plan = core_live.refit(self.plan, items)
        t2 = time.perf_counter()
        tm["fit"] = t2 - t1
        targets = [VertexTarget.of_frame(it, objs[it.name]) for it in items
                   if it.name in self.targets]
        loop = Loop(targets, max([t.count for t in targets] + [1]))
        loop.start(plan)
        loop.run()
        aos = {t.item.name: t.ao for t in targets}
        for name, held in self.held.items():
            if name in aos and len(aos[name]) == len(held):
                np.multiply(aos[name], held, out=aos[name])  # the target's own array
        tm["evaluate"] = time.perf_counter() - t2
        tm["total"] = time.perf_counter() - t0
        return aos, tm


def begin(job):
    """After a live bake's commit: the scene's session and its record (saved with the file)."""
    session = keep(job.scene.name, Session(job))
    live_render.forget()
    job.scene[RECORD] = session.record
    # ID property arrays take and give numpy buffers (1M labels in < 1 ms); keys are indices,
    # as tree names may be longer than an ID property key.
    job.scene[SHELLS] = {str(i): np.ascontiguousarray(job.plan.shell_labels[t], np.int32)
                         for i, t in enumerate(session.shell_trees)}
    # by object name (at most 63 characters, as an ID property key)
    job.scene[HELD] = {n: np.ascontiguousarray(a, np.float32) for n, a in session.held.items()}
    job.scene.canopy_ao.live = True
    return session


def keep(scene_name, session):
    """Make session the scene's; returns it."""
    _SESSIONS[scene_name] = session
    return session


def suspend(on):
    """While on (nested), frame changes do not update live AO (a frame-range bake steps the
    frames and evaluates them itself)."""
    if on:
        flush_all()  # the frames it steps evaluate the targets from their originals
        _SUSPENDED.append(True)
    elif _SUSPENDED:
        _SUSPENDED.pop()


def suspended():
    return bool(_SUSPENDED)


def session_of(scene):
    return _SESSIONS.get(scene.name)


def stop(scene):
    """Stop a scene's live AO: the toggle off, the session gone (the record stays, so ticking
    the toggle on again resumes with the same rung and τ); the originals keep the last frame's
    AO."""
    session = _SESSIONS.pop(scene.name, None)
    if session is not None:
        session.flush(scene)
    if scene.canopy_ao.live:
        scene.canopy_ao.live = False


def any_lagging():
    return any(s.lagging for s in _SESSIONS.values())


def flush_all(tag_names=None):
    """Every session's lagging originals written (a save: tag_names None), or only sessions
    with a lagging target among tag_names (objects evaluated again from their original), then
    tagged so the viewport redraws them."""
    import bpy
    for scene_name, session in list(_SESSIONS.items()):
        scene = bpy.data.scenes.get(scene_name)
        if scene is None or not session.lagging:
            continue
        if tag_names is None:
            session.flush(scene)
        elif tag_names & session.lagging.keys():
            session.flush(scene, tag=True)


def forget_all():
    """Undo, redo and file loads replace every datablock: drop what the sessions cached."""
    _SESSIONS.clear()
    live_render.forget()
