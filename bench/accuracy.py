"""Speed against accuracy of every AO method on every benchmark scene (bench/README.md).

    /usr/bin/python3 bench/accuracy.py [--quick] [--scenes round_tree grove ...] [--no-cycles]

Pure Python over numpy, ``canopy_ao._core`` and the add-on's bpy-free ``engine`` (the same code
path as a bake in Blender, minus bpy I/O). For each scene (examples/canopy_scenes.py):

1. Reference: Embree (``_core.RayTracer``) at ``--ref-samples`` cosine-weighted rays per face
   corner (1024 unless --ref-samples), every vertex traced as the add-on's exact rung traces it
   (its own receiver, started at Cycles' bake point; the scenes are built in Blender one face per
   triangle), AO distance D = the scene's bbox diagonal, seed 12345 so its noise
   is independent of the methods' own ray-traced runs. Cached in
   bench/out/cache/embree_<scene>[_quick]_<samples>.npz (keyed by a hash of the geometry).
   Cycles' bake (bench/cycles_reference.py, run in Blender) is read from the same cache folder
   when present; its highest sample count is the second reference.
2. Methods, each timed on the whole scene (prepare = fits + calibration, eval = every vertex):
   - reeves_blau, sphere, ellipsoid, shells (k = 2, 4, 8): the engine's product path with τ
     calibrated by the engine against a few hundred ray-traced points ("calibrated"), and the
     same model with the τ that minimises the MSE against the reference on a 4000-vertex sample
     ("best τ": an upper bound on what calibration can reach; its prepare time excludes the
     search).
   - auto: the engine's own ladder walk.
   - grid: the engine's density-grid method, and DensityGrid straight from the core at
     resolutions 16-128 (all geometry except the ground, 32 directions).
   - medium_sphere / medium_ellipsoid / medium_shells (k = 2, 4, 8): the leaf-medium expectation
     (ao_medium_shells over every tree's proxies, product), τ calibrated the engine's way (256
     traced points) and best τ; not yet used by the engine.
   - raytrace at 1, 4, 16, 64, 256 samples per face corner, as the reference (prepare = BVH
     build).
   - cycles at every cached sample count below the Cycles reference (time = the bake call).
3. Errors per object role (canopy, trunk, ground, grass, all, and "unburied": all but the
   vertices whose reference AO is <= 0.02, i.e. buried inside other geometry) against each reference: MAE,
   RMSE, p95, correlation, bias (canopy_ao.metrics.compare) → bench/out/results.csv; per-vertex
   AO of every method → bench/out/ao/<scene>.npz (float16) for the picture strip.

Times are wall-clock (time.perf_counter), best of --repeats runs when a run is short, on a
shared 2-core machine: read them as orders of magnitude.
"""
from __future__ import annotations

import csv
import math
import os
import sys
import time

import harness  # noqa: E402  (addon/ and examples/ on sys.path)

HERE, REPO = harness.HERE, harness.REPO

import numpy as np  # noqa: E402

import canopy_scenes as cs  # noqa: E402
from canopy_ao import _core  # noqa: E402
from canopy_ao import core  # noqa: E402
from canopy_ao.core.metrics import compare  # noqa: E402

OUT, CACHE = harness.OUT, harness.CACHE
REF_SEED = 12345
# Which tracer made a cached reference: the native tracer's rule for vertex starts (Cycles' bake
# point, native raytrace.h 'Origins', kTracerRule), so a reference traced by an earlier rule is
# traced again.
TRACER_TAG = _core.TRACER_RULE
ROLES = ("canopy", "trunk", "ground", "grass")
BURIED = 0.02   # reference AO at or below this: a vertex buried inside other geometry
DEFAULT_SCENES = [n for n in cs.SCENES if n != "large_tree"]
FIELDS = ["scene", "vertices", "family", "method", "setting", "tau", "tau_mode", "reference",
          "role", "mae", "rmse", "p95", "corr", "bias", "n", "t_prepare", "t_eval", "t_total",
          "note"]


def log(*a):
    print(*a, flush=True)


# === Scene preparation ========================================================================

