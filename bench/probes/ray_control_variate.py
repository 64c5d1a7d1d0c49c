"""Probe, answered: the canopy proxy as a control variate saves at most 1.4x rays at 8 and none at 64; not built.

The canopy proxy as a control variate for the exact rung's rays (issue #39 item 1).

    /usr/bin/python3.11 bench/probes/ray_control_variate.py [--scenes sap_callistemon ...] \
        [--samples 8 16 32 64]

On the Sapling exports with a 1024-sample Cycles bake: each vertex's rays at S (the exact rung's
even deal, core/ray_budget.py) give a = mean_i V_i. A proxy whose visibility v(x, ω) along any
ray is known in closed form gives, for the *same* directions, v̄ = mean_i v_i, and its
hemisphere integral m(x) = (1/π) ∫ v (ω·n) dω. The control-variate estimate

    a_cv = a − β (v̄ − m)

has the same expectation as a and less variance when V_i and v_i correlate (variance × (1 − ρ²)
at the best β). The directions are the tracer's own (the lattice, Cranley–Patterson-rotated by
the vertex id's hash, raytrace.cpp's point_directions, around the vertex normal; the tracer
turns them around each corner's smooth normal, a hair away), checked against the tracer's bent
normals at open vertices. m is the mean of v over 256 stratified directions (another rotation).
Proxies:

- ``ellipsoid``: the minimum ellipsoid around the canopy and trunk vertices (the ellipsoid
  rung's fit) as a uniform medium, σ = leaf area / (2 × its volume) (the density grid's rule):
  v = exp(−σ × the chord of the ray's first D inside it), in closed form;
- ``grid``: the density grid (core/lighting.build_grid's DensityGrid, its finest level),
  v = exp(−∫σ) marched at half a voxel from one voxel out (its self-skip).

Prints per scene and S the MAE against Cycles' 1024 samples (all, unburied) of plain rays at S
and 2S and of a_cv at β = 1 and at the least-squares β fitted against the reference itself (an
oracle: an upper bound on the gain), with ρ, the correlation of the rays' error a − ref with
v̄ − m, and the CPU seconds of the proxy's rays (numpy here; only the correlation matters).

Measured (quick exports of the quaking aspen and the callistemon, S = 8 / 16 / 32 / 64; the
directions reproduce the tracer's, 0.00° median from its bent normals): the ellipsoid's
visibility does not correlate with the rays' (ρ 0.02-0.08; MAE 0.98-1.01 of plain rays at any β;
on the white birch and the small maple at 16 / 64, ``--proxies ellipsoid``, ρ 0.02-0.07 and MAE
0.998-1.001), though its rays in numpy already cost 0.35-1.3x Embree's CPU. The density grid's
does a little, less as S grows (ρ 0.37 / 0.29 / 0.22 / 0.14 on the aspen, 0.37 / 0.32 / 0.25 /
0.17 on the callistemon): unburied MAE at β = 1 0.82 / 0.93 / 1.00 / 1.04 of plain rays on the
aspen and 0.91 / 0.95 / 0.98 / 1.01 on the callistemon, at the oracle β 0.84 / 0.93 / 0.97 /
0.99 and 0.91 / 0.94 / 0.97 / 0.99, where twice the rays give 0.65-0.73. So at most 1.4x fewer
rays at S = 8 on the aspen (1.16x on the callistemon) before the proxy's own rays are paid, and
≤ 1.05x at S ≥ 32 (the add-on's default is 64): the lattice already stratifies away the smooth,
crown-scale part of the integrand, the only part a medium can predict; what is left is
individual leaves' edges, which no medium sees.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # bench/
import harness  # noqa: E402,F401  (addon/, examples/ and bench/ on sys.path)

import real_scenes as rs  # noqa: E402
from canopy_ao import _core  # noqa: E402
from canopy_ao.core import lighting, ray_budget  # noqa: E402

M64 = np.uint64(0xFFFFFFFFFFFFFFFF)
GOLDEN = 0x9E3779B97F4A7C15
MEAN_DIRECTIONS = 256


def mix64(z):
    """splitmix64's finaliser on uint64 arrays (raytrace.cpp's mix64)."""
    z = np.asarray(z, np.uint64)
    with np.errstate(over="ignore"):
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


def shifts(keys, seed):
    """(du, dv) float32 of raytrace.cpp's point_shift."""
    base = mix64(np.uint64(GOLDEN ^ seed))
    with np.errstate(over="ignore"):
        h = mix64(np.asarray(keys, np.uint64) + base)
    k24 = np.float32(1.0 / 16777216.0)
    du = (h >> np.uint64(40)).astype(np.float32) * k24
    dv = ((h >> np.uint64(8)) & np.uint64(0xFFFFFF)).astype(np.float32) * k24
    return du, dv


