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


def tau_of(tau, tree):
    """τ of one tree: ``tau`` is one number for every tree or {tree: τ} (calibrated per tree;
    a tree missing from it takes the value under None)."""
    if isinstance(tau, dict):
        return float(tau.get(tree, tau.get(None, 1.0)))
    return float(tau)


def _occluders(p, n, shells, tau, distance, solid=False):
    """Visibility through shells (or solids) seen from outside, cut at the AO distance
    (0 = unlimited; occluders.h, 'AO distance')."""
    if not shells or len(p) == 0:
        return np.ones(len(p), np.float32)
    kw = {"distance": float(distance)} if distance > 0 else {}
    return _core.ao_occluders(p, n, list(shells), float(tau), solid=solid, **kw)


def _tree_occluders(p, n, shells_by_tree, tau, distance):
    """Visibility through every tree's shells, each with its own τ: V = Π (1 − occ) over the
    shells (occluders.h), so one call per distinct τ multiplied is the same field."""
    groups = {}
    for t, es in shells_by_tree.items():
        groups.setdefault(tau_of(tau, t), []).extend(es)
    ao = None
    for tt, es in groups.items():
        v = _occluders(p, n, es, tt, distance)
        ao = v if ao is None else ao * v
    return np.ones(len(p), np.float32) if ao is None else ao


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
                    p: np.ndarray, n: np.ndarray, method: str, tau: float,
                    own=None) -> np.ndarray:
    """AO for receiver points p, n of an item: the scene's own objects (below) times the
    instanced trees of attach_forest, if any (V = Π (1 − occ), so the fields multiply).
    own: None, or {"vertex_ids" | "triangle_ids": int32 (N,)}, each point's vertex or triangle
    in its item (-1 = none), so the exact rung's rays skip only what they start on."""
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
        return trace(plan, p, n, plan.settings.samples, own=own_ids(plan, grass_key, own))
    if method == "grid":
        return _grass(plan, role, grass_key, p, n, _grid_ao(plan, p, n))
    if method == "regression":
        return plan.regression.ao(role, tree, p, n, grass_key, own)
    if method == "hybrid":
        return _grass(plan, role, grass_key, p, n,
                      _hybrid_ao(plan, p, n, own_ids(plan, grass_key, own)))
    ao = np.ones(len(p), np.float32)
    dist = plan.settings.distance
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
        ao[outside_all] = _tree_occluders(po, no, shells, tau, dist)
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
        others = {u: es for u, es in shells.items() if u != t}
        val = _in_shell(pi, ni, plan.fits[t], method, tau_of(tau, t))
        if others:
            val = val * _tree_occluders(pi, ni, others, tau, dist)
        if every:
            ao = np.asarray(val, dtype=np.float32)
        else:
            ao[done] = val
    solids = [e for t, es in plan.trunks.items()
              if t != tree or role in ("GROUND", "GRASS") for e in es]
    if solids:
        ao = ao * _occluders(p, n, solids, 1.0, dist, solid=True)  # opaque: τ is not used
    return _grass(plan, role, grass_key, p, n, ao)


def _grass(plan: Plan, role, grass_key, p, n, ao):
    """ao times the grass: Hegeman Eq. 9 for a blade, every grass layer over the ground
    (grass_layer.py) for a ground point. Returns a new float32 array clipped to [0, 1]."""
    ao = np.array(ao, dtype=np.float32)
    if role == "GRASS":
        ground, blade = plan.grass.get(grass_key, (float(p[:, 2].min()), 1.0))
        ao *= _core.ao_grass(p, n, float(ground), float(blade))
    elif role == "GROUND":
        for layer in plan.grass_layers:
            ao *= layer.ground_visibility(p)
    return np.clip(ao, 0.0, 1.0, out=ao)


def own_ids(plan: Plan, name, own):
    """An item's own ids (see evaluate_points) shifted into the tracer's mesh, or None when the
    item is not in it (or its name is not unique there). -1 (none) stays -1."""
    base = plan.tracer_bases.get(name)
    if not own or base is None:
        return None
    out = {}
    for key, first in zip(("vertex_ids", "triangle_ids"), base):
        ids = own.get(key)
        if ids is not None:
            ids = np.asarray(ids, np.int64)
            out[key] = np.ascontiguousarray(np.where(ids >= 0, ids + first, -1), np.int32)
    return out or None