class Prepared:
    """A scene with normals, engine items, merged mesh and per-role masks over all vertices."""

    def __init__(self, scene, quick):
        self.scene = scene
        self.quick = quick
        self.name = scene.name
        self.hash = cs.geometry_hash(scene)
        self.distance = scene.ao_distance()
        self.normals = [cs.vertex_normals(p.vertices, p.triangles) for p in scene]
        self.items = [core.SceneItem(p.name, p.role.upper(), p.tree or "", p.vertices, n,
                                       p.triangles) for p, n in zip(scene, self.normals)]
        self.V, self.T, self.part = scene.merged()
        self.N = np.concatenate(self.normals)
        self.ids = np.arange(len(self.V), dtype=np.int32)
        self.role = np.concatenate([np.full(p.n_vertices, p.role, dtype=object) for p in scene])
        self.offsets = np.cumsum([0] + [p.n_vertices for p in scene])

    def tracer(self):
        """The scene's tracer as the add-on builds it (vertex normals: Cycles' bake point)."""
        return _core.RayTracer(self.V, self.T, normals=np.ascontiguousarray(self.N, np.float32))

    def trace(self, tracer, samples, distance, seed, rows=slice(None), shared=False):
        """AO at vertices ``rows``, each its own receiver: ``samples`` rays at every face
        corner, or (shared, every vertex) as the add-on's exact rung casts them, the same rays
        in all spread evenly over the vertices (core/ray_budget.py)."""
        if shared:
            from canopy_ao.core import ray_budget
            return ray_budget.trace_mesh(tracer, self.V, self.N, samples, seed, distance)
        return np.asarray(tracer.ao(self.V[rows], self.N[rows], samples=samples,
                                    distance=distance, seed=seed, vertex_ids=self.ids[rows]),
                          np.float32)

    def split(self, ao_all):
        return {p.name: ao_all[a:b] for p, a, b in zip(self.scene, self.offsets[:-1],
                                                        self.offsets[1:])}

    def join(self, per_part):
        return np.concatenate([np.asarray(per_part[p.name], np.float32) for p in self.scene])


def cache_name(kind, prep, samples):
    return os.path.join(CACHE, f"{kind}_{prep.name}{'_quick' if prep.quick else ''}_{samples}.npz")


def embree_reference(prep, samples):
    """(ao over all vertices, seconds), cached on disk."""
    path = cache_name("embree", prep, samples)
    key = dict(geometry=prep.hash, distance=prep.distance, tracer=TRACER_TAG)
    z = harness.load_cached(path, **key)
    if z is not None:
        return z["ao"].astype(np.float32), float(z["seconds"])
    if not hasattr(_core, "RayTracer"):
        return None, None
    ao, dt = harness.timed(lambda: prep.trace(prep.tracer(), samples, prep.distance, REF_SEED))
    harness.save_cached(path, dict(ao=ao, seconds=dt, samples=samples), **key)
    return ao, dt


def cycles_runs(prep):
    """{samples: (ao over all vertices, seconds)} for every cached Cycles bake of this scene."""
    out = {}
    if not os.path.isdir(CACHE):
        return out
    stem = f"cycles_{prep.name}{'_quick' if prep.quick else ''}_"
    for f in os.listdir(CACHE):
        if not (f.startswith(stem) and f.endswith(".npz")):
            continue
        tail = f[len(stem):-4]
        if not tail.isdigit():
            continue
        with np.load(os.path.join(CACHE, f)) as z:
            if str(z["geometry"]) != prep.hash:
                log(f"  (ignoring stale {f}: geometry changed)")
                continue
            per = {p.name: z[f"ao/{p.name}"] for p in prep.scene}
            out[int(tail)] = (prep.join(per), float(z["seconds"]))
    return dict(sorted(out.items()))


# === Methods ==================================================================================

def timed(fn, repeats, stop_after=2.0):
    """(result, best seconds): repeat only while runs are shorter than stop_after seconds."""
    return harness.timed(fn, repeats, stop_after)


def run_engine(prep, settings, repeats):
    """Bake every item with the engine; (ao all vertices, t_prepare, t_eval, plan)."""
    def prepare():
        return core.prepare(prep.items, settings)

    plan, t_prep = timed(prepare, repeats)

    def evaluate():
        return {it.name: core.evaluate_item(plan, it).ao for it in prep.items}

    per, t_eval = timed(evaluate, repeats)
    return prep.join(per), t_prep, t_eval, plan


