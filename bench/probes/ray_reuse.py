"""Probe, answered: reusing mesh neighbours' rays saves 1.1-1.2x rays at 64 on three trees of four, little at contacts; not built.

Fewer rays for the same error by reusing neighbours' rays (issue #39 item 1).

    /usr/bin/python3.11 bench/probes/ray_reuse.py [--scenes sap_callistemon ...] \
        [--samples 8 16 32 64]

On the Sapling exports with a 1024-sample Cycles bake (examples/sapling_scenes.py --quick
--bake-cycles 1024; bench/README.md): the exact rung's rays at S (core/ray_budget.py: S × k̄ per
vertex, dealt evenly) and at 2S, against the same rays at S then combined with the vertex's mesh
neighbours (its 1-ring: the vertices sharing a triangle with it), a joint bilateral filter

    a'_i = (a_i + λ Σ_j w_ij a_j) / (1 + λ Σ_j w_ij)

with weights that vanish across creases and contacts:

- ``normal``: w = ((n_i·n_j − c) / (1 − c))₊, c = cos 30° (a crease, a leaf's other side);
- ``range``: also × exp(−(a_i − a_j)² / (2 h² (σ_i² + σ_j²))), σ² = a(1 − a)/rays + 1/rays²
  the estimate's binomial variance: a difference larger than the noise is kept, not averaged;
- ``near``: also 0 wherever i or j has a ray blocked within ρ × its longest ring edge (at
  least the distance between them; a short trace of 4 rays, distances rounded up to √2
  levels): the neighbour sees an occluder the receiver may not (a contact), so its rays are
  not ours.

Prints per scene and S the MAE against Cycles' 1024 samples over all vertices, over the
unburied ones (bench/real_scenes.py, core/buried.py's rule), the mean error of the worst 1 %
of vertices, and over the contact vertices (unburied, a ray blocked within twice the longest
ring edge: a leaf on a branch, a leaf crossing a leaf, a branch entering its parent), each as a
ratio to plain rays at S, the CPU seconds of the trace and of the filter, and "rays saved":
the plain rays that reach the same unburied MAE, (MAE ratio)^(−1/α) × S with α from S and 2S,
over the rays cast (the short trace's counted as whole rays).

Measured on the quick exports with a Cycles bake (quaking aspen 5,494 vertices, callistemon
14,412, small maple 75,036, white birch 51,660): weights on the normals alone bleed, as
expected — a buried branch base (AO 0) pulls its open neighbours down and the worst 1 % of
vertices err 2-20x more than plain rays (aspen 0.61 against 0.03-0.09). With the range
kernel the best variant of each scene and S (picked after the fact: a bound) saves, in rays
at equal unburied MAE (S = 8 / 16 / 32 / 64):

- quaking aspen (a quick export: few, isolated leaves): 2.6 / 2.4 / 2.1 / 1.9x;
- white birch: 1.5 / 1.4 / 1.3 / 1.2x; small maple: 1.5 / 1.3 / 1.2 / 1.15x; callistemon
  (needles): 1.3 / 1.2 / 1.15 / 1.1x (mostly range h 1, λ 0.5-1, no short trace; the short
  trace buys 1-3 % of MAE for S + 4 rays).

Against Embree's own 1024-ray reference instead (``--reference embree``, so Cycles' noise and
its differences from our rays are not in the floor) the same: callistemon 1.22 / 1.14x and
white birch 1.40 / 1.19x at S = 16 / 64.

The filter itself is ≤ 0.01 CPU s on 75,036 vertices (numpy); the short trace of 4 rays 0.17
CPU s there, 6 % of the 64-ray trace and 38 % of the 8-ray one (one run, load 4-5).

At contacts it does little: there the weights vanish, as they must, so the contact vertices
keep 0.83-1.03 of plain S's error (0.92-1.03 at 32-64; the worst 1 %: 0.85-1.0), where twice
the rays give 0.63-0.72; cutting the rays for the same mean error would make contacts worse. At the
add-on's default of 64 samples three of the four trees gain 1.1-1.2x, short of the 1.3x asked:
a leaf's vertices differ truly by 0.1-0.3 (docs/studies/rays_vs_cycles.md), far more than the
noise left at 64 rays, so the range kernel averages little, and a wider one biases (h 2 at λ 1
is worse than plain rays at 64 on three trees). So the ray rung keeps each vertex's own rays.
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

import real_scenes as rs  # noqa: E402
from canopy_ao.core import ray_budget  # noqa: E402

CREASE = math.cos(math.radians(30.0))
NEAR_LEVEL = math.sqrt(2.0)


def ring(triangles, n):
    """(rows, cols) int64: every ordered pair of distinct vertices sharing a triangle."""
    t = np.asarray(triangles, np.int64).reshape(-1, 3)
    e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    e = np.concatenate([e, e[:, ::-1]])
    e = e[e[:, 0] != e[:, 1]]
    key = np.unique(e[:, 0] * n + e[:, 1])
    return key // n, key % n


class Scene:
    def __init__(self, sc):
        self.sc = sc
        self.tracer = rs.scene_tracer(sc)
        n = sc.n_vertices
        self.rows, self.cols = ring(sc.T, n)
        v = sc.V.astype(np.float64)
        self.d = np.linalg.norm(v[self.rows] - v[self.cols], axis=1)
        self.reach = np.zeros(n)
        np.maximum.at(self.reach, self.rows, self.d)
        u = sc.N.astype(np.float64)
        u /= np.maximum(np.linalg.norm(u, axis=1, keepdims=True), 1e-30)
        c = np.einsum("ij,ij->i", u[self.rows], u[self.cols])
        self.w_normal = np.clip((c - CREASE) / (1.0 - CREASE), 0.0, 1.0)
        self.corners = self.tracer.vertex_corners(0, n).astype(np.int64)

    def rays(self, s):
        return ray_budget.vertex_rays(self.corners, s * self.tracer.corners_per_vertex)

    def trace(self, s, distance=None, rows=slice(None), seed=0):
        """(AO float64 of rows, CPU seconds): the exact rung's deal at S."""
        t0 = time.process_time()
        ao = ray_budget.trace_mesh(self.tracer, self.sc.V, self.sc.N, s, seed,
                                   distance or self.sc.distance, rows)
        return ao.astype(np.float64), time.process_time() - t0

    def near_open(self, s, rho):
        """(float64 (N,) fraction of rays open to rho × the vertex's reach, CPU seconds); the
        reach rounded up to √2 levels so each level is one call."""
        n = self.sc.n_vertices
        out = np.ones(n)
        ok = self.reach > 0
        lev = np.full(n, np.inf)
        lev[ok] = NEAR_LEVEL ** np.ceil(np.log(rho * self.reach[ok]) / np.log(NEAR_LEVEL))
        cpu = 0.0
        for level in np.unique(lev[np.isfinite(lev)]):
            sel = np.flatnonzero(lev == level)
            out[sel], c = self.trace(s, min(float(level), self.sc.distance), sel, seed=3)
            cpu += c
        return out, cpu

    def combine(self, a, s, lam, h=None, near=None, rho=None):
        """(the filtered AO (module doc), CPU seconds)."""
        t0 = time.process_time()
        r, c = self.rows, self.cols
        w = self.w_normal.copy()
        if h is not None:
            n = self.rays(s).astype(np.float64)
            var = a * (1 - a) / n + 1.0 / n ** 2
            w *= np.exp(-(a[r] - a[c]) ** 2 / (2 * h * h * (var[r] + var[c])))
        if near is not None:
            # near[i] = fraction open to rho × reach_i ≥ rho × d_ij: blocked there ⇒ no reuse
            w *= (near[r] >= 1.0) & (near[c] >= 1.0)
        num = a + lam * np.bincount(r, w * a[c], minlength=len(a))
        den = 1.0 + lam * np.bincount(r, w, minlength=len(a))
        return num / den, time.process_time() - t0


