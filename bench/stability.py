"""Where methods fail: every AO method against inputs that break naive code (docs/DESIGN.md,
'How we check ourselves').

    /usr/bin/python3 bench/stability.py [--timeout 30] [--out bench/out/stability.md]

Each case is a small scene (canopy triangles + receiver points with normals). Each method fits
its proxies to the canopy vertices and evaluates AO at the receivers. Every (case, method) pair
runs in a forked child with a time limit, so a crash or a hang is recorded instead of ending
the study. A cell reads:

    MAE 0.043 [0.31, 0.97]     finite result in [0, 1]; MAE against Embree at 256 rays, range
    ValueError: ...            a clear error (the accepted alternative)
    NaN! / OUT OF RANGE!       a bug
    CRASH (signal 11)          a bug
    TIMEOUT                    a bug
    -                          the function does not exist in this build

tests/python/test_stability.py runs the same cases (``CASES``, ``METHODS`` below) in-process and
asserts the accepted behaviours only.
"""
from __future__ import annotations

import multiprocessing as mp
import os
import sys
import time

import harness  # noqa: E402  (addon/ and examples/ on sys.path)

HERE, REPO = harness.HERE, harness.REPO

import numpy as np  # noqa: E402

import canopy_scenes as cs  # noqa: E402

try:
    from canopy_ao import _core  # noqa: E402
except Exception:  # pragma: no cover - the study reports it
    _core = None

TAU = 1.5


# === Cases =====================================================================================

def _crown(rng, n=300, center=(0, 0, 5), radii=(2, 2, 2), size=0.15):
    a = cs._in_crown(rng, n, [(np.asarray(center, float), np.asarray(radii, float))], 0.0)
    return cs.leaf_quads(a, cs._unit(rng, n), rng, size, size * 0.6)


def _case(verts, tris, points=None, normals=None, note=""):
    v = np.ascontiguousarray(np.asarray(verts, np.float64).reshape(-1, 3), dtype=np.float32)
    t = np.ascontiguousarray(np.asarray(tris, np.int64).reshape(-1, 3), dtype=np.int32)
    with np.errstate(all="ignore"):
        n_v = cs.vertex_normals(np.nan_to_num(v), t) if len(v) else np.zeros((0, 3), np.float32)
    if points is None:
        points, normals = v, n_v
    p = np.ascontiguousarray(np.asarray(points, np.float32).reshape(-1, 3))
    n = np.ascontiguousarray(np.asarray(normals, np.float32).reshape(-1, 3))
    return {"vertices": v, "triangles": t, "points": p, "normals": n, "note": note}


def case_flat_canopy():
    rng = np.random.default_rng(1)
    n = 200
    a = np.c_[rng.uniform(-3, 3, (n, 2)), np.full(n, 5.0)]
    v = np.repeat(a, 4, 0) + np.tile([[0, 0, 0], [.1, 0, 0], [.1, .1, 0], [0, .1, 0]], (n, 1))
    t = (np.array([[0, 1, 2], [0, 2, 3]])[None] + 4 * np.arange(n)[:, None, None]).reshape(-1, 3)
    return _case(v, t, note="200 horizontal leaves in the plane z = 5 (zero-thickness canopy)")


def case_line_of_leaves():
    n = 100
    x = np.linspace(0, 10, n)
    a = np.c_[x, np.zeros(n), np.full(n, 3.0)]
    v = np.repeat(a, 4, 0) + np.tile([[0, 0, 0], [.05, 0, 0], [.05, 0, 1e-3], [0, 0, 1e-3]], (n, 1))
    t = (np.array([[0, 1, 2], [0, 2, 3]])[None] + 4 * np.arange(n)[:, None, None]).reshape(-1, 3)
    return _case(v, t, note="100 leaves along the x axis, 1 mm tall: nearly collinear points")


def case_single_leaf():
    v = [[0, 0, 1], [0.1, 0, 1], [0.1, 0.06, 1.02], [0, 0.06, 1.02]]
    return _case(v, [[0, 1, 2], [0, 2, 3]], note="one quad: 4 coplanar points")


def case_coincident():
    v = np.tile([[1.0, 2.0, 3.0]], (12, 1))
    v[1::3] += [1e-7, 0, 0]
    t = np.arange(12).reshape(-1, 3)
    return _case(v, t, note="12 vertices at (almost) one point: degenerate triangles")


