"""Forest: ground AO cost per vertex against the number of instanced trees (docs/DESIGN.md,
'The method ladder': large occluders).

    /usr/bin/python3 bench/forest.py [--vertices 1e6] [--counts 10,100,1000,10000]
                                     [--epsilon 1e-2] [--side 1000]

One prototype, the round tree of examples/canopy_scenes.py (crown r ≈ 3 m at 5.5 m, 2.5 m
trunk), fitted once by the add-on's engine (4 ellipsoid shells + 1 solid trunk, τ calibrated
against Embree on the lone tree); N instances at
random places (fixed seed), random heading, scale 0.8–1.2, the same transforms the add-on gets
from Blender's depsgraph. Receivers: a ground grid of --vertices vertices, normals up.

Two tables, because "the tree count" can grow two ways:
- fixed ground (--side m square) with more and more trees: the density grows, so the occluders
  in reach of a ground point grow too; the cut-off bounds the cost by that local count
  ("in reach": mean over 2000 vertices of the occluders whose d_far reaches them), never by N;
  brute force (ε = 0: every shell for every vertex, timed on a subsample of ≤ 20k vertices) is
  O(N) per vertex.
- fixed density (the forest grows with N, 1 tree per 100 m² as the 10,000-tree, 1 km² case):
  ns per vertex should stay flat once the forest is wider than the cut-off reach.
Also printed: the largest AO change the cut-off makes on the subsample (against ε = 0).
Wall-clock on a shared 2-core machine; the field build (grid) is timed apart from evaluation.
--check also compares a small forest of real tree meshes with Embree (the law, not the speed;
the previous solid_opacity occluder law is printed alongside).
"""
from __future__ import annotations

import math
import time

import harness  # noqa: E402  (addon/ and examples/ on sys.path)

HERE, REPO = harness.HERE, harness.REPO

import numpy as np  # noqa: E402

import canopy_scenes as cs  # noqa: E402
from canopy_ao import core
from canopy_ao.core import forest  # noqa: E402


def prototype_plan():
    """The round tree fitted once by the engine, τ calibrated against Embree on the lone tree
    (as the add-on does for each prototype; not part of the timed evaluation)."""
    scene = cs.round_tree(seed=0, leaves=4000, ground=False)
    items = [core.SceneItem(p.name, p.role.upper(), "T", p.vertices,
                              cs.vertex_normals(p.vertices, p.triangles), p.triangles)
             for p in scene]
    return core.prepare(items, core.BakeSettings(method="shells", tau=None, shells=4))


def instance_matrices(count, side, seed=0):
    rng = np.random.default_rng(seed)
    a = rng.uniform(0, 2 * math.pi, count)
    s = rng.uniform(0.8, 1.2, count)
    m = np.zeros((count, 4, 4))
    m[:, 0, 0], m[:, 0, 1] = s * np.cos(a), -s * np.sin(a)
    m[:, 1, 0], m[:, 1, 1] = s * np.sin(a), s * np.cos(a)
    m[:, 2, 2] = s
    m[:, :2, 3] = rng.uniform(-side / 2, side / 2, (count, 2))
    m[:, 3, 3] = 1.0
    return m


def ground(vertices, side):
    k = int(round(math.sqrt(vertices)))
    x = np.linspace(-side / 2, side / 2, k, dtype=np.float32)
    X, Y = np.meshgrid(x, x)
    p = np.ascontiguousarray(np.stack([X.ravel(), Y.ravel(), np.zeros(k * k, np.float32)], 1))
    n = np.ascontiguousarray(np.tile(np.float32([0, 0, 1]), (k * k, 1)))
    return p, n


def in_reach(shells, epsilon, points, chunk=256):
    """Mean number of shells whose cut-off sphere (d_far about the centre, Shanmugam–Arikan
    Eq. 5) holds a point: the per-receiver work a perfect grid would leave (machine-free)."""
    c, _q, r = forest.shell_arrays(shells)
    far2 = (r.max(1) / math.sin(math.acos(1 - epsilon / (2 * math.pi)))) ** 2
    total = 0
    for i in range(0, len(points), chunk):
        d2 = ((points[i:i + chunk, None, :] - c[None]) ** 2).sum(-1)
        total += int(np.sum(d2 <= far2))
    return total / max(len(points), 1)


