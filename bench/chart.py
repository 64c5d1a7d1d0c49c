"""Error against time chart, summary table and picture strips from bench/accuracy.py's output.

    /usr/bin/python3 bench/chart.py [--csv bench/out/results.csv] [--reference embree|cycles]
                                    [--role all] [--quick]

Writes bench/out/chart.png (one panel per scene: MAE against wall time, log-log, one curve per
method family, Cycles' curve on the same axes, the Pareto front marked), bench/out/summary.md
(the key rows as a markdown table) and bench/out/strip_<scene>.png (side views of the scene
coloured by AO: reference, then the best setting of each family).
"""
from __future__ import annotations

import csv
import math
import os
import sys
from collections import defaultdict

import numpy as np

import harness  # noqa: E402  (bench's paths)

HERE, OUT = harness.HERE, harness.OUT

STYLE = {  # family -> (colour, marker)
    "reeves_blau": ("#8c564b", "v"),
    "sphere": ("#1f77b4", "o"),
    "ellipsoid": ("#2ca02c", "s"),
    "shells": ("#17becf", "D"),
    "medium": ("#000000", "h"),
    "medium_sphere": ("#e377c2", "o"),
    "medium_ellipsoid": ("#7f7f7f", "s"),
    "medium_shells": ("#000080", "D"),
    "medium_sphere+ground": ("#e377c2", "h"),
    "grid+ground": ("#bcbd22", "p"),
    "auto": ("#9467bd", "*"),
    "grid": ("#bcbd22", "P"),
    "raytrace": ("#d62728", "^"),
    "cycles": ("#ff7f0e", "X"),
}
ORDER = list(STYLE)


def load(path, reference, role):
    rows = []
    with open(path) as fh:
        for r in csv.DictReader(fh):
            if r["reference"] != reference or r["role"] != role:
                continue
            if r["family"] == "embree_ref" or r["mae"] == "" or r["t_total"] == "":
                continue
            if r["family"] == reference and "reference" in r["note"]:
                continue   # the reference against itself
            for k in ("mae", "rmse", "p95", "corr", "bias", "t_total", "t_prepare", "t_eval"):
                r[k] = float(r[k]) if r[k] != "" else math.nan
            r["tau"] = float(r["tau"]) if r["tau"] else math.nan
            rows.append(r)
    return rows


def load_all(path):
    with open(path) as fh:
        return list(csv.DictReader(fh))


def pareto(points):
    """Indices of the non-dominated points (lower time and lower error are better)."""
    order = sorted(range(len(points)), key=lambda i: (points[i][0], points[i][1]))
    front, best = [], math.inf
    for i in order:
        if points[i][1] < best:
            front.append(i)
            best = points[i][1]
    return front


def setting_key(r):
    s = r["setting"]
    digits = "".join(ch for ch in s if ch.isdigit())
    return int(digits) if digits else 0


def label(r):
    s = r["family"]
    if r["setting"]:
        s += f" {r['setting']}"
    if r["tau_mode"] == "best":
        s += " (best τ)"
    return s


def chart(rows, path, reference, role, metric="mae"):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    if not scenes:
        print("chart: no rows to plot")
        return {}
    ncol = min(4, len(scenes))
    nrow = math.ceil(len(scenes) / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.6 * ncol, 3.9 * nrow), squeeze=False)
    fronts = {}
    for ax, scene in zip(axes.ravel(), scenes):
        sr = [r for r in rows if r["scene"] == scene and np.isfinite(r[metric])
              and r["t_total"] > 0]
        for fam in ORDER:
            for mode in ("calibrated", "", "best"):
                fr = sorted([r for r in sr if r["family"] == fam and r["tau_mode"] == mode],
                            key=setting_key)
                if not fr:
                    continue
                c, m = STYLE[fam]
                t = [r["t_total"] for r in fr]
                e = [r[metric] for r in fr]
                filled = mode != "best"
                lbl = fam + (" (best τ)" if mode == "best" else "")
                ax.plot(t, e, "-" if len(fr) > 1 else "", color=c, marker=m, ms=6 if fam != "auto" else 10,
                        mfc=c if filled else "none", alpha=0.9 if filled else 0.6, label=lbl, lw=1.2)
        # The front is over what a user can run: best-τ rows need the reference itself.
        cand = [r for r in sr if r["tau_mode"] != "best"]
        pts = [(r["t_total"], r[metric]) for r in cand]
        front = [cand[i] for i in pareto(pts)] if pts else []
        fronts[scene] = front
        if front:
            ft = [r["t_total"] for r in front]
            fe = [r[metric] for r in front]
            ax.step(ft, fe, where="post", color="k", ls="--", lw=0.9, alpha=0.7)
            ax.scatter(ft, fe, s=110, facecolors="none", edgecolors="k", lw=1.0, zorder=5,
                       label="Pareto front")
        nv = sr[0]["vertices"] if sr else "?"
        ax.set_title(f"{scene} ({int(nv):,} vertices)", fontsize=10)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.grid(True, which="both", alpha=0.25)
        ax.set_xlabel("wall time, s (log)")
        ax.set_ylabel(f"{metric.upper()} vs {reference} ({role})")
    for ax in axes.ravel()[len(scenes):]:
        ax.axis("off")
    handles, labels = {}, {}
    for ax in axes.ravel():
        for h, l in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(l, h)
    cols = max(2, min(6, int(fig.get_figwidth() / 3.0)))
    rows_leg = math.ceil(len(handles) / cols)
    fig.legend(list(handles.values()), list(handles.keys()), loc="lower center",
               ncol=cols, fontsize=8, frameon=False)
    fig.suptitle(f"Canopy AO: error against time — reference: {reference}, receivers: {role}\n"
                 "filled = product path (τ calibrated), open = best τ, circled = Pareto front",
                 fontsize=10)
    fig.set_figheight(fig.get_figheight() + 0.22 * rows_leg)
    fig.tight_layout(rect=(0, 0.22 * rows_leg / fig.get_figheight() + 0.02, 1, 0.95))
    fig.savefig(path, dpi=110)
    plt.close(fig)
    print(f"chart: wrote {path}")
    return fronts


