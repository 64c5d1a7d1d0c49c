"""The regression rung's calibration sample and fit: the sample's size and its points per
group, ridge regression with λ by cross-validation, and the fitted model of one (tree, role)
group over the expanded features (docs/DESIGN.md, 'The ray-free rung'). No bpy."""
from __future__ import annotations

import numpy as np

from . import native

LAMBDAS = (1e-3, 1e-2, 1e-1, 1.0, 10.0, 100.0)
CV_TOLERANCE = 0.005     # relative: CV errors closer than this are a tie (ridge)
NATIVE = 13              # OcclusionFeatures' columns (occlusion_features.h); LeafTable's follow
PIECES_GAIN = 0.02       # the piece columns must cut a fit's CV MAE by more than this (fit_group)

POINTS = 1024            # calibration points of the rung (the ray-free contract: <= 1024)
# Sizing on small scenes (calibration_size): counted work, scale-free.
RAYS_PER_RECEIVER = 8    # calibration samples per receiver at most: 1/8 of a 64-sample bake
MIN_SAMPLES = 32         # rays per calibration point at least
MIN_POINTS = 256         # calibration points at least (when the scene has them)


def _sample(groups, count, seed):
    """{group: sorted row indices} of at most `count` points in all (or one per group), every
    group some, larger groups more (∝ sqrt of their size: small groups such as a trunk are not
    starved)."""
    rng = np.random.default_rng(seed)
    sizes = {g: n for g, n in groups.items() if n > 0}
    if not sizes:
        return {}
    w = {g: np.sqrt(n) for g, n in sizes.items()}
    tot = sum(w.values())
    ks = {g: min(n, max(1, int(round(count * w[g] / tot)))) for g, n in sizes.items()}
    while sum(ks.values()) > max(count, len(ks)):  # rounding up must not break the cap
        g = max(ks, key=lambda g_: (ks[g_], str(g_)))
        ks[g] -= 1
    return {g: np.sort(rng.choice(sizes[g], size=ks[g], replace=False)) for g in sizes}


