"""Seeded random-input fuzz of every public function of canopy_ao._core.

    /usr/bin/python3 bench/fuzz.py [--cases 12000] [--seed 1] [--timeout 20] [--only NAME]

Each case draws one call: special values (0, -0, denormals, 1e-9 ... 3e38, inf, nan), extreme
magnitudes, odd shapes, dtypes and strides, out-of-range integers, hostile paths. Calls run in
a worker child process that the parent feeds one case at a time with a time limit: a hang (no
answer within --timeout s) or a crash (the child dies) is recorded against that case, and a
fresh child continues. A case passes when the call either
  - raises ValueError with a message (or CanopyAOError for a file the library cannot use), or
  - returns a result that is finite and in range: AO arrays float32 (N,) in [0, 1], fits with
    finite radii and orthonormal axes, texel normals of unit length, images finite.
Anything else (another exception type, NaN, a value outside [0, 1], a hang, a crash) fails.
Prints cases tried / failed by function and by kind, and the first failures with the case
number (re-run one case with --case N). tests/python/test_fuzz.py runs a short seeded run.
"""
import argparse
import json
import os
import select
import subprocess
import sys
import tempfile
import time
import traceback

import numpy as np

ADDON = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "addon"))

# === Value pools
SPECIAL = [0.0, -0.0, 1.0, -1.0, 0.5, 2.0, 1e-45, 1e-40, 1e-10, 1e-9, 1e-3, 1e9, 1e10, 1e11,
           1e19, 3e38, 1e300, float("inf"), float("-inf"), float("nan")]
SCALES = [1e-30, 1e-9, 1e-8, 1e-3] + [1.0] * 12 + [1e3, 3e8, 1e9, 1e10, 1e20, 3e38]
EDGE = [1e-9, 1.0001e-9, 1e-6, 1e6, 9.99e8, 1e10]  # lengths at the ends of the accepted range
INTS = [0, 1, 2, 3, 7, 64, -1, -2**31, 2**31 - 1, 2**31, 2**32, 2**63, 2**64, 2**100]
COUNTS = [0, 1, 2, 5, 33]


class Gen:
    """Draws arguments from one case's own random stream."""

    def __init__(self, seed, case):
        self.r = np.random.default_rng([seed, case])

    def pick(self, pool):
        return pool[int(self.r.integers(len(pool)))]

    def chance(self, p):
        return self.r.random() < p

    def scalar(self, lo=None, hi=None, p_special=0.08):
        """A float: usually in [lo, hi] (or a normal draw), sometimes a special value."""
        if self.chance(p_special):
            return float(self.pick(SPECIAL))
        if lo is None:
            return float(self.r.normal())
        return float(self.r.uniform(lo, hi))

    def integer(self, lo, hi, p_special=0.08):
        if self.chance(p_special):
            v = self.pick(INTS)
            return np.int64(v) if self.chance(0.1) and -2**63 <= v < 2**63 else v
        return int(self.r.integers(lo, hi + 1))

    def count(self):
        return self.pick(COUNTS)

    def mutate(self, a, p=0.08):
        """Sometimes a wrong dtype, shape, stride, or a special value inside."""
        if a.size and self.chance(p):
            a = a.copy()
            a.flat[int(self.r.integers(a.size))] = self.pick(SPECIAL)
        if self.chance(p / 3):
            a = a.astype(self.pick([np.float64, np.float16, np.int32, np.bool_]))
        if self.chance(p / 3) and a.ndim == 2:
            a = np.ascontiguousarray(np.repeat(a, 2, axis=0))[::2]  # non-contiguous
        if self.chance(p / 3):
            a = a.reshape(-1) if self.chance(0.5) else a[..., None]
        return a

    def points(self, n=None, center=0.0):
        n = self.count() if n is None else n
        with np.errstate(all="ignore"):
            a = (self.r.normal(size=(n, 3)) * self.pick(SCALES) + center).astype(np.float32)
        return self.mutate(a)

    def normals(self, n):
        v = self.r.normal(size=(n, 3))
        with np.errstate(all="ignore"):
            v /= np.linalg.norm(v, axis=1)[:, None]
            if n and self.chance(0.3):
                v[int(self.r.integers(n))] = 0
            if self.chance(0.2):
                v *= self.pick([1e-45, 1e-38, 1e-20, 1e19, 3e38])
            a = v.astype(np.float32)
        return self.mutate(a)

    def vec3(self, direction=False):
        if self.chance(0.1):
            return tuple(self.scalar(p_special=0.3) for _ in range(3))
        v = self.r.normal(size=3) * (1.0 if direction else self.pick(SCALES))
        return tuple(float(x) for x in v)

    def radius(self):
        if self.chance(0.1):
            return float(self.pick(EDGE))
        return self.scalar(0.05, 3.0, 0.03)

    def sphere(self, core):
        return core.Sphere(self.vec3() if self.chance(0.3) else (0, 0, 0), self.radius())

    def axes(self):
        q, _ = np.linalg.qr(self.r.normal(size=(3, 3)))
        if self.chance(0.1):
            q = q + self.r.normal(size=(3, 3)) * self.pick([1e-5, 1e-2, 1.0])
        return q

    def ellipsoid(self, core):
        radii = tuple(self.radius() for _ in range(3))
        centre = self.vec3() if self.chance(0.3) else (0, 0, 0)
        return core.Ellipsoid(centre, self.axes(), radii)

    def shells(self, core):
        return [self.ellipsoid(core) for _ in range(int(self.r.integers(1, 4)))]

    def tau(self):
        if self.chance(0.05):
            return float(self.pick([1e-30, 100.0, 1e6, 3e38]))
        return self.scalar(0.0, 4.0)

    def mesh(self, leaves=None):
        leaves = int(self.r.integers(0, 60)) if leaves is None else leaves
        scale = self.pick(SCALES) if self.chance(0.3) else 1.0
        with np.errstate(all="ignore"):
            c = self.r.normal(size=(leaves, 1, 3))
            v = (c + 0.1 * self.r.normal(size=(leaves, 3, 3))).reshape(-1, 3) * scale
            v = v.astype(np.float32)
        t = np.arange(3 * leaves, dtype=np.int32).reshape(leaves, 3)
        if leaves and self.chance(0.1):
            t = t.copy()
            t.flat[int(self.r.integers(t.size))] = self.pick([-1, 3 * leaves, 2**31 - 1])
        return self.mutate(v, 0.1), self.mutate(t, 0.05)

    def path(self, tmp):
        name = self.pick([b"a.exr", b"a.png", b"caf\xe9.exr", b"a#%04d?:*.exr", b"a\0b.exr",
                          b"", b"noext", b"a.unknownext", b"missing_dir/a.exr", b"a.tif"])
        full = os.fsencode(tmp) + b"/" + name if name else b""
        return full if self.chance(0.5) else os.fsdecode(full)


