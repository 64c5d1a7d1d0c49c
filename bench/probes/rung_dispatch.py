"""Probe, answered: asking the rung costs about 0.4 µs per scene-plan call, negligible at a bake's chunk sizes.

What asking the rung costs per evaluate call: lighting.evaluate_points on 8 points, 2000
calls, best of 5 by process CPU time, for a scene-plan rung (sphere) and the density grid,
with this checkout's add-on and another's (the baseline), each in its own process; prints
microseconds per call and the ratio (this / baseline).

    PYTHONDONTWRITEBYTECODE=1 nice /usr/bin/python3.11 bench/probes/rung_dispatch.py \\
        --base /work/main/addon
"""
import argparse
import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.abspath(os.path.join(HERE, "..", ".."))
METHODS = ("sphere", "grid")


def measure(addon):
    sys.path.insert(0, os.path.abspath(addon))
    sys.path.insert(0, os.path.join(ROOT, "examples"))
    import canopy_scenes as cs
    from canopy_ao import core
    from canopy_ao.core import lighting
    its = [core.SceneItem(p.name, p.role.upper(), p.tree or "", p.vertices,
                          cs.vertex_normals(p.vertices, p.triangles), p.triangles)
           for p in cs.make_scene("round_tree", seed=0, leaves=2000)]
    out = []
    for m in METHODS:
        plan = core.prepare(its, core.BakeSettings(method=m, tau=1.5, seed=5))
        it = its[0]
        p, n = it.positions[:8].copy(), it.normals[:8].copy()
        best = float("inf")
        for _ in range(5):
            t0 = time.process_time()
            for _ in range(2000):
                lighting.evaluate_points(plan, it.role, it.tree, it.name, p, n, m, 1.5)
            best = min(best, time.process_time() - t0)
        out.append(best / 2000 * 1e6)
    print(" ".join(f"{x:.3f}" for x in out))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", required=True, help="the baseline checkout's addon/ folder")
    ap.add_argument("--measure", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.measure:
        return measure(args.measure)
    got = {}
    for name, addon in (("base", args.base), ("this", os.path.join(ROOT, "addon"))):
        run = subprocess.run([sys.executable, __file__, "--base", args.base, "--measure", addon],
                             capture_output=True, text=True, check=True)
        got[name] = [float(x) for x in run.stdout.split()]
    for k, m in enumerate(METHODS):
        b, t = got["base"][k], got["this"][k]
        print(f"{m}: {b:.2f} us/call base, {t:.2f} this, ratio {t / b:.3f}")


if __name__ == "__main__":
    sys.exit(main())
