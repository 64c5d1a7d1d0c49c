"""The per-receiver lighting composition as the add-on did it in Python before the native scene
plan (_core.ScenePlan) took it over: kept here, unchanged in substance, as the reference the
native plan is tested against (tests/python/test_scene_plan.py). Analytic rungs only (sphere,
ellipsoid, reeves_blau, shells, medium); the forest and the grass layers over the ground stay
Python multipliers in core/lighting.py and are not part of it."""

import numpy as np

from canopy_ao.core.lighting import tau_of
from canopy_ao.core.native import _core
from canopy_ao.core.proxies import own_shells


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
        ao *= _core.ao_grass(p, n, float(ground), float(blade))
    elif role == "GROUND":
        for layer in plan.grass_layers:
            ao *= layer.ground_visibility(p)
    return np.clip(ao, 0.0, 1.0, out=ao)