def errors(ao, ref, keep, contact):
    e = np.abs(ao - ref)
    k = max(1, len(e) // 100)
    worst = np.sort(e)[-k:].mean()
    return e.mean(), e[keep].mean(), worst, e[contact].mean()


def main(argv=None):
    ap = argparse.ArgumentParser(prog="ray_reuse.py", description=__doc__.split("\n")[0])
    ap.add_argument("--scenes", nargs="*")
    ap.add_argument("--samples", type=int, nargs="+", default=[8, 16, 32, 64])
    ap.add_argument("--lam", type=float, nargs="+", default=[0.5, 1.0])
    ap.add_argument("--h", type=float, nargs="+", default=[1.0, 2.0])
    ap.add_argument("--rho", type=float, default=1.0)
    ap.add_argument("--near-rays", type=int, default=4,
                    help="rays per vertex of the short trace (the exact rung's deal)")
    ap.add_argument("--reference", choices=("cycles", "embree"), default="cycles",
                    help="Cycles' 1024 samples, or Embree's (bench/real_scenes.reference)")
    ap.add_argument("--no-naive", action="store_true", help="leave out the normal-only filter")
    a = ap.parse_args(argv)
    names = a.scenes or harness.real_names(cycles=1024)
    for name in names:
        sc = rs.load(name)
        ref = rs.cycles_ao(sc, 1024) if a.reference == "cycles" else rs.reference(sc)[0]
        if ref is None:
            print(f"{name}: no 1024-sample Cycles bake, skipped")
            continue
        ref = ref.astype(np.float64)
        g = Scene(sc)
        keep = ~rs.buried(sc, g.tracer)
        # contact: a ray blocked within twice the ring's reach (scale-free)
        near2, _ = g.near_open(16, 2.0)
        contact = keep & (near2 < 1.0)
        print(f"\n{name}: {sc.n_vertices} vertices, {(~keep).sum()} buried, {contact.sum()} "
              f"contact, {len(g.rows) / sc.n_vertices:.1f} neighbours a vertex, load "
              f"{os.getloadavg()[0]:.1f}")
        print(f"{'S':>3} {'method':<26} {'all':>7} {'unbur.':>7} {'worst1%':>7} "
              f"{'contact':>7} | ratios to plain S        | CPU s trace + extra | rays saved")
        for s in a.samples:
            base, cpu = g.trace(s)
            e0 = errors(base, ref, keep, contact)

            two, cpu2 = g.trace(2 * s)
            alpha = math.log(e0[1] / errors(two, ref, keep, contact)[1]) / math.log(2.0)

            def line(label, ao, cpu_t, extra=0.0, rays=s):
                e = errors(ao, ref, keep, contact)
                rat = " ".join(f"{x / y:5.3f}" for x, y in zip(e, e0))
                # plain rays for this unburied MAE, (ratio)^(-1/α) × S, over the rays cast
                # (the short trace's counted as whole rays; the filter's CPU is in the column)
                fewer = (e[1] / e0[1]) ** (-1.0 / alpha) * s / rays
                print(f"{s:3d} {label:<26} {e[0]:7.4f} {e[1]:7.4f} {e[2]:7.4f} {e[3]:7.4f} | "
                      f"{rat} | {cpu_t:6.2f} + {extra:5.2f} | {fewer:5.2f}", flush=True)

            line("plain S", base, cpu)
            line("plain 2S", two, cpu2, rays=2 * s)
            near, cpu_near = g.near_open(a.near_rays, a.rho)
            for lam in a.lam:
                if not a.no_naive:
                    f, c = g.combine(base, s, lam)
                    line(f"normal, lam {lam:g}", f, cpu, c)
                for h in a.h:
                    f, c = g.combine(base, s, lam, h=h)
                    line(f"range h {h:g}, lam {lam:g}", f, cpu, c)
                    f, c = g.combine(base, s, lam, h=h, near=near, rho=a.rho)
                    line(f"range+near h {h:g}, lam {lam:g}", f, cpu, c + cpu_near,
                         rays=s + a.near_rays)
    return 0


if __name__ == "__main__":
    sys.exit(main())
