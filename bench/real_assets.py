"""Every rung on the real-generator scenes (Sapling Tree Gen trees, grass field, grove).

    /usr/bin/python3 bench/real_assets.py [--scenes sap_callistemon ...] [--full] [--csv FILE]

The scenes are the exports of examples/sapling_scenes.py (bench/out/real/<scene>[_quick].npz;
build them first, in Blender — the command is printed when one is missing). Reference: Embree at
1024 cosine-weighted rays per vertex, AO distance = the scene's diagonal (bench/real_scenes.py,
cached); Cycles' own bake is a second reference when examples/sapling_scenes.py --bake-cycles N has
been run (the highest N). Per scene, per method: MAE over all vertices and with buried vertices
left out (leaf and branch vertices whose rays all stop within 1 % of their object's size),
correlation (buried left out), MAE against the Cycles reference (buried left out), and wall time of the whole bake as a user waits for it (BVH,
grids, fits and calibration included):

- constant: the median reference AO of the unburied vertices for every vertex (an oracle
  baseline: a rung that does not beat it has learnt nothing);
- sphere, ellipsoid, shells, medium, grid: the engine's rungs, τ calibrated by the engine
  (each with the bake's buried test: leaf and branch receivers whose 8 short rays all stop
  within 1 % of their object's size read 0, docs/DESIGN.md, 'Buried receivers');
- rays N: Embree at N = 1, 4, 16, 64, 256 rays (BVH build included);
- regression: the ray-free rung (addon/canopy_ao/core/regression.py, occlusion_features.h),
  as `--method regression` bakes it: a traced calibration sample sized to the scene (at most
  1024 points × 128 rays and 8 rays per receiver), then no rays but the bake's buried test;
- hybrid 2v/N: the engine's hybrid at N samples (N rays per face corner out to 2 voxels of
  its density grid, the grid beyond: what `--method hybrid --samples N` bakes; other near
  distances in bench/probes/hybrid_study.py);
- auto: what `--method auto` bakes (its choice per role in the note: counted work against the
  time budget, tested on traced points, docs/DESIGN.md, 'Auto mode');
- cycles N: Cycles' bake at N samples, when cached (time: the bake call).

Designed on sap_callistemon, sap_white_birch, sap_small_maple (marked *); every other scene is
held out, and so is any scene --scenes names beyond the list (examples/sapling_scenes.py builds
sap_<preset>_s<seed> and sap_grove_s<seed> for any bundled preset and seed). Times are
wall-clock on a shared 2-core machine: compare ratios within one run.
"""
from __future__ import annotations

import csv
import sys

import harness  # noqa: E402  (addon/ and examples/ on sys.path)

HERE, REPO = harness.HERE, harness.REPO

import numpy as np  # noqa: E402

import real_scenes as rs  # noqa: E402
from canopy_ao import core  # noqa: E402
from canopy_ao.core import buried  # noqa: E402
from canopy_ao.core.metrics import compare  # noqa: E402

DESIGN = ("sap_callistemon", "sap_white_birch", "sap_small_maple")
TREES = DESIGN + ("sap_douglas_fir", "sap_small_pine", "sap_weeping_willow",
                  "sap_quaking_aspen", "sap_japanese_maple", "sap_grove")
SCENES = TREES + ("grass_field_real",)
ENGINE_RUNGS = ("sphere", "ellipsoid", "shells", "medium", "grid")
RAYS = (1, 4, 16, 64, 256)
HYBRID_SAMPLES = (16, 64)  # the engine's hybrid (lighting.HYBRID_VOXELS = 2) at these samples


_WARM = []


def timed(fn):
    """(result, seconds) of one run (the scenes are large: one run each)."""
    return harness.timed(fn)


def auto_choice(report):
    """What auto chose, per role, from a bake's report: "CANOPY regression, GROUND raytrace"."""
    chosen = {}
    for o in report["objects"].values():
        chosen.setdefault(o["role"], set()).add(o["method"])
    return ", ".join(f"{role} {'/'.join(sorted(m))}" for role, m in sorted(chosen.items()))


