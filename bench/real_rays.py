"""The exact rung's rays against Cycles' samples on the real-tree scenes, at the same count.

    /usr/bin/python3 bench/real_rays.py [--scenes NAME ...] [--samples 16 64 256] [--seeds 2]
                                        [--no-pooled]

Scenes: every Sapling Tree Gen export in bench/out/real (examples/sapling_scenes.py, read through
bench/real_scenes.py) that has a Cycles bake at the reference count (--reference, default
1024 samples: `<scene>_quick_cycles_<N>.npz`). Receivers are every vertex, each started at
Cycles' bake point (real_scenes.scene_tracer, as the add-on bakes: native raytrace.h,
'Origins'); errors are MAE against Cycles at the reference count,
over all vertices and with buried ones (real_scenes.buried) left out.

Per scene and sample count S: Cycles at S samples (when baked), our rays at S rays (the
default lattice, mean of --seeds seeds), their ratio (docs/DESIGN.md, 'Rays against Cycles'
samples': the target is ours ≤ 0.85 × Cycles), and the contact share (vertices with a ray
blocked within 1e-4 of the AO distance) with the MAE there.

"pooled" (16 and 64 rays; --no-pooled skips it) is the experiment that DESIGN section
describes: each vertex's far field (beyond R, its distance to the farthest vertex of its 2-ring
on the same side) pooled over that 2-ring, its near field its own, blended with its own
estimate by the weight that minimises the squared error (estimated from an independent second
trace of up to 2000 vertices per role). It traces extra rays (the near pass per distance level
and the second trace), so it is a measurement of what pooling could buy, not a rung.
"""
from __future__ import annotations

import argparse
import glob
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

import real_scenes as rs  # noqa: E402
from canopy_ao import _core  # noqa: E402

CONTACT = 1e-4  # of the AO distance: a ray blocked this close starts on touching geometry
SAME_SIDE = 0.8  # normals' cosine for two vertices to share a far field


def cycles(sc, samples):
    """Cycles' AO per vertex at ``samples`` (merged like sc.V), or None when not baked."""
    path = sc.path[:-4] + f"_cycles_{samples}.npz"
    if not os.path.exists(path):
        return None
    with np.load(path) as z:
        if str(z["geometry"]) != sc.geometry:
            return None
        return np.concatenate([z[f"ao/{n}"] for n in sc.names]).astype(np.float32)


def two_ring(sc):
    """(rows, cols) of vertex pairs within two mesh edges, self included, same normal side."""
    n, t = sc.n_vertices, sc.T.astype(np.int64)
    e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    e = np.concatenate([e, e[:, ::-1], np.repeat(np.arange(n)[:, None], 2, 1)])
    key = np.unique(e[:, 0] * n + e[:, 1])
    a, b = key // n, key % n
    first = np.searchsorted(a, np.arange(n + 1))
    # 2-ring: for each pair (a, b), every neighbour c of b.
    deg = np.diff(first)[b]
    rows = np.repeat(a, deg)
    starts = np.repeat(first[b], deg)
    offs = np.arange(deg.sum()) - np.repeat(np.cumsum(deg) - deg, deg)
    cols = b[starts + offs]
    key = np.unique(rows * n + cols)
    rows, cols = key // n, key % n
    nn = sc.N / np.maximum(np.linalg.norm(sc.N, axis=1, keepdims=True), 1e-30)
    keep = np.einsum("ij,ij->i", nn[rows], nn[cols]) > SAME_SIDE
    return rows[keep], cols[keep]


