"""One bake in Blender, shared by the operator (modal or not) and the command line: gather and
check (nothing changed on failure), prepare, evaluate one target per step, commit."""

import time

import bpy
import numpy as np

from . import cycles_check, gather, instances, materials, mesh_io
from .. import core
from ..core import metrics, settings
from ..core.native import CanopyAOError

# Seconds per stage of the last committed bake (for bench/blender_bake_speed.py).
LAST_TIMINGS = {}


class BakeJob:
    """One bake: gather and check (nothing changed on failure), prepare, evaluate one target at
    a time, then commit every write at once, so a cancelled or failed bake changes nothing."""

    def __init__(self, context, object_names, opts):
        """opts: option name -> value (properties.scene_options, cli.options_from_args);
        options left out take their defaults. Raises CanopyAOError before changing anything."""
        opts = self.opts = dict(settings.defaults(), **opts)
        for o in settings.OPTIONS:  # every value in range before anything is read or written
            opts[o.name] = o.check(opts[o.name])
        self.settings = settings.BakeSettings(**{o.name: opts[o.name] for o in settings.OPTIONS
                                                 if o.group == "bake"})
        self.scene = context.scene
        self.results = []
        # Seconds per stage of this bake (bench/blender_bake_speed.py prints them).
        self.timings = {}
        t_start = time.perf_counter()
        self.lines = []
        ok, msg = core.core_status()
        if not ok:
            raise CanopyAOError(msg)
        if opts["wire_material"] or opts["add_aov"]:
            try:
                materials.check_aov_name(opts["aov_name"])
            except ValueError as exc:
                raise CanopyAOError(str(exc)) from None
        targets = gather.bake_targets(context, object_names)
        target_names = {o.name for o in targets}
        depsgraph = context.evaluated_depsgraph_get()
        self.items, self.objects, self.how = gather.scene_items(context, depsgraph, targets,
                                                                opts, self.timings)
        self.targets = [it for it in self.items if it.name in target_names]
        if not self.targets:
            raise CanopyAOError("every object to bake has the role Ignore")
        for it in self.targets if opts["mode"] == 'VERTEX' else ():
            why = mesh_io.check_attribute(self.objects[it.name], opts["attribute"],
                                          opts["overwrite"])
            if why:
                raise CanopyAOError(why + " (nothing was changed)")
        t0 = time.perf_counter()
        # Instanced trees (particles, collection instances, geometry nodes): each prototype is
        # baked once (its instances share its mesh) and every instance occludes (instances.py).
        self.prototypes = instances.Prototypes(depsgraph, vertex_mode=opts["mode"] == 'VERTEX')
        why = self.prototypes.check(opts["attribute"], opts["overwrite"], skip=target_names)
        if why:
            raise CanopyAOError(why + " (nothing was changed)")
        self.plan = None
        self.index = 0
        self._lap("instances", t0)
        self._lap("gather (total)", t_start)

    def _lap(self, key, t0):
        """Add the seconds since t0 to timings[key]; returns now."""
        t1 = time.perf_counter()
        self.timings[key] = self.timings.get(key, 0.0) + t1 - t0
        return t1

    @property
    def steps(self):
        return len(self.targets) + 1

    def prepare(self):
        t0 = time.perf_counter()
        # CanopyAOError (bad input, with its reason) passes to the caller as it is; anything
        # else is a bug and keeps its traceback.
        self.plan = core.prepare(self.items, self.settings)
        t0 = self._lap("prepare (fit, calibrate)", t0)
        if self.prototypes:
            skip = {it.name for it in self.targets}
            core.attach_forest(self.plan, self.prototypes.bake(self.settings, skip=skip))
            self.lines.extend(self.prototypes.lines())
            self._lap("instances", t0)

    def step(self):
        """Bake the next target; returns the line to report, or None when all are done."""
        if self.index >= len(self.targets):
            return None
        it = self.targets[self.index]
        self.index += 1
        t0 = time.perf_counter()
        try:
            r = core.evaluate_item(self.plan, it)
        except CanopyAOError as exc:
            raise CanopyAOError(f"{it.name}: {exc}") from exc
        self._lap("evaluate", t0)
        self.results.append(r)
        line = (f"{r.name}: role {r.role} ({self.how[r.name]}), tree {r.tree}, method {r.method}, "
                f"{r.vertices} vertices, {r.seconds:.3f} s")
        return line

    def run(self, progress=None):
        self.prepare()
        while True:
            if progress:
                progress(self.index)
            if self.step() is None:
                break

    def commit(self, context):
        """Write every result, then the optional extras. Returns the JSON-ready report."""
        o = self.opts
        texel_stats = {}
        t0 = time.perf_counter()
        if o["mode"] == 'TEXEL':
            from . import texel_io
            try:
                texel_stats = texel_io.bake_objects(context, self.plan, self.targets, o)
            except ValueError as exc:  # no UV map, bad resolution: said before any change
                raise CanopyAOError(str(exc)) from None
        else:
            for r in self.results:
                obj = self.objects[r.name]
                mesh_io.write_ao_attribute(obj, o["attribute"], r.ao, overwrite=o["overwrite"])
            self.prototypes.commit(o["attribute"], o["overwrite"])
        t0 = self._lap("write", t0)
        if o["show_proxies"]:
            mesh_io.show_proxies(self.scene, core.proxy_dicts(self.plan))
        elif mesh_io.PROXY_COLLECTION in bpy.data.collections:
            mesh_io.show_proxies(self.scene, {})  # stale proxies of an earlier bake go
        t0 = self._lap("proxies", t0)
        rep = core.report(self.plan, self.results)
        rep["attribute"] = o["attribute"] if o["mode"] == 'VERTEX' else None
        rep["mode"] = o["mode"].lower()
        rep["instances"] = {
            "instances": self.prototypes.count if self.prototypes else 0,
            "prototypes": {r.name: {"tree": r.tree, "method": r.method, "vertices": r.vertices,
                                    "seconds": r.seconds, "ao_mean": float(r.ao.mean())
                                    if r.vertices else None}
                           for r in self.prototypes.results}}
        for name, st in texel_stats.items():
            rep["objects"][name]["texel"] = {k: v for k, v in st.items()
                                             if isinstance(v, (int, float, str, list))}
            rep["notes"].extend(st.get("warnings", []))
        for r in self.results:
            rep["objects"][r.name]["role_source"] = self.how[r.name]
        if o["mode"] == 'VERTEX' and o["wire_material"] or o["add_aov"]:
            self._wire(rep)
        if o["check_cycles"]:
            self._check_cycles(context, rep)
        for r in self.results:
            e = rep["objects"][r.name]
            text = (f"{e['role']}, {e['method']}, {e['vertices']} verts, {e['seconds']:.3f} s, "
                    f"mean AO {e['ao_mean']:.3f}")
            if "cycles" in e:
                text += f", vs Cycles MAE {e['cycles'].get('mae', float('nan')):.3f}"
            self.objects[r.name].canopy_ao.last_result = text
        self.scene.canopy_ao.last_report = (
            f"{rep['method']}, τ {rep['tau']:.3g}, {len(self.results)} object(s)")
        self._lap("report, extras", t0)
        rep["stage_seconds"] = dict(self.timings)
        LAST_TIMINGS.clear()
        LAST_TIMINGS.update(self.timings)
        self.report_dict = rep
        return rep

    def _wire(self, rep):
        o = self.opts
        if o["wire_material"]:
            for r in self.results:
                materials.wire_vertex_ao(self.objects[r.name], o["attribute"], o["aov_name"])
            for r in self.prototypes.results:
                materials.wire_vertex_ao(self.prototypes.objects[r.name], o["attribute"],
                                         o["aov_name"])
        if o["add_aov"]:
            materials.ensure_view_layer_aov(self.scene, o["aov_name"])

    def _check_cycles(self, context, rep):
        objs = [self.objects[r.name] for r in self.results]
        d = self.opts["distance"]
        ref = cycles_check.bake_cycles_vertex_ao(context, objs, d if d > 0 else 1.0e6,
                                                 self.opts["cycles_samples"])
        for r in self.results:
            if r.name in ref and np.shape(ref[r.name]) != r.ao.shape:
                rep["notes"].append(f"{r.name}: Cycles check skipped (its modifiers change the "
                                    "vertex count)")
            elif r.name in ref:
                rep["objects"][r.name]["cycles"] = {
                    k: float(v) for k, v in metrics.compare(r.ao, ref[r.name]).items()}


def run_bake(context, object_names, opts):
    """Synchronous bake for scripts and the CLI. Returns (job, report); raises CanopyAOError."""
    t0 = time.perf_counter()
    job = BakeJob(context, object_names, opts)
    job.run()
    rep = job.commit(context)
    rep["seconds"] = time.perf_counter() - t0
    return job, rep