def methods(sc, seen=None):
    """Yield (method, ao over all vertices, seconds, note). seen, a dict, gets the regression
    bake's buried test: "buried" (bool over all vertices: what it set to 0) and "seconds"."""
    items = sc.engine_items()
    D = sc.distance
    if not _WARM:  # the first bake of a process builds the medium table and thread pools
        core.bake(items, core.BakeSettings(method="medium", distance=D))
        _WARM.append(True)
    for m in ENGINE_RUNGS:
        try:
            (res, rep), dt = timed(lambda: core.bake(items, core.BakeSettings(
                method=m, distance=D)))
            yield m, np.concatenate([r.ao for r in res]), dt, f"tau {rep.get('tau', '')}"
        except Exception as exc:  # a rung that refuses the scene says why
            yield m, None, 0.0, f"failed: {exc}"
    tracer, t_bvh = timed(lambda: rs.scene_tracer(sc))
    for n in RAYS:
        ao, dt = timed(lambda: rs.trace_vertices(tracer, sc, n, D, 0, shared=True))
        yield f"rays {n}", ao, dt + t_bvh, ""
    def regression_bake():  # core.bake's steps, keeping the plan: what its buried test found
        plan = core.prepare(items, core.BakeSettings(method="regression", distance=D))
        res = [core.evaluate_item(plan, it) for it in items]
        return plan, res, core.report(plan, res)
    (plan, res, rep), dt = timed(regression_bake)
    if seen is not None:
        seen["buried"] = np.concatenate([plan.buried.get(n, np.zeros(len(sc.parts[n]["positions"]),
                                                                     bool)) for n in sc.names])
        seen["seconds"] = rep["timings"].get("buried_test", 0.0)
    cal = rep["calibration"]
    yield "regression", np.concatenate([r.ao for r in res]), dt, \
        (f"sample {cal['calibration_points']} x {cal['calibration_samples']} rays; "
         f"buried set to 0: {sum(o['buried_set_to_0'] for o in rep['objects'].values())}; " +
         " ".join(f"{k}:{v['source']}" for k, v in cal["groups"].items()))
    (res, rep), dt = timed(lambda: core.bake(items, core.BakeSettings(method="auto",
                                                                     distance=D)))
    yield "auto", np.concatenate([r.ao for r in res]), dt, "chose " + auto_choice(rep)
    for n in HYBRID_SAMPLES:
        (res, _rep), dt = timed(lambda: core.bake(items, core.BakeSettings(
            method="hybrid", samples=n, distance=D)))
        yield f"hybrid 2v/{n}", np.concatenate([r.ao for r in res]), dt, "engine"
    for s, (ao, dt) in rs.cycles_runs(sc).items():
        yield f"cycles {s}", ao, dt, "Cycles bake"


def run_scene(name, quick, writer):
    sc = rs.load(name, quick)
    ref, _ = rs.reference(sc)
    bur = rs.buried(sc)
    keep = ~bur
    star = "*" if name in DESIGN else ""
    print(f"\n== {name}{star}: {sc.n_vertices} vertices, {len(sc.T)} triangles, buried "
          f"{bur.sum()} ({bur.sum() / max(1, np.isin(sc.role, ('canopy', 'trunk')).sum()):.0%} "
          f"of leaf+branch vertices), mean AO {ref.mean():.3f}, AO distance {sc.distance:.3g}")
    cyc = rs.cycles_runs(sc)
    cref = cyc[max(cyc)][0] if cyc else None  # the highest-sample Cycles bake: 2nd reference
    ctitle = f"vs cy{max(cyc)}" if cyc else ""
    print(f"{'method':16s} {'MAE all':>8s} {'MAE unb':>8s} {'corr':>6s} {'seconds':>8s} "
          f"{ctitle:>8s}  note")
    const = np.full_like(ref, np.median(ref[keep]))
    rows = [("constant", const, 0.0, "median reference AO (oracle)")]
    t64 = None
    seen = {}
    for row in [*rows, *methods(sc, seen)]:
        m, ao, dt, note = row
        if ao is None:
            print(f"{m:16s} {'-':>8s} {'-':>8s} {'-':>6s} {'-':>8s}  {note}")
            continue
        a, u = compare(ao, ref), compare(ao, ref, keep)
        if m == "rays 64":
            t64 = dt
        vs_c = f"{compare(ao, cref, keep)['mae']:8.4f}" if cref is not None else ""
        print(f"{m:16s} {a['mae']:8.4f} {u['mae']:8.4f} {u['corr']:6.3f} {dt:8.3f} {vs_c:>8s}  "
              f"{note}", flush=True)
        if writer is not None:
            writer.writerow(dict(scene=name, design=bool(star), vertices=sc.n_vertices,
                                 method=m, mae_all=a["mae"], mae_unburied=u["mae"],
                                 corr=u["corr"], bias=u["bias"], seconds=dt,
                                 mae_vs_cycles=compare(ao, cref, keep)["mae"]
                                 if cref is not None else "",
                                 t64=t64 if t64 else "", note=note))
        if m == "regression" and "buried" in seen:
            found = seen["buried"]
            extra = found & keep
            print(f"  its buried test (bake._zero_buried, {buried.BURIED_RECEIVER_RAYS} rays per "
                  f"leaf or branch vertex, {seen['seconds']:.3f} s"
                  + (f" = {seen['seconds'] / t64:.3f}x rays 64" if t64 else "")
                  + f"): {(found & bur).sum()} of the {bur.sum()} buried, and {extra.sum()} "
                  f"others (reference AO there {ref[extra].mean() if extra.any() else 0:.3f} "
                  "on average)")
        if m == "regression":
            for role in ("canopy", "trunk", "ground", "grass"):
                r = compare(ao, ref, keep & (sc.role == role))
                if r["n"]:
                    print(f"  {role:14s} {'':8s} {r['mae']:8.4f} {r['corr']:6.3f} "
                          f"{'':8s}  bias {r['bias']:+.3f}")


