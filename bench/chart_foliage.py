"""Error against time on the foliage scenes (examples/foliage_scenes.py), from bench/foliage.py's
CSV (bench/foliage.py --png draws it at the end of its run).

    /usr/bin/python3 bench/chart_foliage.py [--csv bench/out/foliage.csv]
                                            [--png bench/out/chart_foliage.png]

One panel per scene: MAE over every vertex with buried ones left out, against our rays at 256
samples, against the bake's wall time (log-log): every rung in the house colours
(bench/chart_real.py's), the exact rung at 16 and 64 rays as a curve, the constant (each
object's mean reference AO, an oracle) as a dashed line.
"""
from __future__ import annotations

import csv
import math
import os
import sys

import harness  # noqa: E402

import chart_real  # noqa: E402

STYLE = dict(chart_real.STYLE)
# Two rungs chart_real.py does not draw, in colours apart from its hybrid's and regression's.
STYLE.update(reeves_blau=("#e377c2", "<"), auto=("#7f7f7f", "p"))


def load(path):
    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    for r in rows:
        for k in ("mae_all", "mae_unburied", "bias", "seconds"):
            r[k] = float(r[k]) if r[k] not in ("", "nan") else math.nan
    return rows


def draw(rows, path):
    """rows: bench/foliage.py's errors() rows with a "scene" each (only role "all" drawn)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FormatStrFormatter

    rows = [r for r in rows if r["role"] == "all"]
    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    ncol = min(4, len(scenes))
    nrow = math.ceil(len(scenes) / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.6 * ncol, 3.9 * nrow + 0.8), squeeze=False)
    for ax, scene in zip(axes.ravel(), scenes):
        sr = {r["method"]: r for r in rows if r["scene"] == scene}
        for fam, (c, m) in STYLE.items():
            fr = [r for k, r in sr.items() if k.split()[0] == fam and r["seconds"] > 0]
            if not fr:
                continue
            fr.sort(key=lambda r: r["seconds"])
            ax.plot([r["seconds"] for r in fr], [r["mae_unburied"] for r in fr],
                    ls="-" if fam == "rays" else "none", color=c, marker=m,
                    ms=9 if fam == "regression" else 6, label=fam, lw=1.2)
            if fam == "rays":
                for r in fr:
                    ax.annotate(r["method"].split()[1], (r["seconds"], r["mae_unburied"]),
                                fontsize=6, color=c, xytext=(3, 3), textcoords="offset points")
        if "constant" in sr:
            ax.axhline(sr["constant"]["mae_unburied"], color="0.4", ls="--", lw=0.9,
                       label="constant")
        ax.set_title(scene, fontsize=10)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.grid(True, which="both", alpha=0.25)
        for axis in (ax.xaxis, ax.yaxis):  # plain numbers, not 3×10⁻¹
            axis.set_major_formatter(FormatStrFormatter("%g"))
            axis.set_minor_formatter(FormatStrFormatter("%g"))
        ax.tick_params(which="minor", labelsize=6)
        ax.set_xlabel("wall time of the bake, s (log)")
        ax.set_ylabel("MAE vs rays 256, buried left out")
    chart_real.finish(fig, axes, len(scenes), "Canopy AO on foliage as artists make it: every "
                      "rung's error against time (all vertices, buried left out)", path, ncol=7,
                      dpi=100)
    print(f"chart_foliage: wrote {path}")


def main(argv=None):
    ap = harness.parser(__doc__, prog="chart_foliage.py")
    ap.add_argument("--csv", default=os.path.join(harness.OUT, "foliage.csv"))
    ap.add_argument("--png", default=os.path.join(harness.OUT, "chart_foliage.png"))
    a = ap.parse_args(argv)
    if not os.path.exists(a.csv):
        ap.error(f"{a.csv} missing: run bench/foliage.py with --csv {a.csv} (its docstring)")
    draw(load(a.csv), a.png)
    return 0


if __name__ == "__main__":
    sys.exit(main())
