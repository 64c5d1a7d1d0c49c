"""Stand-ins in numpy for native functions a partial build of ``_core`` does not have yet.

Only used when ``_core`` imports but lacks a function (a build from older sources); the engine
notes each use in its report so a result is never silently from here. The native versions are the
product (exact fits, horizon-clipped occluders); these are coarse but keep the add-on usable:
- fit_sphere: bounding-box centre, radius to the farthest point (encloses every point);
- fit_ellipsoid: PCA axes, radii scaled until every point is inside;
- occluders: a shell seen from outside blocks (r/d)^2 max(n.w, 0) of the AO (DESIGN 3.4),
  times its opacity 1 - exp(-tau).
"""

from __future__ import annotations

import numpy as np


def _core():
    from . import _core as c
    return c


def fit_sphere(points, trim=0.0):
    p = np.asarray(points, np.float64)
    c = 0.5 * (p.min(axis=0) + p.max(axis=0))
    r = float(np.sqrt(((p - c) ** 2).sum(axis=1).max()))
    return _core().Sphere(c.astype(np.float32), r * (1 + 1e-5))


def fit_ellipsoid(points, trim=0.0, **_):
    p = np.asarray(points, np.float64)
    mean = p.mean(axis=0)
    cov = np.cov((p - mean).T) if len(p) > 1 else np.eye(3)
    _, vecs = np.linalg.eigh(cov)
    q = vecs[:, ::-1].copy()
    if np.linalg.det(q) < 0:
        q[:, 2] = -q[:, 2]
    local = (p - mean) @ q
    lo, hi = local.min(axis=0), local.max(axis=0)
    centre_local = 0.5 * (lo + hi)
    half = np.maximum(0.5 * (hi - lo), 1e-3 * max(float((hi - lo).max()), 1e-6))
    scale = float(np.sqrt((((local - centre_local) / half) ** 2).sum(axis=1).max()))
    radii = half * max(scale, 1e-6) * (1 + 1e-4)
    centre = mean + q @ centre_local
    return _core().Ellipsoid(centre.astype(np.float32), q.astype(np.float32),
                             radii.astype(np.float32))


def _to_unit(p, n, e):
    q = np.asarray(e.axes, np.float64)
    r = np.asarray(e.radii, np.float64)
    c = np.asarray(e.center, np.float64)
    x = ((np.asarray(p, np.float64) - c) @ q) / r
    m = (np.asarray(n, np.float64) @ q) * r
    m /= np.maximum(np.linalg.norm(m, axis=1, keepdims=True), 1e-20)
    return x, m


def _unit_sphere_ao(x, m, tau):
    """Hegeman Eq. 4-6 on the unit sphere (DESIGN 3.1), R = 1, k = tau / Vhemi."""
    cvec = -x
    c = (cvec * m).sum(axis=1)
    h = np.clip(1.0 + c, 0.0, 2.0)
    vcap = np.pi * h * h * (3.0 - h) / 3.0
    d2 = ((cvec - c[:, None] * m) ** 2).sum(axis=1)
    f = np.where(h > 0, h * h / np.maximum(h * h + d2, 1e-20), 0.0)
    return np.exp(-tau * f * vcap / (2.0 * np.pi / 3.0)).astype(np.float32)


def ao_canopy_sphere(p, n, s, tau):
    return ao_canopy_ellipsoid(p, n, _core().Ellipsoid.from_sphere(s), tau)


def ao_canopy_ellipsoid(p, n, e, tau):
    x, m = _to_unit(p, n, e)
    return _unit_sphere_ao(x, m, tau)


def ao_canopy_shells(p, n, shells, tau, combine="product"):
    out = np.ones(len(p), np.float32)
    for e in shells:
        inside = np.asarray(e.contains(p), bool)
        if inside.any():
            out[inside] *= ao_canopy_ellipsoid(p[inside], n[inside], e, tau)
    return out


def ao_reeves_blau(p, n, e, tau):
    x, _ = _to_unit(p, n, e)
    depth = np.clip(1.0 - np.linalg.norm(x, axis=1), 0.0, 1.0)
    return np.exp(-tau * depth).astype(np.float32)


def ao_occluders(p, n, shells, tau, epsilon=1e-3, solid=False):
    p = np.asarray(p, np.float64)
    n = np.asarray(n, np.float64)
    out = np.ones(len(p), np.float64)
    opacity = 1.0 if solid else 1.0 - np.exp(-tau)
    for e in shells:
        c = np.asarray(e.center, np.float64)
        r = float(np.prod(np.asarray(e.radii, np.float64)) ** (1 / 3))
        v = c - p
        d = np.maximum(np.linalg.norm(v, axis=1), 1e-12)
        sin2 = np.minimum((r / d) ** 2, 1.0)
        cos = (v * n).sum(axis=1) / d
        occ = sin2 * np.clip(0.5 * (cos + np.sqrt(sin2)), 0.0, 1.0)  # soft horizon clip
        out *= 1.0 - opacity * np.clip(occ, 0.0, 1.0)
    return out.astype(np.float32)


def ao_grass(p, n, ground_height, blade_height, up=(0.0, 0.0, 1.0), floor=0.05):
    u = np.asarray(up, np.float64)
    u /= np.linalg.norm(u)
    pz = np.asarray(p, np.float64) @ u - ground_height
    cos = np.asarray(n, np.float64) @ u
    v = pz / (2.0 * blade_height) * (1.0 + cos)
    return np.clip(v, floor, 1.0).astype(np.float32)