def auto_note(row):
    """The auto cell's choice, shortened: "; rays" when every role took one method."""
    if row is None or not row["note"].startswith("chose "):
        return ""
    choice = row["note"][len("chose "):].replace("raytrace", "rays")
    picked = {part.split(" ", 1)[1] for part in choice.split(", ")}
    return "; " + (picked.pop() if len(picked) == 1 else choice.lower())


def markdown(rows):
    """The README's table from the CSV rows: per scene, the rungs that matter for the targets."""
    out = ["| scene | vertices | constant | best proxy rung | grid | rays 16 | rays 64 | "
           "regression (ray-free) | hybrid 2 voxels / 64 rays | auto (its choice) |",
           "|---|---|---|---|---|---|---|---|---|---|"]
    scenes = []
    for r in rows:
        if r["scene"] not in scenes:
            scenes.append(r["scene"])
    for sc in scenes:
        m = {r["method"]: r for r in rows if r["scene"] == sc}
        t64 = float(m["rays 64"]["seconds"])

        def cell(name, ratio=True):
            r = m.get(name)
            if r is None or r["mae_unburied"] == "":
                return "–"
            txt = (f"{float(r['mae_all']):.3f} / {float(r['mae_unburied']):.3f}, "
                   f"r {float(r['corr']):.2f}, {float(r['seconds']):.2g} s")
            return txt + (f" ({float(r['seconds']) / t64:.2f}×)" if ratio else "")
        proxies = [k for k in ENGINE_RUNGS if k != "grid" and k in m and m[k]["mae_unburied"]]
        best = min(proxies, key=lambda k: float(m[k]["mae_unburied"])) if proxies else None
        star = "*" if m["rays 64"]["design"] == "True" else ""
        out.append(f"| {sc}{star} | {m['rays 64']['vertices']} | "
                   f"{float(m['constant']['mae_all']):.3f} / "
                   f"{float(m['constant']['mae_unburied']):.3f} | "
                   f"{best + ': ' + cell(best, False) if best else '–'} | {cell('grid', False)} | "
                   f"{cell('rays 16', False)} | {cell('rays 64', False)} | {cell('regression')} | "
                   f"{cell('hybrid 2v/64')} | {cell('auto')}{auto_note(m.get('auto'))} |")
    return "\n".join(out)


def main(argv=None):
    ap = harness.parser(__doc__, prog="real_assets.py")
    ap.add_argument("--scenes", nargs="+", default=list(SCENES),
                    help="scenes exported to bench/out/real: the listed ones, or held-out "
                         "ones (examples/sapling_scenes.py sap_<preset>_s<seed>, "
                         "sap_grove_s<seed>)")
    ap.add_argument("--full", action="store_true", help="full-size exports instead of quick")
    ap.add_argument("--csv", help="also write every row to this CSV file")
    ap.add_argument("--markdown", metavar="FILE.md",
                    help="only format an earlier --csv run as the README's table, into FILE.md")
    a = ap.parse_args(argv)
    if a.markdown:
        if not a.csv:
            ap.error("--markdown needs --csv (the run to format)")
        with open(a.csv, newline="") as fh:
            text = markdown(list(csv.DictReader(fh)))
        with open(a.markdown, "w") as fh:
            fh.write(text + "\n")
        print(text)
        return 0
    fh = open(a.csv, "w", newline="") if a.csv else None
    writer = None
    if fh:
        writer = csv.DictWriter(fh, ["scene", "design", "vertices", "method", "mae_all",
                                     "mae_unburied", "corr", "bias", "seconds", "mae_vs_cycles", "t64",
                                     "note"])
        writer.writeheader()
    try:
        for s in a.scenes:
            run_scene(s, not a.full, writer)
    finally:
        if fh:
            fh.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