def run(proto, count, side, vertices, epsilon, sub):
    mats = instance_matrices(count, side)
    p, n = ground(vertices, side)
    pr = forest.prototype_from_plan(proto, "T", mats)
    t0 = time.perf_counter()
    f = forest.Forest([pr], epsilon=epsilon)
    build = time.perf_counter() - t0
    dt, ao = math.inf, None
    for _ in range(2):  # best of 2 when short: the machine is shared
        t0 = time.perf_counter()
        ao = f.ao(p, n)
        dt = min(dt, time.perf_counter() - t0)
        if dt > 20:
            break
    # ε = 0 costs every occluder for every vertex: at most ~1e8 pairs, at least 500 vertices.
    sub = int(min(sub, len(p), max(500, 1e8 / max(count * 5, 1))))
    idx = np.random.default_rng(1).choice(len(p), size=sub, replace=False)
    ps, ns = np.ascontiguousarray(p[idx]), np.ascontiguousarray(n[idx])
    brute = forest.Forest([pr], epsilon=0.0)
    t0 = time.perf_counter()
    full = brute.ao(ps, ns)
    dt_full = time.perf_counter() - t0
    shells = forest.instance_shells(pr.shells + pr.solids, mats)
    reach = in_reach(shells, epsilon, ps[:2000].astype(np.float64))
    return {
        "trees": count, "side": side, "shells": f.shell_count + f.solid_count,
        "reach": reach, "max_cand": f.max_candidates,
        "build_s": build, "eval_s": dt, "ns_vertex": dt / len(p) * 1e9,
        "ns_reach": dt / len(p) * 1e9 / max(reach, 1e-9),
        "brute_ns_vertex": dt_full / len(ps) * 1e9,
        "max_err": float(np.max(np.abs(ao[idx] - full))), "mean_ao": float(ao.mean()),
    }


def check_against_raytrace(proto, trees=36, side=60.0, points=3000, samples=256, distance=0.0):
    """The law, not the speed: a small forest of real tree meshes traced by Embree against the
    instances' occluders (and the same trees as real objects through the engine, which must
    agree with the instances: same law, same shells). distance > 0: the AO distance, for the
    rays and the occluders alike (and "ignoring it": the occluders without it)."""
    from canopy_ao import _core
    scene = cs.round_tree(seed=0, leaves=4000, ground=False)
    mats = instance_matrices(trees, side, seed=3)
    verts, tris, base, items = [], [], 0, []
    for i, m in enumerate(mats):
        for part in scene:
            v = (part.vertices @ m[:3, :3].T + m[:3, 3]).astype(np.float32)
            verts.append(v)
            tris.append(part.triangles + base)
            base += len(v)
            items.append(core.SceneItem(f"{part.name}{i}", part.role.upper(), f"T{i}", v,
                                          cs.vertex_normals(v, part.triangles), part.triangles))
    rng = np.random.default_rng(0)
    p = np.c_[rng.uniform(-side / 2 + 5, side / 2 - 5, (points, 2)), np.zeros(points)]
    p = np.ascontiguousarray(p, dtype=np.float32)
    n = np.ascontiguousarray(np.tile(np.float32([0, 0, 1]), (points, 1)))
    ref = _core.RayTracer(np.concatenate(verts), np.concatenate(tris).astype(np.int32)).ao(
        p, n, samples=samples, distance=distance if distance > 0 else math.inf)
    pr = forest.prototype_from_plan(proto, "T", mats)
    inst = forest.Forest([pr], epsilon=forest.DEFAULT_EPSILON, distance=distance).ao(p, n)
    ignoring = forest.Forest([pr], epsilon=forest.DEFAULT_EPSILON).ao(p, n)
    # The previous occluder law (solid sphere × mean-chord opacity), same shells and trunks.
    eps = forest.DEFAULT_EPSILON
    old = (_core.ao_occluders(p, n, forest.instance_shells(pr.shells, mats), float(pr.tau),
                              epsilon=eps, law="solid_opacity") *
           _core.ao_occluders(p, n, forest.instance_shells(pr.solids, mats), 1.0, epsilon=eps,
                              solid=True))
    ground = core.SceneItem("ground", "GROUND", "", p, n, np.zeros((0, 3), np.int32))
    plan = core.prepare(items + [ground], core.BakeSettings(method=proto.method,
                                                                  tau=proto.tau, shells=4,
                                                                  distance=distance))
    real = core.evaluate_item(plan, ground).ao
    print(f"\nAgainst Embree ({samples} rays, {points} ground points, {trees} real round trees "
          f"on {side:g} m, τ {proto.tau:.3g}, {proto.method}, AO distance "
          f"{distance if distance > 0 else 'unlimited'}):")
    rows = [("instances", inst), ("real objects", real), ("solid_opacity", old)]
    if distance > 0:
        rows.append(("instances ignoring the distance", ignoring))
    for name, a in rows:
        print(f"  {name:31s} mean AO {a.mean():.3f} (traced {ref.mean():.3f}), MAE "
              f"{np.abs(a - ref).mean():.3f}, bias {(a - ref).mean():+.3f}, "
              f"corr {np.corrcoef(a, ref)[0, 1]:.3f}")
    print(f"  instances vs real objects: max |Δ| {np.abs(inst - real).max():.4f}")