def summary(rows, all_rows, fronts, reference, role, path):
    lines = [f"# Canopy AO — speed against accuracy", "",
             f"Reference: **{reference}**; receivers: **{role}** (every vertex of the scene). "
             "Times are wall-clock seconds on a shared 2-core machine (whole scene: fits + "
             "calibration + evaluation; ray tracing includes the BVH build; Cycles is the whole "
             "bake call). `best τ` = the τ that minimises the error against the reference "
             "(an upper bound on calibration; not eligible for the front). ★ = on the Pareto front.", ""]
    # reference agreement
    agree = [r for r in all_rows if r["family"] == "cycles" and r["role"] == role
             and r["reference"] == "embree"]
    if agree:
        lines += ["## Cycles against the Embree reference (1024 rays): agreement and convergence",
                  "", "Cycles' bake at each sample count scored against Embree. If the two "
                  "renderers compute the same AO, the MAE is noise only: it halves per 4× samples "
                  "and stays under the noise-only bound (unstratified, so loose).", "",
                  "| scene | Cycles samples | MAE | noise-only bound | RMSE | corr | bias |",
                  "|---|---|---|---|---|---|---|"]
        for r in agree:
            bound = r["note"].split("<=")[-1].strip() if "<=" in r["note"] else ""
            lines.append(f"| {r['scene']} | {r['setting'].split()[0]} | {float(r['mae']):.4f} | "
                         f"{bound} | {float(r['rmse']):.4f} | {float(r['corr']):.3f} | "
                         f"{float(r['bias']):+.4f} |")
        lines.append("")
    lines += ["## Key rows per scene", "",
              "| scene | method | τ | time (s) | MAE | RMSE | p95 | corr | bias |",
              "|---|---|---|---|---|---|---|---|---|"]
    for scene in dict.fromkeys(r["scene"] for r in rows):
        sr = [r for r in rows if r["scene"] == scene]
        keep = []
        for fam in ORDER:
            for mode in ("calibrated", "", "best"):
                fr = [r for r in sr if r["family"] == fam and r["tau_mode"] == mode]
                if not fr:
                    continue
                if fam in ("raytrace", "cycles"):
                    keep += sorted(fr, key=setting_key)
                else:
                    keep.append(min(fr, key=lambda r: r["mae"]))
        front_ids = {id(r) for r in fronts.get(scene, [])}
        for r in keep:
            star = " ★" if id(r) in front_ids else ""
            tau = "" if math.isnan(r["tau"]) else f"{r['tau']:.3g}"
            lines.append(f"| {scene} | {label(r)}{star} | {tau} | {r['t_total']:.3g} | "
                         f"{r['mae']:.4f} | {r['rmse']:.4f} | {r['p95']:.4f} | {r['corr']:.3f} | "
                         f"{r['bias']:+.4f} |")
    # per-role view of the calibrated product rows
    roles = [r for r in all_rows if r["reference"] == reference and r["role"] not in ("all", "")
             and r["tau_mode"] == "calibrated"]
    if roles:
        lines += ["", "## Per role (product path, τ calibrated): MAE / bias", "",
                  "| scene | method | canopy | trunk | ground | grass |", "|---|---|---|---|---|---|"]
        by = defaultdict(dict)
        for r in roles:
            by[(r["scene"], label(r))][r["role"]] = f"{float(r['mae']):.3f} / {float(r['bias']):+.3f}"
        for (scene, lab), d in by.items():
            lines.append(f"| {scene} | {lab} | " + " | ".join(d.get(k, "") for k in
                                                             ("canopy", "trunk", "ground", "grass")) + " |")
    failures = [r for r in all_rows if r["reference"] == "" and r["note"]]
    if failures:
        lines += ["", "## Methods that did not run", ""]
        for r in failures:
            lines.append(f"- {r['scene']} / {r['family']} {r['setting']} {r['tau_mode']}: {r['note']}")
    notes = sorted({r["note"] for r in all_rows if "stand-in" in r["note"]})
    if notes:
        lines += ["", "Notes: " + " / ".join(notes)]
    with open(path, "w") as fh:
        fh.write("\n".join(lines) + "\n")
    print(f"chart: wrote {path}")


