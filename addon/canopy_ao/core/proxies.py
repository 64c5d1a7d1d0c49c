"""Fitted proxies per tree: the canopy's sphere, ellipsoid and k shells, and solid trunks
(docs/DESIGN.md, 'The method ladder'). Trunk points are receivers, not shape."""

from __future__ import annotations

import numpy as np

from . import card_area
from . import roles as _roles
from .grass_layer import grass_layer
from .native import _core
from .rungs import base as rungs
from .rungs.base import Proxy
from .scene import Plan, SceneItem

# Khachiyan's tolerance of live AO's ellipsoid fits (fit_tree's warm), against a bake's 1e-3:
# tight enough that a frame's fit no longer depends on the frame it started from (the same
# points reached from two histories: centres and radii within 5e-7), so playback order, a
# render farm's chunks and a reloaded file give the same AO; warm-started it still costs half
# a fresh fit at 1e-3 (5 against 10 ms of one core per 100k points, loaded machine).
LIVE_TOLERANCE = 1e-6
MIN_BOLE = 8  # points a piece of a bole needs outside the crown to be fitted as a solid


def fit_tree(points: np.ndarray, settings, labels=None, warm=None):
    """Fitted canopy proxies for one tree and its points' shells: ((sphere, ellipsoid,
    [k shells]), labels int32 (N,) or None). The k-means shells cost most (1.2 s for 1M
    points), so only the methods that use them get them; the others get [ellipsoid].

    ``labels`` (an earlier fit's, for the same points moved: live AO) keeps that partition: each
    shell is refitted to the same leaves, as fit_shells fits a cluster, instead of clustering
    again, whose partition can flip between two frames (docs/DESIGN.md, 'Live and per-frame
    AO').

    ``warm`` (live AO: {key: _core.EllipsoidWarmStart}, kept between frames) starts each
    ellipsoid's fit from the previous frame's (its Khachiyan support and weights) and solves
    it to LIVE_TOLERANCE; None = a fresh fit at the bake's tolerance."""
    rung = rungs.get(settings.method)

    def fit(pts, key):
        if warm is None:
            return _core.fit_ellipsoid(pts, trim=settings.trim)
        if key not in warm:
            warm[key] = _core.EllipsoidWarmStart()
        st = warm[key]
        return _core.fit_ellipsoid(pts, trim=settings.trim, tolerance=LIVE_TOLERANCE,
                                   warm=st)
    sphere = _core.fit_sphere(points, trim=settings.trim)
    if rung.proxy is Proxy.SPHERE:
        # The sphere model uses no ellipsoid: skip its fit (~40 ms per million points); the
        # sphere is then also the crown a trunk's bole is cut from (bole), as it is the medium.
        ell = _core.Ellipsoid.from_sphere(sphere)
    else:
        ell = fit(points, -1)
    k = max(1, min(settings.shells, len(points) // 64))
    if rung.proxy is not Proxy.SHELLS:
        k = 1
    if k > 1 and labels is not None and len(labels) == len(points):
        shells = [fit(np.ascontiguousarray(points[labels == c]), int(c))
                  for c in np.unique(labels)]
    elif k > 1:
        shells, labels = _core.fit_shells(points, k, kind="ellipsoid", trim=settings.trim,
                                          seed=settings.seed)
        shells = list(shells)
    else:
        shells, labels = [ell], None
    return (sphere, ell, shells), labels


def own_shells(plan: Plan, tree: str, method) -> list:
    """The shells of ``tree`` that ``method`` (a rung or its name) lights with (and that
    occlude for it): Rung.own_shells."""
    return rungs.get(method).own_shells(plan, tree)


def bole(plan: Plan, item: SceneItem) -> list:
    """The trunk points solid occluders should stand for: those outside the tree's crown, one
    float32 (K, 3) array per connected piece of the mesh (a stem, a branch tube: Sapling
    bevels each on its own) with at least MIN_BOLE points there. Branches inside the crown are
    already in the canopy's medium; an ellipsoid fitted to them too would be a solid as big as
    the crown (it darkened the ground by 0.1 on the grove). A piece with fewer points outside
    is a branch's base poking out of the crown's proxy, the crown's: fitted with the stem into
    one ellipsoid, such bases made it a slab metres wide, opaque over the ground (the Sapling
    aspen's 0.04 too dark under the sphere, whose narrow bottom the lowest branches leave; the
    white birch's 0.017 under the ellipsoid; docs/DESIGN.md, 'How each role is lit'). A mesh
    without faces is one piece."""
    p = item.positions
    inside = np.zeros(len(p), bool)
    if item.tree in plan.fits:
        _sphere, ell, shells = plan.fits[item.tree]
        inside = np.asarray(ell.contains(p), bool)
        for e in shells:
            inside |= np.asarray(e.contains(p), bool)
    out = np.flatnonzero(~inside)
    if len(item.triangles) == 0:
        labels = np.zeros(len(out), np.int64)
    else:
        labels = _roles.connected_components(len(p), item.triangles)[out]
    order = np.argsort(labels, kind="stable")
    cuts = np.flatnonzero(np.diff(labels[order])) + 1
    return [np.ascontiguousarray(p[out[g]]) for g in np.split(order, cuts)
            if len(g) >= MIN_BOLE]


def bole_solids(plan: Plan, item: SceneItem) -> list:
    """The solid ellipsoids standing for a trunk's bole (bole): one over all its pieces where
    it is no larger than their own ellipsoids together (pieces bundled where a stem forks,
    each inside the others' hull), else one per piece (branches reaching out of the crown
    apart: one ellipsoid over them would be mostly air). Volumes are compared, so the choice
    is scale-free."""
    pieces = bole(plan, item)
    solids = [_core.fit_ellipsoid(b) for b in pieces]
    if len(solids) < 2:
        return solids
    whole = _core.fit_ellipsoid(np.ascontiguousarray(np.concatenate(pieces)))
    volume = lambda e: float(np.prod(np.asarray(e.radii, np.float64)))  # noqa: E731 (× 4π/3)
    return [whole] if volume(whole) <= sum(map(volume, solids)) else solids


def fit_scene(plan: Plan, items) -> None:
    """Fill plan.fits (per tree, from its CANOPY points), plan.trunks (solid ellipsoids per
    trunk, fitted to its bole: bole_solids), plan.grass (ground level and blade height per
    grass item) and plan.grass_layers (each grass field as an occluder of the ground under
    it)."""
    trees = {}
    for it in items:
        # a card's points where it is opaque (card_area.counted_points): none when all clear
        pts = card_area.counted_points(it) if it.role == "CANOPY" else ()
        if len(pts):
            trees.setdefault(it.tree, []).append(pts)
    for tree, pts in trees.items():
        pts = np.ascontiguousarray(pts[0] if len(pts) == 1 else np.concatenate(pts),
                                   dtype=np.float32)
        warm = None if plan.fit_warm is None else plan.fit_warm.setdefault(tree, {})
        plan.fits[tree], labels = fit_tree(pts, plan.settings, plan.shell_labels.get(tree), warm)
        if labels is not None:
            plan.shell_labels[tree] = labels
    for it in items:
        if it.role == "TRUNK":
            solids = bole_solids(plan, it)
            if solids:
                plan.trunks.setdefault(it.tree, []).extend(solids)
        if it.role == "GRASS":
            plan.grass[it.name] = _roles.blade_heights(it.positions, it.triangles)
            layer = grass_layer(it.name, it.positions, it.triangles, *plan.grass[it.name],
                                distance=plan.settings.distance)
            if layer is not None:
                plan.grass_layers.append(layer)


def proxy_dicts(plan: Plan) -> dict:
    """Proxies as plain data {tree: [{"center", "axes", "radii"}]} for display and JSON."""
    out = {}
    for tree, shells in plan.proxies.items():
        out[tree] = [{"center": np.asarray(e.center, float).tolist(),
                      "axes": np.asarray(e.axes, float).tolist(),
                      "radii": np.asarray(e.radii, float).tolist()} for e in shells]
    return out