def table(title, rows):
    print(f"\n{title}")
    head = ("trees", "side m", "occluders", "in reach (mean)", "max cand", "build s", "eval s",
            "ns/vertex", "ns per occluder in reach", "ε=0 ns/vertex", "max |Δ| vs ε=0",
            "mean AO")
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for r in rows:
        print(f"| {r['trees']} | {r['side']:.0f} | {r['shells']} | {r['reach']:.0f} | "
              f"{r['max_cand']} | {r['build_s']:.2f} | {r['eval_s']:.2f} | "
              f"{r['ns_vertex']:.0f} | {r['ns_reach']:.0f} | {r['brute_ns_vertex']:.0f} | "
              f"{r['max_err']:.4f} | "
              f"{r['mean_ao']:.3f} |", flush=True)


def main(argv=None):
    ap = harness.parser(__doc__)
    ap.add_argument("--vertices", type=float, default=1e6)
    ap.add_argument("--counts", default="10,100,1000,10000")
    ap.add_argument("--epsilon", type=float, default=1e-2)
    ap.add_argument("--side", type=float, default=1000.0, help="fixed ground side, m")
    ap.add_argument("--density", type=float, default=0.01, help="trees per m², second table")
    ap.add_argument("--subsample", type=int, default=20000,
                    help="most vertices timed at ε = 0 (fewer for big forests: ≤ 1e8 pairs)")
    ap.add_argument("--check", action="store_true",
                    help="also compare a small forest with Embree (the law, not the speed)")
    ap.add_argument("--distance", type=float, default=0.0,
                    help="--check: AO distance for rays and occluders (0 = unlimited)")
    ap.add_argument("--check-only", action="store_true", help="only the --check comparison")
    args = ap.parse_args(argv)
    counts = [int(float(c)) for c in args.counts.split(",")]
    verts = int(args.vertices)
    proto = prototype_plan()
    ex = proto.proxies["T"]
    print(f"prototype: round tree, {len(ex)} shells (largest semi-axis "
          f"{max(float(np.max(e.radii)) for e in ex):.2f} m) + {len(proto.trunks.get('T', []))} "
          f"trunk, τ {proto.tau:.3g} (calibrated); "
          f"ground {int(round(math.sqrt(verts))) ** 2} vertices; "
          f"ε {args.epsilon:g}")
    if args.check_only:
        check_against_raytrace(proto, distance=args.distance)
        return
    table(f"Fixed ground, {args.side:.0f} m square (density grows with the count)",
          [run(proto, c, args.side, verts, args.epsilon, args.subsample) for c in counts])
    table(f"Fixed density, {args.density:g} trees/m² (the forest grows with the count)",
          [run(proto, c, math.sqrt(c / args.density), verts, args.epsilon, args.subsample)
           for c in counts])
    if args.check:
        check_against_raytrace(proto, distance=args.distance)


if __name__ == "__main__":
    main()
