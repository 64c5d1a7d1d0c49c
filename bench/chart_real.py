"""Error against time on the real-generator scenes, from bench/real_assets.py's CSV.

    /usr/bin/python3 bench/chart_real.py [--csv bench/out/real_assets.csv]
                                         [--png bench/out/chart_real.png] [--md FILE.md]

One panel per scene: MAE (buried vertices left out) against the Embree 1024-ray reference,
against the bake's wall time (log-log): every rung, plain rays at 1-256 as a curve, Cycles at
each cached sample count as a curve, the front of our methods circled (the constant is an oracle
and Cycles is not ours: neither is on the front). Prints, and writes to --md, per scene and
Cycles sample count, our fastest method at Cycles' error or better and its time against
Cycles' (the benchmark's "who wins at equal error").
"""
from __future__ import annotations

import csv
import math
import os
import sys

import harness  # noqa: E402

HERE, OUT = harness.HERE, harness.OUT

import chart  # noqa: E402
from chart import pareto  # noqa: E402

# family -> (colour, marker): chart.py's, plus the two rungs it does not draw.
STYLE = {f: chart.STYLE[f] for f in ("sphere", "ellipsoid", "shells", "medium", "grid")}
STYLE.update(regression=("#9467bd", "*"), hybrid=("#8c564b", "v"), rays=chart.STYLE["raytrace"],
             cycles=chart.STYLE["cycles"])


def family(method):
    return method.split()[0]


def load(path):
    rows = []
    with open(path, newline="") as fh:
        for r in csv.DictReader(fh):
            if r["method"] == "constant" or r["mae_unburied"] == "":
                continue
            r["mae"] = float(r["mae_unburied"])
            r["t"] = float(r["seconds"])
            if r["t"] > 0 and family(r["method"]) in STYLE:
                rows.append(r)
    return rows


def front(rows):
    """Our non-dominated rows of one scene (Cycles is the yardstick, not a method of ours)."""
    ours = [r for r in rows if family(r["method"]) != "cycles"]
    return [ours[i] for i in pareto([(r["t"], r["mae"]) for r in ours])]


def equal_error(rows):
    """[(cycles row, our fastest row at its MAE or better or None)] for one scene."""
    ours = [r for r in rows if family(r["method"]) != "cycles"]
    out = []
    for c in sorted((r for r in rows if family(r["method"]) == "cycles"),
                    key=lambda r: int(r["method"].split()[1])):
        ok = [r for r in ours if r["mae"] <= c["mae"]]
        out.append((c, min(ok, key=lambda r: r["t"]) if ok else None))
    return out


def chart(rows, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    ncol = min(4, len(scenes))
    nrow = math.ceil(len(scenes) / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.6 * ncol, 3.9 * nrow + 0.8), squeeze=False)
    for ax, scene in zip(axes.ravel(), scenes):
        sr = [r for r in rows if r["scene"] == scene]
        for fam, (c, m) in STYLE.items():
            fr = [r for r in sr if family(r["method"]) == fam]
            if fam in ("rays", "cycles"):
                fr.sort(key=lambda r: int(r["method"].split()[1]))
            if not fr:
                continue
            ax.plot([r["t"] for r in fr], [r["mae"] for r in fr],
                    ls="-" if fam in ("rays", "cycles") else "none", color=c, marker=m,
                    ms=9 if fam == "regression" else 6, label=fam, lw=1.2)
            if fam in ("rays", "cycles"):
                for r in fr:
                    ax.annotate(r["method"].split()[1], (r["t"], r["mae"]), fontsize=6,
                                color=c, xytext=(3, 3), textcoords="offset points")
        fr = front(sr)
        ax.step([r["t"] for r in fr], [r["mae"] for r in fr], where="post", color="k",
                ls="--", lw=0.9, alpha=0.7)
        ax.scatter([r["t"] for r in fr], [r["mae"] for r in fr], s=110, facecolors="none",
                   edgecolors="k", lw=1.0, zorder=5, label="front (ours)")
        star = "*" if sr and sr[0]["design"] == "True" else ""
        ax.set_title(f"{scene}{star} ({int(sr[0]['vertices']):,} vertices)", fontsize=10)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.grid(True, which="both", alpha=0.25)
        ax.set_xlabel("wall time, s (log)")
        ax.set_ylabel("MAE vs Embree 1024, buried left out")
    finish(fig, axes, len(scenes), "Canopy AO on Sapling Tree Gen trees: error against time "
           "(* = scenes the rungs were designed on; circled = our front)", path, ncol=10)
    print(f"chart_real: wrote {path}")


def finish(fig, axes, used, title, path, ncol, dpi=110):
    """Blank the panels past the first ``used``, one legend below them all (each label once),
    the title, and write ``path``."""
    import matplotlib.pyplot as plt
    for ax in axes.ravel()[used:]:
        ax.axis("off")
    handles = {}
    for ax in axes.ravel():
        for h, lab in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(lab, h)
    fig.legend(list(handles.values()), list(handles.keys()), loc="lower center",
               ncol=min(ncol, len(handles)), fontsize=8, frameon=False)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout(rect=(0, 0.05, 1, 0.96))
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)


def table(rows):
    out = ["| scene | Cycles samples | Cycles MAE, s | our fastest at that MAE or better | "
           "time ratio (ours / Cycles) |", "|---|---|---|---|---|"]
    for scene in dict.fromkeys(r["scene"] for r in rows):
        for c, best in equal_error([r for r in rows if r["scene"] == scene]):
            win = (f"{best['method']}: {best['mae']:.3f}, {best['t']:.2g} s" if best
                   else "none")
            ratio = f"{best['t'] / c['t']:.2f}×" if best else "–"
            out.append(f"| {scene} | {c['method'].split()[1]} | {c['mae']:.3f}, "
                       f"{c['t']:.2g} s | {win} | {ratio} |")
        fr = front([r for r in rows if r["scene"] == scene])
        out.append(f"| {scene} | front | | {' → '.join(r['method'] for r in fr)} | |")
    return "\n".join(out)


def main(argv=None):
    ap = harness.parser(__doc__, prog="chart_real.py")
    ap.add_argument("--csv", default=os.path.join(OUT, "real_assets.csv"))
    ap.add_argument("--png", default=os.path.join(OUT, "chart_real.png"))
    ap.add_argument("--md", help="also write the equal-error table to this markdown file")
    a = ap.parse_args(argv)
    if not os.path.exists(a.csv):
        ap.error(f"{a.csv} missing: run /usr/bin/python3 bench/real_assets.py --csv {a.csv}")
    rows = load(a.csv)
    if not rows:
        ap.error(f"{a.csv} has no rows")
    text = table(rows)
    print(text)
    if a.md:
        with open(a.md, "w") as fh:
            fh.write(text + "\n")
    chart(rows, a.png)
    return 0


if __name__ == "__main__":
    sys.exit(main())
