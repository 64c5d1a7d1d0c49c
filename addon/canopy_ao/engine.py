"""The bake, in numpy and the native core; no bpy (issue 3, item 3; DESIGN 3, 5, 7).

Input: scene items (name, role, tree, world positions, world normals, triangles) and
:class:`BakeSettings`. Output: one float32 AO array per item (1 = open sky) and a report: fitted
proxies per tree, τ, the method chosen and why, timings.

How each role is lit (DESIGN 3):
- CANOPY / TRUNK of tree t: points inside t's shells get the in-shell model (sphere, ellipsoid or
  several shells, Hegeman Eq. 4-6); points outside them see t's shells as occluders; every other
  tree's shells and trunks are occluders.
- GROUND: every tree's shells (as semi-transparent occluders) and every trunk (a solid ellipsoid
  fitted to the trunk) are occluders.
- GRASS: Hegeman Eq. 9 with ground level and blade height found from the blades (connected
  components) × the same occluders as the ground.
- method "raytrace": Embree rays against every non-ignored triangle of the scene.

The work is split so a modal operator can do one object per tick: :func:`prepare` fits the
proxies and calibrates; :func:`evaluate_item` bakes one item; :func:`bake` does both.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from . import roles as _roles

try:  # the add-on must load without it; the caller reports why (see core_status()).
    from . import _core
    _CORE_ERROR = None
except Exception as exc:  # ImportError, or an undefined symbol from a stale build
    _core = None
    _CORE_ERROR = f"{type(exc).__name__}: {exc}"

# Method ladder, cheapest first (DESIGN 3): one sphere, one ellipsoid, k shells, the shells as a
# uniform random medium (exact expected AO, tabulated), the leaf-density grid; Reeves-Blau is the
# paper's baseline and ray tracing the reference.
ANALYTIC_METHODS = ("sphere", "ellipsoid", "shells")
METHODS = ("auto",) + ANALYTIC_METHODS + ("medium", "reeves_blau", "grid", "raytrace")
# Optional rungs and the native function each needs.
_OPTIONAL = {"medium": "ao_medium_shells", "grid": "DensityGrid"}
RECEIVER_ROLES = ("CANOPY", "TRUNK", "GROUND", "GRASS")
DEFAULT_TAU = 1.5
UP = np.array([0.0, 0.0, 1.0], dtype=np.float32)


class EngineError(RuntimeError):
    """A bake that cannot be done, with a message a user can act on."""


def core_status() -> tuple[bool, str]:
    """(available, message). The message says how to fix a missing or broken module."""
    if _core is not None:
        return True, f"native core loaded ({_core.__file__})"
    import sys
    return False, (
        f"Canopy AO's native module could not be loaded ({_CORE_ERROR}). It must be built for "
        f"this Blender's Python {sys.version_info.major}.{sys.version_info.minor}: run "
        "'cmake -S . -B build-addon && cmake --build build-addon -j2' in the Canopy AO source "
        "tree (it copies _core*.so into addon/canopy_ao/), then restart Blender.")


def available_methods() -> tuple[str, ...]:
    """Methods the loaded core can run."""
    return tuple(m for m in METHODS
                 if m not in _OPTIONAL or (_core is not None and hasattr(_core, _OPTIONAL[m])))


def triangles_needed(method: str, tau, role: str) -> bool:
    """Whether an item's triangles take part in a bake (the add-on skips fetching them
    otherwise: Blender's loop triangulation costs more than positions and normals together).
    They are rays' targets (method "raytrace", and the calibration of "auto" or of any method
    with tau None), the density grid's input, and grass blades (connected components); the
    analytic models with a given τ need positions and normals only."""
    if role == "IGNORE":
        return False
    if method in ("raytrace", "grid", "auto") or tau is None:
        return True
    return role == "GRASS"


def _need(name: str):
    if _core is None:
        raise EngineError(core_status()[1])
    fn = getattr(_core, name, None)
    if fn is None:
        raise EngineError(
            f"the native module has no '{name}' yet (built from an older source?): rebuild with "
            "'cmake --build build-addon -j2' and restart Blender")
    return fn


# === Data ====================================================================================

@dataclass
class SceneItem:
    """One mesh object in world space: positions, normals float32 (N, 3); triangles int32 (M, 3)."""

    name: str
    role: str
    tree: str
    positions: np.ndarray
    normals: np.ndarray
    triangles: np.ndarray

    def __post_init__(self):
        self.positions = np.ascontiguousarray(self.positions, dtype=np.float32).reshape(-1, 3)
        self.normals = np.ascontiguousarray(self.normals, dtype=np.float32).reshape(-1, 3)
        self.triangles = np.ascontiguousarray(self.triangles, dtype=np.int32).reshape(-1, 3)
        if self.role not in _roles.ROLES:
            raise EngineError(f"{self.name}: unknown role {self.role!r} (one of {_roles.ROLES})")
        if len(self.positions) != len(self.normals):
            raise EngineError(f"{self.name}: {len(self.positions)} positions but "
                              f"{len(self.normals)} normals")


@dataclass
class BakeSettings:
    """method: one of METHODS. tau: optical depth (AO at a shell's centre = exp(-tau)); None =
    calibrate. distance: AO distance in scene units, 0 = unlimited (Cycles' meaning: a hard
    cut-off on ray length; the analytic models ignore it). samples: rays per point for
    "raytrace". shells: k for "shells". calibration_points: reference points traced for "auto".
    time_budget: seconds the whole bake may take; "auto" does not pick a rung predicted to take
    longer (0 = no limit). target_rmse: "auto" stops climbing once a rung's sample RMSE is
    below it; 0.06 ≈ an MAE of 0.05, an error an artist does not see (issue 6). forest_epsilon: the cut-off ε (Shanmugam–Arikan Eq. 5) for instanced trees
    (attach_forest): each instance's shell is ignored where it would block < ε; 1e-2 keeps a
    ground vertex under a 10,000-tree forest to ~1000 occluders (bench/forest.py) at a cost
    of < 0.08 AO against no cut-off."""

    method: str = "auto"
    tau: float | None = None
    distance: float = 0.0
    samples: int = 64
    shells: int = 4
    trim: float = 0.0
    calibration_points: int = 256
    calibration_samples: int = 128
    time_budget: float = 2.0
    target_rmse: float = 0.06
    seed: int = 0
    forest_epsilon: float = 1e-2


@dataclass
class Plan:
    """What prepare() decided: proxies per tree, method, τ, and the shared state for the bake."""

    settings: BakeSettings
    method: str
    tau: float
    fits: dict = field(default_factory=dict)  # tree -> (Sphere, Ellipsoid, [Ellipsoid] shells)
    proxies: dict = field(default_factory=dict)  # tree -> [Ellipsoid] the chosen method's shells
    trunks: dict = field(default_factory=dict)  # tree -> list of _core.Ellipsoid (solid)
    grass: dict = field(default_factory=dict)  # item name -> (ground_height, blade_height)
    tracer: object = None
    # item name -> (first vertex, first triangle) of its mesh inside the tracer's (the receiver
    # ids that let a ray skip only its own triangles, as Cycles does)
    tracer_bases: dict = field(default_factory=dict)
    grid: object = None
    calibration: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    forest: object = None  # forest.Forest: instanced trees occluding every receiver (attach_forest)


@dataclass
class ItemResult:
    name: str
    role: str
    tree: str
    method: str
    ao: np.ndarray
    seconds: float

    @property
    def vertices(self) -> int:
        return int(len(self.ao))


# === Proxies =================================================================================

def _fit_tree(points: np.ndarray, settings: BakeSettings):
    """Fitted canopy proxies for one tree: (sphere, ellipsoid, [k shells]). The k-means shells
    cost most (1.2 s for 1M points), so only the methods that use them get them; the others
    get [ellipsoid]."""
    sphere = _need("fit_sphere")(points, trim=settings.trim)
    if settings.method == "sphere":
        # The sphere model uses no ellipsoid: skip its fit (~40 ms per million points); the
        # sphere is then also the crown a trunk's bole is cut from (_bole), as it is the medium.
        ell = _core.Ellipsoid.from_sphere(sphere)
    else:
        ell = _need("fit_ellipsoid")(points, trim=settings.trim)
    k = max(1, min(settings.shells, len(points) // 64))
    if settings.method not in ("auto", "shells", "medium"):
        k = 1
    if k > 1 and hasattr(_core, "fit_shells"):
        shells, _labels = _core.fit_shells(points, k, kind="ellipsoid", trim=settings.trim,
                                           seed=settings.seed)
        shells = list(shells)
    else:
        shells = [ell]
    return sphere, ell, shells


def proxy_dicts(plan: Plan) -> dict:
    """Proxies as plain data {tree: [{"center", "axes", "radii"}]} for display and JSON."""
    out = {}
    for tree, shells in plan.proxies.items():
        out[tree] = [{"center": np.asarray(e.center, float).tolist(),
                      "axes": np.asarray(e.axes, float).tolist(),
                      "radii": np.asarray(e.radii, float).tolist()} for e in shells]
    return out


# === Evaluation ==============================================================================

def _occluders(p, n, shells, tau, solid=False):
    if not shells or len(p) == 0:
        return np.ones(len(p), np.float32)
    return _need("ao_occluders")(p, n, list(shells), float(tau), solid=solid)


def _in_shell(p, n, tree_fit, method, tau):
    """The in-shell model for a tree's own receivers (DESIGN 3.1-3.3, 3.7)."""
    sphere, ell, shells = tree_fit
    if method == "sphere":
        return _need("ao_canopy_sphere")(p, n, sphere, float(tau))
    if method == "ellipsoid":
        return _need("ao_canopy_ellipsoid")(p, n, ell, float(tau))
    if method == "reeves_blau":
        return _need("ao_reeves_blau")(p, n, ell, float(tau))
    if method == "shells":
        if len(shells) == 1:
            return _need("ao_canopy_ellipsoid")(p, n, shells[0], float(tau))
        return _need("ao_canopy_shells")(p, n, list(shells), float(tau), combine="product")
    if method == "medium":
        return _need("ao_medium_shells")(p, n, list(shells), float(tau), combine="product")
    raise EngineError(f"unknown analytic method {method!r}")


def _own_shells(plan, tree, method):
    sphere, ell, shells = plan.fits[tree]
    if method == "sphere":
        return [_core.Ellipsoid.from_sphere(sphere)]
    if method in ("ellipsoid", "reeves_blau"):
        return [ell]
    return list(shells)


def _evaluate_points(plan: Plan, role: str, tree: str, grass_key: str | None,
                     p: np.ndarray, n: np.ndarray, method: str, tau: float,
                     own=None) -> np.ndarray:
    """AO for receiver points p, n of an item: the scene's own objects (below) times the
    instanced trees of :func:`attach_forest`, if any (V = Π (1 − occ), so the fields multiply).
    own: None or {"vertex_ids": int32 (N,), "triangle_ids": int32 (N,)}, the item's own
    vertex / triangle of each point in its mesh (-1 = none), for the ray-traced rung (_trace)."""
    ao = _evaluate_scene_points(plan, role, tree, grass_key, p, n, method, tau, own)
    if plan.forest is not None and len(p):
        ao = np.clip(ao * plan.forest.ao(p, n), 0.0, 1.0).astype(np.float32, copy=False)
    return ao


def _evaluate_scene_points(plan: Plan, role: str, tree: str, grass_key: str | None,
                           p: np.ndarray, n: np.ndarray, method: str, tau: float,
                           own=None) -> np.ndarray:
    """AO for receiver points p, n (float32 (N, 3)) of an item with this role and tree.

    Any receiver inside a tree's shells (its own canopy, a trunk, but also ground or grass that
    a low crown reaches down to) gets that tree's in-shell model; every shell it is outside of
    is an occluder. Trunks are solid occluders for everything but their own tree's canopy and
    trunk (which sit inside or on them)."""
    if len(p) == 0:
        return np.ones(0, np.float32)
    if method == "raytrace":
        return _trace(plan, p, n, plan.settings.samples, own=_tracer_ids(plan, grass_key, own))
    if method == "grid":
        return _grid_ao(plan, p, n)
    ao = np.ones(len(p), np.float32)
    shells = {t: _own_shells(plan, t, method) for t in plan.fits}
    inside = {}
    for t, es in shells.items():
        ins = np.zeros(len(p), bool)
        for e in es:
            ins |= np.asarray(e.contains(p), bool)
        if ins.any():
            inside[t] = ins
    outside_all = np.ones(len(p), bool)
    for ins in inside.values():
        outside_all &= ~ins
    if outside_all.any():  # the common case for ground: one call, the core's spatial grid
        po, no = np.ascontiguousarray(p[outside_all]), np.ascontiguousarray(n[outside_all])
        ao[outside_all] = _occluders(po, no, [e for es in shells.values() for e in es], tau)
    claimed = np.zeros(len(p), bool)
    for t, ins in inside.items():
        done = ins & ~claimed
        claimed |= ins
        if not done.any():
            continue
        every = bool(done.all())  # one crown and all its leaves: no gather / scatter copies
        pi, ni = (p, n) if every else (np.ascontiguousarray(p[done]),
                                       np.ascontiguousarray(n[done]))
        # Inside several trees' shells (crowns that interlock): the in-shell model of the
        # first, the others as occluders (which skip shells a point is inside).
        others = [e for u, es in shells.items() if u != t for e in es]
        val = _in_shell(pi, ni, plan.fits[t], method, tau)
        if others:
            val = val * _occluders(pi, ni, others, tau)
        if every:
            ao = np.asarray(val, dtype=np.float32)
        else:
            ao[done] = val
    solids = [e for t, es in plan.trunks.items()
              if t != tree or role in ("GROUND", "GRASS") for e in es]
    if solids:
        ao = ao * _occluders(p, n, solids, tau, solid=True)
    if role == "GRASS":
        ground, blade = plan.grass.get(grass_key, (float(p[:, 2].min()), 1.0))
        ao *= _need("ao_grass")(p, n, float(ground), float(blade))
    ao = np.asarray(ao, dtype=np.float32)
    return np.clip(ao, 0.0, 1.0, out=ao)  # ao is this function's own array


def _tracer_ids(plan: Plan, name, own):
    """An item's own ids (see _evaluate_points) shifted to the tracer's mesh, or None when the
    item is not in it. -1 (none) stays -1."""
    if not own or plan.tracer_bases.get(name) is None:
        return None
    bases = dict(zip(("vertex_ids", "triangle_ids"), plan.tracer_bases[name]))
    out = {}
    for key, ids in own.items():
        if ids is not None:
            ids = np.asarray(ids, np.int64)
            out[key] = np.ascontiguousarray(np.where(ids >= 0, ids + bases[key], -1), np.int32)
    return out


def _trace(plan: Plan, p, n, samples, seed=None, own=None):
    """Ray-traced AO; own: None or tracer-mesh ids {"vertex_ids", "triangle_ids"} (_tracer_ids)
    so each ray skips only its receiver's own triangles (RayTracer.ao)."""
    if plan.tracer is None:
        raise EngineError("ray tracing needs the scene's triangles; none were given")
    d = plan.settings.distance
    return plan.tracer.ao(p, n, samples=int(samples), distance=float(d) if d > 0 else math.inf,
                          seed=plan.settings.seed if seed is None else int(seed), **(own or {}))


# === Calibration (DESIGN 5) ==================================================================

def _sample_receivers(items, count, seed):
    """Up to ``count`` receiver points spread over the items in proportion to their size, at
    least a few per item so small objects (a trunk) are represented."""
    rng = np.random.default_rng(seed)
    receivers = [it for it in items if it.role in RECEIVER_ROLES and len(it.positions)]
    total = sum(len(it.positions) for it in receivers)
    picks = []
    for it in receivers:
        m = min(len(it.positions), max(16, int(round(count * len(it.positions) / max(total, 1)))))
        idx = np.sort(rng.choice(len(it.positions), size=m, replace=False))
        picks.append((it, idx))
    return picks


def _golden_min(f, lo, hi, iters=16):
    """Minimise a unimodal f on [lo, hi] by golden-section search."""
    g = (math.sqrt(5) - 1) / 2
    a, b = lo, hi
    c, d = b - g * (b - a), a + g * (b - a)
    fc, fd = f(c), f(d)
    for _ in range(iters):
        if fc < fd:
            b, d, fd = d, c, fc
            c = b - g * (b - a)
            fc = f(c)
        else:
            a, c, fc = c, d, fd
            d = a + g * (b - a)
            fd = f(d)
    return (c, fc) if fc < fd else (d, fd)


def calibrate(plan: Plan, items, candidates, tau_fixed=None):
    """Pick τ (unless fixed) and a method among ``candidates`` against ray-traced samples.

    Traces a few hundred receiver points (DESIGN 5), then for each candidate finds the τ that
    minimises the mean squared error (golden-section search on log τ in [0.02, 50]; the density
    grid has no τ) and walks up the ladder while the RMSE drops by more than 10 %, stays above
    ``target_rmse`` and the richer rung's predicted time (its cost per sample point times the
    receivers) fits ``time_budget``. Returns (method, tau, info dict).
    Kept apart so a better search can replace it.
    """
    s = plan.settings
    picks = _sample_receivers(items, s.calibration_points, s.seed)
    t0 = time.perf_counter()
    refs, groups = [], []
    for it, idx in picks:
        p = np.ascontiguousarray(it.positions[idx])
        n = np.ascontiguousarray(it.normals[idx])
        own = _tracer_ids(plan, it.name, {"vertex_ids": np.asarray(idx)})
        refs.append(_trace(plan, p, n, s.calibration_samples, own=own))
        groups.append((it, p, n, own))
    ref = np.concatenate(refs) if refs else np.zeros(0, np.float32)
    t_trace = time.perf_counter() - t0

    def err(method, tau):
        if method == "raytrace":
            # Its own noise, not the reference's: another seed than the reference traced with.
            got = [_trace(plan, p, n, s.samples, seed=s.seed + 7919, own=own)
                   for _it, p, n, own in groups]
        else:
            got = [_evaluate_points(plan, it.role, it.tree, it.name, p, n, method, tau)
                   for it, p, n, _own in groups]
        got = np.concatenate(got) if got else np.zeros(0, np.float32)
        return float(np.mean((got - ref) ** 2)) if len(ref) else 0.0

    n_receivers = sum(len(it.positions) for it in items if it.role in RECEIVER_ROLES)
    big = max((g[0] for g in groups), key=lambda it: len(it.positions))
    bp = np.ascontiguousarray(big.positions[:4096])
    bn = np.ascontiguousarray(big.normals[:4096])
    results, predicted = {}, {}
    for m in candidates:
        if m in ("grid", "raytrace"):  # physical density / exact: no τ to fit
            tau = float(tau_fixed or DEFAULT_TAU)
        elif tau_fixed is not None:
            tau = float(tau_fixed)
        else:
            lt, _e = _golden_min(lambda x: err(m, math.exp(x)), math.log(0.02), math.log(50.0))
            tau = math.exp(lt)
        results[m] = (tau, err(m, tau))
        # Cost per point on one batch of the largest receiver, scaled to every receiver (a
        # batch large enough that per-call overhead does not dominate).
        t1 = time.perf_counter()
        _evaluate_points(plan, big.role, big.tree, big.name, bp, bn, m, tau,
                         own={"vertex_ids": np.arange(len(bp), dtype=np.int32)})
        predicted[m] = (time.perf_counter() - t1) / max(len(bp), 1) * n_receivers
    # Walk up the ladder (DESIGN 5): a richer rung only if it cuts the error by > 10 %, the
    # current one misses the target, and the richer one fits the time budget.
    chosen, skipped = candidates[0], []
    for m in candidates[1:]:
        if math.sqrt(results[chosen][1]) <= s.target_rmse:
            break
        if results[m][1] < 0.81 * results[chosen][1]:  # RMSE down by more than 10 %
            if s.time_budget > 0 and predicted[m] > s.time_budget:
                skipped.append(m)
                continue
            chosen = m
    rmse = math.sqrt(results[chosen][1])
    why = (f"{chosen}: sample RMSE {rmse:.3f}; no richer rung cut it by more than 10 %"
           if rmse > s.target_rmse else f"{chosen}: sample RMSE {rmse:.3f} meets the target "
           f"{s.target_rmse}")
    if skipped:
        why += f" within the {s.time_budget:g} s budget (over it: {', '.join(skipped)})"
    info = {
        "points": int(len(ref)),
        "reference_samples": s.calibration_samples,
        "trace_seconds": t_trace,
        "seconds": time.perf_counter() - t0,
        "candidates": {m: {"tau": t, "rmse": math.sqrt(e), "predicted_seconds": predicted[m]}
                       for m, (t, e) in results.items()},
        "chosen": chosen,
        "why": why,
    }
    return chosen, results[chosen][0], info


# === Public entry points =====================================================================

def prepare(items, settings: BakeSettings) -> Plan:
    """Fit the proxies, build the ray tracer if needed, calibrate. Raises EngineError."""
    if settings.method not in METHODS:
        raise EngineError(f"unknown method {settings.method!r}; one of {', '.join(METHODS)}")
    if settings.method not in available_methods():
        raise EngineError(f"method {settings.method!r} is not available in this build")
    if settings.tau is not None and not (settings.tau > 0 and math.isfinite(settings.tau)):
        raise EngineError(f"tau must be a finite number > 0, got {settings.tau}")
    items = list(items)
    t_start = time.perf_counter()
    plan = Plan(settings=settings, method=settings.method,
                tau=settings.tau if settings.tau is not None else DEFAULT_TAU)
    # Proxies per tree, from its canopy points (trunk points are receivers, not shape: DESIGN 4).
    t0 = time.perf_counter()
    trees = {}
    for it in items:
        if it.role == "CANOPY" and len(it.positions):
            trees.setdefault(it.tree, []).append(it.positions)
    for tree, pts in trees.items():
        pts = np.ascontiguousarray(pts[0] if len(pts) == 1 else np.concatenate(pts),
                                   dtype=np.float32)
        sphere, ell, shells = _fit_tree(pts, settings)
        plan.fits[tree] = (sphere, ell, shells)
    for it in items:
        if it.role == "TRUNK":
            bole = _bole(plan, it)
            if len(bole) >= 8:
                plan.trunks.setdefault(it.tree, []).append(_need("fit_ellipsoid")(bole))
        if it.role == "GRASS":
            plan.grass[it.name] = _roles.blade_heights(it.positions, it.triangles)
    plan.timings["fit"] = time.perf_counter() - t0

    # Grass has no proxies to calibrate, but auto still weighs its law against rays.
    grass_only_auto = (settings.method == "auto" and not plan.fits
                       and any(it.role == "GRASS" for it in items))
    needs_tracer = settings.method == "raytrace" or grass_only_auto or (
        settings.method == "auto" or settings.tau is None) and bool(plan.fits)
    if needs_tracer:
        t0 = time.perf_counter()
        try:
            plan.tracer, plan.tracer_bases = _build_tracer(items)
        except EngineError as exc:
            if settings.method == "raytrace":
                raise
            plan.notes.append(f"calibration skipped: {exc}")
        plan.timings["tracer"] = time.perf_counter() - t0

    if settings.method == "grid":
        t0 = time.perf_counter()
        plan.grid = _build_grid(items, settings)
        plan.timings["grid"] = time.perf_counter() - t0
    elif (settings.method == "auto" and "grid" in available_methods() and plan.fits
          and plan.tracer is not None):
        t0 = time.perf_counter()
        try:  # the top rung of the ladder: only worth it if it beats the shells (calibrate)
            plan.grid = _build_grid(items, settings)
        except EngineError as exc:
            plan.notes.append(f"density grid not considered: {exc}")
        plan.timings["grid"] = time.perf_counter() - t0

    # Method and τ for the analytic rungs.
    analytic = settings.method in ANALYTIC_METHODS + ("medium", "reeves_blau", "auto")
    plan.method = settings.method
    if analytic and plan.fits:
        candidates = list(ANALYTIC_METHODS) if settings.method == "auto" else [settings.method]
        if settings.method == "auto" and "medium" in available_methods():
            candidates.append("medium")
        if settings.method == "auto" and plan.grid is not None:
            candidates.append("grid")
        if settings.method == "auto" and plan.tracer is not None:
            # The exact rung tops the ladder: on small or sparse scenes a few rays per vertex
            # beat every proxy within the time budget; on big ones the budget rules it out.
            candidates.append("raytrace")
        if plan.tracer is not None and (settings.method == "auto" or settings.tau is None):
            method, tau, info = calibrate(plan, items, candidates, settings.tau)
            plan.method, plan.tau, plan.calibration = method, tau, info
        else:
            plan.method = "ellipsoid" if settings.method == "auto" else settings.method
            if settings.tau is None:
                plan.notes.append(f"tau not calibrated; using the default {DEFAULT_TAU}")
    elif analytic:
        plan.method = "ellipsoid" if settings.method == "auto" else settings.method
        plan.notes.append("no CANOPY object: no proxies fitted")
        if grass_only_auto and plan.tracer is not None:
            # The grass law (Hegeman Eq. 9) against the exact rung, on the same sample.
            method, tau, info = calibrate(plan, items, ["ellipsoid", "raytrace"], DEFAULT_TAU)
            plan.method, plan.tau, plan.calibration = method, tau, info
    plan.proxies = {t: _own_shells(plan, t, plan.method) for t in plan.fits}
    plan.timings["prepare"] = time.perf_counter() - t_start
    return plan


def _scene_triangles(items, bases=None):
    """Every non-ignored item's triangles in one mesh: (vertices float32, triangles int32).
    bases: a dict to fill with item name -> (its first vertex, its first triangle) there."""
    verts, tris, base, tri_base = [], [], 0, 0
    for it in items:
        if it.role == "IGNORE" or not len(it.triangles):
            continue
        if bases is not None:  # a name seen twice cannot say which mesh it means: no ids
            bases[it.name] = None if it.name in bases else (base, tri_base)
        verts.append(it.positions)
        tris.append(it.triangles + base)
        base += len(it.positions)
        tri_base += len(it.triangles)
    if not verts:
        raise EngineError("the scene has no triangles")
    return (np.ascontiguousarray(np.concatenate(verts), dtype=np.float32),
            np.ascontiguousarray(np.concatenate(tris), dtype=np.int32))


def _bole(plan: Plan, item: SceneItem) -> np.ndarray:
    """The trunk points a solid occluder should stand for: those outside the tree's crown.
    Branches inside the crown are already in the canopy's medium; an ellipsoid fitted to them
    too would be a solid as big as the crown (it darkened the ground by 0.1 on the grove)."""
    p = item.positions
    if item.tree not in plan.fits:
        return p
    _sphere, ell, shells = plan.fits[item.tree]
    inside = np.asarray(ell.contains(p), bool)
    for e in shells:
        inside |= np.asarray(e.contains(p), bool)
    return np.ascontiguousarray(p[~inside])


def _build_tracer(items):
    """(RayTracer of every item's triangles, item name -> (first vertex, first triangle))."""
    cls = _need("RayTracer")
    bases = {}
    return cls(*_scene_triangles(items, bases)), bases


def _build_grid(items, settings):
    """The leaf-density grid of DESIGN 3.6 from the leaves and branches (CANOPY and TRUNK
    triangles). Not the ground: as density its area would fill the voxel layer a ground
    receiver's grazing rays travel in (round tree: ground AO 0.67 against 0.92 traced)."""
    cls = _need("DensityGrid")
    if not any(it.role == "CANOPY" for it in items):
        raise EngineError("method 'grid' needs at least one CANOPY object")
    verts, tris = _scene_triangles([it for it in items if it.role in ("CANOPY", "TRUNK")])
    try:
        return cls(verts, tris)
    except TypeError as exc:
        raise EngineError(f"this build's DensityGrid has an interface the add-on does not "
                          f"know yet: {exc}") from exc


def _grid_ao(plan, p, n):
    d = plan.settings.distance
    kw = {"distance": float(d)} if d > 0 else {}
    try:
        return np.asarray(plan.grid.ao(p, n, **kw), dtype=np.float32)
    except TypeError as exc:
        raise EngineError(f"this build's DensityGrid.ao has an interface the add-on does not "
                          f"know yet: {exc}") from exc


def evaluate_item(plan: Plan, item: SceneItem) -> ItemResult:
    """Bake one item with the plan's method and τ."""
    t0 = time.perf_counter()
    if item.role == "IGNORE":
        ao = np.ones(len(item.positions), np.float32)
    else:
        ao = _evaluate_points(plan, item.role, item.tree, item.name, item.positions,
                              item.normals, plan.method, plan.tau,
                              own={"vertex_ids": np.arange(len(item.positions), dtype=np.int32)})
    if ao.shape != (len(item.positions),) or not np.all(np.isfinite(ao)):
        raise EngineError(f"{item.name}: the {plan.method} model gave invalid values")
    return ItemResult(item.name, item.role, item.tree, plan.method, ao,
                      time.perf_counter() - t0)


def attach_forest(plan: Plan, prototypes, epsilon=None) -> None:
    """Make instanced trees occlude every item :func:`evaluate_item` bakes with this plan.

    prototypes: :class:`forest.Prototype` list (shells in the prototype's space, instance
    matrices). Attached after :func:`prepare`, so calibration (which traces only the real
    triangles) does not see occluders its reference has not got."""
    from . import forest as _forest
    t0 = time.perf_counter()
    eps = plan.settings.forest_epsilon if epsilon is None else float(epsilon)
    plan.forest = _forest.Forest(prototypes, epsilon=eps) if prototypes else None
    plan.timings["forest"] = time.perf_counter() - t0
    if plan.forest is not None:
        # The scene's own trees may all be instances: then "no CANOPY object" is not news.
        plan.notes = [n for n in plan.notes if not n.startswith("no CANOPY object")]
        plan.notes.append(
            f"forest: {plan.forest.instances} instance(s) of {len(plan.forest.prototypes)} "
            f"prototype(s), {plan.forest.shell_count} shells, {plan.forest.solid_count} trunks "
            f"as occluders (ε {plan.forest.epsilon:g}, at most {plan.forest.max_candidates} "
            "per receiver)")


def report(plan: Plan, results) -> dict:
    """A JSON-ready summary of a bake."""
    return {
        "method": plan.method,
        "requested_method": plan.settings.method,
        "tau": plan.tau,
        "distance": plan.settings.distance,
        "samples": plan.settings.samples,
        "proxies": proxy_dicts(plan),
        "calibration": plan.calibration,
        "timings": dict(plan.timings),
        "notes": list(plan.notes),
        "objects": {r.name: {"role": r.role, "tree": r.tree, "method": r.method,
                             "vertices": r.vertices, "seconds": r.seconds,
                             "ao_mean": float(r.ao.mean()) if r.vertices else None}
                    for r in results},
    }


def bake(items, settings: BakeSettings, progress=None):
    """prepare + evaluate every item. progress(i, n, name) is called before each item.
    Returns (list[ItemResult], report dict)."""
    items = list(items)
    plan = prepare(items, settings)
    results = []
    for i, it in enumerate(items):
        if progress is not None:
            progress(i, len(items), it.name)
        results.append(evaluate_item(plan, it))
    return results, report(plan, results)
