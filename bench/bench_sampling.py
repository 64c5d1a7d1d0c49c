"""The exact rung's rays: sample sets, and where geometry touches (RayTracer, raytrace.h).

    /usr/bin/python3 bench/bench_sampling.py [--scenes NAME ...] [--points 6000] [--seeds 3]

Scenes: the Sapling Tree Gen exports in bench/out/real (`<scene>_quick.npz`, written by
examples/sapling_scenes.py and read through bench/real_scenes.py: every object's positions,
normals, triangles, role; AO distance = the scene's bbox diagonal) when there are any, else the
repository's example scenes (examples/canopy_scenes.py, quick sizes). Every vertex is its own receiver (vertex_ids), as the add-on bakes.

1. Sample sets: MAE over --points random vertices against a 4096-ray reference (four
   1024-ray lattice runs with other seeds, mean) at 16, 64 and 256 rays per vertex, for the
   lattice (the default), the Owen-scrambled Sobol' net and independent rays, mean of --seeds
   seeds. The reference's own noise is in every figure alike.
2. Where geometry touches: per height band above the lowest ground vertex (grass and
   trunks), the mean AO with the receiver's own triangles skipped minus the mean with the old
   normal offset, 256 rays: the bias the offset put on vertices lying on another surface.
   When a Cycles bake of the scene is present (`<scene>_quick_cycles_<N>.npz`, ao/<object>),
   the bias of both against it.
"""
from __future__ import annotations

import glob
import os
import time

import numpy as np

import harness  # noqa: E402  (addon/ and examples/ on sys.path)

HERE = harness.HERE

from canopy_ao import _core  # noqa: E402
import real_scenes  # noqa: E402

SAMPLERS = ("lattice", "sobol", "independent")


def sapling_dir():
    """The folder of the exported Sapling scenes (real_scenes.REAL), or None without any."""
    folder = real_scenes.REAL
    return folder if glob.glob(os.path.join(folder, "*_quick.npz")) else None


def load_npz(path):
    """[(name, role, positions, normals, triangles)], AO distance."""
    sc = real_scenes.RealScene(path)
    return [(n, r, p, nrm, t) for n, r, _tree, p, nrm, t in sc.items()], sc.distance


def load_example(name):
    import canopy_scenes as cs

    scene = cs.make_scene(name, quick=True)
    objs = [(p.name, p.role, p.vertices, cs.vertex_normals(p.vertices, p.triangles), p.triangles)
            for p in scene]
    allv = np.concatenate([o[2] for o in objs])
    return objs, float(np.linalg.norm(allv.max(0) - allv.min(0)))


def scenes(args):
    folder = sapling_dir()
    if folder:
        paths = sorted(glob.glob(os.path.join(folder, "*_quick.npz")))
        found = {os.path.basename(p)[:-len("_quick.npz")]: p for p in paths}
        for name in args.scenes or sorted(found):
            if name in found:
                yield name, (lambda p=found[name]: load_npz(p)), found[name]
        return
    for name in args.scenes or ["round_tree", "conifer", "grass_field"]:
        yield name, (lambda n=name: load_example(n)), None


def flatten(objs):
    verts, tris, normals, roles, names, base = [], [], [], [], [], 0
    for name, role, v, n, t in objs:
        verts.append(v)
        normals.append(n)
        tris.append(np.asarray(t) + base)
        roles += [role] * len(v)
        names += [name] * len(v)
        base += len(v)
    return (np.ascontiguousarray(np.concatenate(verts), np.float32),
            np.ascontiguousarray(np.concatenate(tris), np.int32),
            np.ascontiguousarray(np.concatenate(normals), np.float32),
            np.array(roles), np.array(names))


def main():
    ap = harness.parser(__doc__)
    ap.add_argument("--scenes", nargs="*")
    ap.add_argument("--points", type=int, default=6000)
    ap.add_argument("--seeds", type=int, default=3)
    args = ap.parse_args()
    print(f"scenes from {sapling_dir() or 'examples/canopy_scenes.py (quick)'}")
    for name, load, path in scenes(args):
        objs, dist = load()
        V, T, N, roles, names = flatten(objs)
        t0 = time.perf_counter()
        rt = _core.RayTracer(V, T)
        sel = np.sort(np.random.default_rng(0).choice(len(V), min(len(V), args.points),
                                                      replace=False)).astype(np.int32)
        p, n = np.ascontiguousarray(V[sel]), np.ascontiguousarray(N[sel])

        def ao(samples, seed, sampling="lattice", own=True, pts=(p, n, sel)):
            kw = {"vertex_ids": pts[2]} if own else {}
            return rt.ao(pts[0], pts[1], samples=samples, distance=dist, seed=seed,
                         sampling=sampling, **kw)

        ref = np.mean([ao(1024, 1000 + k) for k in range(4)], axis=0)
        print(f"\n{name}: {len(V)} vertices, {len(T)} triangles, {len(p)} sampled, "
              f"D = {dist:.1f}, mean AO {ref.mean():.3f} ({time.perf_counter() - t0:.0f} s)")
        print("  MAE vs 4096 rays  " + "".join(f"{s:>13s}" for s in SAMPLERS))
        for samples in (16, 64, 256):
            maes = [np.mean([np.abs(ao(samples, seed, s) - ref).mean()
                             for seed in range(args.seeds)]) for s in SAMPLERS]
            print(f"  {samples:4d} rays         " + "".join(f"{m:13.4f}" for m in maes)
                  + f"   lattice / independent {maes[0] / maes[2]:.2f}")

        # Where geometry touches: own triangles skipped vs the normal offset, per height band.
        ground = [o for o in objs if o[1] == "ground"]
        z0 = float(min(o[2][:, 2].min() for o in ground)) if ground else float(V[:, 2].min())
        cycles = sorted(glob.glob(path[:-4] + "_cycles_*.npz")) if path else []
        cyc = None
        if cycles:
            c = np.load(cycles[-1])
            cyc = np.concatenate([c[f"ao/{o[0]}"] for o in objs])
        for role in ("grass", "trunk"):
            idx = np.flatnonzero(roles == role).astype(np.int32)
            if not len(idx):
                continue
            h = V[idx, 2] - z0
            top = float(np.percentile(h, 99)) or 1.0
            pts = (np.ascontiguousarray(V[idx]), np.ascontiguousarray(N[idx]), idx)
            new = ao(256, 7, own=True, pts=pts)
            old = ao(256, 7, own=False, pts=pts)
            print(f"  {role}: mean AO per height band (fraction of its 99th-percentile height "
                  f"{top:.2f}); own triangles skipped vs normal offset"
                  + ("; bias vs Cycles " + os.path.basename(cycles[-1]) if cyc is not None
                     else ""))
            edges = [0.0, 0.02, 0.1, 0.25, 0.5, 1.0, np.inf]
            for lo, hi in zip(edges[:-1], edges[1:]):
                b = (h >= lo * top) & (h < hi * top)
                if not b.any():
                    continue
                line = (f"    [{lo:4.2f}, {hi:4.2f}) {b.sum():7d} vertices: skip own "
                        f"{new[b].mean():.3f}, offset {old[b].mean():.3f}, "
                        f"difference {new[b].mean() - old[b].mean():+.3f}")
                if cyc is not None:
                    ref_c = cyc[idx][b]
                    line += (f"; bias skip own {np.mean(new[b] - ref_c):+.3f}, offset "
                             f"{np.mean(old[b] - ref_c):+.3f}")
                print(line)


if __name__ == "__main__":
    main()
