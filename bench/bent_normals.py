"""Bent normals: how far each estimate is from the ray-traced bent normals (bench/README.md).

    /usr/bin/python3 bench/bent_normals.py [--quick] [--scenes round_tree grove ...] [--no-real]

Per scene (examples/canopy_scenes.py, and the real Sapling Tree Gen scenes cached in
bench/out/real/*_quick.npz when present), the reference is the ray tracer's bent normal
(docs/DESIGN.md, 'Bent normals') at every vertex with 256 rays (seed 12345, each vertex
skipping only its own triangles, AO distance the scene's diagonal). Each estimate's mean angle
to it, in degrees, over all vertices and over the occluded ones (reference AO in (0.02, 0.9):
neither buried nor open sky), and over the canopy and ground vertices:

- normal: the surface normal itself (what a shader uses without a bent-normal map);
- rays 16 / 64: the ray tracer at fewer rays (seed 0: its noise against the reference's);
- grid 32 / 128: the density grid's transmittance-weighted mean direction (the leaves and
  branches voxelised as the grid rung does, resolution 48, 32 or 128 directions).

Prints a table (Markdown) with each estimate's seconds (and those of the 64-ray AO traced
without bent normals, for their own cost); no figure is checked here.
"""
from __future__ import annotations

import glob
import math
import os
import time

import harness  # noqa: E402  (addon/ and examples/ on sys.path)

HERE, REPO = harness.HERE, harness.REPO

import numpy as np  # noqa: E402

import canopy_scenes as cs  # noqa: E402
from canopy_ao import _core  # noqa: E402

REF_SAMPLES = 256
REF_SEED = 12345
SYNTHETIC = ("round_tree", "columnar_tree", "conifer", "grove", "grass_field")


def angles(a, b):
    """Degrees between rows of a and b (unit vectors; a zero row counts as 0°)."""
    c = np.clip(np.einsum("ij,ij->i", a.astype(np.float64), b.astype(np.float64)), -1.0, 1.0)
    return np.degrees(np.arccos(c))


def scene_arrays(name, quick):
    """(name, V, N, T, role per vertex, distance) of a synthetic scene."""
    sc = cs.make_scene(name, quick=quick)
    V, T, part = sc.merged()
    N = cs.vertex_normals(V, T).astype(np.float32)
    role = np.array([p.role for p in sc], dtype=object)[part]
    return name, V, N, T, role, sc.ao_distance()


def real_arrays(path):
    import real_scenes
    sc = real_scenes.RealScene(path)
    role = np.array([r.lower() for r in sc.role], dtype=object)
    return sc.name, sc.V, sc.N, sc.T, role, sc.distance


def run(name, V, N, T, role, distance):
    ids = np.arange(len(V), dtype=np.int32)
    tracer = _core.RayTracer(V, T)
    t0 = time.perf_counter()
    ref_ao, ref = tracer.ao(V, N, samples=REF_SAMPLES, distance=distance, seed=REF_SEED,
                            vertex_ids=ids, bent_normals=True)
    t_ref = time.perf_counter() - t0
    estimates = {"normal": (N / np.linalg.norm(N, axis=1, keepdims=True), 0.0)}
    for s in (16, 64):
        t0 = time.perf_counter()
        _ao, b = tracer.ao(V, N, samples=s, distance=distance, seed=0, vertex_ids=ids,
                           bent_normals=True)
        estimates[f"rays {s}"] = (b, time.perf_counter() - t0)
    t0 = time.perf_counter()  # the same trace without the bent normals: their own cost
    tracer.ao(V, N, samples=64, distance=distance, seed=0, vertex_ids=ids)
    t_ao = time.perf_counter() - t0
    wood = np.isin(role, ("canopy", "trunk"))
    keep = np.zeros(len(V), bool)
    keep[np.unique(T[wood[T[:, 0]]])] = True  # the grid's triangles: leaves and branches
    tri = T[wood[T[:, 0]]]
    if len(tri):
        grid = _core.DensityGrid(V, tri, resolution=48)
        for k in (32, 128):
            t0 = time.perf_counter()
            _ao, b = grid.ao(V, N, directions=k, distance=distance, bent_normals=True)
            estimates[f"grid {k}"] = (b, time.perf_counter() - t0)
    occluded = (ref_ao > 0.02) & (ref_ao < 0.9)
    rows = []
    for est, (b, sec) in estimates.items():
        a = angles(b, ref)
        cells = [a.mean(), a[occluded].mean() if occluded.any() else math.nan]
        for r in ("canopy", "ground"):
            m = role == r
            cells.append(a[m].mean() if m.any() else math.nan)
        rows.append((name, est, len(V), *cells, sec))
    return rows, t_ref, occluded.mean(), t_ao


def main(argv=None):
    ap = harness.parser(__doc__)
    ap.add_argument("--quick", action="store_true", help="the smaller scene sizes")
    ap.add_argument("--scenes", nargs="*", default=list(SYNTHETIC))
    ap.add_argument("--no-real", action="store_true", help="leave out bench/out/real scenes")
    args = ap.parse_args(argv)
    sources = [lambda n=n: scene_arrays(n, args.quick) for n in args.scenes]
    if not args.no_real:
        real = sorted(p for p in glob.glob(os.path.join(harness.REAL, "*_quick.npz"))
                      if "_embree_" not in p and "_cycles_" not in p)
        sources += [lambda p=p: real_arrays(p) for p in real]
    print(f"Mean angle (degrees) to the ray-traced bent normals at {REF_SAMPLES} rays; "
          "occluded = reference AO in (0.02, 0.9)\n")
    print("| scene | estimate | vertices | all | occluded | canopy | ground | seconds |")
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    for src in sources:
        name, V, N, T, role, d = src()
        rows, t_ref, frac, t_ao = run(name, V, N, T, role, d)
        for r in rows:
            cells = " | ".join("–" if math.isnan(x) else f"{x:.1f}" for x in r[3:7])
            print(f"| {r[0]} | {r[1]} | {r[2]} | {cells} | {r[7]:.2f} |")
        print(f"| {name} | (reference: {REF_SAMPLES} rays, {frac:.0%} occluded) | {len(V)} "
              f"| | | | | {t_ref:.2f} |")
        print(f"| {name} | (rays 64, AO without bent normals) | {len(V)} | | | | "
              f"| {t_ao:.2f} |", flush=True)


if __name__ == "__main__":
    main()
