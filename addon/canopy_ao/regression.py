"""The ray-free "regression" rung: a ridge fit of the traced calibration sample on cheap
per-vertex occlusion features, carried over to every vertex. No bpy.

Why (docs/DESIGN.md, "The method ladder"): the leaf-density grid follows where the leaves are but
misses what is below a voxel (a leaf shaded by its neighbour or by its own branch); the
calibration sample measures exactly that, per scene. The features and the model's evaluation are
native (``_core.OcclusionFeatures``, ``_core.predict_features``: occlusion_features.h); here are
the sample, the fit and the bookkeeping.

Cost: grids O(triangles), one Embree BVH and ``points`` × ``samples`` calibration rays, then a
fixed number of grid lookups per vertex, whatever the leaf count. No rays beyond the sample.

Fit, per (tree, role) group with enough sample points (else per role, else scene-wide):
standardised features, expanded to [1, z, z², z_grid·z] (native), ridge regression with λ chosen
by 5-fold cross-validation on the sample. Buried sample points (every ray stops within
``BURIED_FRACTION`` of the object's size: a leaf base inside its branch) are kept out of the fit —
their AO of 0 says nothing about the rest of the leaf; the model predicts them like any vertex.
"""
from __future__ import annotations

import time

import numpy as np

try:
    from . import _core
except Exception:  # the engine reports a missing core (engine.core_status)
    _core = None

OCCLUDER_ROLES = ("CANOPY", "TRUNK", "GRASS")
RECEIVER_ROLES = ("CANOPY", "TRUNK", "GROUND", "GRASS")
BURIED_FRACTION = 0.01   # of the receiver's object bbox diagonal
BURIED_RAYS = 32
LAMBDAS = (1e-3, 1e-2, 1e-1, 1.0, 10.0, 100.0)
MIN_GROUP = 96           # sample points a group needs for its own fit


def _merged(items):
    verts, tris, off = [], [], 0
    for it in items:
        verts.append(it.positions)
        tris.append(it.triangles + off)
        off += len(it.positions)
    if not verts:
        return np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int32)
    return (np.ascontiguousarray(np.concatenate(verts), np.float32),
            np.ascontiguousarray(np.concatenate(tris), np.int32))


def tree_frame(points):
    """(center (3,), radius, z_min, z_max) of a tree from its points: the vertical axis through
    the median xy, the 95th-percentile horizontal distance from it."""
    p = np.asarray(points, np.float64)
    c = np.median(p, axis=0)
    r = np.hypot(p[:, 0] - c[0], p[:, 1] - c[1])
    radius = float(np.percentile(r, 95)) if len(r) else 1.0
    extent = float(np.linalg.norm(p.max(0) - p.min(0))) if len(p) else 1.0
    radius = max(radius, 1e-3 * extent, 1e-9)
    return c.astype(np.float32), radius, float(p[:, 2].min()), float(p[:, 2].max())


def ridge(X, y, lambdas=LAMBDAS, folds=5, seed=0):
    """Weights of a ridge fit (intercept column 0 not penalised), λ by k-fold CV. Returns
    (weights float64 (P,), λ, CV mean absolute error)."""
    X = np.asarray(X, np.float64)
    y = np.asarray(y, np.float64)
    n, p = X.shape
    pen = np.eye(p)
    pen[0, 0] = 0.0

    def solve(A, b, lam):
        return np.linalg.solve(A.T @ A + lam * len(A) * pen, A.T @ b)

    fold = np.random.default_rng(seed).permutation(n) % folds
    best = (np.inf, lambdas[0])
    for lam in lambdas:
        err = 0.0
        for f in range(folds):
            tr, te = fold != f, fold == f
            if tr.sum() <= 1 or te.sum() == 0:
                continue
            w = solve(X[tr], y[tr], lam)
            err += float(np.abs(np.clip(X[te] @ w, 0, 1) - y[te]).sum())
        err /= max(n, 1)
        if err < best[0]:
            best = (err, lam)
    return solve(X, y, best[1]), best[1], best[0]


class Model:
    """One fitted group: feature mean/scale and the expanded weights (float32, native layout)."""

    def __init__(self, feats, target):
        self.mean = feats.mean(0).astype(np.float32)
        sd = feats.std(0)
        self.scale = np.where(sd > 1e-6, sd, 1.0).astype(np.float32)
        X = _core.expand_features(np.ascontiguousarray(feats, np.float32), self.mean, self.scale)
        w, self.lam, self.cv_mae = ridge(X, target)
        self.weights = w.astype(np.float32)
        self.n = len(target)

    def predict(self, feats):
        return np.asarray(_core.predict_features(np.ascontiguousarray(feats, np.float32),
                                                 self.mean, self.scale, self.weights))


def _sample(groups, count, seed):
    """{group: row indices} of at most `count` points in all, every group some, larger groups
    more (∝ sqrt of their size: small groups such as a trunk are not starved)."""
    rng = np.random.default_rng(seed)
    sizes = {g: n for g, n in groups.items() if n > 0}
    if not sizes:
        return {}
    w = {g: np.sqrt(n) for g, n in sizes.items()}
    tot = sum(w.values())
    out = {}
    for g, n in sizes.items():
        k = min(n, max(1, int(round(count * w[g] / tot))))
        out[g] = np.sort(rng.choice(n, size=k, replace=False))
    return out