# === Result checks
def check_ao(r, n=None):
    assert isinstance(r, np.ndarray) and r.dtype == np.float32 and r.ndim == 1, "not float32 (N,)"
    assert n is None or r.shape == (n,), f"shape {r.shape}, expected ({n},)"
    assert np.all(np.isfinite(r)), "non-finite AO"
    assert np.all((r >= 0) & (r <= 1)), f"AO outside [0, 1]: {r.min()} .. {r.max()}"


def check_unit_interval(x):
    assert np.isfinite(x) and 0 <= x <= 1, f"{x} outside [0, 1]"


def check_sphere(s):
    assert np.all(np.isfinite(s.center)) and np.isfinite(s.radius) and s.radius >= 0, repr(s)


def check_ellipsoid(e):
    assert np.all(np.isfinite(e.center)) and np.all(np.isfinite(e.radii)), repr(e)
    assert np.all(e.radii > 0), repr(e)
    assert np.allclose(e.axes.T @ e.axes, np.eye(3), atol=2e-3), "axes not orthonormal"


def check_texels(t):
    n = len(t)
    assert t.positions.shape == (n, 3) and np.all(np.isfinite(t.positions)), "texel positions"
    assert np.allclose(np.linalg.norm(t.normals, axis=1), 1, atol=1e-3), "texel normals not unit"
    assert np.all((t.pixels >= 0) & (t.pixels < t.width * t.height)), "pixel index out of range"
    assert np.all(np.isfinite(t.barycentrics)), "barycentrics"


def check_image(a):
    assert isinstance(a, np.ndarray) and np.all(np.isfinite(a)), "non-finite image"


# === Cases: one generator per public function (name -> fn(gen, core, tmp) -> (call, check))
def receivers(g):
    n = g.count()
    return g.points(n), g.normals(n), n


def c_sphere(g, core, tmp):
    return (lambda: core.Sphere(g.vec3(), g.scalar(0, 3))), check_sphere


def c_ellipsoid(g, core, tmp):
    radii = tuple(g.scalar(0.01, 3) for _ in range(3))
    return (lambda: core.Ellipsoid(g.vec3(), g.axes(), radii)), check_ellipsoid


