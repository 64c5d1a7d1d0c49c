"""Calibration and evaluation with the native scene plan against the Python composition it
replaced, on a multi-tree scene, in one run (bench/README.md, "The scene plan").

    /usr/bin/python3 bench/scene_plan_speed.py [--trees 5] [--leaves 12000] [--repeat 3]
                                               [--forest 0]

The scene is examples/canopy_scenes.grove (mixed trees on a ground, trunks). One plan is
prepared (fits, ray tracer); --forest K then attaches K instances of the first tree (its
shells and trunk, rotated and moved over the ground; core/forest.py), which occlude every
receiver. Then, both ways, best of --repeat:

- calibrate: core/ladder.calibrate over the analytic rungs (sphere, ellipsoid, shells,
  medium), τ searched per rung and per tree (golden section: many evaluations of the same
  few hundred sample points); the reference rays are traced inside it, the same cost both ways;
- evaluate: every item's vertices with the chosen rung and τ.

"python" runs lighting's analytic branch as tests/python/lighting_reference.py (the old
composition: containment, gather/scatter per tree, an OccluderField built per call, then the
grass layers' numpy disc count and the forest's per-prototype fields, built once, as
multipliers), "native" the one _core.ScenePlan.evaluate call per item, forest included. The
results of both are compared too.
"""

import os
import sys
import time

import numpy as np

import harness  # noqa: E402  (addon/ and examples/ on sys.path)

HERE, ROOT = harness.HERE, harness.REPO
sys.path.insert(0, os.path.join(ROOT, "tests", "python"))  # lighting_reference, the Python path

import canopy_scenes  # noqa: E402
import lighting_reference  # noqa: E402
from canopy_ao import core  # noqa: E402
from canopy_ao.core import forest, ladder, lighting  # noqa: E402

RUNGS = ["sphere", "ellipsoid", "shells", "medium"]


def grove_items(trees, leaves):
    scene = canopy_scenes.grove(n_trees=trees, leaves=leaves)
    return [core.SceneItem(p.name, p.role.upper(), p.tree or "", p.vertices,
                           canopy_scenes.vertex_normals(p.vertices, p.triangles), p.triangles)
            for p in scene]


def instances(plan, count, size=30.0, seed=1):
    """forest.Prototype of the plan's first tree at ``count`` places over the ground (each
    turned about its own vertical axis), or [] for count 0."""
    if count <= 0:
        return []
    tree = next(iter(plan.fits))
    cx, cy = np.asarray(plan.fits[tree][1].center, np.float64)[:2]
    rng = np.random.default_rng(seed)
    mats = []
    for x, y, a in zip(rng.uniform(-size / 2, size / 2, count),
                       rng.uniform(-size / 2, size / 2, count), rng.uniform(0, 2 * np.pi, count)):
        m = np.eye(4)
        c, s = np.cos(a), np.sin(a)
        m[:2, :2] = [[c, -s], [s, c]]
        m[:2, 3] = np.array([x, y]) - m[:2, :2] @ (cx, cy)  # turn about the tree, move to x, y
        mats.append(m)
    return [forest.prototype_from_plan(plan, tree, np.stack(mats))]


def python_composition():
    """lighting._evaluate_scene_points with its analytic branch as the old Python code."""
    native = lighting._evaluate_scene_points

    def old(plan, role, tree, grass_key, p, n, rung, tau, own=None, group=1):
        method = rung.name
        if not rung.scene_plan:
            return native(plan, role, tree, grass_key, p, n, rung, tau, own, group)
        if not isinstance(tree, tuple):
            return lighting_reference.evaluate(plan, role, tree, grass_key, p, n, method, tau)
        # A tree per point (calibration's batches): one call per tree, as the old code made
        # one per item.
        names, labels = tree
        out = np.ones(len(p), np.float32)
        for k, name in enumerate(names):
            sel = np.flatnonzero(labels == k)
            out[sel] = lighting_reference.evaluate(
                plan, role, name, grass_key, np.ascontiguousarray(p[sel]),
                np.ascontiguousarray(n[sel]), method, tau)
        return out
    return native, old


def run(plan, items, repeat):
    """(calibrate seconds, of which tracing, evaluate seconds, the AO arrays), best of repeat."""
    best_cal = best_eval = best_trace = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        method, tau, info = ladder.calibrate(plan, items, RUNGS)
        best_cal = min(best_cal, time.perf_counter() - t0)
        best_trace = min(best_trace, info["trace_seconds"])
        t0 = time.perf_counter()
        aos = [lighting.evaluate_points(plan, it.role, it.tree, it.name, it.positions,
                                        it.normals, method, tau) for it in items]
        best_eval = min(best_eval, time.perf_counter() - t0)
    return best_cal, best_trace, best_eval, (method, tau, aos)


def main():
    ap = harness.parser(__doc__)
    ap.add_argument("--trees", type=int, default=5)
    ap.add_argument("--leaves", type=int, default=12000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--forest", type=int, default=0,
                    help="instances of the first tree attached as a forest (0: none)")
    a = ap.parse_args()
    items = grove_items(a.trees, a.leaves)
    settings = core.BakeSettings(method="shells", tau=None, distance=0.0)
    plan = core.prepare(items, settings)  # fits, tracer, one calibration (warms the caches)
    protos = instances(plan, a.forest)
    if protos:
        core.attach_forest(plan, protos)
    split = core.scene.split_trees(items)
    receivers = sum(len(it.positions) for it in split if it.role in core.RECEIVER_ROLES)
    inst = (f", a forest of {plan.forest.instances} instances ({plan.forest.shell_count} "
            f"shells, {plan.forest.solid_count} trunks)" if protos else "")
    print(f"grove: {len(plan.fits)} crowns, {sum(map(len, plan.trunks.values()))} trunks"
          f"{inst}, {receivers} receivers; calibration of {', '.join(RUNGS)} on "
          f"{settings.calibration_points} points; best of {a.repeat}; "
          f"load {os.getloadavg()[0]:.1f}")
    native, old = python_composition()
    figures = {}
    for name, fn in (("python", old), ("native", native)):
        lighting._evaluate_scene_points = fn
        try:
            figures[name] = run(plan, split, a.repeat)
        finally:
            lighting._evaluate_scene_points = native
    print(f"{'':8} {'calibrate s':>12} {'(tracing s)':>12} {'evaluate s':>11}")
    for name, (cal, trace, ev, _res) in figures.items():
        print(f"{name:8} {cal:12.3f} {trace:12.3f} {ev:11.3f}")
    (pc, pt, pe, (pm, ptau, pao)), (nc, nt, ne, (nm, ntau, nao)) = figures.values()
    print(f"native / python: calibrate {nc / pc:.2f}x, calibrate without tracing "
          f"{(nc - nt) / max(pc - pt, 1e-9):.2f}x, evaluate {ne / pe:.2f}x")
    # Calibration may settle on τ a hair apart (round-off flips a comparison in the search):
    # compare both compositions at the native run's rung and τ.
    lighting._evaluate_scene_points = old
    try:
        pao = [lighting.evaluate_points(plan, it.role, it.tree, it.name, it.positions,
                                        it.normals, nm, ntau) for it in split]
    finally:
        lighting._evaluate_scene_points = native
    diff = max(float(np.max(np.abs(x - y))) if len(x) else 0.0 for x, y in zip(pao, nao))
    print(f"chosen: python {pm}, native {nm}; largest difference of the scene-wide τ "
          f"{abs(ladder._scene_tau(ptau) - ladder._scene_tau(ntau)):.1e}; largest AO "
          f"difference at the same rung and τ {diff:.2e}")


if __name__ == "__main__":
    main()