def case_outlier_branch():
    rng = np.random.default_rng(2)
    v, t, _ = _crown(rng)
    extra = np.array([[20, 0, 5], [20.1, 0, 5], [20.1, 0.1, 5]])
    return _case(np.r_[v, extra], np.r_[t, [[len(v), len(v) + 1, len(v) + 2]]],
                 note="a 2 m crown plus one leaf 20 m away (one long outlier branch)")


def case_hollow_shell():
    rng = np.random.default_rng(3)
    n = 400
    d = cs._unit(rng, n)
    v, t, _ = cs.leaf_quads(3.0 * d, d, rng, 0.2, 0.12)
    return _case(v, t, note="leaves only on a sphere of radius 3, facing out (empty interior)")


def case_two_trees_far():
    rng = np.random.default_rng(4)
    v1, t1, _ = _crown(rng, center=(0, 0, 5))
    v2, t2, _ = _crown(rng, center=(100, 0, 5))
    return _case(np.r_[v1, v2], np.r_[t1, t2 + len(v1)],
                 note="two 2 m crowns 100 m apart fitted as one tree")


def case_far_receivers():
    rng = np.random.default_rng(5)
    v, t, _ = _crown(rng)
    p = np.array([[1e3, 0, 0], [0, -1e3, 5], [0, 0, 1e3], [5, 5, 0], [0, 0, -50]], np.float32)
    n = np.array([[0, 0, 1], [0, 1, 0], [0, 0, -1], [0, 0, 1], [0, 0, 1]], np.float32)
    return _case(v, t, p, n, note="receivers 5-1000 m outside the shell, some facing it")


def case_boundary_leaves():
    rng = np.random.default_rng(6)
    v, t, _ = _crown(rng, center=(0, 0, 0), radii=(1, 1, 1))
    d = cs._unit(rng, 50)
    pts = np.r_[v, 2.0 * d]                    # 50 vertices exactly on the radius-2 sphere
    t2 = np.r_[t, np.arange(len(v), len(v) + 48).reshape(-1, 3)]
    nrm = cs.vertex_normals(pts, t2)
    return _case(pts, t2, np.r_[pts, 2.0 * d], np.r_[nrm, d],
                 note="vertices exactly on the enclosing sphere; receivers there facing out")


def _scaled(s):
    rng = np.random.default_rng(7)
    v, t, _ = _crown(rng)
    return _case(v * s, t, note=f"a 2 m crown scaled by {s:g}")


def case_scale_1e_3():
    return _scaled(1e-3)


def case_scale_1e4():
    return _scaled(1e4)


def case_zero_normals():
    rng = np.random.default_rng(8)
    v, t, _ = _crown(rng)
    c = _case(v, t, note="every receiver normal is (0, 0, 0)")
    c["normals"] = np.zeros_like(c["normals"])
    return c


def case_nan_coords():
    rng = np.random.default_rng(9)
    v, t, _ = _crown(rng)
    v = v.astype(np.float32)
    v[7] = np.nan
    c = _case(v, t, note="one vertex (and so one receiver) is NaN")
    return c


def case_empty_mesh():
    return _case(np.zeros((0, 3)), np.zeros((0, 3)), note="no vertices, no triangles")


def case_receivers_empty():
    rng = np.random.default_rng(10)
    v, t, _ = _crown(rng)
    return _case(v, t, np.zeros((0, 3)), np.zeros((0, 3)), note="a crown but no receivers")


CASES = {
    "flat canopy": case_flat_canopy,
    "line of leaves": case_line_of_leaves,
    "single leaf": case_single_leaf,
    "coincident points": case_coincident,
    "outlier branch": case_outlier_branch,
    "hollow shell": case_hollow_shell,
    "two trees far apart": case_two_trees_far,
    "receivers far outside": case_far_receivers,
    "leaves at the boundary": case_boundary_leaves,
    "scale 1e-3": case_scale_1e_3,
    "scale 1e4": case_scale_1e4,
    "zero normals": case_zero_normals,
    "NaN coords": case_nan_coords,
    "empty mesh": case_empty_mesh,
    "no receivers": case_receivers_empty,
}


# === Methods ===================================================================================
# Each takes a case and returns AO at case["points"]; None when this build lacks the function.

def _has(*names):
    return _core is not None and all(hasattr(_core, n) for n in names)


def m_raytrace(c):
    return _core.RayTracer(c["vertices"], c["triangles"]).ao(c["points"], c["normals"], samples=64)


def m_sphere(c):
    s = _core.fit_sphere(c["vertices"])
    return _core.ao_canopy_sphere(c["points"], c["normals"], s, TAU)


