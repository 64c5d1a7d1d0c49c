"""Auto's frontier, predicted against measured (docs/DESIGN.md, 'Auto mode').

    nice /usr/bin/python3.11 bench/auto_frontier.py [--budgets 0 0.5 0.25 0.125] [--repeat 2]

On synthetic scenes (examples/canopy_scenes.py) and time budgets given as fractions of rays at
64 samples' predicted time (0: none), prints auto's choice, then every candidate auto weighed
that a bake reproduces on its own (the exact rung at each count, the ray-free rung) with its
predicted error and time beside the measured ones: RMSE over every vertex against a 256-ray
bake (another seed; a buried vertex is 0 in both, where the bake's buried test zeroes it as the
calibration leaves it out), and the evaluation's wall seconds (the bake's less its prepare,
best of --repeat). The prediction is the sample RMSE against the 128-ray calibration
reference; "pred@256" takes that reference's noise out and the 256-ray one's in (the ray-error
model: v·R^-2α each), so it and "meas" measure the same thing. "front": on the Pareto front of
predicted time and error; "*": auto's choice. Timings are noisy on a shared machine: read the
meas/pred ratios within one run.
"""
import argparse
import math
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path[:0] = [os.path.join(REPO, "addon"), os.path.join(REPO, "examples")]

import canopy_scenes as cs  # noqa: E402
import numpy as np  # noqa: E402

from canopy_ao import core  # noqa: E402

SCENES = {
    "round_tree_800": lambda: cs.round_tree(leaves=800),
    "conifer_1000_no_ground": lambda: cs.conifer(leaves=1000, ground=False),
    "round_tree_3000": lambda: cs.round_tree(leaves=3000),
    "weeping_tree_4000": lambda: cs.weeping_tree(leaves=4000),
}


def items(scene):
    return [core.SceneItem(p.name, p.role.upper(), p.tree or "", p.vertices,
                           cs.vertex_normals(p.vertices, p.triangles), p.triangles)
            for p in scene]


def bake(its, repeat, **kw):
    """(AO of every vertex, evaluation wall seconds best of ``repeat``, report)."""
    best = math.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        res, rep = core.bake(its, core.BakeSettings(**kw))
        best = min(best, time.perf_counter() - t0 - rep["timings"]["prepare"])
    return np.concatenate([r.ao for r in res]), best, rep


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", nargs="+", default=list(SCENES), choices=list(SCENES))
    ap.add_argument("--budgets", nargs="+", type=float, default=[0.0, 0.5, 0.25, 0.125],
                    help="time budgets as fractions of rays at 64 samples' predicted time")
    ap.add_argument("--repeat", type=int, default=2)
    args = ap.parse_args()
    for name in args.scenes:
        its = items(SCENES[name]())
        ref, _t, _r = bake(its, 1, method="raytrace", samples=256, seed=9)
        # Every vertex: a rule such as "reference AO > 0.02" would leave out the vertices in
        # contact that calibration keeps (only the buried test's are out of its sample), where
        # the ray-free rung errs most.
        # Rays at 64's predicted time, from auto without a budget.
        free = core.prepare(its, core.BakeSettings(method="auto", tau=None, time_budget=0.0))
        t64 = next(c["predicted_seconds"] for c in free.calibration["frontier"]
                   if c["method"] == "raytrace" and c["samples"] == 64)
        print(f"== {name}: {len(ref)} vertices; rays at 64 predicted {t64:.3g} s")
        measured = {}  # (method, samples) -> (rmse, seconds): the same whatever the budget
        for frac in args.budgets:
            budget = frac * t64
            got, secs, rep = bake(its, 1, method="auto", tau=None, time_budget=budget)
            cal = rep["calibration"]
            model = cal["ray_error"]
            chosen = (rep["method"], rep["samples"] if rep["method"] == "raytrace" else None)
            rmse = math.sqrt(float(np.mean((got - ref) ** 2)))
            print(f"-- budget {budget:.3g} s ({frac:g} × rays at 64): auto → "
                  f"{chosen[0]}{'' if chosen[1] is None else f' at {chosen[1]} rays'}, "
                  f"measured RMSE {rmse:.4f}, α {model['alpha']:.2f}" if model else "")
            print(f"   {'candidate':16s} {'pred':>7s} {'pred@256':>8s} {'meas':>7s} "
                  f"{'pred s':>8s} {'meas s':>8s} {'ratio':>6s}  front")
            for c in sorted(cal["frontier"], key=lambda c: c["predicted_seconds"]):
                key = (c["method"], c["samples"])
                if c["method"] not in ("raytrace", "regression"):
                    continue
                if key not in measured:
                    kw = (dict(method="raytrace", samples=c["samples"])
                          if c["samples"] else dict(method="regression", tau=None))
                    ao, t, _rep = bake(its, args.repeat, **kw)
                    measured[key] = (math.sqrt(float(np.mean((ao - ref) ** 2))), t)
                m_rmse, m_t = measured[key]
                noise = model["v"] * (256.0 ** (-2 * model["alpha"])
                                      - model["reference_samples"] ** (-2 * model["alpha"]))
                p256 = math.sqrt(max(c["rmse"] ** 2 + noise, 0.0))
                label = c["method"] + (f" {c['samples']}" if c["samples"] else "")
                star = "*" if key == chosen else " "
                print(f" {star} {label:16s} {c['rmse']:7.4f} {p256:8.4f} {m_rmse:7.4f} "
                      f"{c['predicted_seconds']:8.4f} {m_t:8.4f} "
                      f"{m_t / c['predicted_seconds']:6.2f}  {'yes' if c['on_front'] else ''}")


if __name__ == "__main__":
    main()
