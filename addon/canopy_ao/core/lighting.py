"""How each role is lit: AO of receiver points against the plan's proxies, trunks, grass law,
ray tracer or density grid (docs/DESIGN.md, 'How each role is lit').

- CANOPY / TRUNK of tree t: points inside t's shells get the in-shell model (sphere, ellipsoid or
  several shells, Hegeman Eq. 4-6); points outside them see t's shells as occluders; every other
  tree's shells and trunks are occluders.
- GROUND: every tree's shells (as semi-transparent occluders) and every trunk (a solid ellipsoid
  fitted to the trunk) are occluders.
- GRASS: Hegeman Eq. 9 with ground level and blade height found from the blades (connected
  components) × the same occluders as the ground.
- method "raytrace": Embree rays against every non-ignored triangle of the scene.
"""

from __future__ import annotations

import math

import numpy as np

from .native import CanopyAOError, _core
from .proxies import own_shells
from .scene import Plan


def _occluders(p, n, shells, tau, solid=False):
    if not shells or len(p) == 0:
        return np.ones(len(p), np.float32)
    return _core.ao_occluders(p, n, list(shells), float(tau), solid=solid)


def _in_shell(p, n, tree_fit, method, tau):
    """The in-shell model for a tree's own receivers (docs/DESIGN.md, 'The method ladder')."""
    sphere, ell, shells = tree_fit
    if method == "sphere":
        return _core.ao_canopy_sphere(p, n, sphere, float(tau))
    if method == "ellipsoid":
        return _core.ao_canopy_ellipsoid(p, n, ell, float(tau))
    if method == "reeves_blau":
        return _core.ao_reeves_blau(p, n, ell, float(tau))
    if method == "shells":
        if len(shells) == 1:
            return _core.ao_canopy_ellipsoid(p, n, shells[0], float(tau))
        return _core.ao_canopy_shells(p, n, list(shells), float(tau), combine="product")
    if method == "medium":
        return _core.ao_medium_shells(p, n, list(shells), float(tau), combine="product")
    raise CanopyAOError(f"unknown analytic method {method!r}")


def evaluate_points(plan: Plan, role: str, tree: str, grass_key: str | None,
                    p: np.ndarray, n: np.ndarray, method: str, tau: float) -> np.ndarray:
    """AO for receiver points p, n of an item: the scene's own objects (below) times the
    instanced trees of attach_forest, if any (V = Π (1 − occ), so the fields multiply)."""
    ao = _evaluate_scene_points(plan, role, tree, grass_key, p, n, method, tau)
    if plan.forest is not None and len(p):
        ao = np.clip(ao * plan.forest.ao(p, n), 0.0, 1.0).astype(np.float32, copy=False)
    return ao


def _evaluate_scene_points(plan: Plan, role: str, tree: str, grass_key: str | None,
                           p: np.ndarray, n: np.ndarray, method: str, tau: float) -> np.ndarray:
    """AO for receiver points p, n (float32 (N, 3)) of an item with this role and tree.

    Any receiver inside a tree's shells (its own canopy, a trunk, but also ground or grass that
    a low crown reaches down to) gets that tree's in-shell model; every shell it is outside of
    is an occluder. Trunks are solid occluders for everything but their own tree's canopy and
    trunk (which sit inside or on them)."""
    if len(p) == 0:
        return np.ones(0, np.float32)
    if method == "raytrace":
        return trace(plan, p, n, plan.settings.samples)
    if method == "grid":
        return _grid_ao(plan, p, n)
    if method == "regression":
        return plan.regression.ao(role, tree, p, n)
    if method == "hybrid":
        return _hybrid_ao(plan, p, n)
    ao = np.ones(len(p), np.float32)
    shells = {t: own_shells(plan, t, method) for t in plan.fits}
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
        ao *= _core.ao_grass(p, n, float(ground), float(blade))
    ao = np.asarray(ao, dtype=np.float32)
    return np.clip(ao, 0.0, 1.0, out=ao)  # ao is this function's own array


def trace(plan: Plan, p, n, samples, seed=None):
    """Ray-traced AO of points p, n against the scene's triangles (the exact rung)."""
    if plan.tracer is None:
        raise CanopyAOError("ray tracing needs the scene's triangles; none were given")
    d = plan.settings.distance
    return plan.tracer.ao(p, n, samples=int(samples), distance=float(d) if d > 0 else math.inf,
                          seed=plan.settings.seed if seed is None else int(seed))


def _grid_ao(plan, p, n):
    d = plan.settings.distance
    kw = {"distance": float(d)} if d > 0 else {}
    return np.asarray(plan.grid.ao(p, n, **kw), dtype=np.float32)


# The hybrid's near distance in voxels of the density grid: the grid resolves occlusion beyond
# a few voxels, rays the contact shadows inside them (scale-free: the voxel is the grid's box /
# its resolution). Chosen on the design Sapling trees, bench/real_assets.py.
HYBRID_VOXELS = 2.0


def _hybrid_ao(plan, p, n):
    """Near exact, far statistical (native ao_near_far): settings.samples rays out to
    HYBRID_VOXELS grid voxels, the density grid beyond."""
    d = plan.settings.distance
    near = HYBRID_VOXELS * float(plan.grid.voxel_size)
    return np.asarray(_core.ao_near_far(plan.tracer, plan.grid, p, n, near,
                                        samples=int(plan.settings.samples),
                                        distance=float(d) if d > 0 else math.inf,
                                        seed=plan.settings.seed), dtype=np.float32)


def _scene_triangles(items):
    """Every non-ignored item's triangles in one mesh: (vertices float32, triangles int32)."""
    verts, tris, base = [], [], 0
    for it in items:
        if it.role == "IGNORE" or not len(it.triangles):
            continue
        verts.append(it.positions)
        tris.append(it.triangles + base)
        base += len(it.positions)
    if not verts:
        raise CanopyAOError("the scene has no triangles")
    return (np.ascontiguousarray(np.concatenate(verts), dtype=np.float32),
            np.ascontiguousarray(np.concatenate(tris), dtype=np.int32))


def build_tracer(items):
    """The Embree ray tracer over every non-ignored item's triangles."""
    return _core.RayTracer(*_scene_triangles(items))


def build_grid(items):
    """The leaf-density grid (docs/DESIGN.md, 'The method ladder') from the leaves and branches
    (CANOPY and TRUNK triangles). Not the ground: as density its area would fill the voxel layer
    a ground receiver's grazing rays travel in (round tree: ground AO 0.67 against 0.92 traced)."""
    if not any(it.role == "CANOPY" for it in items):
        raise CanopyAOError("method 'grid' needs at least one CANOPY object")
    return _core.DensityGrid(*_scene_triangles(
        [it for it in items if it.role in ("CANOPY", "TRUNK")]))