def c_contains(g, core, tmp):
    shape = g.sphere(core) if g.chance(0.5) else g.ellipsoid(core)
    p = g.points()
    return (lambda: shape.contains(p, g.scalar(0, 1e-3))), None


def c_from_sphere(g, core, tmp):
    return (lambda: core.Ellipsoid.from_sphere(g.sphere(core))), check_ellipsoid


def c_fit_sphere(g, core, tmp):
    return (lambda: core.fit_sphere(g.points(), g.scalar(0, 0.4))), check_sphere


def c_fit_ellipsoid(g, core, tmp):
    kw = dict(trim=g.scalar(0, 0.4, 0.1), method=g.pick(["auto", "khachiyan", "pca", "x"]),
              tolerance=g.scalar(1e-4, 0.1, 0.1), max_points=g.integer(4, 500, 0.1),
              min_radius_ratio=g.scalar(1e-3, 0.5, 0.1))
    return (lambda: core.fit_ellipsoid(g.points(), **kw)), check_ellipsoid


def c_fit_shells(g, core, tmp):
    p = g.points()

    def check(r):
        shells, labels = r
        for e in shells:
            check_ellipsoid(e)
        assert labels.dtype == np.int32 and labels.shape == (p.shape[0],)
        assert np.all((labels >= 0) & (labels < max(len(shells), 1)))
    kw = dict(kind=g.pick(["ellipsoid", "sphere", "cube"]), trim=g.scalar(0, 0.4, 0.1),
              seed=g.integer(0, 100, 0.1), max_iterations=g.integer(1, 50, 0.1))
    return (lambda: core.fit_shells(p, g.integer(1, 6), **kw)), check


def ao_case(fn):
    def case(g, core, tmp):
        p, nrm, n = receivers(g)
        call = fn(g, core, p, nrm)
        return call, (lambda r: check_ao(r, n))
    return case


c_canopy_sphere = ao_case(lambda g, core, p, n: lambda: core.ao_canopy_sphere(
    p, n, g.sphere(core), g.tau(), g.scalar(0, 0.5, 0.1)))
c_canopy_ellipsoid = ao_case(lambda g, core, p, n: lambda: core.ao_canopy_ellipsoid(
    p, n, g.ellipsoid(core), g.tau(), g.scalar(0, 0.5, 0.1)))
c_canopy_shells = ao_case(lambda g, core, p, n: lambda: core.ao_canopy_shells(
    p, n, g.shells(core), g.tau(), g.pick(["product", "nearest", "max"]),
    g.scalar(0, 0.5, 0.1)))
c_reeves_blau = ao_case(lambda g, core, p, n: lambda: core.ao_reeves_blau(
    p, n, g.ellipsoid(core), g.tau()))
c_occluders = ao_case(lambda g, core, p, n: lambda: core.ao_occluders(
    p, n, g.shells(core), g.tau(), g.scalar(0, 0.1), g.chance(0.3),
    g.pick(["medium", "solid_opacity", "soft"])))
c_occluder_field = ao_case(lambda g, core, p, n: lambda: core.OccluderField(
    g.shells(core), g.tau(), g.scalar(0, 0.1), g.chance(0.3),
    g.pick(["medium", "solid_opacity"])).ao(p, n))


def c_scene_plan(g, core, tmp):
    p, nrm, n = receivers(g)
    trees = int(g.r.integers(0, 5))
    crowns = [None if g.chance(0.3) else (g.sphere(core), g.ellipsoid(core), g.shells(core))
              for _ in range(trees)]
    trunks = [g.shells(core) if g.chance(0.5) else [] for _ in range(trees)]
    roles = ["CANOPY", "TRUNK", "GROUND", "GRASS"]
    role = g.pick(roles) if g.chance(0.95) else "LEAF"
    if g.chance(0.8):
        tree = g.integer(-1, trees - 1)
    else:
        tree = g.r.integers(-1, max(trees, 1), n, dtype=np.int32)
    tau = [g.tau() for _ in range(trees if g.chance(0.9) else trees + 1)] \
        if g.chance(0.5) else g.tau()
    grass = (g.scalar(-1, 1), g.scalar(0.05, 2)) if role == "GRASS" or g.chance(0.03) else None
    kw = dict(distance=g.scalar(0.1, 10) if g.chance(0.3) else float("inf"),
              epsilon=g.scalar(0, 0.1))
    methods = ["sphere", "ellipsoid", "reeves_blau", "shells", "medium"]
    method = g.pick(methods) if g.chance(0.95) else "grid"
    covers = [grass_cover(g, core) for _ in range(int(g.r.integers(1, 3)))] \
        if g.chance(0.25) else []
    forest = forest_occluders(g, core) if g.chance(0.25) else None

    def call():
        plan = core.ScenePlan(crowns, trunks, grass_covers=covers, **kw)
        plan.set_forest(forest)
        return plan.evaluate(p, nrm, role, tree, method, tau, grass)
    return call, (lambda r: check_ao(r, n))


