"""One bake in Blender, shared by the operator (modal or not) and the command line: gather and
check (nothing changed on failure), prepare, evaluate receivers in chunks (the bake loop,
loop.py: one per step, so progress and Esc cover vertices and texels alike), commit everything
or nothing. The targets' kind (per vertex, per texel) is the Output's; the job only calls the
targets' interface (targets.Target)."""

import time

import bpy

from . import (bent_io, checks, gather, instances, live_session, materials, mesh_io,
               parts_io)
from .commit import Transaction
from .loop import KINDS, Loop
from .. import core
from ..core import maps, packing, settings
from ..core.native import CanopyAOError

# Receivers per step: a modal tick stays short, and per-call overhead stays small.
CHUNK = 1 << 16
# A blocking bake (execute, the command line: no Esc to answer, no redraw between steps) takes
# this many chunks per step: fewer calls, each one's fixed cost paid less often; the progress
# bar still moves every 2^18 receivers.
BLOCKING_CHUNKS = 4
# Rungs whose receivers cast rays, samples each (Rung.uses_samples): a blocking bake's vertex
# steps shrink as the samples grow (2^14 vertices at 256), so progress and Ctrl-C answer every
# few seconds.


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
        self.kind = KINDS[opts["mode"]]
        self.gather_notes = []
        targets = gather.bake_targets(context, object_names, opts, on_mesh=self.kind.on_mesh,
                                      notes=self.gather_notes)
        target_names = {o.name for o in targets}
        depsgraph = context.evaluated_depsgraph_get()
        self.items, self.objects, self.how = gather.scene_items(
            context, depsgraph, targets, opts, self.timings, notes=self.gather_notes)
        # Every target's receivers, read now: vertices, or texels rasterised from its UVs.
        t0 = time.perf_counter()
        self.targets = [self.kind(it, self.objects[it.name], opts, depsgraph)
                        for it in self.items if it.name in target_names]
        self.targets += parts_io.targets(self.kind, self.items, self.objects, target_names, opts,
                                         depsgraph)  # a mesh baked by parts: one target
        if not self.targets:
            raise CanopyAOError("every object to bake has the role Ignore")
        self.kind.check_outputs(self.targets, opts)  # image files: none collide, none the user's
        self.blocking = blocking
        self.loop = Loop(self.targets, CHUNK * (BLOCKING_CHUNKS if blocking else 1))
        self._lap("receivers", t0)
        t0 = time.perf_counter()
        # Instanced trees (particles, collection instances, geometry nodes): each prototype is
        # baked once (its instances share its mesh) and every instance occludes (instances.py).
        # Their own AO only when asked: a prototype or its instancer a target, or the bake of
        # everything (no names, nothing selected); else they occlude and stay untouched.
        everything = not object_names and not any(
            gather.is_candidate(o) for o in context.selected_objects)
        self.prototypes = instances.Prototypes(depsgraph, vertex_mode=self.kind.per_vertex,
                                               targets=None if everything else target_names)
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
        return len(self.loop.chunks) + 1

    @property
    def steps_done(self):
        return self.loop.next + (self.plan is not None)

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
        # Card vertices carry their opaque part's AO in a single bake without bent normals
        # (loop.start): the calibration samples take them there then (core/card_ao.py).
        cards = (not (self.opts["live"] or self.opts.get("frames"))
                 and self.opts["bent_normals"] == "OFF")
        self.plan = core.prepare(self.items, self.settings, prototypes=protos, targets=targets,
                                 carry_cards=cards, live=self.opts["live"])
        t0 = self._lap("prepare (fit, calibrate)", t0)
        if self.prototypes.realized:
            self.prototypes.bake_realized(self.plan)
            t0 = self._lap("instances", t0)
        self.plan.notes.extend(self.gather_notes + self.prototypes.grass_lines())
        if self.opts["bent_normals"] != "OFF":  # rays, whichever rung lit the AO
            maps.ensure_tracer(self.plan, self.items)
            self._lap("tracer (bent normals)", t0)
        self.loop.start(self.plan, self.opts["bent_normals"], bool(self.opts["thickness"]),
                        self.prototypes.means, cards=cards)
        if self.blocking and core.rung(self.plan.method).uses_samples:  # steps of a few seconds
            self.loop.split(max(4096, CHUNK * BLOCKING_CHUNKS * 16
                                // max(self.settings.samples, 16)))

    def step(self):
        """Evaluate the next chunk of receivers. Returns the line to report when it completes
        a target, "" when it does not, None when every chunk is done."""
        out = self.loop.step()
        if out is None:
            return None
        t, seconds, complete = out
        self.timings["evaluate"] = self.timings.get("evaluate", 0.0) + seconds
        if not complete:
            return ""
        it = t.item
        r = core.ItemResult(it.name, it.role, it.tree, self.plan.method, t.ao, t.seconds,
                            it.tree_source, it.tree_why)
        self.results.append(r)
        return (f"{r.name}: role {r.role} ({self.how[r.name]}), tree {r.tree}, method "
                f"{r.method}, {t.count} {t.kind if t.count == 1 else t.kinds}, "
                f"{r.seconds:.3f} s")

    def progress(self):
        """(stage, object, receivers done, receivers in all) for a progress report."""
        if self.plan is None:
            return "preparing", "", 0, 0
        return ("evaluating", *self.loop.progress())

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
            live_session.check_job(self)  # what auto chose, a frame cache: refused unwritten
        t0 = time.perf_counter()
        txn = Transaction()
        # Only vertex attributes, no instances, AOV or Cycles check: the report can be made
        # first (it reads no write), and then nothing that can fail follows the last target's
        # write, which therefore copies no old values to undo it (commit.Transaction).
        attributes_only = (self.kind.per_vertex and not self.prototypes
                           and not o["add_aov"] and not o["check_cycles"])
        try:
            rep = self._report() if attributes_only else None
            texts = self._result_texts(rep) if attributes_only else None
            extra = self.kind.write_all(self.targets, txn, o, last=attributes_only,
                                        checked=self.blocking)
            self.prototypes.commit(txn, o, skip={t.item.name for t in self.targets})
            if o["add_aov"]:  # undone only on the view layers that lacked it
                lacking = [vl.name for vl in self.scene.view_layers
                           if not any(a.name == o["aov_name"] for a in vl.aovs)]
                if lacking:
                    txn.add(lambda: materials.remove_view_layer_aov(
                        self.scene, o["aov_name"], lacking))
                materials.ensure_view_layer_aov(self.scene, o["aov_name"])
            t0 = self._lap("write", t0)
            if rep is None:
                rep = self._report()
            rep.update(extra)
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
            live_session.begin(self)  # every frame change from now on re-evaluates (live.py)
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
        rep["attribute"] = self.kind.attribute(o)
        rep["mode"] = o["mode"].lower()
        rep["channel"] = o["channel"]
        if o["channel"] != "RGBA" and o["wire_material"]:
            rep["notes"].append(f"the AO went into channel {o['channel']} only, so it was not "
                                "multiplied into the materials (a packed map is for engines)")
        elif o["wire_material"]:
            for t in self.targets:
                for name in materials.without_colour(t.obj):
                    rep["notes"].append(
                        f"{t.obj.name}: material '{name}' has no surface shader colour to "
                        f"multiply the AO into (it reaches only the AOV '{o['aov_name']}')")
        rep["instances"] = instances.report(self.prototypes, self.how)
        for t in self.targets:
            e = rep["objects"][t.item.name]
            e["role_source"] = self.how[t.item.name]
            e["vertices"] = len(t.item.positions)
            if t.thickness is not None:
                e["thickness_mean"] = float(t.thickness.mean()) if t.count else None
            if t.bent is not None:
                e["bent_normals"] = bent_io.summary(t, o["bent_normals"])
            t.report_into(e, rep["notes"])
        return rep

    def _check_cycles(self, context, rep):
        """Cycles' AO bake of the same objects, compared receiver by receiver: per vertex (one
        Cycles bake for every vertex target), or per texel of the image just written."""
        d = gather.cycles_distance(context.evaluated_depsgraph_get(), self.opts["distance"])
        try:
            self.kind.check_cycles(context, self.targets, d, self.opts["cycles_samples"], rep)
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
