"""The regression rung's fit: ridge regression with λ by cross-validation, and the fitted model
of one (tree, role) group over the expanded features (docs/DESIGN.md, 'The ray-free rung').
No bpy."""
from __future__ import annotations

import numpy as np

from . import native

LAMBDAS = (1e-3, 1e-2, 1e-1, 1.0, 10.0, 100.0)
CV_TOLERANCE = 0.005     # relative: CV errors closer than this are a tie (ridge)
NATIVE = 13              # OcclusionFeatures' columns (occlusion_features.h); LeafTable's follow
PIECES_GAIN = 0.02       # the piece columns must cut a fit's CV MAE by more than this (fit_group)


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

    def __init__(self, feats, target):
        self.mean = feats.mean(0).astype(np.float32)
        # The sample's range per feature: a live frame's features are held to it (predict).
        self.lo, self.hi = feats.min(0).astype(np.float32), feats.max(0).astype(np.float32)
        sd = feats.std(0)
        self.scale = np.where(sd > 1e-6, sd, 1.0).astype(np.float32)
        w, self.lam, self.cv_mae = ridge(self.expand(feats), target)
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


def fit_group(F, y):
    """The group's Model, with the piece columns (LeafTable) only if they cut its
    cross-validated MAE on the sample by more than PIECES_GAIN, else the simpler model without
    them (a tie is the folds' noise); ``.pieces`` says which. The columns say where on its
    piece — a leaf card, a branch tube — a point is: they cut the CV MAE by 6 % on
    japanese_maple's leaves and 12 % on douglas_fir's twigs, under 2 % on broadleaf limbs and
    on a grove's small per-tree samples (docs/DESIGN.md, 'The ray-free rung'), so each sample
    decides."""
    plain = Model(F[:, :NATIVE], y)
    plain.pieces = False
    if not np.any(F[:, NATIVE:]):  # no piece columns (ground, grass): nothing to choose
        return plain
    full = Model(F, y)
    full.pieces = True
    return full if full.cv_mae < (1.0 - PIECES_GAIN) * plain.cv_mae else plain
