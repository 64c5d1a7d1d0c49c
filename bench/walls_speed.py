"""The GROUND patches' evaluation (core/walls.py): native patch_visibility against the numpy
reference, and what the patches add to an analytic rung's evaluation.

    /usr/bin/python3.11 bench/walls_speed.py [--leaves 20000] [--repeats 3]

On examples/canopy_scenes.py's round tree with a wall beside it (a 4 × 3 vertical quad grid 6
units off the trunk), every vertex a receiver at the AO distance 10 (Cycles' default) and
unlimited:
- per receiver and patch: numpy, native on one thread, native on all threads (µs, ratios);
- the round tree alone (no wall): the sphere rung's whole evaluation of every item without
  patches (a live frame's) and with the ground's patch (a bake's), native and numpy (ratios
  to none).
Contenders are timed in turn (harness.interleave); quote the ratios, the machine is shared.
"""
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

import canopy_scenes as cs  # noqa: E402
from canopy_ao import core  # noqa: E402
from canopy_ao.core import native, walls  # noqa: E402


def _items(scene):
    return [core.SceneItem(p.name, p.role.upper(), p.tree or "", p.vertices,
                           cs.vertex_normals(p.vertices, p.triangles), p.triangles)
            for p in scene]


def _wall():
    u, v = np.meshgrid(np.linspace(-2, 2, 9), np.linspace(0, 3, 7))
    p = np.column_stack([u.ravel(), np.full(u.size, 6.0), v.ravel()]).astype(np.float32)
    i = np.arange(u.size).reshape(u.shape)
    a, b, c, d = i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, 1:].ravel(), i[1:, :-1].ravel()
    t = np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])]).astype(np.int32)
    return core.SceneItem("Wall", "GROUND", "", p, cs.vertex_normals(p, t), t)


def main():
    ap = harness.parser(__doc__, repeats=3)
    ap.add_argument("--leaves", type=int, default=20000)
    args = ap.parse_args()
    items = _items(cs.round_tree(leaves=args.leaves))
    p = np.concatenate([it.positions for it in items]).astype(np.float64)
    n = np.concatenate([it.normals for it in items]).astype(np.float64)
    patches = walls.build(items + [_wall()])
    print(f"round tree + wall: {len(p)} receivers, {len(patches)} patches; {harness.load_note()}")
    for distance in (10.0, np.inf):
        def native_on(threads):
            def run():
                before = native._core.set_max_threads(threads)
                try:
                    return walls.visibility(patches, p, n, distance)
                finally:
                    native._core.set_max_threads(before)
            return run
        t = harness.interleave({
            "numpy": lambda: walls.visibility_numpy(patches, p, n, distance),
            "native 1 thread": native_on(1), "native all threads": native_on(0)},
            repeats=args.repeats, warmup=True)
        assert np.abs(t["numpy"].result - t["native 1 thread"].result).max() < 1e-6
        base = min(t["numpy"].seconds)
        for name, timing in t.items():
            us = 1e6 * min(timing.seconds) / (len(p) * len(patches))
            print(f"  distance {distance}: {name:20s} {us:7.3f} µs per receiver and patch, "
                  f"numpy / this {harness.ratio(base, min(timing.seconds)):6.1f}")

    plan = core.prepare(items, core.BakeSettings(method="sphere", tau=1.5, distance=10.0))
    # the ground's own patch, as a bake makes it (a live frame makes none for a ground alone)
    ground = [pt for pt in walls.build(items) if abs(pt.normal[2]) > 0.9]
    print(f"round tree alone, sphere rung at distance 10: the ground's patches {len(ground)}")

    def evaluate(patch_list, fn):
        def run():
            plan.walls, saved = patch_list, walls.visibility
            walls.visibility = fn
            try:
                return [core.evaluate_item(plan, it).ao for it in items]
            finally:
                walls.visibility = saved
        return run
    t = harness.interleave({"no patches": evaluate([], walls.visibility),
                            "ground patch, native": evaluate(ground, walls.visibility),
                            "ground patch, numpy": evaluate(ground, walls.visibility_numpy)},
                           repeats=args.repeats, warmup=True)
    base = min(t["no patches"].seconds)
    for name, timing in t.items():
        print(f"  {name:22s} {min(timing.seconds):7.3f} s, / no patches "
              f"{harness.ratio(min(timing.seconds), base):5.2f}")


if __name__ == "__main__":
    main()
