"""Probe, answered: pooling the far field over mesh neighbours costs more than twice the samples, which do better; not built.

Ray pooling, measured and not kept: the exact rung's far field shared over mesh neighbours.

    /usr/bin/python3 bench/probes/ray_pooling.py [--scenes NAME ...] [--samples 16 64]

On the Sapling exports with a 1024-sample Cycles bake (as bench/real_rays.py): each vertex keeps
the fraction of its own rays open to R_i, the reach of its ring (vertices within two mesh edges
whose normals face its way, cosine > 0.8), and takes the fraction open beyond R_i from the ring
(Shanmugam–Arikan's near/far split):

    pooled_i = near_i × Σ_j full_j / Σ_j near_j        (j in the ring of i, i included)

near traced by the same rays (they are keyed by vertex id) to R rounded up to √2 levels; own and
pooled blended per object by the least-squares weight w = −E[(own − own₂)(pooled − own)] /
E[(pooled − own)²] from a second trace of up to 2000 of its vertices. Prints, per scene and S,
the MAE against Cycles' 1024 samples of plain rays at S, of pooled rays at S and of plain rays
at 2S and 3S, each as a ratio to Cycles at S, with its seconds (one run; this machine is
shared): pooling lowers the error at the same S but costs 2-3x, and plain rays given that time
do better (docs/DESIGN.md, 'Rays against Cycles' samples').
"""
from __future__ import annotations

import glob
import math
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # bench/
import harness  # noqa: E402  (addon/, examples/ and bench/ on sys.path)

import real_scenes as rs  # noqa: E402

SAME_SIDE, SAMPLE, SECOND_SEED = 0.8, 2000, 7919


def ring(triangles, normals, n):
    """(rows, cols): vertex pairs within two edges, self included, normals within SAME_SIDE."""
    t = np.asarray(triangles, np.int64).reshape(-1, 3)
    e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    e = np.concatenate([e, e[:, ::-1], np.repeat(np.arange(n, dtype=np.int64)[:, None], 2, 1)])
    key = np.unique(e[:, 0] * n + e[:, 1])
    a, b = key // n, key % n
    first = np.searchsorted(a, np.arange(n + 1))
    deg = np.diff(first)[b]
    rows = np.repeat(a, deg)
    offs = np.arange(int(deg.sum())) - np.repeat(np.cumsum(deg) - deg, deg)
    key = np.unique(rows * n + b[np.repeat(first[b], deg) + offs])
    rows, cols = key // n, key % n
    u = np.asarray(normals, np.float64)
    u = u / np.maximum(np.linalg.norm(u, axis=1, keepdims=True), 1e-30)
    keep = np.einsum("ij,ij->i", u[rows], u[cols]) > SAME_SIDE
    return rows[keep], cols[keep]


def pooled(tracer, sc, samples, full):
    """The pooled estimate of every vertex of sc (module docstring), object by object."""
    out = full.astype(np.float64).copy()
    first = 0
    for name in sc.names:
        part = sc.parts[name]
        n = len(part["positions"])
        rows, cols = ring(part["triangles"], part["normals"], n)
        g = first + np.arange(n)
        reach = np.zeros(n)
        np.maximum.at(reach, rows, np.linalg.norm(sc.V[g][rows] - sc.V[g][cols], axis=1))
        at = np.full(n, math.inf)
        ok = reach > 0
        at[ok] = 2.0 ** (np.ceil(2 * np.log2(reach[ok])) / 2)
        at[at >= sc.distance] = math.inf
        own = full[g].astype(np.float64)
        near = own.copy()
        for level in np.unique(at[np.isfinite(at)]):
            sel = np.flatnonzero(at == level)
            near[sel] = rs.trace_vertices(tracer, sc, samples, float(level), 0, rows=g[sel])
        near = np.maximum(near, own)
        sf = np.bincount(rows, own[cols], minlength=n)
        sn = np.bincount(rows, near[cols], minlength=n)
        pool = np.minimum(near * np.where(sn > 0, sf / np.maximum(sn, 1e-30), 1.0), 1.0)
        sub = np.sort(np.random.default_rng(0).choice(n, min(n, SAMPLE), replace=False))
        second = rs.trace_vertices(tracer, sc, samples, sc.distance, SECOND_SEED, rows=g[sub])
        d = pool[sub] - own[sub]
        den = float(np.mean(d * d))
        w = float(np.clip(-np.mean((own[sub] - second) * d) / den, 0, 1)) if den > 1e-12 else 0
        out[g] = own + w * (pool - own)
        first += n
    return out


def main():
    ap = harness.parser(__doc__)
    ap.add_argument("--scenes", nargs="*")
    ap.add_argument("--samples", type=int, nargs="*", default=[16, 64])
    args = ap.parse_args()
    names = [os.path.basename(p)[:-len("_quick.npz")]
             for p in sorted(glob.glob(os.path.join(rs.REAL, "*_quick.npz")))]
    print("scene, S: ratio to Cycles at S (seconds) — plain S | pooled S | plain 2S | plain 3S")
    for name in [s for s in (args.scenes or names) if s in names]:
        sc = rs.load(name)
        ref = rs.cycles_ao(sc, 1024)
        if ref is None:
            continue
        tracer = rs.scene_tracer(sc)
        for s in args.samples:
            cyc = rs.cycles_ao(sc, s)
            if cyc is None:
                continue
            e_c = np.abs(cyc - ref).mean()
            t0 = time.perf_counter()
            own = rs.trace_vertices(tracer, sc, s, sc.distance, 0)
            t1 = time.perf_counter()
            pool = pooled(tracer, sc, s, own)
            t2_pool = time.perf_counter() - t0
            extra = []
            for k in (2, 3):
                t2 = time.perf_counter()
                more = rs.trace_vertices(tracer, sc, k * s, sc.distance, 0)
                extra.append((np.abs(more - ref).mean() / e_c, time.perf_counter() - t2))
            r = [np.abs(x - ref).mean() / e_c for x in (own, pool)]
            print(f"  {name:20s} {s:4d}: {r[0]:.3f} ({t1 - t0:.2f} s) | {r[1]:.3f} "
                  f"({t2_pool:.2f} s) | " + " | ".join(f"{e:.3f} ({t:.2f} s)" for e, t in extra),
                  flush=True)

if __name__ == "__main__":
    main()