def onb(n):
    """Duff et al.'s basis (t, b) around unit normals n (N, 3)."""
    sign = np.where(n[:, 2] >= 0, 1.0, -1.0)
    a = -1.0 / (sign + n[:, 2])
    c = n[:, 0] * n[:, 1] * a
    t = np.stack([1.0 + sign * n[:, 0] ** 2 * a, sign * c, -sign * n[:, 0]], 1)
    b = np.stack([c, sign + n[:, 1] ** 2 * a, -n[:, 1]], 1)
    return t, b


def directions(normals, keys, count, seed):
    """float64 (N, count, 3): the lattice directions of each point (one count for all)."""
    i = np.arange(count)
    u0 = ((i + 0.5) / count).astype(np.float32)
    v = np.fmod(i * 0.6180339887498948482, 1.0)
    du, dv = shifts(keys, seed)
    u = u0[None, :] + du[:, None]
    u = np.where(u >= 1.0, u - 1.0, u).astype(np.float64)
    phi = 2 * np.pi * (v[None, :] + dv[:, None].astype(np.float64))
    r = np.sqrt(u)
    x, y, z = r * np.cos(phi), r * np.sin(phi), np.sqrt(np.maximum(0.0, 1.0 - u))
    n = normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-30)
    t, b = onb(n)
    return x[..., None] * t[:, None] + y[..., None] * b[:, None] + z[..., None] * n[:, None]


class EllipsoidProxy:
    def __init__(self, sc, distance):
        keep = np.isin(sc.role, ("canopy", "trunk"))
        e = _core.fit_ellipsoid(np.ascontiguousarray(sc.V[keep]))
        self.c = np.asarray(e.center, np.float64)
        self.A = np.asarray(e.axes, np.float64) * np.asarray(e.radii, np.float64)[None, :]
        self.Ainv = np.linalg.inv(self.A)
        tri = sc.T[np.isin(sc.role[sc.T[:, 0]], ("canopy", "trunk"))]
        v = sc.V.astype(np.float64)
        area = 0.5 * np.linalg.norm(np.cross(v[tri[:, 1]] - v[tri[:, 0]],
                                             v[tri[:, 2]] - v[tri[:, 0]]), axis=1).sum()
        self.sigma = area / (2.0 * float(e.volume()))
        self.D = distance

    def visibility(self, x, d):
        """x (N, 3), d (N, R, 3) unit: exp(−σ × chord in [0, D])."""
        p = (x - self.c) @ self.Ainv.T
        w = d @ self.Ainv.T
        aa = np.einsum("nrk,nrk->nr", w, w)
        bb = np.einsum("nrk,nk->nr", w, p)
        cc = np.einsum("nk,nk->n", p, p)[:, None] - 1.0
        disc = bb * bb - aa * cc
        s = np.sqrt(np.maximum(disc, 0.0))
        t0 = np.clip((-bb - s) / aa, 0.0, self.D)
        t1 = np.clip((-bb + s) / aa, 0.0, self.D)
        chord = np.where(disc > 0, t1 - t0, 0.0)
        return np.exp(-self.sigma * chord)


class GridProxy:
    def __init__(self, sc, distance):
        grid = lighting.build_grid(sc.engine_items())
        self.sigma = np.asarray(grid.sigma(0), np.float64)
        self.o = np.asarray(grid.origin, np.float64)
        self.h = float(grid.voxel_size)
        self.D = distance
        self.shape = np.array(self.sigma.shape)

    def visibility(self, x, d):
        step = 0.5 * self.h
        ext = np.linalg.norm(self.shape * self.h)
        n = int(np.ceil(min(self.D, ext) / step))
        depth = np.zeros(d.shape[:2])
        for k in range(n):
            t = self.h + (k + 0.5) * step
            if t > self.D:
                break
            q = np.floor(((x[:, None, :] + t * d) - self.o) / self.h).astype(np.int64)
            inside = np.all((q >= 0) & (q < self.shape), axis=2)
            qi = np.where(inside[..., None], q, 0)
            depth += np.where(inside, self.sigma[qi[..., 0], qi[..., 1], qi[..., 2]], 0.0) * step
        return np.exp(-depth)


def proxy_rays(proxy, sc, rays, chunk=2048):
    """(v̄ float64 (N,) over each vertex's own rays, CPU seconds)."""
    vbar = np.zeros(sc.n_vertices)
    t0 = time.process_time()
    V, N = sc.V.astype(np.float64), sc.N.astype(np.float64)
    for r in np.unique(rays):
        sel = np.flatnonzero(rays == r)
        for a in range(0, len(sel), chunk):
            s = sel[a:a + chunk]
            vbar[s] = proxy.visibility(V[s], directions(N[s], s, int(r), 0)).mean(1)
    return vbar, time.process_time() - t0