def best_tau(prep, plan, ref, n_sample=4000, seed=1):
    """τ minimising the MSE against ``ref`` on a random vertex sample (golden section, log τ)."""
    rng = np.random.default_rng(seed)
    idx = np.sort(rng.choice(len(prep.V), size=min(n_sample, len(prep.V)), replace=False))
    sub = []
    for it, a, b in zip(prep.items, prep.offsets[:-1], prep.offsets[1:]):
        k = idx[(idx >= a) & (idx < b)] - a
        if len(k):
            sub.append(core.SceneItem(it.name, it.role, it.tree, it.positions[k],
                                        it.normals[k], it.triangles))
    r = ref[idx]

    def err(log_tau):
        plan.tau = math.exp(log_tau)
        got = np.concatenate([core.evaluate_item(plan, it).ao for it in sub])
        return float(np.mean((got - r) ** 2))

    lt, _ = core.ladder.golden_min(err, math.log(0.02), math.log(50.0), iters=20)
    plan.tau = math.exp(lt)
    return plan.tau


def analytic_methods():
    """(family, method, setting, BakeSettings kwargs) of every analytic rung the core can run."""
    rows = [("reeves_blau", "reeves_blau", "", {}), ("sphere", "sphere", "", {}),
            ("ellipsoid", "ellipsoid", "", {})]
    for k in (2, 4, 8):
        rows.append(("shells", "shells", f"k={k}", {"shells": k}))
    for k in (1, 4):
        rows.append(("medium", "medium", f"k={k}", {"shells": k}))
    return rows


def method_runs(prep, ref, args):
    """Yield (family, method, setting, tau, tau_mode, ao, t_prepare, t_eval, note)."""
    D = prep.distance
    avail = core.available_methods()
    for family, method, setting, kw in analytic_methods():
        if method not in avail:
            continue
        # product path: τ calibrated by the engine against ray-traced samples
        try:
            s = core.BakeSettings(method=method, tau=None, distance=D, seed=0, **kw)
            ao, tp, te, plan = run_engine(prep, s, args.repeats)
            yield family, method, setting, plan.tau, "calibrated", ao, tp, te, "; ".join(plan.notes)
        except Exception as exc:  # a missing native function, a bad fit: tabulate, go on
            yield family, method, setting, math.nan, "calibrated", None, math.nan, math.nan, \
                f"{type(exc).__name__}: {exc}"
            continue
        # best τ against the reference (upper bound on calibration)
        if ref is not None:
            try:
                s = core.BakeSettings(method=method, tau=1.0, distance=D, seed=0, **kw)
                plan = core.prepare(prep.items, s)
                tau = best_tau(prep, plan, ref)
                s.tau = tau
                ao, tp, te, plan = run_engine(prep, s, args.repeats)
                yield family, method, setting, tau, "best", ao, tp, te, ""
            except Exception as exc:
                yield family, method, setting, math.nan, "best", None, math.nan, math.nan, \
                    f"{type(exc).__name__}: {exc}"
    # the engine's own choice
    try:
        s = core.BakeSettings(method="auto", tau=None, distance=D, seed=0)
        ao, tp, te, plan = run_engine(prep, s, args.repeats)
        yield "auto", "auto", plan.method, plan.tau, "calibrated", ao, tp, te, \
            (plan.calibration or {}).get("why", "")
    except Exception as exc:
        yield "auto", "auto", "", math.nan, "calibrated", None, math.nan, math.nan, \
            f"{type(exc).__name__}: {exc}"
    if "grid" in avail:
        try:
            s = core.BakeSettings(method="grid", tau=None, distance=D, seed=0)
            ao, tp, te, plan = run_engine(prep, s, args.repeats)
            yield "grid", "grid", "engine", math.nan, "", ao, tp, te, "the engine's grid method"
        except Exception as exc:
            yield "grid", "grid", "engine", math.nan, "", None, math.nan, math.nan, \
                f"{type(exc).__name__}: {exc}"
    yield from raw_runs(prep, ref, args)
    if hasattr(_core, "RayTracer"):
        tracer, t_build = timed(prep.tracer, 1)
        for n in args.ray_samples:
            ao, te = timed(lambda: prep.trace(tracer, n, D, 0, shared=True), args.repeats)
            yield "raytrace", "raytrace", f"{n} rays", math.nan, "", ao, t_build, te, ""