def m_sphere_trim(c):
    s = _core.fit_sphere(c["vertices"], trim=0.05)
    return _core.ao_canopy_sphere(c["points"], c["normals"], s, TAU)


def m_ellipsoid(c):
    e = _core.fit_ellipsoid(c["vertices"])
    return _core.ao_canopy_ellipsoid(c["points"], c["normals"], e, TAU)


def m_reeves_blau(c):
    e = _core.fit_ellipsoid(c["vertices"])
    return _core.ao_reeves_blau(c["points"], c["normals"], e, TAU)


def m_shells(c):
    shells, _ = _core.fit_shells(c["vertices"], 4)
    return _core.ao_canopy_shells(c["points"], c["normals"], list(shells), TAU)


def m_occluders(c):
    e = _core.fit_ellipsoid(c["vertices"])
    return _core.ao_occluders(c["points"], c["normals"], [e], TAU)


def m_grass(c):
    p = c["points"]
    ground = float(np.nanmin(p[:, 2])) if len(p) else 0.0
    return _core.ao_grass(p, c["normals"], ground, 0.3)


def m_grid(c):
    g = _core.DensityGrid(c["vertices"], c["triangles"])
    return g.ao(c["points"], c["normals"])


def m_medium_sphere(c):
    s = _core.fit_sphere(c["vertices"])
    return _core.ao_medium_sphere(c["points"], c["normals"], s, TAU)


def m_medium_shells(c):
    shells, _ = _core.fit_shells(c["vertices"], 4)
    return _core.ao_medium_shells(c["points"], c["normals"], list(shells), TAU)


def _engine_method(method):
    def run(c):
        from canopy_ao import core
        items = [core.SceneItem("leaves", "CANOPY", "t", c["vertices"],
                                  cs.vertex_normals(np.nan_to_num(c["vertices"]), c["triangles"])
                                  if len(c["vertices"]) else np.zeros((0, 3), np.float32),
                                  c["triangles"])]
        same = (c["points"].shape == c["vertices"].shape
                and np.array_equal(c["points"], c["vertices"], equal_nan=True))
        if same:
            items[0].normals = c["normals"]
        else:
            items.append(core.SceneItem("receivers", "GROUND", "", c["points"], c["normals"],
                                          np.zeros((0, 3), np.int32)))
        s = core.BakeSettings(method=method, tau=None if method == "auto" else TAU,
                                calibration_points=64, calibration_samples=32, samples=32)
        results, _ = core.bake(items, s)
        return results[0].ao if same else results[1].ao
    return run


METHODS = {
    "raytrace 64": (m_raytrace, ("RayTracer",)),
    "sphere": (m_sphere, ("fit_sphere", "ao_canopy_sphere")),
    "sphere trim 5%": (m_sphere_trim, ("fit_sphere", "ao_canopy_sphere")),
    "ellipsoid": (m_ellipsoid, ("fit_ellipsoid", "ao_canopy_ellipsoid")),
    "reeves-blau": (m_reeves_blau, ("fit_ellipsoid", "ao_reeves_blau")),
    "shells k=4": (m_shells, ("fit_shells", "ao_canopy_shells")),
    "occluders": (m_occluders, ("fit_ellipsoid", "ao_occluders")),
    "grass": (m_grass, ("ao_grass",)),
    "medium sphere": (m_medium_sphere, ("fit_sphere", "ao_medium_sphere")),
    "medium shells k=4": (m_medium_shells, ("fit_shells", "ao_medium_shells")),
    "density grid": (m_grid, ("DensityGrid",)),
    "engine auto": (_engine_method("auto"), ("RayTracer",)),
    "engine ellipsoid": (_engine_method("ellipsoid"), ()),
    "engine raytrace": (_engine_method("raytrace"), ("RayTracer",)),
    "engine grid": (_engine_method("grid"), ("DensityGrid",)),
}

ACCEPTED_ERRORS = (ValueError,)   # plus RuntimeError subclasses with a message (see classify)


def available(method):
    return _core is not None and _has(*METHODS[method][1])


