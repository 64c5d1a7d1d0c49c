"""One bake in Blender, shared by the operator (modal or not) and the command line: gather and
check (nothing changed on failure), prepare, evaluate receivers in chunks (one per step, so
progress and Esc cover vertices and texels alike), commit everything or nothing."""

import time

import bpy
import numpy as np

from . import (bent_io, checks, cycles_check, gather, instances, live, materials, mesh_io,
               parts_io, tiles_io)
from .commit import Transaction
from .targets import TexelTarget, VertexTarget, check_outputs, chunks, chunks_done, \
    split_vertex_chunks
from .. import core
from ..core import card_ao, maps, metrics, packing, settings
from ..core.native import CanopyAOError

# Receivers per step: a modal tick stays short, and per-call overhead stays small.
CHUNK = 1 << 16
# A blocking bake (execute, the command line: no Esc to answer, no redraw between steps) takes
# this many chunks per step: fewer calls, each one's fixed cost paid less often; the progress
# bar still moves every 2^18 receivers.
BLOCKING_CHUNKS = 4
# Rungs whose receivers cast rays, samples each: a blocking bake's vertex steps shrink as the
# samples grow (2^14 vertices at 256), so progress and Ctrl-C answer every few seconds.
RAY_METHODS = ("raytrace", "hybrid")