def _tree_points(prep):
    trees = {}
    for p in prep.scene:
        if p.role == "canopy":
            trees.setdefault(p.tree, []).append(p.vertices)
    return {t: np.ascontiguousarray(np.concatenate(v)) for t, v in trees.items()}


def _fit_proxies(prep, kind, k):
    """One proxy per tree ("sphere", "ellipsoid") or k shells per tree, as Ellipsoids."""
    out = []
    for pts in _tree_points(prep).values():
        if kind == "sphere":
            out.append(_core.Ellipsoid.from_sphere(_core.fit_sphere(pts)))
        elif kind == "ellipsoid":
            out.append(_core.fit_ellipsoid(pts))
        else:
            shells, _ = _core.fit_shells(pts, k, kind="ellipsoid", seed=0)
            out += list(shells)
    return out


def _calibration_sample(prep, n=256, rays=128, seed=0):
    """The engine's recipe (docs/DESIGN.md, 'Auto mode'): trace a few hundred random receivers;
    (idx, ao, seconds)."""
    t0 = time.perf_counter()
    rng = np.random.default_rng(seed)
    idx = np.sort(rng.choice(len(prep.V), size=min(n, len(prep.V)), replace=False))
    ao = prep.trace(prep.tracer(), rays, prep.distance, 0, rows=idx)
    return idx, ao, time.perf_counter() - t0


def _fit_tau(f, idx, target):
    P, N = np.ascontiguousarray(PREP_CACHE["V"][idx]), np.ascontiguousarray(PREP_CACHE["N"][idx])
    lt, _ = core.ladder.golden_min(lambda x: float(np.mean((f(P, N, math.exp(x)) - target) ** 2)),
                               math.log(0.02), math.log(50.0), iters=20)
    return math.exp(lt)


PREP_CACHE = {}


def raw_runs(prep, ref, args):
    """Rungs the engine does not use yet, straight from _core over every vertex of the scene:
    the leaf-medium expectation (ao_medium_shells over every tree's proxies, product) and the
    density grid at several resolutions (all geometry except the ground)."""
    PREP_CACHE.update(V=prep.V, N=prep.N)
    # Experiment (not in the engine): an infinite ground plane under every non-ground receiver
    # blocks exactly (1 - n_z)/2 of its cosine-weighted hemisphere (the part of the hemisphere
    # below the horizon), when the AO distance reaches the ground.
    gterm = None
    grounds = [p for p in prep.scene if p.role == "ground"]
    if grounds:
        gterm = np.where(prep.role == "ground", 1.0,
                         np.clip(0.5 * (1.0 + prep.N[:, 2]), 0.0, 1.0)).astype(np.float32)
    have_trees = bool(_tree_points(prep))
    rng = np.random.default_rng(1)
    best_idx = np.sort(rng.choice(len(prep.V), size=min(4000, len(prep.V)), replace=False))
    calib = None
    if have_trees and hasattr(_core, "ao_medium_shells") and hasattr(_core, "RayTracer"):
        for kind, k in (("sphere", 1), ("ellipsoid", 1), ("shells", 2), ("shells", 4), ("shells", 8)):
            if kind == "shells" and not hasattr(_core, "fit_shells"):
                continue
            fam, setting = f"medium_{kind}", (f"k={k}" if kind == "shells" else "")
            try:
                t0 = time.perf_counter()
                shells = _fit_proxies(prep, kind, k)
                t_fit = time.perf_counter() - t0

                def f(P, N, tau, shells=shells):
                    return np.asarray(_core.ao_medium_shells(P, N, shells, float(tau)), np.float32)

                if calib is None:
                    calib = _calibration_sample(prep)
                t0 = time.perf_counter()
                tau_c = _fit_tau(f, calib[0], calib[1])
                t_cal = calib[2] + time.perf_counter() - t0
                ao, te = timed(lambda: f(prep.V, prep.N, tau_c), args.repeats)
                yield fam, fam, setting, tau_c, "calibrated", ao, t_fit + t_cal, te, \
                    "256 points traced at 128 rays"
                if gterm is not None and kind == "sphere":
                    gsub = gterm[calib[0]]
                    t0 = time.perf_counter()
                    lt, _ = core.ladder.golden_min(lambda x: float(np.mean(
                        (f(prep.V[calib[0]], prep.N[calib[0]], math.exp(x)) * gsub - calib[1]) ** 2)),
                        math.log(0.02), math.log(50.0), iters=20)
                    tau_g = math.exp(lt)
                    t_cal = calib[2] + time.perf_counter() - t0
                    ao, te = timed(lambda: f(prep.V, prep.N, tau_g) * gterm, args.repeats)
                    yield fam + "+ground", fam + "+ground", setting, tau_g, "calibrated", ao, \
                        t_fit + t_cal, te, "experiment: times (1 + n_z)/2 for non-ground receivers"
                if ref is not None:
                    tau_b = _fit_tau(f, best_idx, ref[best_idx])
                    ao, te = timed(lambda: f(prep.V, prep.N, tau_b), args.repeats)
                    yield fam, fam, setting, tau_b, "best", ao, t_fit, te, ""
            except Exception as exc:
                yield fam, fam, setting, math.nan, "calibrated", None, math.nan, math.nan, \
                    f"{type(exc).__name__}: {exc}"
    if hasattr(_core, "DensityGrid"):
        keep = [p for p in prep.scene if p.role != "ground"]
        off = np.cumsum([0] + [p.n_vertices for p in keep])
        GV = np.ascontiguousarray(np.concatenate([p.vertices for p in keep]))
        GT = np.ascontiguousarray(np.concatenate([p.triangles + o for p, o in zip(keep, off[:-1])]))
        for r in (16, 32, 64, 128):
            try:
                g, tb = timed(lambda: _core.DensityGrid(GV, GT, resolution=r), 1)
                ao, te = timed(lambda: np.asarray(g.ao(prep.V, prep.N, directions=32,
                                                       distance=prep.distance), np.float32),
                               args.repeats)
                yield "grid", "grid", f"r={r}", math.nan, "", ao, tb, te, \
                    "32 directions; grid of all geometry but the ground"
                if gterm is not None:
                    yield "grid+ground", "grid+ground", f"r={r}", math.nan, "", ao * gterm, tb, \
                        te, "experiment: times (1 + n_z)/2 for non-ground receivers"
            except Exception as exc:
                yield "grid", "grid", f"r={r}", math.nan, "", None, math.nan, math.nan, \
                    f"{type(exc).__name__}: {exc}"


