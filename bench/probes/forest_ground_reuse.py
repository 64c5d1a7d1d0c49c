"""Probe, answered: sharing rays between a forest ground's neighbours halves its rays only where the ground is finer than its shade; not built.

Whether a forest ground's vertices can cast half their rays and share them with their mesh
neighbours at the same error (issue #39 item 5: the ground in ≤ ½ of its time).

    /usr/bin/python3.11 bench/probes/forest_ground_reuse.py [--grounds 20 40 100] [--reference 3008]

bench/forest_rays.py's forest (200 instanced trees, two prototypes, on 50 m) over a k × k grid
ground, each vertex casting S rays up (376: the 200-tree example's 64 samples × 5.88 corners).
Every vertex's estimate a_i is averaged with its 1-ring (the six grid neighbours) by the range
kernel of bench/probes/ray_reuse.py,

    a'_i = (a_i + Σ_j w_ij a_j) / (1 + Σ_j w_ij),  w_ij = exp(−(a_i − a_j)² / (2 h² (σ_i² + σ_j²)))

σ² = a(1 − a)/S + 1/S² the estimate's binomial variance, once or twice (--passes); and again with
the ray_reuse guard: a vertex with one of 4 short rays blocked within ρ × its longest ring edge
shares nothing (its neighbours may see an occluder it does not). MAE and the 99th percentile of
the error against the same rays at --reference per vertex (another seed).

Measured (load 1.6-2.9; 0.5 / 1.3 / 2.6 m grid spacing for k = 100 / 40 / 20), MAE (p99):

- k = 100: plain 376 rays 0.0109 (0.036); half the rays shared (h 2, one pass) 0.0082 (0.033),
  a quarter shared twice (h 1) 0.0102 (0.043): here it halves the ground and more.
- k = 40: plain 376 0.0109; 188 shared 0.0135-0.0136, worse than plain 376.
- k = 20: sharing is worse than the same rays unshared at every count (188: 0.0158 h 1,
  0.0211 h 2 against plain 0.0141): neighbours 2.6 m apart differ truly by more than the noise.
- the guard makes it safe on the coarse grounds (within 0.0004 of plain: 3-9 % of the vertices
  share at ρ 4) and takes the gain away where it was: k = 100, 188 rays shared 0.0116 (ρ 4, 58 %
  of the vertices sharing) and 0.0146 (ρ 8, 17 %) against plain 376's 0.0109.
So the gain is the ground's resolution against the distance to its occluders, which a bake does
not know before its rays; a filter that only pays on grounds finer than their shade, and hurts
the others, is not a default. The ray rung keeps each vertex's own rays.
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # bench/
import harness  # noqa: E402,F401  (addon/, examples/ and bench/ on sys.path)

import forest_rays as fr  # noqa: E402
from canopy_ao import _core  # noqa: E402

TREES, SIDE = 200, 50.0


def forest_tracer(k):
    """The forest over a k × k grid ground; (tracer, points, normals, ring pairs i, j)."""
    which, mats = fr.placements(TREES, SIDE)
    gv, gt = fr.grid_ground(k, SIDE)
    rt = _core.RayTracer(gv, gt, prototypes=[fr.merge(t) for t in fr.prototypes()],
                         instance_prototypes=which, instance_matrices=mats)
    idx = np.arange(k * k).reshape(k, k)
    pairs = [(idx[:k - di, :k - dj].ravel(), idx[di:, dj:].ravel())
             for di, dj in ((0, 1), (1, 0), (1, 1))]
    ii = np.concatenate([p[0] for p in pairs] + [p[1] for p in pairs])
    jj = np.concatenate([p[1] for p in pairs] + [p[0] for p in pairs])
    points = gv + np.float32([0, 0, 1e-3])
    normals = np.tile(np.float32([0, 0, 1]), (len(gv), 1))
    return rt, points, normals, ii, jj


def share(ao, rays, ii, jj, h, passes):
    ao = ao.astype(np.float64)
    for _ in range(passes):
        var = ao * (1 - ao) / rays + 1.0 / rays ** 2
        w = np.exp(-(ao[ii] - ao[jj]) ** 2 / (2 * h * h * (var[ii] + var[jj])))
        ao = (ao + np.bincount(ii, w * ao[jj], len(ao))) / (1 + np.bincount(ii, w, len(ao)))
    return ao


def scores(ao, ref):
    err = np.abs(ao - ref)
    return f"{err.mean():.4f} ({np.quantile(err, 0.99):.3f})"


def main():
    ap = argparse.ArgumentParser(prog="forest_ground_reuse.py")
    ap.add_argument("--grounds", type=int, nargs="+", default=[20, 40, 100])
    ap.add_argument("--samples", type=int, nargs="+", default=[376, 188, 94])
    ap.add_argument("--reference", type=int, default=3008)
    args = ap.parse_args()
    print(f"forest_ground_reuse: {TREES} trees on {SIDE:g} m, load {os.getloadavg()[0]:.1f}")
    for k in args.grounds:
        rt, p, n, ii, jj = forest_tracer(k)
        c0 = time.process_time()
        ref = rt.ao(p, n, samples=args.reference, seed=7)
        print(f"k {k}: {k * k} receivers, {SIDE / (k - 1):.2f} m apart; reference "
              f"{time.process_time() - c0:.1f} CPU s, mean AO {ref.mean():.3f}", flush=True)
        edge = SIDE / (k - 1) * math.sqrt(2)
        guards = {rho: rt.ao(p, n, samples=4, distance=rho * edge, seed=3) < 1.0
                  for rho in (4, 8)}
        for s in args.samples:
            c0 = time.process_time()
            ao = rt.ao(p, n, samples=s)
            cpu = time.process_time() - c0
            line = f"  S {s:4d} {cpu:5.2f} CPU s  plain {scores(ao, ref)}"
            for h, passes in ((1, 1), (2, 1), (1, 2)):
                line += f"  h{h}x{passes} {scores(share(ao, s, ii, jj, h, passes), ref)}"
            for rho, near in guards.items():
                keep = ~(near[ii] | near[jj])
                line += (f"  guard ρ{rho} ({1 - near.mean():.0%} share) "
                         f"{scores(share(ao, s, ii[keep], jj[keep], 2, 1), ref)}")
            print(line, flush=True)


if __name__ == "__main__":
    main()