def classify(result=None, exc=None, n_points=None):
    """(status, text): status in ok / error / bad."""
    if exc is not None:
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
        ok = isinstance(exc, (ValueError, RuntimeError)) and bool(msg)
        return ("error" if ok else "bad"), f"{type(exc).__name__}: {msg[:90]}"
    a = np.asarray(result, dtype=np.float64)
    if n_points is not None and a.shape != (n_points,):
        return "bad", f"SHAPE {a.shape}!"
    if a.size == 0:
        return "ok", "empty result"
    if not np.isfinite(a).all():
        return "bad", f"NaN! ({int((~np.isfinite(a)).sum())} of {a.size})"
    if a.min() < 0 or a.max() > 1:
        return "bad", f"OUT OF RANGE! [{a.min():.3g}, {a.max():.3g}]"
    return "ok", f"[{a.min():.2f}, {a.max():.2f}]"


# === Study =====================================================================================

def _child(conn, case_name, method):
    try:
        c = CASES[case_name]()
        fn = METHODS[method][0]
        out = np.asarray(fn(c), dtype=np.float32)
        conn.send(("result", out))
    except BaseException as exc:  # noqa: BLE001 - we tabulate whatever comes out
        conn.send(("exc", exc if _picklable(exc) else RuntimeError(str(exc))))
    conn.close()


def _picklable(exc):
    import pickle
    try:
        pickle.dumps(exc)
        return True
    except Exception:
        return False


def run_one(case_name, method, timeout):
    ctx = mp.get_context("fork")
    a, b = ctx.Pipe(duplex=False)
    p = ctx.Process(target=_child, args=(b, case_name, method))
    t0 = time.perf_counter()
    p.start()
    b.close()
    msg = None
    if a.poll(timeout):
        try:
            msg = a.recv()
        except EOFError:
            msg = None
    p.join(max(0.1, timeout - (time.perf_counter() - t0)))
    dt = time.perf_counter() - t0
    if p.is_alive():
        p.kill()
        p.join()
        return "bad", "TIMEOUT", dt, None
    if msg is None:
        return "bad", f"CRASH (exit {p.exitcode})", dt, None
    kind, payload = msg
    if kind == "exc":
        st, txt = classify(exc=payload)
        return st, txt, dt, None
    return (*classify(payload, n_points=None), dt, payload)


def reference(case):
    """Embree AO at 256 rays where the case is valid input for it, else None."""
    if not _has("RayTracer"):
        return None
    try:
        return np.asarray(_core.RayTracer(case["vertices"], case["triangles"]).ao(
            case["points"], case["normals"], samples=256, seed=99), np.float32)
    except Exception:
        return None


def main(argv=None):
    ap = harness.parser(__doc__)
    ap.add_argument("--timeout", type=float, default=30.0)
    ap.add_argument("--out", default=os.path.join(harness.OUT, "stability.md"))
    a = ap.parse_args(argv)
    methods = list(METHODS)
    lines = ["# Canopy AO — stability study", "",
             "Each cell: the method's result on the case — `MAE x [min, max]` against Embree at "
             "256 rays (finite, in [0, 1]), or the error it raised. Bugs are shouted: `NaN!`, "
             "`OUT OF RANGE!`, `CRASH`, `TIMEOUT`. `-` = not in this build. Every pair ran in a "
             f"forked child with a {a.timeout:g} s limit. τ = {TAU}.", "",
             "| case | " + " | ".join(methods) + " |", "|---" * (len(methods) + 1) + "|"]
    bad = 0
    t_start = time.perf_counter()
    for cname, make in CASES.items():
        case = make()
        ref = reference(case)
        cells = []
        for m in methods:
            if not available(m):
                cells.append("-")
                continue
            st, txt, dt, res = run_one(cname, m, a.timeout)
            if st == "ok" and ref is not None and res is not None and res.shape == ref.shape \
                    and res.size and np.isfinite(ref).all():
                txt = f"MAE {np.mean(np.abs(res - ref)):.3f} {txt}"
            if st == "bad":
                bad += 1
                txt = f"**{txt}**"
            cells.append(txt.replace("|", "/"))
            print(f"{cname:24s} {m:18s} {dt:6.2f} s  {st:5s} {txt}", flush=True)
        lines.append(f"| {cname} | " + " | ".join(cells) + " |")
    lines += ["", "Cases:", ""] + [f"- **{k}**: {f()['note']}" for k, f in CASES.items()]
    lines += ["", f"{bad} bad outcomes (NaN, out of range, crash, hang, or an error without a "
              f"message). Study took {time.perf_counter() - t_start:.1f} s."]
    os.makedirs(os.path.dirname(os.path.abspath(a.out)), exist_ok=True)
    with open(a.out, "w") as fh:
        fh.write("\n".join(lines) + "\n")
    print(f"stability: wrote {a.out} ({bad} bad outcomes)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