# === Metrics and output =======================================================================

def metric_rows(prep, ao, ref, base):
    rows = []
    for role in ROLES + ("all", "unburied"):
        if role == "all":
            mask = np.ones(len(ref), bool)
        elif role == "unburied":   # vertices inside other geometry read AO ~ 0
            mask = ref > BURIED
        else:
            mask = prep.role == role
        if not mask.any():
            continue
        m = compare(ao, ref, mask=mask)
        row = dict(base, role=role, **{k: m[k] for k in ("mae", "rmse", "p95", "corr", "bias", "n")})
        rows.append(row)
    return rows


def fmt(v):
    if isinstance(v, float):
        return "" if math.isnan(v) else f"{v:.6g}"
    return v


def run_scene(name, args, writer, fh):
    scene = cs.make_scene(name, quick=args.quick)
    prep = Prepared(scene, args.quick)
    log(f"== {name}: {scene.n_vertices} vertices, {scene.n_triangles} triangles, "
        f"D = {prep.distance:.2f}")
    ref, t_ref = embree_reference(prep, args.ref_samples)
    refs = {}
    if ref is not None:
        refs["embree"] = ref
        log(f"  embree reference {args.ref_samples} rays: {t_ref:.1f} s, mean AO {ref.mean():.3f}")
    cyc = cycles_runs(prep) if args.cycles else {}
    cyc_ref_samples = max(cyc) if cyc else None
    if cyc_ref_samples is not None and cyc_ref_samples >= args.cycles_ref_min:
        refs["cycles"] = cyc[cyc_ref_samples][0]
        log(f"  cycles reference {cyc_ref_samples} samples: {cyc[cyc_ref_samples][1]:.1f} s, "
            f"mean AO {refs['cycles'].mean():.3f}")
    if not refs:
        log("  no reference (no RayTracer in _core and no cached Cycles bake): skipped")
        return
    primary = refs.get("embree", refs.get("cycles"))
    nv = scene.n_vertices
    saved = {}

    def emit(family, method, setting, tau, tau_mode, ao, tp, te, note):
        base = dict(scene=name, vertices=nv, family=family, method=method, setting=setting,
                    tau=tau, tau_mode=tau_mode, t_prepare=tp, t_eval=te,
                    t_total=(tp + te) if ao is not None else math.nan, note=note)
        if ao is None:
            writer.writerow({k: fmt(v) for k, v in dict(base, reference="", role="").items()})
            log(f"  {family:12s} {setting:8s} {tau_mode:10s} FAILED {note}")
            return
        bad = int(np.count_nonzero(~np.isfinite(ao)))
        if bad:
            base["note"] = (note + f"; {bad} non-finite values").strip("; ")
        for rname, r in refs.items():
            if rname == family:   # Cycles against its own reference: noise only, still useful
                pass
            for row in metric_rows(prep, ao, r, dict(base, reference=rname)):
                writer.writerow({k: fmt(v) for k, v in row.items()})
        fh.flush()
        m = compare(ao, primary)
        log(f"  {family:12s} {setting:8s} {tau_mode:10s} tau={fmt(float(tau)) or '-':8s} "
            f"t={tp + te:8.3f} s  MAE {m['mae']:.4f}  RMSE {m['rmse']:.4f}  corr {m['corr']:.3f}")
        key = "|".join(x for x in (family, setting, tau_mode) if x)
        saved[key] = ao.astype(np.float16)

    # the references against each other (Embree-vs-Cycles agreement)
    if "embree" in refs:
        emit("embree_ref", "raytrace", f"{args.ref_samples} rays", math.nan, "", refs["embree"],
             0.0, t_ref, "reference")
    for s, (ao, dt) in cyc.items():
        note = "reference" if s == cyc_ref_samples and "cycles" in refs else ""
        if "embree" in refs:
            # MAE two unbiased estimators would show from noise alone (unstratified bound:
            # var = a(1-a)(1/N_cycles + 1/N_embree), E|X| = sqrt(2/pi) sigma for a normal X)
            a = refs["embree"].astype(np.float64)
            noise = math.sqrt(2 / math.pi) * float(np.mean(np.sqrt(
                np.clip(a * (1 - a), 0, None) * (1 / s + 1 / args.ref_samples))))
            note = (note + f"; noise-only MAE vs embree <= {noise:.4f}").strip("; ")
        emit("cycles", "cycles", f"{s} samples", math.nan, "", ao, 0.0, dt, note)
    for out in method_runs(prep, primary, args):
        emit(*out)
    os.makedirs(os.path.join(OUT, "ao"), exist_ok=True)
    np.savez_compressed(os.path.join(OUT, "ao", f"{name}{'_quick' if args.quick else ''}.npz"),
                        V=prep.V, N=prep.N, role=prep.role.astype(str), **saved,
                        **{f"ref_{k}": v.astype(np.float16) for k, v in refs.items()})