def trace(plan: Plan, p, n, samples, seed=None, own=None, distance=None):
    """Ray-traced AO of points p, n against the scene's triangles (the exact rung). own: the
    tracer-mesh ids of own_ids, so each ray skips only its receiver's own triangles, as Cycles'
    does (docs/DESIGN.md, 'The method ladder'). distance: the AO distance (default: the
    settings'; 0 = unlimited)."""
    if plan.tracer is None:
        raise CanopyAOError("ray tracing needs the scene's triangles; none were given")
    d = plan.settings.distance if distance is None else distance
    return plan.tracer.ao(p, n, samples=int(samples), distance=float(d) if d > 0 else math.inf,
                          seed=plan.settings.seed if seed is None else int(seed), **(own or {}))


def _grid_ao(plan, p, n):
    if plan.grid is None:  # no leaves or branches to voxelise (a grass field): nothing above
        return np.ones(len(p), np.float32)
    d = plan.settings.distance
    kw = {"distance": float(d)} if d > 0 else {}
    return np.asarray(plan.grid.ao(p, n, **kw), dtype=np.float32)


# The hybrid's near distance in voxels of the density grid: the grid resolves occlusion beyond
# a few voxels, rays the contact shadows inside them (scale-free: the voxel is the grid's box /
# its resolution). Chosen on the design Sapling trees, bench/real_assets.py.
HYBRID_VOXELS = 2.0


def _hybrid_ao(plan, p, n, own=None):
    """Near exact, far statistical (as native ao_near_far): settings.samples rays out to
    HYBRID_VOXELS grid voxels, each skipping only its receiver's own triangles (own: the tracer
    ids of own_ids), times the density grid's transmittance beyond (docs/DESIGN.md, 'The
    near/far hybrid')."""
    d = plan.settings.distance
    far = float(d) if d > 0 else math.inf
    near = min(HYBRID_VOXELS * float(plan.grid.voxel_size), far)
    ao = np.asarray(trace(plan, p, n, plan.settings.samples, own=own, distance=near),
                    dtype=np.float32)
    tail = plan.grid.ao(p, n, distance=far, start=near, seed=plan.settings.seed)
    return ao * np.asarray(tail, dtype=np.float32)


def _scene_triangles(items, bases=None):
    """Every non-ignored item's triangles in one mesh: (vertices float32, triangles int32).
    bases: a dict to fill with item name -> (its first vertex, its first triangle) there (None
    for a name seen twice: it cannot say which mesh it means)."""
    verts, tris, base, tri_base = [], [], 0, 0
    for it in items:
        if it.role == "IGNORE" or not len(it.triangles):
            continue
        if bases is not None:
            bases[it.name] = None if it.name in bases else (base, tri_base)
        verts.append(it.positions)
        tris.append(it.triangles + base)
        base += len(it.positions)
        tri_base += len(it.triangles)
    if not verts:
        raise CanopyAOError("the scene has no triangles")
    return (np.ascontiguousarray(np.concatenate(verts), dtype=np.float32),
            np.ascontiguousarray(np.concatenate(tris), dtype=np.int32))


def build_tracer(items, bases=None):
    """The Embree ray tracer over every non-ignored item's triangles; bases as
    _scene_triangles."""
    return _core.RayTracer(*_scene_triangles(items, bases))


def build_grid(items):
    """The leaf-density grid (docs/DESIGN.md, 'The method ladder') from the leaves and branches
    (CANOPY and TRUNK triangles). Not the ground: as density its area would fill the voxel layer
    a ground receiver's grazing rays travel in (round tree: ground AO 0.67 against 0.92 traced).
    Returns None when there are none (a grass field alone: its blades and the ground under
    them follow the grass laws, as under every other rung)."""
    wood_and_leaves = [it for it in items if it.role in ("CANOPY", "TRUNK") and len(it.triangles)]
    if not wood_and_leaves:
        return None
    return _core.DensityGrid(*_scene_triangles(wood_and_leaves))
