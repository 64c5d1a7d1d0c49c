"""The per-receiver lighting composition as the add-on did it in Python before the native scene
plan (_core.ScenePlan) took it over: kept here, unchanged in substance, as the reference the
native plan is tested against (tests/python/test_scene_plan.py). Analytic rungs only (sphere,
ellipsoid, reeves_blau, shells, medium), with the two multipliers that were applied after it:
the grass layers over a ground point (the numpy disc count core/grass_layer.py had) and the
instanced forest (one OccluderField per prototype and one for the solids, as core/forest.py
had); then the GROUND surfaces' patches (core/walls.py), which lighting multiplies in after
the native call."""

import math

import numpy as np

from canopy_ao.core import forest as _forest, walls
from canopy_ao.core.lighting import tau_of
from canopy_ao.core.scene import ray_length
from canopy_ao.core.native import _core
from canopy_ao.core.proxies import own_shells


def ground_visibility(layer, p):
    """float32 (N,): a GrassLayer's V for ground points p (N, 3) under its footprint, else 1."""
    p = np.asarray(p, np.float64).reshape(-1, 3)
    v = np.ones(len(p), np.float32)
    if not len(p):
        return v
    near = np.flatnonzero(np.abs(p[:, 2] - layer.ground) <= layer.blade)
    if not len(near):
        return v
    c = layer.cells
    m = max(1, int(math.ceil(layer.blade / c.h)))
    ij = c._ij(p[near, :2])
    hits = np.zeros(len(near))
    total = 0
    for di in range(-m, m + 1):
        for dj in range(-m, m + 1):
            if di * di + dj * dj > m * m:
                continue
            total += 1
            jj = ij[:, 1] + dj
            ok = (ij[:, 0] + di >= 0) & (jj >= 0) & (jj < c.width)
            hit, _pos = c._find((ij[:, 0] + di) * c.width + jj)
            hits += ok & hit
    v[near] = 1.0 - (hits / total) * (1.0 - layer.visibility)
    return v


_FIELDS = {}  # id(forest.Forest) -> (the forest, its OccluderFields)


def forest_ao(forest, p, n):
    """Visibility float32 (N,) of receivers under every instance of a forest.Forest."""
    if id(forest) not in _FIELDS or _FIELDS[id(forest)][0] is not forest:
        kw = {"distance": forest.distance} if forest.distance > 0 else {}
        fields, solids = [], []
        for pr in forest.prototypes:
            world = _forest.instance_shells(pr.shells, pr.matrices)
            if world:
                fields.append(_core.OccluderField(world, float(pr.tau), epsilon=forest.epsilon,
                                                  **kw))
            solids += _forest.instance_shells(pr.solids, pr.matrices)
        if solids:
            fields.append(_core.OccluderField(solids, 1.0, epsilon=forest.epsilon, solid=True,
                                              **kw))
        _FIELDS[id(forest)] = (forest, fields)
    out = np.ones(len(p), np.float32)
    for f in _FIELDS[id(forest)][1]:
        out *= np.asarray(f.ao(p, n), np.float32)
    return out


def _occluders(p, n, shells, tau, distance, solid=False):
    if not shells or len(p) == 0:
        return np.ones(len(p), np.float32)
    kw = {"distance": float(distance)} if distance > 0 else {}
    return _core.ao_occluders(p, n, list(shells), float(tau), solid=solid, **kw)


def _tree_occluders(p, n, shells_by_tree, tau, distance):
    groups = {}
    for t, es in shells_by_tree.items():
        groups.setdefault(tau_of(tau, t), []).extend(es)
    ao = None
    for tt, es in groups.items():
        v = _occluders(p, n, es, tt, distance)
        ao = v if ao is None else ao * v
    return np.ones(len(p), np.float32) if ao is None else ao


def _in_shell(p, n, tree_fit, method, tau):
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
    raise ValueError(method)


def evaluate(plan, role, tree, grass_key, p, n, method, tau):
    """AO of receivers p, n as the old lighting._evaluate_scene_points (analytic branch)."""
    if len(p) == 0:
        return np.ones(0, np.float32)
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
    if outside_all.any():
        po, no = np.ascontiguousarray(p[outside_all]), np.ascontiguousarray(n[outside_all])
        ao[outside_all] = _tree_occluders(po, no, shells, tau, dist)
    claimed = np.zeros(len(p), bool)
    for t, ins in inside.items():
        done = ins & ~claimed
        claimed |= ins
        if not done.any():
            continue
        pi, ni = np.ascontiguousarray(p[done]), np.ascontiguousarray(n[done])
        others = {u: es for u, es in shells.items() if u != t}
        val = _in_shell(pi, ni, plan.fits[t], method, tau_of(tau, t))
        if others:
            val = val * _tree_occluders(pi, ni, others, tau, dist)
        ao[done] = val
    solids = [e for t, es in plan.trunks.items()
              if t != tree or role in ("GROUND", "GRASS") for e in es]
    if solids:
        ao = ao * _occluders(p, n, solids, 1.0, dist, solid=True)
    ao = np.array(ao, dtype=np.float32)
    if role == "GRASS":
        ground, blade = plan.grass.get(grass_key, (float(p[:, 2].min()), 1.0))
        layer = next((g.layer for g in plan.grass_layers if g.name == grass_key), None)
        ao *= _core.ao_grass(p, n, float(ground), float(blade), layer=layer)
    ao = np.clip(ao, 0.0, 1.0, out=ao)
    if role == "GROUND" and plan.grass_layers:
        for layer in plan.grass_layers:
            ao *= ground_visibility(layer, p)
        np.clip(ao, 0.0, 1.0, out=ao)
    if plan.forest is not None:
        ao = np.clip(ao * forest_ao(plan.forest, p, n), 0.0, 1.0).astype(np.float32)
    # the GROUND surfaces' patches (core/walls.py), multiplied after the native plan's call
    if role == "GRASS":  # the grass law holds the ground the blades stand on
        return ao
    return ao * walls.visibility(plan.walls, p, n, ray_length(plan.settings.distance))