class BakeJob:
    """One bake: gather the targets' receivers and check (nothing changed on failure),
    prepare, evaluate the receivers one chunk per step, then commit every write at once, so a
    cancelled or failed bake changes nothing."""

    def __init__(self, context, object_names, opts, blocking=False):
        """opts: option name -> value (properties.scene_options, cli.options_from_args);
        options left out take their defaults. blocking: run without a modal tick between
        steps (BLOCKING_CHUNKS per step). Raises CanopyAOError before changing anything."""
        opts = self.opts = dict(settings.defaults(), **opts)
        for o in settings.OPTIONS:  # every value in range before anything is read or written
            opts[o.name] = o.check(opts[o.name])
        packing.apply(opts)  # a packing preset is its channel
        self.settings = settings.BakeSettings(**{o.name: opts[o.name] for o in settings.OPTIONS
                                                 if o.group == "bake"})
        self.scene = context.scene
        self.results = []
        # Seconds per stage of this bake (bench/blender_bake_speed.py prints them).
        self.timings = {}
        t_start = time.perf_counter()
        self.lines = []
        checks.check_request(opts)  # what needs no geometry: refused before any work
        targets = gather.bake_targets(context, object_names, opts)
        target_names = {o.name for o in targets}
        depsgraph = context.evaluated_depsgraph_get()
        self.gather_notes = []
        self.items, self.objects, self.how = gather.scene_items(
            context, depsgraph, targets, opts, self.timings, notes=self.gather_notes)
        # Every target's receivers, read now: vertices, or texels rasterised from its UVs.
        t0 = time.perf_counter()
        self.targets = [VertexTarget(it, self.objects[it.name], opts, depsgraph)
                        if opts["mode"] == 'VERTEX'
                        else TexelTarget(it, self.objects[it.name], opts, depsgraph)
                        for it in self.items if it.name in target_names]
        self.targets += parts_io.targets(self.items, self.objects, target_names, opts, depsgraph)
        if not self.targets:
            raise CanopyAOError("every object to bake has the role Ignore")
        check_outputs(self.targets, opts)  # image files: none collide, none is the user's
        # (target, first, last receiver) per step; an empty target still gets its one step.
        self.blocking = blocking
        self._chunks = chunks(self.targets, CHUNK * (BLOCKING_CHUNKS if blocking else 1))
        self._next = 0
        self._lap("receivers", t0)
        t0 = time.perf_counter()
        # Instanced trees (particles, collection instances, geometry nodes): each prototype is
        # baked once (its instances share its mesh) and every instance occludes (instances.py).
        self.prototypes = instances.Prototypes(depsgraph, vertex_mode=opts["mode"] == 'VERTEX')
        why = self.prototypes.check(opts["attribute"], opts["overwrite"], skip=target_names)
        if why:
            raise CanopyAOError(why + " (nothing was changed)")
        # Instanced grass or scattered leaves, realised: they occlude as the same made real
        # (never a target themselves).
        self.items = self.items + self.prototypes.realized_items
        self.how.update({it.name: self.prototypes.how[it.name]
                         for it in self.prototypes.realized_items})
        self.plan = None
        self._lap("instances", t0)
        self._lap("gather (total)", t_start)

    def _lap(self, key, t0):
        """Add the seconds since t0 to timings[key]; returns now."""
        t1 = time.perf_counter()
        self.timings[key] = self.timings.get(key, 0.0) + t1 - t0
        return t1

    @property
    def steps(self):
        """Steps of the whole bake: prepare, then one per chunk of receivers."""
        return len(self._chunks) + 1

    @property
    def steps_done(self):
        return self._next + (self.plan is not None)

    def prepare(self):
        t0 = time.perf_counter()
        # CanopyAOError (bad input, with its reason) passes to the caller as it is; anything
        # else is a bug and keeps its traceback. The instanced trees first: the main plan's
        # ray tracer and calibration trace them (core.prepare's prototypes).
        protos = None
        if self.prototypes:
            skip = {t.item.name for t in self.targets}
            protos = self.prototypes.bake(self.settings, skip=skip)
            self.lines.extend(self.prototypes.lines())
            t0 = self._lap("instances", t0)
        targets = parts_io.receivers(self.targets)  # a mesh baked by parts: its parts'
        self.plan = core.prepare(self.items, self.settings, prototypes=protos, targets=targets)
        t0 = self._lap("prepare (fit, calibrate)", t0)
        if self.prototypes.realized:
            self.prototypes.bake_realized(self.plan)
            t0 = self._lap("instances", t0)
        self.plan.notes.extend(self.gather_notes + self.prototypes.grass_lines())
        if self.opts["bent_normals"] != "OFF":  # rays, whichever rung lit the AO
            maps.ensure_tracer(self.plan, self.items)
            self._lap("tracer (bent normals)", t0)
        if self.blocking and self.plan.method in RAY_METHODS:  # steps of a few seconds
            self._chunks[self._next:] = split_vertex_chunks(self._chunks[self._next:], max(
                4096, CHUNK * BLOCKING_CHUNKS * 16 // max(self.settings.samples, 16)))

    def step(self):
        """Evaluate the next chunk of receivers. Returns the line to report when it completes
        a target, "" when it does not, None when every chunk is done."""
        if self._next >= len(self._chunks):
            return None
        t, a, b = self._chunks[self._next]
        self._next += 1
        t0 = time.perf_counter()
        bent = self.opts["bent_normals"] != "OFF"
        try:
            if t.item.name in self.prototypes.means and t.kind == "vertex":
                # A grass blade instanced over a field: what its instances see, not the lone
                # prototype (instances.Prototypes.bake_realized).
                t.ao[a:b] = self.prototypes.means[t.item.name][a:b]
            elif getattr(t, "parts", None):  # a mesh baked by parts (parts_io.py)
                t.ao[a:b] = parts_io.evaluate(self.plan, t, a, b)
            elif bent and maps.rung_is_the_trace(self.plan, t.item):  # one trace gives both
                t.ao[a:b] = self._bent_step(t, a, b)
            else:
                t.ao[a:b] = core.evaluate_receivers(
                    self.plan, t.item, t.positions[a:b], t.normals[a:b], group=t.group,
                    vertices=slice(a, b) if t.kind == "vertex" else None,
                    triangles=t.triangles[a:b] if t.triangles is not None else None)
                card_ao.carry_target(self.plan, t, a, b, self.opts)
                if bent:
                    self._bent_step(t, a, b)
        except CanopyAOError as exc:
            raise CanopyAOError(f"{t.item.name}: {exc}") from exc
        if self.opts["thickness"]:
            if t.thickness is None:
                t.thickness = np.zeros(t.count, np.float32)
            t.thickness[a:b] = maps.thickness(self.plan, t.item, t.positions[a:b],
                                              slice(a, b) if t.kind == "vertex" else None)
        t.seconds += self._lap("evaluate", t0) - t0
        if b < t.count:
            return ""
        t.finish()
        it = t.item
        r = core.ItemResult(it.name, it.role, it.tree, self.plan.method, t.ao, t.seconds,
                            it.tree_source, it.tree_why)
        self.results.append(r)
        return (f"{r.name}: role {r.role} ({self.how[r.name]}), tree {r.tree}, method "
                f"{r.method}, {t.count} {t.kind}{'s' if t.count != 1 else ''}, "
                f"{r.seconds:.3f} s")

    def _bent_step(self, t, a, b):
        """Bent normals of receivers a..b of target t, in the space asked for. Returns the
        AO of the same trace (maps.bent_normals)."""
        if t.bent is None:
            t.bent = np.zeros((t.count, 3), np.float32)
        ao, world = maps.bent_normals(self.plan, t.item, t.positions[a:b], t.normals[a:b],
                                      vertices=slice(a, b) if t.kind == "vertex" else None,
                                      triangles=t.triangles[a:b] if t.triangles is not None
                                      else None, with_ao=True)
        frames = (t.frames[0][a:b], t.frames[1][a:b]) if t.frames is not None else None
        t.bent[a:b] = bent_io.in_space(world, t.normals[a:b], self.opts["bent_normals"],
                                       frames)
        return ao

    def progress(self):
        """(stage, object, receivers done, receivers in all) for a progress report."""
        if self.plan is None:
            return "preparing", "", 0, 0
        return ("evaluating", *chunks_done(self.targets, self._chunks, self._next))

    def run(self, progress=None):
        """prepare() and every step(), blocking. progress(stage, name, done, total) is called
        before each; it may raise (core.progress.Cancelled) to stop the bake unwritten."""
        report = progress or (lambda *a: None)
        report(*self.progress())
        self.prepare()
        while report(*self.progress()) or self.step() is not None:
            pass

    def commit(self, context, progress=None):
        """Write every result (attributes or images, the instances' attributes, the wiring and
        AOV), then run the Cycles check if asked: all of it or, on any failure, none (the
        Transaction undoes what was written, and the error goes on). Returns the JSON-ready
        report, whose "stage_seconds" are this bake's times per stage. progress: as run()'s;
        it may still stop the bake, and undo every write, until the writes are kept."""
        report = progress or (lambda *a: None)
        report("writing", "", 0, 0)
        o = self.opts
        if o["live"]:
            live.check_job(self)  # what auto chose, a frame cache: refused unwritten
        t0 = time.perf_counter()
        txn = Transaction()
        # Only vertex attributes, no instances, AOV or Cycles check: the report can be made
        # first (it reads no write), and then nothing that can fail follows the last target's
        # write, which therefore copies no old values to undo it (commit.Transaction).
        vertex_only = (all(t.kind == "vertex" for t in self.targets) and not self.prototypes
                       and not o["add_aov"] and not o["check_cycles"])
        try:
            rep = self._report() if vertex_only else None
            texts = self._result_texts(rep) if vertex_only else None
            if o["atlas"] and o["mode"] == 'TEXEL':  # one image for every object
                rep_atlas = tiles_io.write_atlas(self.targets, txn, o)
            else:
                rep_atlas = None
                for i, t in enumerate(self.targets):
                    if t.kind != "vertex":
                        t.write(txn, o)
                    else:  # a modal bake yields to the UI: the user may have painted since
                        t.write(txn, o, last=vertex_only and i == len(self.targets) - 1,
                                checked=self.blocking)
            self.prototypes.commit(txn, o, skip={t.item.name for t in self.targets})
            if o["add_aov"]:
                if not any(a.name == o["aov_name"] for vl in self.scene.view_layers
                           for a in vl.aovs):
                    txn.add(lambda: materials.remove_view_layer_aov(self.scene, o["aov_name"]))
                materials.ensure_view_layer_aov(self.scene, o["aov_name"])
            t0 = self._lap("write", t0)
            if rep is None:
                rep = self._report()
            if rep_atlas is not None:
                rep["atlas"] = {"name": o["atlas"], "paths": rep_atlas["paths"],
                                "shared_texels": rep_atlas["shared_texels"]}
            if o["check_cycles"]:
                report("checking with Cycles", "", 0, 0)
                self._check_cycles(context, rep)
            if texts is None:
                texts = self._result_texts(rep)
            report("writing", "", 0, 0)  # the last moment a stop undoes every write
        except BaseException:
            txn.rollback()
            raise
        txn.done()  # from here on, only what cannot fail for a bake's data (the texts are made)
        t0 = self._lap("report, extras", t0)
        self.scene.canopy_ao.last_report = texts.pop(None)
        for name, text in texts.items():
            self.objects[name].canopy_ao.last_result = text
        if o["show_proxies"]:
            mesh_io.show_proxies(self.scene, core.proxy_dicts(self.plan))
        elif mesh_io.PROXY_COLLECTION in bpy.data.collections:
            mesh_io.show_proxies(self.scene, {})  # stale proxies of an earlier bake go
        self._lap("proxies", t0)
        if o["live"]:
            live.begin(self)  # every frame change from now on re-evaluates (live.py)
        rep["stage_seconds"] = dict(self.timings)
        self.report_dict = rep
        return rep

    def _result_texts(self, rep):
        """{object name: its panel line, None: the scene's}, made from rep before the commit's
        last write (a failure here still undoes every write)."""
        texts = {None: f"{rep['method']}, τ {rep['tau']:.3g}, {len(self.results)} object(s)"}
        for r in self.results:
            e = rep["objects"][r.name]
            texts[r.name] = (f"{e['role']}, {e['method']}, {e['vertices']} verts, "
                             f"{e['seconds']:.3f} s, mean AO {e['ao_mean']:.3f}")
            if "cycles" in e:
                texts[r.name] += f", vs Cycles MAE {e['cycles'].get('mae', float('nan')):.3f}"
        return texts

    def _report(self):
        o = self.opts
        rep = core.report(self.plan, self.results)
        rep["attribute"] = o["attribute"] if o["mode"] == 'VERTEX' else None
        rep["mode"] = o["mode"].lower()
        rep["channel"] = o["channel"]
        if o["channel"] != "RGBA" and o["wire_material"]:
            rep["notes"].append(f"the AO went into channel {o['channel']} only, so it was not "
                                "multiplied into the materials (a packed map is for engines)")
        rep["instances"] = instances.report(self.prototypes, self.how)
        for t in self.targets:
            e = rep["objects"][t.item.name]
            e["role_source"] = self.how[t.item.name]
            e["vertices"] = len(t.item.positions)
            if getattr(t, "parts", None):
                e["parts"] = parts_io.summary(t)
            if t.thickness is not None:
                e["thickness_mean"] = float(t.thickness.mean()) if t.count else None
            if t.bent is not None:
                e["bent_normals"] = bent_io.summary(t, o["bent_normals"])
            if t.kind == "texel":
                e["texel"] = t.report()
                rep["notes"].extend(t.stats.get("warnings", []))
        return rep

    def _check_cycles(self, context, rep):
        """Cycles' AO bake of the same objects, compared receiver by receiver: per vertex (one
        Cycles bake for every vertex target), or per texel of the image just written."""
        d = gather.cycles_distance(context.evaluated_depsgraph_get(), self.opts["distance"])
        samples = self.opts["cycles_samples"]
        vertex = [t for t in self.targets if t.kind == "vertex"]
        try:
            ref = (cycles_check.bake_cycles_vertex_ao(context, [t.obj for t in vertex], d,
                                                      samples) if vertex else {})
            for t in vertex:
                name = t.item.name
                if name in ref and np.shape(ref[name]) != t.ao.shape:
                    rep["notes"].append(f"{name}: Cycles check skipped (its modifiers change "
                                        "the vertex count)")
                elif name in ref:
                    rep["objects"][name]["cycles"] = {
                        k: float(v) for k, v in metrics.compare(t.ao, ref[name]).items()}
            for t in self.targets:
                if t.kind == "texel" and "image_tiles" in t.stats:  # UDIM or atlas
                    rep["objects"][t.item.name]["cycles"] = tiles_io.check_tiles(
                        context, t, d, samples)
                elif t.kind == "texel":
                    m = cycles_check.check_texel(context, t.obj, t.stats["image"], t.rx.uv_map,
                                                 d, samples, ours_mask=t.stats["mask"] == 1)
                    rep["objects"][t.item.name]["cycles"] = {k: float(v) for k, v in m.items()}
        except CanopyAOError:
            raise
        except ValueError as exc:  # the check's refusals (an empty material slot, ...)
            raise CanopyAOError(f"Cycles check: {exc}") from exc


def run_bake(context, object_names, opts, progress=None):
    """Synchronous bake for scripts and the CLI. Returns (job, report); raises CanopyAOError.
    progress(stage, name, done, total), called at each stage and step, may raise to stop the
    bake with nothing written (BakeJob.run, commit)."""
    t0 = time.perf_counter()
    if progress is not None:
        progress("gathering", "", 0, 0)
    job = BakeJob(context, object_names, opts, blocking=True)
    job.run(progress)
    rep = job.commit(context, progress)
    rep["seconds"] = time.perf_counter() - t0
    return job, rep