def bake(items, tracer=None, distance=0.0, points=1024, samples=128, resolution=64,
         directions=24, seed=0):
    """AO per receiver item by the regression rung.

    items: engine SceneItems (name, role, tree, positions, normals, triangles; roles upper
    case). tracer: a ``_core.RayTracer`` of every occluding triangle (built when None).
    distance: the AO distance (0 = unlimited) for the calibration rays.
    Returns ({item name: float32 (V,)}, report dict)."""
    if _core is None or not hasattr(_core, "OcclusionFeatures"):
        raise RuntimeError("the native core has no OcclusionFeatures (rebuild it)")
    t0 = time.perf_counter()
    items = [it for it in items if it.role != "IGNORE"]
    occ = [it for it in items if it.role in OCCLUDER_ROLES]
    grid = _core.DensityGrid(*_merged(occ), resolution=resolution)
    feats_of = _core.OcclusionFeatures(grid, directions=directions)
    t_grid = time.perf_counter()

    # Frames: one per tree (its leaves and branches), the occluders' for everything else.
    scene_frame = tree_frame(np.concatenate([it.positions for it in occ] or
                                            [np.zeros((1, 3), np.float32)]))
    frames = {}
    for tree in sorted({it.tree for it in items if it.tree}):
        pts = [it.positions for it in items if it.tree == tree and it.role in ("CANOPY", "TRUNK")]
        frames[tree] = tree_frame(np.concatenate(pts)) if pts else scene_frame

    receivers = [it for it in items if it.role in RECEIVER_ROLES and len(it.positions)]
    feats = {}
    for it in receivers:
        c, r, z0, z1 = frames.get(it.tree, scene_frame)
        feats[it.name] = feats_of.compute(it.positions, it.normals, c, r, z0, z1)
    t_feat = time.perf_counter()

    # Calibration sample, stratified by (tree, role): per group, its items' rows stacked.
    key = {it.name: (it.tree, it.role) for it in receivers}
    stacks = {}
    for it in receivers:
        st = stacks.setdefault(key[it.name], dict(P=[], N=[], F=[], diag=[]))
        st["P"].append(it.positions)
        st["N"].append(it.normals)
        st["F"].append(feats[it.name])
        st["diag"].append(np.full(len(it.positions), _diag(it.positions)))
    stacks = {g: {k: np.concatenate(v) for k, v in st.items()} for g, st in stacks.items()}
    picks = _sample({g: len(st["P"]) for g, st in stacks.items()}, points, seed)
    if tracer is None:
        tracer = _core.RayTracer(*_merged(occ + [it for it in items if it.role == "GROUND"]))
    d = float(distance) if distance and distance > 0 else float("inf")
    sample = {}
    for g, idx in picks.items():
        st = stacks[g]
        P = np.ascontiguousarray(st["P"][idx])
        N = np.ascontiguousarray(st["N"][idx])
        ao = np.asarray(tracer.ao(P, N, samples=samples, distance=d, seed=seed + 1))
        buried = _near_ao(tracer, P, N, st["diag"][idx]) <= 0.0
        sample[g] = dict(features=st["F"][idx][~buried], ao=ao[~buried],
                         buried=int(buried.sum()), n=len(idx))
    t_cal = time.perf_counter()

    # Fit per group, falling back to the role's pooled sample, then to everything.
    models, fits = {}, {}
    by_role = {}
    for g, s in sample.items():
        by_role.setdefault(g[1], []).append(s)
    pooled_all = [s for s in sample.values()]

    def pool(ss):
        F = np.concatenate([s["features"] for s in ss])
        y = np.concatenate([s["ao"] for s in ss])
        return F, y

    cache = {}
    for g in stacks:
        s = sample.get(g)
        if s is not None and len(s["ao"]) >= MIN_GROUP:
            src, F, y = "own", s["features"], s["ao"]
        elif sum(len(t["ao"]) for t in by_role.get(g[1], [])) >= MIN_GROUP:
            src = f"role {g[1]}"
            F, y = pool(by_role[g[1]])
        else:
            src = "scene"
            F, y = pool(pooled_all)
        if len(y) < 8:
            raise RuntimeError("regression: fewer than 8 unburied calibration points")
        ck = src if src != "own" else g
        if ck not in cache:
            cache[ck] = Model(F, y)
        models[g] = cache[ck]
        m = models[g]
        fits[f"{g[0] or '-'}/{g[1]}"] = dict(source=src, points=int(m.n), lam=float(m.lam),
                                             cv_mae=round(float(m.cv_mae), 4),
                                             buried=int(s["buried"]) if s else 0)
    t_fit = time.perf_counter()
    out = {it.name: models[key[it.name]].predict(feats[it.name]) for it in receivers}
    for it in items:
        if it.name not in out:
            out[it.name] = np.ones(len(it.positions), np.float32)
    t_end = time.perf_counter()
    report = dict(method="regression", groups=fits, resolution=resolution,
                  directions=directions, calibration_points=int(sum(len(v) for v in
                                                                   picks.values())),
                  calibration_samples=samples,
                  timings=dict(grids=t_grid - t0, features=t_feat - t_grid,
                               calibration=t_cal - t_feat, fit=t_fit - t_cal,
                               predict=t_end - t_fit, total=t_end - t0))
    return out, report


def _diag(p):
    return float(np.linalg.norm(p.max(0) - p.min(0))) if len(p) else 0.0


def _near_ao(tracer, P, N, diag):
    """Traced AO out to BURIED_FRACTION × each point's object diagonal (0 = buried)."""
    out = np.ones(len(P), np.float32)
    for dg in np.unique(diag):
        m = diag == dg
        if dg <= 0:
            continue
        out[m] = tracer.ao(P[m], N[m], samples=BURIED_RAYS, distance=BURIED_FRACTION * dg,
                           seed=7)
    return out