def pooled(tracer, sc, samples, seed, full, rows, cols, roles):
    """The pooled estimate (module docstring) and the blend weight per role."""
    n = sc.n_vertices
    d = np.linalg.norm(sc.V[rows] - sc.V[cols], axis=1)
    reach = np.zeros(n)
    np.maximum.at(reach, rows, d)
    level = np.where(reach > 0, np.round(2 * np.log2(np.maximum(reach, 1e-30))), -1e9)
    near = np.ones(n, np.float32)
    for lv in np.unique(level[reach > 0]):
        sel = level == lv
        near[sel] = rs.trace_vertices(tracer, sc, samples, min(2.0 ** (lv / 2), sc.distance),
                                      seed)[sel]
    near = np.maximum(near, full)  # the same rays: what is open to D is open to R
    sn = np.bincount(rows, near[cols], minlength=n)
    sf = np.bincount(rows, full[cols], minlength=n)
    far = np.where(sn > 0, sf / np.maximum(sn, 1e-30), 1.0)
    pool = np.minimum(near * far, 1.0)
    est = full.astype(np.float64).copy()
    weights = {}
    rng = np.random.default_rng(seed)
    for r in np.unique(roles):
        idx = np.flatnonzero(roles == r)
        sub = np.sort(rng.choice(idx, min(len(idx), 2000), replace=False))
        second = rs.trace_vertices(tracer, sc, samples, sc.distance, seed + 7919)[sub]
        diff = pool[sub] - full[sub]
        w = -np.mean((full[sub] - second) * diff) / max(float(np.mean(diff * diff)), 1e-12)
        w = float(np.clip(w, 0.0, 1.0))
        weights[r] = w
        est[idx] = full[idx] + w * (pool[idx] - full[idx])
    return est.astype(np.float32), weights


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenes", nargs="*")
    ap.add_argument("--samples", type=int, nargs="*", default=[16, 64, 256])
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--reference", type=int, default=1024)
    ap.add_argument("--no-pooled", action="store_true")
    args = ap.parse_args()
    paths = sorted(glob.glob(os.path.join(rs.REAL, "*_quick.npz")))
    names = [os.path.basename(p)[:-len("_quick.npz")] for p in paths]
    picked = [s for s in (args.scenes or names) if s in names]
    if not picked:
        sys.exit(f"real_rays: {' '.join(args.scenes) if args.scenes else 'no scenes'} not in "
                 f"{rs.REAL} (examples/sapling_scenes.py writes them; there: "
                 f"{' '.join(names) or 'none'})")
    summary = []
    for name in picked:
        sc = rs.load(name)
        ref = cycles(sc, args.reference)
        if ref is None:
            print(f"\n{name}: no Cycles bake at {args.reference} samples, skipped")
            continue
        t0 = time.perf_counter()
        tracer = rs.scene_tracer(sc)
        keep = ~rs.buried(sc, tracer)
        contact = rs.trace_vertices(tracer, sc, 64, CONTACT * sc.distance, 7) < 1.0
        roles = np.asarray(sc.role, dtype=str)
        ring = None if args.no_pooled else two_ring(sc)
        print(f"\n{name}: {sc.n_vertices} vertices ({(~keep).sum()} buried, {contact.sum()} "
              f"contact), reference Cycles {args.reference} samples")
        print("   S | Cycles all / unburied | ours all / unburied | ours / Cycles all / "
              "unburied | contact: Cycles / ours | pooled all (ratio); per role: blend weight, ratio; "
              "contact MAE")
        for s in args.samples:
            cyc = cycles(sc, s)
            ours = [rs.trace_vertices(tracer, sc, s, sc.distance, seed)
                    for seed in range(args.seeds)]
            e_ours = np.mean([np.abs(o - ref) for o in ours], axis=0)
            line = f"{s:4d} |"
            if cyc is not None:
                e_c = np.abs(cyc - ref)
                line += f" {e_c.mean():.4f} / {e_c[keep].mean():.4f}   |"
            else:
                e_c = None
                line += "     —   /    —     |"
            line += f" {e_ours.mean():.4f} / {e_ours[keep].mean():.4f} |"
            if e_c is not None:
                ra, ru = e_ours.mean() / e_c.mean(), e_ours[keep].mean() / e_c[keep].mean()
                line += (f"      {ra:.3f} / {ru:.3f}       | {e_c[contact].mean():.3f} / "
                         f"{e_ours[contact].mean():.3f}  |")
            else:
                ra = ru = None
                line += "            —          |       —       |"
            rp = None
            if ring is not None and s <= 64:
                est, w = pooled(tracer, sc, s, 0, ours[0], *ring, roles)
                e_p = np.abs(est - ref).mean()
                rp = e_p / e_c.mean() if e_c is not None else None
                e_pv = np.abs(est - ref)
                line += (f" {e_p:.4f}" + (f" ({rp:.3f})" if rp is not None else "") + "; "
                         + ", ".join(f"{k} w {v:.2f}" + (
                             f" ratio {e_pv[roles == k].mean() / e_c[roles == k].mean():.2f}"
                             if e_c is not None else "") for k, v in sorted(w.items()))
                         + f"; contact {e_pv[contact].mean():.3f}")
            print(line)
            summary.append((name, s, ra, ru, rp))
        print(f"  ({time.perf_counter() - t0:.0f} s)")
    print("\nours / Cycles (target ≤ 0.85), all vertices / unburied; pooled experiment:")
    for name, s, ra, ru, rp in summary:
        if ra is not None:
            print(f"  {name:24s} {s:4d} rays: {ra:.3f} / {ru:.3f}"
                  + (f"; pooled {rp:.3f}" if rp is not None else ""))


if __name__ == "__main__":
    main()