def grass_cover(g, core):
    """A GrassCover over a random footprint (sometimes bad data, refused at construction)."""
    width = g.integer(1, 40)
    span = 40 * (int(width) if 1 <= int(width) <= 40 else 40)
    keys = np.unique(g.r.integers(0, span, int(g.r.integers(0, 30))))
    if g.chance(0.1):
        keys = keys[::-1].copy()
    return core.GrassCover(g.scalar(-1, 1), g.scalar(0.01, 2), g.scalar(0, 1), g.scalar(0.01, 1),
                           (g.scalar(-3, 0), g.scalar(-3, 0)), width, g.mutate(keys, 0.05))


def forest_occluders(g, core):
    crowns = [(g.shells(core), g.tau()) for _ in range(int(g.r.integers(0, 3)))]
    solids = g.shells(core) if g.chance(0.5) else []
    return core.ForestOccluders(crowns, solids, g.scalar(0, 0.1),
                                g.scalar(0.1, 10) if g.chance(0.3) else float("inf"))


def c_grass_cover(g, core, tmp):
    p, _nrm, n = receivers(g)
    return (lambda: grass_cover(g, core).ground_visibility(p)), (lambda r: check_ao(r, n))


def c_forest_occluders(g, core, tmp):
    p, nrm, n = receivers(g)
    return (lambda: forest_occluders(g, core).ao(p, nrm)), (lambda r: check_ao(r, n))


c_grass = ao_case(lambda g, core, p, n: lambda: core.ao_grass(
    p, n, g.scalar(-1, 1), g.scalar(0.05, 2), g.vec3(direction=True), g.scalar(0, 1, 0.2)))
c_medium_sphere = ao_case(lambda g, core, p, n: lambda: core.ao_medium_sphere(
    p, n, g.sphere(core), g.tau()))
c_medium_ellipsoid = ao_case(lambda g, core, p, n: lambda: core.ao_medium_ellipsoid(
    p, n, g.ellipsoid(core), g.tau()))


def c_medium_shells(g, core, tmp):
    p, nrm, n = receivers(g)
    shells = g.shells(core)
    tau = g.tau() if g.chance(0.5) else [g.tau() for _ in range(g.pick([len(shells), 1, 5]))]
    return (lambda: core.ao_medium_shells(p, nrm, shells, tau,
                                          g.pick(["product", "nearest", "x"]))), \
        (lambda r: check_ao(r, n))


def c_shell_opacity(g, core, tmp):
    return (lambda: core.shell_opacity(g.tau())), check_unit_interval


def c_patch_visibility(g, core, tmp):
    k = int(g.r.integers(0, 4))
    counts = g.r.integers(3, 9, k).astype(np.int32)
    scale = g.pick(SCALES) if g.chance(0.3) else 1.0
    with np.errstate(all="ignore"):
        m = g.r.normal(size=(k, 3))
        m /= np.linalg.norm(m, axis=1)[:, None]
        corners = g.r.normal(size=(int(counts.sum()), 3)) * scale
        planes = np.column_stack([m, g.r.normal(size=k) * scale,
                                  g.r.uniform(0.1, 3, k) * scale])
    p, n, count = receivers(g)
    p, n = (g.mutate(a.astype(np.float64)) for a in (p, n))
    distance = g.pick([np.inf, g.radius()])
    near = g.pick([0.0, g.radius()])
    call = (lambda: core.patch_visibility(g.mutate(corners), g.mutate(counts), g.mutate(planes),
                                          p, n, distance, near))
    return call, (lambda r: check_ao(r, count))


def c_sphere_occlusion(g, core, tmp):
    return (lambda: core.sphere_occlusion(g.scalar(-1, 1), g.scalar(0, 1.5))), \
        check_unit_interval


def c_medium_ao(g, core, tmp):
    return (lambda: core.medium_ao(g.scalar(0, 12), g.scalar(-1, 1), g.tau())), \
        check_unit_interval


def c_medium_quadrature(g, core, tmp):
    return (lambda: core.medium_ao_quadrature(g.scalar(0, 12), g.scalar(-1, 1), g.tau(),
                                              g.integer(1, 512))), check_unit_interval


