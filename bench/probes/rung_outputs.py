"""Probe, answered: turning rungs into objects (core/rungs/) left all 298 arrays and 72 plans bit-identical.

Every rung's output, saved so a refactor can show it changed nothing (bit for bit).

Bakes each method of the ladder per vertex through the core API (canopy_ao.core.prepare /
evaluate_item, no Blender) on the tests' tree scene (trunk, leaves, ground, grass blades) with
τ calibrated and with τ given, on the same scene under instanced trees (forest prototypes with
meshes, so the rays see them), auto over a tiny time budget and ray-free, and once per texel (points on the ground's and the leaves'
triangles, four anti-aliasing sub-samples a texel). Also saves what each plan chose (method,
τ, the calibration's candidates) and the cost model's prediction of every rung.

    /usr/bin/python3.11 bench/probes/rung_outputs.py save /tmp/rungs_before.npz
    /usr/bin/python3.11 bench/probes/rung_outputs.py compare /tmp/rungs_before.npz

compare bakes again and prints each array that differs (its largest difference) and a count;
exit 1 if any differs. --addon DIR bakes with the add-on in DIR (another checkout's addon/, for
a baseline made from it: PYTHONDONTWRITEBYTECODE=1 keeps that checkout unwritten). The
example scenes (examples/canopy_scenes.py, small sizes) are baked with every rung too.
"""
import json
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.join(HERE, "..", "..")
ADDON = (sys.argv[sys.argv.index("--addon") + 1] if "--addon" in sys.argv
         else os.path.join(ROOT, "addon"))
sys.path.insert(0, os.path.abspath(ADDON))
sys.path.insert(0, os.path.join(ROOT, "tests", "python"))
sys.path.insert(0, os.path.join(ROOT, "examples"))

import canopy_scenes as cs  # noqa: E402
import tree_scene as ts  # noqa: E402
from canopy_ao import core  # noqa: E402
from canopy_ao.core import native  # noqa: E402

_core = native._core


def items(with_grass=True):
    out = []
    for name, (p, t) in ts.scene(with_grass).items():
        q = np.asarray(p, np.float32)
        out.append(core.SceneItem(name, ts.ROLE[name], "T" if name in ("Trunk", "Leaves")
                                  else "", q, ts.vertex_normals(q, t), t))
    return out


def prototypes():
    from canopy_ao.core import forest
    crown = [_core.Ellipsoid((0.3, 0.0, 2.4), np.eye(3, dtype=np.float32), (1.0, 0.8, 0.9))]
    trunk = [_core.Ellipsoid((0.0, 0.0, 1.0), np.eye(3, dtype=np.float32), (0.15, 0.15, 1.0))]
    mats = []
    for x, y in ((-4.0, 3.0), (4.5, -3.5)):
        m = np.eye(4)
        m[:3, 3] = (x, y, 0.0)
        mats.append(m)
    p, t = ts.leaves(count=200, center=(0.3, 0.0, 2.4), seed=4)
    tri = (np.ascontiguousarray(p, np.float32), np.ascontiguousarray(t, np.int32))
    return [forest.Prototype("Oak", crown, 1.3, np.stack(mats), trunk, tri)]


def texel_points(item, count, seed):
    """Points on random triangles of item (barycentric), their face normals, triangle ids."""
    rng = np.random.default_rng(seed)
    tri = rng.integers(0, len(item.triangles), count)
    a, b = rng.random(count), rng.random(count)
    flip = a + b > 1
    a[flip], b[flip] = 1 - a[flip], 1 - b[flip]
    v = item.positions[item.triangles[tri]]
    p = v[:, 0] + a[:, None] * (v[:, 1] - v[:, 0]) + b[:, None] * (v[:, 2] - v[:, 0])
    fn = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    fn /= np.maximum(np.linalg.norm(fn, axis=1, keepdims=True), 1e-30)
    return (np.ascontiguousarray(p, np.float32), np.ascontiguousarray(fn, np.float32),
            tri.astype(np.int32))


# Example scenes, small: (scene, its arguments).
EXAMPLES = (("round_tree", dict(leaves=2000)), ("grove", dict(n_trees=3, leaves=1500)),
            ("grass_field", dict(blades=1500)), ("conifer", dict(leaves=3000)))


def example_items(name, kw):
    return [core.SceneItem(p.name, p.role.upper(), p.tree or "", p.vertices,
                           cs.vertex_normals(p.vertices, p.triangles), p.triangles)
            for p in cs.make_scene(name, seed=0, **kw)]