def strips(ao_dir, out_dir, quick, tag="", max_points=25000):
    """One PNG per scene: side views coloured by AO (reference, then each family's best)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    paths = []
    for f in sorted(os.listdir(ao_dir)) if os.path.isdir(ao_dir) else []:
        if not f.endswith(".npz") or f.endswith("_quick.npz") != quick:
            continue
        scene = f[:-4].replace("_quick", "")
        z = np.load(os.path.join(ao_dir, f))
        V = z["V"].astype(np.float32)
        keys = [k for k in z.files if k.startswith("ref_")]
        ref = z[keys[0]].astype(np.float32) if keys else None
        wanted = ["ref_embree", "ref_cycles", "cycles|16 samples", "raytrace|16 rays",
                  "reeves_blau|calibrated", "sphere|calibrated", "ellipsoid|calibrated",
                  "shells|k=4|calibrated", "medium_sphere|calibrated",
                  "medium_shells|k=4|calibrated", "grid|r=64", "grid+ground|r=64", "medium_sphere+ground|calibrated",
                  "auto|calibrated"]
        shown = [k for k in wanted if k in z.files]
        shown += [k for k in z.files if k.startswith("auto|") and k not in shown][:1]
        if not shown:
            continue
        rng = np.random.default_rng(0)
        idx = rng.choice(len(V), size=min(max_points, len(V)), replace=False)
        # a three-quarter view from above so the ground (and the canopy's shadow on it) shows
        phi, theta = np.radians(30.0), np.radians(25.0)
        sx = V[:, 0] * np.cos(phi) - V[:, 1] * np.sin(phi)
        depth = V[:, 0] * np.sin(phi) + V[:, 1] * np.cos(phi)
        sy = V[:, 2] * np.cos(theta) + depth * np.sin(theta)
        idx = idx[np.argsort(depth[idx] * np.cos(theta) - V[idx, 2] * np.sin(theta))[::-1]]
        nc = min(5, len(shown))
        nr = math.ceil(len(shown) / nc)
        fig, axes = plt.subplots(nr, nc, figsize=(3.4 * nc, 2.9 * nr + 0.4), squeeze=False)
        for ax in axes.ravel()[len(shown):]:
            ax.axis("off")
        for ax, k in zip(axes.ravel(), shown):
            a = z[k].astype(np.float32)
            ax.scatter(sx[idx], sy[idx], c=a[idx], s=0.8, cmap="gray", vmin=0, vmax=1,
                       linewidths=0)
            t = k.replace("|", " ").replace("ref_", "reference ")
            if ref is not None and not k.startswith("ref_"):
                t += f"\nMAE {np.nanmean(np.abs(a - ref)):.3f}"
            ax.set_title(t, fontsize=8)
            ax.set_aspect("equal")
            ax.set_xticks([]); ax.set_yticks([])
            ax.set_facecolor("#6a8fb5")
        fig.suptitle(f"{scene}: AO per vertex (three-quarter view from above; black = 0, white = 1 open sky)", fontsize=9)
        fig.tight_layout()
        p = os.path.join(out_dir, f"strip_{scene}{tag}.png")
        fig.savefig(p, dpi=65)
        plt.close(fig)
        paths.append(p)
    if paths:
        print(f"chart: wrote {len(paths)} picture strips in {out_dir}")
    return paths


def main(argv=None):
    ap = harness.parser(__doc__)
    ap.add_argument("--csv", default=os.path.join(OUT, "results.csv"))
    ap.add_argument("--reference", default="embree", choices=("embree", "cycles"))
    ap.add_argument("--role", default="all")
    ap.add_argument("--metric", default="mae", choices=("mae", "rmse", "p95"))
    ap.add_argument("--quick", action="store_true", help="picture strips from the --quick run")
    ap.add_argument("--out", default=OUT)
    ap.add_argument("--tag", default="", help="suffix for the output names, e.g. _full")
    a = ap.parse_args(argv)
    rows = load(a.csv, a.reference, a.role)
    all_rows = load_all(a.csv)
    suffix = ("" if a.reference == "embree" else f"_{a.reference}") + a.tag
    fronts = chart(rows, os.path.join(a.out, f"chart{suffix}.png"), a.reference, a.role, a.metric)
    summary(rows, all_rows, fronts, a.reference, a.role, os.path.join(a.out, f"summary{suffix}.md"))
    strips(os.path.join(a.out, "ao"), a.out, a.quick, a.tag)
    return 0


if __name__ == "__main__":
    sys.exit(main())