def c_raytracer(g, core, tmp):
    v, t = g.mesh()
    p, nrm, n = receivers(g)
    kw = dict(samples=g.integer(1, 64), distance=g.scalar(0.1, 10), seed=g.integer(0, 9),
              offset=g.scalar(-1, 0.01, 0.2))
    return (lambda: core.RayTracer(v, t).ao(p, nrm, **kw)), (lambda r: check_ao(r, n))


def c_raytracer_bake_point(g, core, tmp):
    """The tracer with vertex normals (and sometimes faces): its own vertices and triangles as
    receivers, at Cycles' bake point (native raytrace.h, 'Origins')."""
    v, t = g.mesh()
    nv = len(v) if isinstance(v, np.ndarray) and v.ndim == 2 else 0
    vn = g.normals(nv) if not g.chance(0.05) else g.normals(max(nv - 1, 0))
    mt = len(t) if isinstance(t, np.ndarray) and t.ndim == 2 else 0
    polys = None
    if g.chance(0.5):
        polys = g.mutate((np.arange(mt) // int(g.r.integers(1, 4))).astype(np.int32), 0.05)
    n = int(g.r.integers(0, nv + 1)) if nv else 0  # a count, not a special value to allocate
    own = {}
    if n and g.chance(0.5):
        own["vertex_ids"] = g.mutate(g.r.integers(-1, nv, size=n).astype(np.int32), 0.05)
    elif n and mt:
        own["triangle_ids"] = g.mutate(g.r.integers(-1, mt, size=n).astype(np.int32), 0.05)
    p = v[:n] if nv else g.points(0)
    nrm = g.normals(n)
    kw = dict(samples=g.integer(1, 64), distance=g.scalar(0.1, 10), seed=g.integer(0, 9), **own)
    return (lambda: core.RayTracer(v, t, normals=vn, polygons=polys).ao(p, nrm, **kw)), \
        (lambda r: check_ao(r, n))


def c_ao_raytrace(g, core, tmp):
    v, t = g.mesh()
    p, nrm, n = receivers(g)
    kw = dict(samples=g.integer(1, 64), distance=g.scalar(0.1, 10), seed=g.integer(0, 9))
    return (lambda: core.ao_raytrace(v, t, p, nrm, **kw)), (lambda r: check_ao(r, n))


def grid_of(g, core):
    v, t = g.mesh()
    return core.DensityGrid(v, t, g.integer(1, 32, 0.2))


def c_density_grid(g, core, tmp):
    p, nrm, n = receivers(g)
    kw = dict(directions=g.integer(1, 64), distance=g.scalar(0.1, 10), seed=g.integer(0, 9),
              sigma_scale=g.scalar(0, 3), self_skip=g.scalar(0, 2), start=g.scalar(0, 1))
    return (lambda: grid_of(g, core).ao(p, nrm, **kw)), (lambda r: check_ao(r, n))


def c_optical_depth(g, core, tmp):
    def check(x):
        assert np.isfinite(x) and x >= 0, x
    return (lambda: grid_of(g, core).optical_depth(
        g.vec3(), g.vec3(direction=g.chance(0.5)), g.scalar(0.1, 10),
        g.scalar(0, 2))), check


def c_grid_sigma(g, core, tmp):
    def check(a):
        assert np.all(np.isfinite(a)) and np.all(a >= 0)
    return (lambda: grid_of(g, core).sigma(g.integer(0, 3))), check


def c_near_far(g, core, tmp):
    v, t = g.mesh()
    p, nrm, n = receivers(g)
    kw = dict(samples=g.integer(1, 32), directions=g.integer(1, 32),
              distance=g.scalar(0.1, 10), seed=g.integer(0, 9), sigma_scale=g.scalar(0, 2))
    return (lambda: core.ao_near_far(core.RayTracer(v, t), core.DensityGrid(v, t, 8), p, nrm,
                                     g.scalar(0.01, 1), **kw)), (lambda r: check_ao(r, n))


def corners(g, m, d):
    with np.errstate(all="ignore"):
        a = (g.r.normal(size=(3 * m, d)) * (g.pick(SCALES) if g.chance(0.2) else 1.0))
        a = a.astype(np.float32)
    if g.chance(0.5):
        a = a.reshape(m, 3, d)
    return g.mutate(a, 0.1)


def c_rasterize(g, core, tmp):
    m = int(g.r.integers(0, 12))
    uvs = corners(g, m, 2)
    if not g.chance(0.2):
        uvs = np.abs(uvs) % 1 if uvs.dtype == np.float32 else uvs
    pos = corners(g, m, 3)
    nrm = None if g.chance(0.4) else corners(g, m, 3)
    res = g.pick([1, 4, 16, 64, (8, 3), 0, 16385, -1, 2**31, (4,), 2.5])
    return (lambda: core.rasterize_uv(uvs, pos, nrm, res, g.chance(0.7))), check_texels


def c_texel_splat(g, core, tmp):
    m = int(g.r.integers(1, 6))
    uvs = np.abs(g.r.normal(size=(3 * m, 2))).astype(np.float32) % 1
    t = core.rasterize_uv(uvs, g.r.normal(size=(3 * m, 3)).astype(np.float32), None, 8)
    vals = g.mutate(g.r.random(size=(len(t),)).astype(np.float32), 0.2)
    return (lambda: t.splat(vals, g.integer(0, 20), g.scalar(0, 1, 0.2))), check_image


def c_splat_texels(g, core, tmp):
    n = g.count()
    w = g.pick([1, 4, 16, 0, 2**31])
    pix = g.mutate(g.r.integers(-1, 20, size=n).astype(np.int32), 0.1)
    vals = g.mutate(g.r.random(size=(n, g.pick([1, 1, 3, 4, 5]))).astype(np.float32), 0.2)
    if g.chance(0.5) and vals.ndim == 2:
        vals = np.ascontiguousarray(vals[:, 0])
    return (lambda: core.splat_texels(pix, vals, w, g.integer(0, 20), g.scalar(0, 1, 0.2),
                                      g.chance(0.3))), None


def c_dilate(g, core, tmp):
    h, w = int(g.r.integers(1, 9)), int(g.r.integers(1, 9))
    img = g.mutate(g.r.random(size=(h, w)).astype(np.float32), 0.1)
    mask = (g.r.random(size=(h, w)) < 0.3).astype(np.uint8)
    if g.chance(0.1):
        mask = mask[:, :-1] if w > 1 else mask.astype(np.int32)

    def call():
        core.dilate_margin(img, mask, g.integer(0, 10))
        return img
    return call, None


def c_write_read(g, core, tmp):
    img = g.mutate(g.r.random(size=(int(g.r.integers(1, 5)), int(g.r.integers(1, 5)),
                                    g.pick([1, 3, 4]))).astype(np.float32), 0.1)
    path = g.path(tmp)
    dtype = g.pick(["auto", "float", "half", "uint16", "uint8", "int7"])
    attrs = g.pick([None, None, {"canopy_ao": '{"owner": "Tree.001"}'}, {"a_1": "", "B": "é"}, {"a_1": "x", "B": "é"},
                    {"bad name": "x"}, {"": "x"}, {"k": 3}, {"k": "a\0b"}, ["k"]])

    def call():
        core.write_image(path, img, dtype, g.chance(0.8), attrs)
        out = core.read_image(path, g.chance(0.8))
        got = core.read_image_attributes(path)
        assert isinstance(got, dict) and all(isinstance(v, str) for v in got.values())
        if isinstance(attrs, dict) and os.fsdecode(path).endswith(".exr"):
            assert all(got.get(k) == v for k, v in attrs.items()), f"header {got} lost {attrs}"
        for f in os.listdir(tmp):
            os.remove(os.path.join(tmp, f))
        return out
    return call, check_image


def c_properties(g, core, tmp):
    """The remaining methods and properties: volume, pickling, repr, the objects' sizes."""
    import pickle

    def call():
        e, sph = g.ellipsoid(core), g.sphere(core)
        assert np.isfinite(e.volume()) and e.volume() > 0
        for obj in (e, sph):  # unpickling re-orthonormalises the axes: equal to ~1 ulp
            back = pickle.loads(pickle.dumps(obj))
            for field in ("center", "radius", "radii", "axes"):
                if hasattr(obj, field):
                    assert np.allclose(getattr(back, field), getattr(obj, field), rtol=1e-6,
                                       atol=1e-6), f"pickled {field} differs"
        v, t = g.mesh()
        grid, tracer = core.DensityGrid(v, t, g.integer(1, 16)), core.RayTracer(v, t)
        field = core.OccluderField(g.shells(core), g.tau())
        assert np.isfinite(grid.voxel_size) and grid.levels >= 1 and len(grid.shape) == 3
        assert np.all(np.isfinite(grid.origin)) and np.isfinite(grid.total_area)
        assert tracer.vertex_count == len(v) and np.isfinite(tracer.auto_offset)
        assert field.max_candidates <= len(field)
        return [repr(x) for x in (grid, tracer)]
    return call, None


def c_to_world(g, core, tmp):
    p, nrm, n = receivers(g)
    m = None if g.chance(0.2) else g.mutate(np.vstack([np.c_[g.axes() * g.scalar(0.1, 3),
                                                             g.vec3()], [0, 0, 0, 1]]))

    def call():
        core.to_world(p, nrm, m)
        return nrm

    def check(r):
        assert np.allclose(np.linalg.norm(r.astype(np.float64), axis=1), 1, atol=1e-5), \
            "normals not unit"
    return call, check


def c_gray_rgba(g, core, tmp):
    v = g.mutate(g.r.random(g.count()).astype(np.float32))

    def check(r):
        assert r.shape == (len(v), 4) and np.all(r[:, 3] == 1), "not (N, 4) with alpha 1"
        assert np.array_equal(r[:, 0], v, equal_nan=True), "grey is not the value"
    return (lambda: core.gray_rgba(v)), check


def c_connected_components(g, core, tmp):
    v, t = g.mesh()
    n = g.integer(0, 3 * len(t) + 2) if g.chance(0.3) else len(v)

    def check(r):
        assert r.shape == (n,) and r.dtype == np.int64, "not int64 (n_vertices,)"
        if n:
            _, first = np.unique(r, return_index=True)
            assert r.min() == 0 and np.all(np.diff(first) > 0), "not numbered by first vertex"
    return (lambda: core.connected_components(n, t)), check


def c_stage_profiling(g, core, tmp):
    def call():
        previous = core.set_stage_profiling(g.chance(0.5))
        got = core.take_stage_seconds()
        core.set_stage_profiling(previous)
        assert isinstance(got, dict) and all(s >= 0 and k >= 1 for s, k in got.values())
    return call, None


def c_threads(g, core, tmp):
    def call():
        previous = core.set_max_threads(g.integer(0, 4))
        assert core.max_threads() >= 1
        core.set_max_threads(previous)
    return call, None


CASES = {name[2:]: fn for name, fn in sorted(globals().items()) if name.startswith("c_")}


# === Worker: runs cases it is told to, one JSON line back each
def run_case(core, tmp, seed, case, only=None):
    names = [only] if only else sorted(CASES)
    g = Gen(seed, case)
    name = names[case % len(names)]
    if name == "selftest_hang":
        time.sleep(3600)
    if name == "selftest_crash":
        os.abort()
    try:
        call, check = CASES[name](g, core, tmp)
    except ValueError as e:  # a proxy or mesh the generator built was refused: fine
        return name, "rejected", str(e)[:200] or "(empty message)"
    try:
        with np.errstate(all="ignore"):
            result = call()
    except ValueError as e:
        msg = str(e)
        return name, ("rejected" if msg else "fail"), msg[:200] or "ValueError without message"
    except core.CanopyAOError as e:
        if name == "write_read" and str(e):
            return name, "rejected", str(e)[:200]
        return name, "fail", f"CanopyAOError: {e}"[:300]
    except Exception as e:  # noqa: BLE001 - every other type is a finding
        return name, "fail", f"{type(e).__name__}: {e}"[:300]
    try:
        if check is not None:
            with np.errstate(all="ignore"):
                check(result)
    except AssertionError as e:
        return name, "fail", f"bad result: {e}"[:300]
    except Exception:  # noqa: BLE001
        return name, "fail", "check raised: " + traceback.format_exc(limit=1)[-300:]
    return name, "ok", ""


def worker(seed, only):
    sys.path.insert(0, ADDON)
    from canopy_ao import _core as core
    core.medium_ao(0.5, 0.5, 1.0)  # build the medium table before the first timed call
    sys.stdout.write(Runner.PREFIX + "ready\n")
    sys.stdout.flush()
    with tempfile.TemporaryDirectory() as tmp:
        for line in sys.stdin:
            case = int(line)
            name, status, detail = run_case(core, tmp, seed, case, only)
            sys.stdout.write(Runner.PREFIX + json.dumps([case, name, status, detail]) + "\n")
            sys.stdout.flush()


# === Parent: feeds cases, enforces the time limit, attributes hangs and crashes
class Runner:
    """Feeds case numbers to a worker process (cmd) one at a time, one JSON answer line each
    ([case, name, status, detail], after PREFIX); the worker prints PREFIX + "ready" once it
    has started (untimed). Lines without PREFIX are the worker's own noise (Blender's)."""

    PREFIX = "@@fuzz "

    def __init__(self, cmd, timeout, start_timeout=180.0, env=None):
        self.cmd, self.timeout, self.start_timeout, self.env = cmd, timeout, start_timeout, env
        self.child = None

    def _line(self, timeout):
        """The next PREFIX line's payload, "" if the worker died, None on timeout. Reads the
        pipe's file descriptor itself (a buffered reader could hold a complete line that
        select() would never report)."""
        deadline = time.monotonic() + timeout
        while True:
            while b"\n" in self.buffer:
                line, self.buffer = self.buffer.split(b"\n", 1)
                text = line.decode("utf-8", "replace") + "\n"
                if text.startswith(self.PREFIX):
                    return text[len(self.PREFIX):]
            left = deadline - time.monotonic()
            ready, _, _ = select.select([self.child.stdout], [], [], max(left, 0))
            if not ready:
                return None
            chunk = os.read(self.child.stdout.fileno(), 65536)
            if not chunk:
                return ""
            self.buffer += chunk

    def start(self):
        self.child = subprocess.Popen(self.cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                      stderr=subprocess.DEVNULL, env=self.env)
        self.buffer = b""
        if self._line(self.start_timeout) != "ready\n":
            self.stop()
            raise RuntimeError(f"the fuzz worker did not start: {' '.join(self.cmd)}")

    def stop(self):
        if self.child is not None:
            self.child.kill()
            self.child.wait()
            self.child.stdin.close()
            self.child.stdout.close()
            self.child = None

    def run(self, case, name):
        if self.child is None:
            self.start()
        self.child.stdin.write(f"{case}\n".encode())
        self.child.stdin.flush()
        line = self._line(self.timeout)
        if line is None:
            self.stop()
            return name, "hang", f"no answer within {self.timeout} s"
        if not line:
            code = self.child.wait()
            self.stop()
            return name, "crash", f"worker died, exit code {code}"
        _, name, status, detail = json.loads(line)
        return name, status, detail


def module_runner(seed, timeout, only=None):
    cmd = [sys.executable, os.path.abspath(__file__), "--worker", "--seed", str(seed)]
    return Runner(cmd + (["--only", only] if only else []), timeout)


def tally(runner, names, cases, first=0, verbose=False):
    """Runs cases [first, first + cases) through runner; names(case) = the case's function.
    Returns {name: [tried, failed, ok]}, {outcome: count}, [(case, name, outcome, detail)]."""
    by_name, failures, kinds = {}, [], {}
    try:
        for case in range(first, first + cases):
            name, status, detail = runner.run(case, names(case))
            row = by_name.setdefault(name, [0, 0, 0])
            row[0] += 1
            row[2] += status == "ok"
            kinds[status] = kinds.get(status, 0) + 1
            if status not in ("ok", "rejected"):
                row[1] += 1
                failures.append((case, name, status, detail))
                if verbose:
                    print(f"  case {case} {name}: {status}: {detail}", flush=True)
    finally:
        runner.stop()
    return by_name, kinds, failures


def print_table(by_name, kinds, label, seed, seconds):
    tried = sum(r[0] for r in by_name.values())
    failed = sum(r[1] for r in by_name.values())
    print(f"\n{'function':22s} {'tried':>7s} {'ok':>7s} {'refused':>7s} {'failed':>7s}")
    for name, (t, f, ok) in sorted(by_name.items()):
        print(f"{name:22s} {t:7d} {ok:7d} {t - ok - f:7d} {f:7d}")
    print("outcomes: " + ", ".join(f"{k} {v}" for k, v in sorted(kinds.items())))
    print(f"{label}: {tried} cases tried, {failed} failed (crashes {kinds.get('crash', 0)}, "
          f"hangs {kinds.get('hang', 0)}), seed {seed}, {seconds:.0f} s")
    return failed


def fuzz(cases, seed=1, timeout=20.0, only=None, first=0, verbose=False):
    """Runs module cases [first, first + cases); see tally()."""
    names = [only] if only else sorted(CASES)
    return tally(module_runner(seed, timeout, only), lambda c: names[c % len(names)], cases,
                 first, verbose)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cases", type=int, default=12000)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--timeout", type=float, default=20.0, help="seconds per call")
    ap.add_argument("--only", choices=sorted(CASES) + ["selftest_hang", "selftest_crash"])
    ap.add_argument("--case", type=int, help="run this one case (with its --seed)")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.worker:
        worker(a.seed, a.only)
        return 0
    first, cases = (a.case, 1) if a.case is not None else (0, a.cases)
    t0 = time.time()
    by_name, kinds, failures = fuzz(cases, a.seed, a.timeout, a.only, first, verbose=True)
    failed = print_table(by_name, kinds, "module fuzz", a.seed, time.time() - t0)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