def calibration_size(receivers, points=POINTS, samples=128):
    """(points, rays per point) of the calibration sample for ``receivers`` receiver points,
    sized so the sample stays a fraction of a ray-traced bake of the same scene whatever its
    size (docs/DESIGN.md, 'The ray-free rung'): at most RAYS_PER_RECEIVER samples per receiver
    (an eighth of a 64-sample bake; a vertex casts both at each face corner), fewer per point
    first (down to MIN_SAMPLES: the fit averages their noise out), then fewer points (down to
    MIN_POINTS; the floor is MIN_POINTS × MIN_SAMPLES, or every receiver at MIN_SAMPLES on a
    smaller scene).
    Counted, never timed: the same scene always gets the same sample. The grid is not sized
    down: 48 or 32 voxels instead of 64 cut the rung's time on a 14k-vertex tree by 40-50 %
    but cost MAE 0.003-0.006 (callistemon)."""
    receivers = max(int(receivers), 1)
    budget = RAYS_PER_RECEIVER * receivers
    pts = min(int(points), receivers)
    spp = int(min(samples, max(MIN_SAMPLES, budget // max(pts, 1))))
    if pts * spp > budget:
        pts = min(pts, max(MIN_POINTS, budget // spp))
    return pts, spp


def ridge(X, y, lambdas=LAMBDAS, folds=5, seed=0):
    """Weights of a ridge fit (intercept column 0 not penalised), λ by k-fold CV. Returns
    (weights float64 (P,), λ, CV mean absolute error).

    One Gram matrix per fold, the training folds' as the total minus the held-out one, so the
    search costs k products of the sample and k·|λ| small P × P solves."""
    X = np.asarray(X, np.float64)
    y = np.asarray(y, np.float64)
    n, p = X.shape
    pen = np.eye(p)
    pen[0, 0] = 0.0
    G, b = X.T @ X, X.T @ y

    fold = np.random.default_rng(seed).permutation(n) % folds
    parts = []
    for f in range(folds):
        te = fold == f
        ntr = n - int(te.sum())
        if ntr <= 1 or not te.any():
            continue
        Xt = X[te]
        parts.append((G - Xt.T @ Xt, b - Xt.T @ y[te], ntr, Xt, y[te]))
    errs = []
    for lam in lambdas:
        err = 0.0
        for Gt, bt, ntr, Xt, yt in parts:
            w = np.linalg.solve(Gt + lam * ntr * pen, bt)
            err += float(np.abs(np.clip(Xt @ w, 0, 1) - yt).sum())
        errs.append(err / max(n, 1))
    # The largest λ whose CV error is within CV_TOLERANCE of the best: where the folds cannot
    # tell two λ apart, the smoother fit, and a choice that does not flip on rounding (a scene
    # and the same ×1000 picked 0.01 and 0.001 at equal CV error to four digits).
    lo = min(errs)
    lam, err = max((la, e) for la, e in zip(lambdas, errs) if e <= lo * (1 + CV_TOLERANCE))
    return np.linalg.solve(G + lam * n * pen, b), lam, err


class Model:
    """One fitted group: feature mean/scale and the expanded weights. The NATIVE columns expand
    natively (occlusion_features.h: [1, z, z², z_grid·z] and the shape pairs); the leaf
    columns after them (LeafTable) add [z, z², z_grid·z] each."""

    def __init__(self, feats, target, ground=None):
        self.mean = feats.mean(0).astype(np.float32)
        # The sample's range per feature: a live frame's features are held to it (predict).
        self.lo, self.hi = feats.min(0).astype(np.float32), feats.max(0).astype(np.float32)
        sd = feats.std(0)
        self.scale = np.where(sd > 1e-6, sd, 1.0).astype(np.float32)
        # Fitted as g(features) × V_ground (ground: each point's patch visibility, which the
        # caller multiplies back): the rows scaled by it, so the least squares and the CV error
        # are those of the product, the AO the bake shows.
        X = self.expand(feats)
        if ground is not None:
            X = X * np.asarray(ground, np.float64)[:, None]
        w, self.lam, self.cv_mae = ridge(X, target)
        self.weights = w.astype(np.float32)
        self.n = len(target)

    def expand(self, feats):
        """φ: the native part, then the leaf part (_extra), side by side."""
        f = np.ascontiguousarray(feats, np.float32)
        X = np.asarray(native.require().expand_features(
            np.ascontiguousarray(f[:, :NATIVE]), self.mean[:NATIVE], self.scale[:NATIVE]))
        return X if f.shape[1] == NATIVE else np.concatenate([X, self._extra(f)], axis=1)

    def _extra(self, f):
        z = (f[:, NATIVE:] - self.mean[NATIVE:]) / self.scale[NATIVE:]
        zg = ((f[:, 1] - self.mean[1]) / self.scale[1])[:, None]  # the grid AO, standardised
        return np.concatenate([z, z * z, z * zg], axis=1)

    def predict(self, feats, bounded=False):
        """AO of feature rows. bounded: each feature held to the calibration sample's range
        first (a live frame: the first frame's sample can hold a feature all but constant, a
        ground point's shape feature under an unbent crown, which a swayed crown then moves
        thousands of standard deviations, and the fit extrapolates to nonsense)."""
        f = np.ascontiguousarray(feats, np.float32)
        # One native pass (occlusion_features.h, predict_model): held to the range, expanded
        # and weighted row by row, the leaf columns after the native ones; no (N, P) matrix.
        lo, hi = (self.lo, self.hi) if bounded else (None, None)
        return np.asarray(native.require().predict_features(
            f, self.mean, self.scale, self.weights, lo, hi,
            native_features=min(NATIVE, f.shape[1])))


def fit_group(F, y, ground=None):
    """The group's Model, with the piece columns (LeafTable) only if they cut its
    cross-validated MAE on the sample by more than PIECES_GAIN, else the simpler model without
    them (a tie is the folds' noise); ``.pieces`` says which. The columns say where on its
    piece — a leaf card, a branch tube — a point is: they cut the CV MAE by 6 % on
    japanese_maple's leaves and 12 % on douglas_fir's twigs, under 2 % on broadleaf limbs and
    on a grove's small per-tree samples (docs/DESIGN.md, 'The ray-free rung'), so each sample
    decides. ground: each point's GROUND patch visibility (Model), None = 1."""
    plain = Model(F[:, :NATIVE], y, ground)
    plain.pieces = False
    if not np.any(F[:, NATIVE:]):  # no piece columns (ground, grass): nothing to choose
        return plain
    full = Model(F, y, ground)
    full.pieces = True
    return full if full.cv_mae < (1.0 - PIECES_GAIN) * plain.cv_mae else plain
