"""What a forest ground's rays pay for in Embree (issue #39 item 5), without Blender.

    /usr/bin/python3.11 bench/forest_rays.py [--trees 200] [--side 50] [--ground 100]
                                             [--samples 376]

(the module built as in scripts/build.sh). examples/canopy_scenes.py's round tree and conifer
(8000 leaves each, no ground) placed as examples/forest_scene.py does it in spirit (random place,
heading, scale 0.8-1.2, fixed seed, half each) over a --ground by --ground vertex grid, every
vertex casting --samples rays upward-facing (376: the 200-tree ground's 64 samples times its
5.88 corners a vertex). The same rays are traced against the instances' full prototypes, their
wood alone, their leaves alone, one triangle spanning each prototype's box (what visiting the
instances costs before any leaf) and the full prototypes with every triangle longer than 0.5
split by halving its longest edge (the branch tubes' long slivers: same surface), and the full
prototypes cut into 2 x 2 x 2 parts of their box, each part its own instance (tighter instance
boxes, eight times as many). Prints the
CPU seconds of each ray call (every thread) and its mean AO; the load average first.
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import time

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(REPO, "examples"))
sys.path.insert(0, os.path.join(REPO, "addon"))

import canopy_scenes as cs  # noqa: E402
from canopy_ao import _core  # noqa: E402


def merge(parts):
    vs, ts, off = [], [], 0
    for p in parts:
        vs.append(p.vertices)
        ts.append(p.triangles + off)
        off += len(p.vertices)
    return (np.ascontiguousarray(np.concatenate(vs), np.float32),
            np.ascontiguousarray(np.concatenate(ts), np.int32))


def spanning_triangle(parts):
    v, _t = merge(parts)
    lo, hi = v.min(0), v.max(0)
    return np.float32([lo, hi, [lo[0], hi[1], lo[2]]]), np.int32([[0, 1, 2]])


def split_long(mesh, longest):
    """Every triangle with an edge over `longest` halved on its longest edge, until none is."""
    v, t = mesh
    tri, done = v[t].astype(np.float64), []
    while len(tri):
        e = np.linalg.norm(tri - np.roll(tri, -1, axis=1), axis=2)  # edge k: corner k to k + 1
        big = e.max(1) > longest
        done.append(tri[~big])
        tri, e = tri[big], e[big]
        r, k = np.arange(len(tri)), e.argmax(1)
        a, b, c = tri[r, k], tri[r, (k + 1) % 3], tri[r, (k + 2) % 3]
        m = 0.5 * (a + b)
        tri = np.concatenate([np.stack([a, m, c], 1), np.stack([m, b, c], 1)])
    tri = np.concatenate(done)
    return (np.ascontiguousarray(tri.reshape(-1, 3), np.float32),
            np.arange(3 * len(tri), dtype=np.int32).reshape(-1, 3))


def octants(mesh):
    """The mesh's triangles grouped by the 2 x 2 x 2 cell of its box their centroid lies in."""
    v, t = mesh
    lo, hi = v.min(0), v.max(0)
    cell = np.minimum(((v[t].mean(1) - lo) / (hi - lo + 1e-9) * 2).astype(int), 1)
    key = cell[:, 0] + 2 * cell[:, 1] + 4 * cell[:, 2]
    return [(v, np.ascontiguousarray(t[key == q])) for q in np.unique(key)]


def placements(trees, side):
    """The trees' (prototype index int32 (T,), matrices float32 (T, 4, 4)): random place,
    heading and scale 0.8-1.2 (seed 0), the two prototypes alternating."""
    rng = np.random.default_rng(0)
    mats = []
    for _ in range(trees):
        a, s = rng.uniform(0, 2 * math.pi), rng.uniform(0.8, 1.2)
        x, y = rng.uniform(-side / 2, side / 2, 2)
        mats.append([[s * math.cos(a), -s * math.sin(a), 0, x],
                     [s * math.sin(a), s * math.cos(a), 0, y], [0, 0, s, 0], [0, 0, 0, 1]])
    return (np.arange(trees) % 2).astype(np.int32), np.array(mats, np.float32)


def grid_ground(k, side):
    """A k × k vertex grid on side × side at z = 0: (vertices float32, triangles int32)."""
    x = np.linspace(-side / 2, side / 2, k, dtype=np.float32)
    gx, gy = np.meshgrid(x, x)
    gv = np.ascontiguousarray(np.c_[gx.ravel(), gy.ravel(), np.zeros(k * k)], np.float32)
    i = np.arange((k - 1) * (k - 1))
    a = (i // (k - 1)) * k + i % (k - 1)
    gt = np.ascontiguousarray(np.concatenate([np.stack([a, a + 1, a + k + 1], 1),
                                              np.stack([a, a + k + 1, a + k], 1)]), np.int32)
    return gv, gt


def prototypes():
    """The two prototypes' parts: the round tree and the conifer, 8000 leaves each."""
    return [cs.round_tree(seed=1, leaves=8000, ground=False),
            cs.conifer(seed=2, leaves=8000, ground=False)]


def main():
    ap = argparse.ArgumentParser(prog="forest_rays.py")
    ap.add_argument("--trees", type=int, default=200)
    ap.add_argument("--side", type=float, default=50.0)
    ap.add_argument("--ground", type=int, default=100)
    ap.add_argument("--samples", type=int, default=376)
    args = ap.parse_args()
    kinds = prototypes()
    which, mats = placements(args.trees, args.side)
    gv, gt = grid_ground(args.ground, args.side)
    p = gv + np.float32([0, 0, 1e-3])
    n = np.tile(np.float32([0, 0, 1]), (len(gv), 1))
    print(f"forest_rays: {args.trees} trees on {args.side:g} m, {len(gv)} receivers x "
          f"{args.samples} rays, load {os.getloadavg()[0]:.1f}")
    cases = [
        ("full prototypes", [merge(t) for t in kinds]),
        ("wood alone", [merge([q for q in t if q.role != "canopy"]) for t in kinds]),
        ("leaves alone", [merge([q for q in t if q.role == "canopy"]) for t in kinds]),
        ("one triangle spanning each box", [spanning_triangle(t) for t in kinds]),
        ("full, triangles split to edges <= 0.5", [split_long(merge(t), 0.5) for t in kinds]),
    ]
    parts = [octants(merge(t)) for t in kinds]
    first = np.cumsum([0] + [len(q) for q in parts])
    sub = [(first[w] + j, m) for w, m in zip(which, mats) for j in range(len(parts[w]))]
    cases.append(("full, 2 x 2 x 2 parts as instances", parts[0] + parts[1],
                  np.int32([j for j, _m in sub]), np.float32([m for _j, m in sub])))
    for label, protos, *placed in cases:
        ids, where = placed if placed else (which, mats)
        rt = _core.RayTracer(gv, gt, prototypes=protos, instance_prototypes=ids,
                             instance_matrices=np.ascontiguousarray(where))
        c0 = time.process_time()
        ao = rt.ao(p, n, samples=args.samples)
        cpu = time.process_time() - c0
        tris = sum(len(t) for _v, t in protos)
        print(f"{label:<40} {tris:>7} prototype triangles {len(ids):>5} instances "
              f"{cpu:6.2f} CPU s  "
              f"mean AO {ao.mean():.4f}", flush=True)


if __name__ == "__main__":
    main()
