"""Probe, answered: dealing rays by each vertex's estimated variance is 2-7 % worse than the even deal at equal rays; not built.

Fewer rays for the same error? Rays dealt by each vertex's estimated variance, against the
exact rung's even deal, on a Sapling export (issue #39 item 1; why it was not built).

    /usr/bin/python3.11 bench/probes/ray_allocation.py bench/out/real/sap_callistemon.npz \
        [--samples 16 64] [--pilot 0.25 0.5]

The export comes from examples/sapling_scenes.py (bench/README.md); the reference is Embree at
1024 rays per corner with its own seed (bench/real_scenes.py, cached beside the export). At S
samples every variant casts the same rays in all, Cycles' count spread as the add-on spreads
it (core/ray_budget.py: S × k̄ per vertex, a multiple of its corners):

- ``even``: the add-on's deal, one stratified set per vertex (and ``even ×2``: twice the rays,
  to read a MAE change as a change in rays: error falls as rays^-α, α printed);
- ``pilot f, power p``: a pilot pass with the share f of the rays, each vertex's AO a from it
  (Laplace-smoothed, so an all-open or all-blocked pilot still gets rays), then the rest dealt
  in proportion to sqrt(a (1 − a))^p (p = 1: Neyman's allocation, least squared error for
  binomial noise; p = 2/3: least mean absolute error), the two passes' means weighed by their
  rays. Deterministic (the second pass has its own seed).

Prints MAE against the reference, rays and the CPU seconds of each trace. Measured on
sap_callistemon (46,030 vertices) the pilot variants are 1-7 % *worse* than the even deal at
equal rays (S = 16: 0.0176 even, 0.0183-0.0188 pilots; S = 64: 0.0073 even, 0.0074-0.0076):
two stratified sets of n/2 rays have more error than one of n (the even deal's error falls as
n^-0.65, faster than the binomial n^-0.5 a pilot's variance estimate assumes), and the binomial
variance a (1 − a) does not say where a vertex's stratified error is. So the bake keeps the
even deal.

A second way was measured with a native prototype and not kept: a pilot of every m-th round of
a vertex's own rays, the rest cast only when some pilot ray was open (else AO 0), which leaves
every other vertex's AO bit for bit. On sap_callistemon it saved 8-13 % of the CPU at m = 2 for
+4 % (S = 64) to +12 % (S = 16) MAE, no better than casting that many fewer rays evenly
(rays^-0.63: +5 % to +9 %); pilots stopped within 1-3 % of the scene's size (truly enclosed
vertices) stopped too few to pay for the rays cast again (1.3x the CPU).
"""
import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # bench/
import harness  # noqa: E402,F401  (addon/, examples/ and bench/ on sys.path)

import real_scenes as rs  # noqa: E402
from canopy_ao.core import ray_budget  # noqa: E402

SECOND_SEED = 7919  # the second pass's own rotation


class Deal:
    """The scene's tracer and the add-on's even deal of rays over its vertices."""

    def __init__(self, sc):
        self.sc = sc
        self.tracer = rs.scene_tracer(sc)
        self.ids = np.arange(self.tracer.vertex_count, dtype=np.int32)
        self.corners = self.tracer.vertex_corners(0, self.tracer.vertex_count).astype(np.int64)
        self.kbar = self.tracer.corners_per_vertex

    def trace(self, rays, seed):
        """(AO float64 (V,), CPU seconds) with rays[v] rays at vertex v."""
        t0 = time.process_time()
        ao = self.tracer.ao(self.sc.V, self.sc.N, samples=1, distance=self.sc.distance,
                            seed=seed, vertex_ids=self.ids, per_corner=False,
                            point_samples=np.ascontiguousarray(rays, np.int32))
        return np.asarray(ao, np.float64), time.process_time() - t0

    def even(self, per_vertex):
        return ray_budget.vertex_rays(self.corners, per_vertex).astype(np.int64)

    def pilot(self, samples, share, power, seed=0):
        """(AO, rays in all, CPU seconds) of the two-pass deal (module doc)."""
        budget = int(self.even(samples * self.kbar).sum())
        r0 = self.even(share * samples * self.kbar)
        a0, c0 = self.trace(r0, seed)
        n0 = r0.astype(np.float64)
        a = (a0 * n0 + 0.5) / (n0 + 1.0)
        w = np.sqrt(a * (1.0 - a)) ** power
        want = max(budget - int(r0.sum()), 0) * w / w.sum()
        r1 = np.maximum(self.corners, np.rint(want / self.corners) * self.corners)
        a1, c1 = self.trace(r1.astype(np.int64), seed + SECOND_SEED)
        return (a0 * n0 + a1 * r1) / (n0 + r1), int(r0.sum() + r1.sum()), c0 + c1


def main(argv=None):
    ap = argparse.ArgumentParser(prog="ray_allocation.py", description=__doc__.split("\n")[0])
    ap.add_argument("export", help="a Sapling export (.npz, examples/sapling_scenes.py)")
    ap.add_argument("--samples", type=int, nargs="+", default=[16, 64])
    ap.add_argument("--pilot", type=float, nargs="+", default=[0.25, 0.5],
                    help="the pilot pass's shares of the rays")
    a = ap.parse_args(argv)
    sc = rs.RealScene(a.export)
    ref, _ = rs.reference(sc, 1024)
    ref = ref.astype(np.float64)
    deal = Deal(sc)
    print(f"ray_allocation: {sc.name}, {sc.n_vertices} vertices, k̄ {deal.kbar:.2f}, load "
          f"{os.getloadavg()[0]:.1f}")
    print(f"{'S':>4} {'deal':<22} {'rays':>10} {'MAE':>8} {'vs even':>8} {'CPU s':>7}")
    for s in a.samples:
        r = deal.even(s * deal.kbar)
        ao, cpu = deal.trace(r, 0)
        base = float(np.abs(ao - ref).mean())
        print(f"{s:4d} {'even':<22} {int(r.sum()):10d} {base:8.5f} {1.0:8.3f} {cpu:7.2f}")
        r2 = deal.even(2 * s * deal.kbar)
        ao2, cpu2 = deal.trace(r2, 0)
        m2 = float(np.abs(ao2 - ref).mean())
        print(f"{s:4d} {'even x2':<22} {int(r2.sum()):10d} {m2:8.5f} {m2 / base:8.3f} "
              f"{cpu2:7.2f}   alpha {np.log(base / m2) / np.log(r2.sum() / r.sum()):.2f}")
        for share in a.pilot:
            for power, label in ((2 / 3, "2/3"), (1.0, "1")):
                ao, n, cpu = deal.pilot(s, share, power)
                m = float(np.abs(ao - ref).mean())
                print(f"{s:4d} {f'pilot {share:g}, power {label}':<22} {n:10d} {m:8.5f} "
                      f"{m / base:8.3f} {cpu:7.2f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