def main(argv=None):
    ap = harness.parser(__doc__)
    ap.add_argument("--quick", action="store_true", help="smaller scenes and sample counts")
    ap.add_argument("--scenes", nargs="+", default=None, choices=sorted(cs.SCENES))
    ap.add_argument("--ref-samples", type=int, default=None)
    ap.add_argument("--ray-samples", type=int, nargs="+", default=None)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--no-cycles", dest="cycles", action="store_false")
    ap.add_argument("--cycles-ref-min", type=int, default=256,
                    help="a cached Cycles bake counts as a reference from this sample count")
    ap.add_argument("--out", default=os.path.join(OUT, "results.csv"))
    args = ap.parse_args(argv)
    if args.ref_samples is None:
        args.ref_samples = 1024
    if args.ray_samples is None:
        args.ray_samples = [1, 4, 16, 64, 256]
    scenes = args.scenes or DEFAULT_SCENES
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    log(f"canopy_ao._core {getattr(_core, '__version__', '?')}, engine methods "
        f"{core.available_methods()}, threads {_core.max_threads()}")
    t0 = time.perf_counter()
    with open(args.out, "w", newline="") as fh:
        w = csv.DictWriter(fh, FIELDS)
        w.writeheader()
        for name in scenes:
            run_scene(name, args, w, fh)
    log(f"wrote {args.out} in {time.perf_counter() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
