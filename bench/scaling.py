"""Time against vertex count per method, 1e4 … 1e7 vertices (bench/README.md).

    /usr/bin/python3 bench/scaling.py [--max 1e7] [--quick]

The round tree (examples/canopy_scenes.py) with leaves = N/4 quads, no ground, so the vertex
count is N (+ a few thousand trunk vertices); leaves shrink as their count grows so the total
leaf area (the crown's density, and so how far rays travel) stays that of the 20000-leaf tree. Per method: prepare (fits; BVH build for ray
tracing) and evaluation over every vertex, wall-clock, best of 2 when short. τ is fixed (1.5):
calibration costs a constant (a few hundred traced points) and is timed in bench/accuracy.py.
Writes bench/out/scaling.csv and bench/out/scaling.png (log-log).
"""
from __future__ import annotations

import csv
import math
import os
import sys

import harness  # noqa: E402  (addon/ and examples/ on sys.path)

HERE, REPO = harness.HERE, harness.REPO

import numpy as np  # noqa: E402

import canopy_scenes as cs  # noqa: E402
from canopy_ao import _core, core  # noqa: E402


OUT = harness.OUT


def timed(fn, repeats=2):
    return harness.timed(fn, repeats, stop_after=1.0)


def main(argv=None):
    ap = harness.parser(__doc__)
    ap.add_argument("--max", type=float, default=1e7)
    ap.add_argument("--quick", action="store_true", help="stop at 1e6 vertices")
    ap.add_argument("--rays", type=int, default=16)
    a = ap.parse_args(argv)
    top = 1e6 if a.quick else a.max
    sizes = [n for n in (1e4, 3e4, 1e5, 3e5, 1e6, 3e6, 1e7) if n <= top * 1.001]
    methods = [m for m in ("reeves_blau", "sphere", "ellipsoid", "shells", "medium", "grid")
               if m in core.available_methods()]
    rows = []
    os.makedirs(OUT, exist_ok=True)
    for n in sizes:
        leaves = int(n // 4)
        scene = cs.round_tree(seed=0, leaves=leaves, ground=False,
                              leaf_size=cs.area_preserving_leaf_size(leaves))
        V, T, _ = scene.merged()
        N = np.concatenate([cs.vertex_normals(p.vertices, p.triangles) for p in scene])
        items = [core.SceneItem(p.name, p.role.upper(), p.tree or "", p.vertices,
                                  N[o:o + p.n_vertices], p.triangles)
                 for p, o in zip(scene, np.cumsum([0] + [q.n_vertices for q in scene])[:-1])]
        nv = len(V)
        for m in methods:
            try:
                s = core.BakeSettings(method=m, tau=1.5, shells=4)
                plan, tp = timed(lambda: core.prepare(items, s))
                _, te = timed(lambda: [core.evaluate_item(plan, it) for it in items])
                note = ""
            except Exception as exc:
                tp = te = math.nan
                note = f"{type(exc).__name__}: {exc}"
            rows.append(dict(method=m, vertices=nv, t_prepare=tp, t_eval=te, t_total=tp + te,
                             mvps=nv / te / 1e6 if te > 0 else math.nan, note=note))
            print(f"{nv:10d} {m:12s} prepare {tp:8.3f} s eval {te:8.3f} s "
                  f"({rows[-1]['mvps']:.1f} M vertices/s) {note}", flush=True)
        if hasattr(_core, "ao_medium_sphere") and hasattr(_core, "fit_sphere"):
            leaves = np.ascontiguousarray(scene.parts_by_role("canopy")[0].vertices)
            sph, tp = timed(lambda: _core.fit_sphere(leaves))
            _, te = timed(lambda: _core.ao_medium_sphere(V, N, sph, 1.0))
            rows.append(dict(method="medium_sphere (core)", vertices=nv, t_prepare=tp, t_eval=te,
                             t_total=tp + te, mvps=nv / te / 1e6, note="fit_sphere + ao_medium_sphere"))
            print(f"{nv:10d} medium_sphere prepare {tp:8.3f} s eval {te:8.3f} s "
                  f"({rows[-1]['mvps']:.1f} M vertices/s)", flush=True)
        if hasattr(_core, "RayTracer"):
            tr, tb = timed(lambda: _core.RayTracer(V, T), 1)
            for r in (1, a.rays):
                _, te = timed(lambda: tr.ao(V, N, samples=r, distance=scene.ao_distance()), 1)
                rows.append(dict(method=f"raytrace {r}", vertices=nv, t_prepare=tb, t_eval=te,
                                 t_total=tb + te, mvps=nv / te / 1e6, note=""))
                print(f"{nv:10d} raytrace {r:3d} build {tb:8.3f} s trace {te:8.3f} s "
                      f"({nv * r / te / 1e6:.1f} M rays/s)", flush=True)
            del tr
    path = os.path.join(OUT, "scaling.csv")
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    for m in dict.fromkeys(r["method"] for r in rows):
        rr = [r for r in rows if r["method"] == m and np.isfinite(r["t_total"])]
        ax.plot([r["vertices"] for r in rr], [r["t_total"] for r in rr], "o-", label=m)
    ax.set_xscale("log"); ax.set_yscale("log")
    ax.set_xlabel("vertices"); ax.set_ylabel("wall time, s (prepare + evaluate)")
    ax.grid(True, which="both", alpha=0.3); ax.legend(fontsize=8)
    ax.set_title("Canopy AO: time against vertex count (round tree, 2 cores)")
    fig.tight_layout()
    fig.savefig(os.path.join(OUT, "scaling.png"), dpi=110)
    print(f"scaling: wrote {path} and scaling.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