def run_examples(methods, out, meta):
    for scene, kw in EXAMPLES:
        for m in methods:
            its = example_items(scene, kw)
            s = core.BakeSettings(method=m, samples=16, calibration_points=96,
                                  calibration_samples=32, seed=5)
            key = f"example-{scene}/{m}"
            try:
                plan = core.prepare(its, s)
            except core.CanopyAOError as exc:
                meta[key] = {"error": str(exc)}
                continue
            for it in its:
                out[f"{key}/vertex/{it.name}"] = core.evaluate_item(plan, it).ao
            cal = plan.calibration or {}
            meta[key] = {"method": plan.method, "tau": plan.tau, "chosen": cal.get("chosen"),
                         "notes": plan.notes,
                         "buried": {k: int(v) for k, v in plan.buried_count.items()}}


def run():
    out, meta = {}, {}
    methods = list(core.METHODS)
    run_examples(methods, out, meta)
    cases = [("calibrated", dict(tau=None), False),
             ("tau2", dict(tau=2.0), False),
             ("forest", dict(tau=None), True),
             # auto where rays are over the time budget, and ray-free: the ladder's walk
             ("budget", dict(tau=None, time_budget=1e-4), False),
             ("rayfree", dict(tau=None, ray_free=True), False)]
    for case, kw, forest in cases:
        for m in methods if case in ("calibrated", "tau2", "forest") else ["auto"]:
            its = items()
            s = core.BakeSettings(method=m, samples=16, calibration_points=96,
                                  calibration_samples=32, seed=3, distance=0.0 if case !=
                                  "tau2" else 6.0, **kw)
            key = f"{case}/{m}"
            try:
                plan = core.prepare(its, s, prototypes() if forest else None)
            except core.CanopyAOError as exc:
                meta[key] = {"error": str(exc)}
                continue
            for it in its:
                out[f"{key}/vertex/{it.name}"] = core.evaluate_item(plan, it).ao
            if case == "calibrated":  # one texel bake: 4 sub-samples a texel
                for it in its:
                    if it.name not in ("Ground", "Leaves"):
                        continue
                    p, n, tri = texel_points(it, 400, 11)
                    out[f"{key}/texel/{it.name}"] = core.evaluate_receivers(
                        plan, it, p, n, triangles=tri, group=4)
            cal = plan.calibration or {}
            from canopy_ao.core import cost
            predicted = {}
            for r in methods:
                try:
                    predicted[r] = cost.predict(plan, r, 1000)["seconds"]
                except (ValueError, KeyError, AttributeError, TypeError) as exc:
                    predicted[r] = f"{type(exc).__name__}"
            meta[key] = {"method": plan.method, "tau": plan.tau,
                         "tau_by_tree": plan.tau_by_tree, "role_scale": plan.role_scale,
                         "chosen": cal.get("chosen"), "why": cal.get("why"),
                         "candidates": {c: {k: v for k, v in d.items() if k in
                                            ("tau", "rmse", "predicted_seconds", "samples")}
                                        for c, d in cal.get("candidates", {}).items()},
                         "notes": plan.notes, "predicted": predicted,
                         "buried": {k: int(v) for k, v in plan.buried_count.items()}}
    return out, meta


def main():
    args = [a for a in sys.argv[1:] if a != "--addon" and a != ADDON]
    if len(args) != 2 or args[0] not in ("save", "compare"):
        print("usage: rung_outputs.py {save,compare} FILE.npz [--addon DIR]\n" + __doc__)
        return 0 if {"-h", "--help"} & set(args) else 2
    mode, path = [a for a in sys.argv[1:] if a != "--addon" and a != ADDON][:2]
    out, meta = run()
    if mode == "save":
        np.savez(path, __meta__=json.dumps(meta, sort_keys=True, default=str), **out)
        print(f"{len(out)} arrays, {len(meta)} plans from {os.path.dirname(core.__file__)} -> "
              f"{path}")
        return 0
    old = np.load(path)
    bad = 0
    for k in sorted(set(old.files) | set(out)):
        if k == "__meta__":
            continue
        if k not in out or k not in old.files:
            print(f"{k}: only in {'before' if k in old.files else 'after'}")
            bad += 1
        elif old[k].dtype != out[k].dtype or old[k].shape != out[k].shape:
            print(f"{k}: {old[k].dtype}{old[k].shape} -> {out[k].dtype}{out[k].shape}")
            bad += 1
        elif not np.array_equal(old[k], out[k]):
            print(f"{k}: max |diff| {np.max(np.abs(old[k] - out[k])):.3g}")
            bad += 1
    before = json.loads(str(old["__meta__"]))
    after = json.loads(json.dumps(meta, sort_keys=True, default=str))
    for k in sorted(set(before) | set(after)):
        if before.get(k) != after.get(k):
            print(f"{k}: plan differs\n  before {before.get(k)}\n  after  {after.get(k)}")
            bad += 1
    n = len([k for k in old.files if k != "__meta__"])
    print(f"{n} arrays and {len(before)} plans compared: "
          f"{'all bit-identical' if not bad else f'{bad} differ'}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