def proxy_integral(proxy, sc, chunk=256):
    """m float64 (N,): the proxy's AO, its v over MEAN_DIRECTIONS directions (another
    rotation)."""
    n = sc.n_vertices
    m = np.zeros(n)
    V, N = sc.V.astype(np.float64), sc.N.astype(np.float64)
    for a in range(0, n, chunk):
        s = np.arange(a, min(n, a + chunk))
        m[s] = proxy.visibility(V[s], directions(N[s], s + 7919 * n, MEAN_DIRECTIONS, 0)).mean(1)
    return m


def check_directions(tracer, sc, rays):
    """Median angle (degrees) between the tracer's bent normal and our directions' mean at the
    vertices whose every ray is open."""
    ids = np.arange(sc.n_vertices, dtype=np.int32)
    ao, bent = tracer.ao(sc.V, sc.N, samples=1, distance=sc.distance, seed=0, vertex_ids=ids,
                         per_corner=False, point_samples=rays.astype(np.int32),
                         bent_normals=True)
    open_ = np.flatnonzero(np.asarray(ao) >= 1.0)[:4000]
    if not len(open_):
        return float("nan")
    ours = np.stack([directions(sc.N[[v]].astype(np.float64), [v], int(rays[v]), 0)[0].sum(0)
                     for v in open_])
    ours /= np.linalg.norm(ours, axis=1, keepdims=True)
    cos = np.clip(np.einsum("ij,ij->i", ours, np.asarray(bent, np.float64)[open_]), -1, 1)
    return float(np.degrees(np.median(np.arccos(cos))))


def main(argv=None):
    ap = argparse.ArgumentParser(prog="ray_control_variate.py",
                                 description=__doc__.split("\n")[0])
    ap.add_argument("--scenes", nargs="*")
    ap.add_argument("--samples", type=int, nargs="+", default=[8, 16, 32, 64])
    ap.add_argument("--proxies", nargs="+", default=["ellipsoid", "grid"])
    a = ap.parse_args(argv)
    for name in a.scenes or harness.real_names(cycles=1024):
        sc = rs.load(name)
        ref = rs.cycles_ao(sc, 1024)
        if ref is None:
            continue
        ref = ref.astype(np.float64)
        tracer = rs.scene_tracer(sc)
        keep = ~rs.buried(sc, tracer)
        corners = tracer.vertex_corners(0, sc.n_vertices).astype(np.int64)
        proxies = {"ellipsoid": EllipsoidProxy, "grid": GridProxy}
        built = {p: proxies[p](sc, sc.distance) for p in a.proxies}
        integral = {p: proxy_integral(proxy, sc) for p, proxy in built.items()}
        print(f"\n{name}: {sc.n_vertices} vertices, {(~keep).sum()} buried, load "
              f"{os.getloadavg()[0]:.1f}")
        for s in a.samples:
            rays = ray_budget.vertex_rays(corners, s * tracer.corners_per_vertex)
            if s == a.samples[0]:
                print(f"  directions: median {check_directions(tracer, sc, rays):.2f}° from "
                      "the tracer's bent normal at open vertices")
            t0 = time.process_time()
            ao = ray_budget.trace_mesh(tracer, sc.V, sc.N, s, 0, sc.distance).astype(np.float64)
            cpu = time.process_time() - t0
            two = ray_budget.trace_mesh(tracer, sc.V, sc.N, 2 * s, 0, sc.distance)
            e = ao - ref
            base = np.abs(e).mean(), np.abs(e[keep]).mean()
            e2 = np.abs(two - ref)
            print(f"  S {s:3d}: plain {base[0]:.4f} / {base[1]:.4f} ({cpu:.2f} s); 2S "
                  f"{e2.mean() / base[0]:.3f} / {e2[keep].mean() / base[1]:.3f}")
            for p, proxy in built.items():
                vbar, pcpu = proxy_rays(proxy, sc, rays)
                c = vbar - integral[p]
                rho = float(np.corrcoef(e[keep], c[keep])[0, 1])
                beta = float(np.dot(e[keep], c[keep]) / max(np.dot(c[keep], c[keep]), 1e-30))
                out = []
                for b in (1.0, beta):
                    cv = np.clip(ao - b * c, 0.0, 1.0)
                    ec = np.abs(cv - ref)
                    out.append(f"{ec.mean() / base[0]:.3f} / {ec[keep].mean() / base[1]:.3f}")
                print(f"         {p:<9} rho {rho:+.3f}, beta* {beta:.2f}: cv(1) {out[0]}, "
                      f"cv(beta*) {out[1]}  (proxy rays {pcpu:.2f} s)", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
