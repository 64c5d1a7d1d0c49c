"""Probe, answered: the near/far hybrid cannot reach 64 plain rays' error at half their time on real trees (the far field's floor; bench/results/hybrid_study.txt, docs/DESIGN.md).

Why the near/far hybrid does or does not reach 64 plain rays' error at half their time.

    /usr/bin/python3 bench/probes/hybrid_study.py [--scenes sap_callistemon ...] [--voxels 1 2 4 8 16]
                                           [--full]

On the real-generator scenes (bench/out/real, examples/sapling_scenes.py; Embree 1024 rays as
the reference, buried vertices left out as in bench/real_assets.py). The hybrid's AO is the
product near × far: N rays cut at `near` (c voxels of the density grid: scale-free) times the
grid's transmittance beyond it (native ao_near_far; docs/DESIGN.md, 'The near/far hybrid').
Per scene and c, it prints:

- near share: how much of the reference's occlusion the near field holds,
  mean(1 − AO_near) / mean(1 − AO), AO_near traced with 256 rays out to `near` — the part the
  rays must still pay for;
- floor: the MAE of the hybrid with a near field of 256 rays — what the far field (the grid,
  and the product of two averages instead of one average along each ray) costs whatever
  the rays, against the target 1.1 × the MAE of 64 plain rays;
- the hybrid at 16 and 64 near rays, MAE and time / time of 64 rays.

The hybrid is the add-on's native call (core/lighting.py hybrid_ao): native ao_near_far with
each receiver's own vertex named, so its near rays start at Cycles' bake point and are cast at
every face corner as the plain rays are, over the grid the add-on builds (leaves and branches at
resolution 48, lighting.build_grid); near = c × its voxel (the add-on's c is 2). Its far field
is the grid alone: the GROUND patches a bake multiplies in beyond `near` (lighting.hybrid_ao,
core/walls.py) are left out, so the floor here is the grid's, and a bake's hybrid reads lower
(bench/real_assets.py's hybrid rows).

Times include the BVH (and the grid, for the hybrid); one run, ratios only.
"""
from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # bench/
import harness  # noqa: E402  (addon/, examples/ and bench/ on sys.path)

import numpy as np  # noqa: E402

import real_scenes as rs  # noqa: E402
from canopy_ao import _core  # noqa: E402
from canopy_ao.core.metrics import compare  # noqa: E402
from real_assets import SCENES, timed  # noqa: E402

TARGET_MAE = 1.10    # × the MAE of 64 plain rays
TARGET_TIME = 0.5    # × their time


def study(name, voxels, quick=True):
    sc = rs.load(name, quick)
    ref, _ = rs.reference(sc)
    keep = ~rs.buried(sc)
    D = sc.distance
    ids = np.arange(sc.n_vertices, dtype=np.int32)
    tracer, t_bvh = timed(lambda: rs.scene_tracer(sc))
    ao64, t64 = timed(lambda: rs.trace_vertices(tracer, sc, 64, D, 0))
    t64 += t_bvh
    m64 = compare(ao64, ref, keep)["mae"]
    occ = np.isin(sc.role, ("canopy", "trunk"))  # as lighting.build_grid
    tris = np.ascontiguousarray(sc.T[np.all(occ[sc.T], axis=1)])
    grid, t_grid = timed(lambda: _core.DensityGrid(sc.V, tris))
    print(f"\n== {name}: {sc.n_vertices} vertices; 64 rays MAE {m64:.4f} in {t64:.3f} s; "
          f"target MAE <= {TARGET_MAE * m64:.4f} in <= {TARGET_TIME * t64:.3f} s")
    print(f"{'voxels':>6s} {'near':>8s} {'near share':>10s} {'floor':>7s} "
          f"{'16: MAE':>8s} {'time':>6s} {'64: MAE':>8s} {'time':>6s}")
    occl = float(np.mean(1.0 - ref[keep]))
    for c in voxels:
        near = min(c * float(grid.voxel_size), D)

        def hybrid(n, seed=0):
            return np.asarray(_core.ao_near_far(tracer, grid, sc.V, sc.N, near, samples=n,
                                                distance=D, seed=seed, vertex_ids=ids))

        exact_near = np.asarray(tracer.ao(sc.V, sc.N, samples=256, distance=near, seed=5,
                                          vertex_ids=ids))
        share = float(np.mean(1.0 - exact_near[keep])) / max(occl, 1e-9)
        floor = compare(hybrid(256, 5), ref, keep)["mae"]
        cells = []
        for n in (16, 64):
            ao, dt = timed(lambda: hybrid(n))
            cells.append((compare(ao, ref, keep)["mae"], (dt + t_bvh + t_grid) / t64))
        print(f"{c:6g} {near:8.3g} {share:10.2f} {floor:7.4f} "
              f"{cells[0][0]:8.4f} {cells[0][1]:5.2f}× {cells[1][0]:8.4f} {cells[1][1]:5.2f}×",
              flush=True)


def main(argv=None):
    ap = harness.parser(__doc__, prog="hybrid_study.py")
    ap.add_argument("--scenes", nargs="+", default=[s for s in SCENES if s.startswith("sap_")],
                    choices=SCENES)
    ap.add_argument("--full", action="store_true", help="full-size exports instead of quick")
    ap.add_argument("--voxels", nargs="+", type=float, default=[1, 2, 4, 8, 16])
    a = ap.parse_args(argv)
    for s in a.scenes:
        study(s, a.voxels, not a.full)
    return 0


if __name__ == "__main__":
    sys.exit(main())
