"""The ray-free "regression" rung: a ridge fit of the traced calibration sample on cheap
per-vertex occlusion features, carried over to every vertex. No bpy.

Why (docs/DESIGN.md, "The method ladder", "The ray-free rung"): the leaf-density grid follows
where the leaves are but misses what is below a voxel (a leaf shaded by its neighbour or by its
own branch); the calibration sample measures exactly that, per scene. The features and the
model's evaluation are native (``_core.OcclusionFeatures``, ``_core.predict_features``:
occlusion_features.h); here are the sample, the fit and the bookkeeping.

Cost: grids O(triangles), one Embree BVH (the bake's, when it has one) and ``points`` ×
``samples`` calibration rays (calibration_size: at most 1024 × 128, fewer on a small scene),
then a fixed number of grid lookups per vertex, whatever the leaf count. No rays beyond the
sample (a bake's buried test adds its own: bake._zero_buried).

Fit, per (tree, role) group with enough sample points (else per role, else scene-wide):
standardised features, expanded to [1, z, z², z_grid·z] (native), ridge regression with λ
chosen by 5-fold cross-validation on the sample (ties to the larger λ); the piece columns
(LeafTable) only where they cut that CV error by more than PIECES_GAIN (_fit). Buried sample points
(every ray stops within ``buried.BURIED_SCALE`` of the object's size: a leaf base inside its branch)
are kept out of the fit — their AO of 0 says nothing about the rest of the leaf; the model
predicts them like any vertex. The GROUND patches (core/walls.py) are multiplied in as the
proxy rungs do: the model is fitted to the sample as g(features) × V_ground (its rows weighted
by each point's patch visibility) and its caller multiplies that visibility back
(rungs/regression.py, lighting.walls_ao)."""
from __future__ import annotations

import copy
import time

import numpy as np

from . import buried as _buried
from . import card_ao, native, walls
from .leaf_features import LeafTable, tree_frame  # noqa: F401 (tree_frame: tests)
from .meshes import bake_shading, merged
from .native import CanopyAOError
from .regression_fit import NATIVE, PIECES_GAIN, fit_group as _fit  # noqa: F401 (tests)
from .regression_fit import (MIN_POINTS, MIN_SAMPLES, POINTS, RAYS_PER_RECEIVER,  # noqa: F401
                             _sample, calibration_size)
from .regression_geometry import LEAF_TABLE_ROLES, geometry as _geometry  # noqa: F401
from .scene import RECEIVER_ROLES, ray_length

OCCLUDER_ROLES = ("CANOPY", "TRUNK", "GRASS")
# Buried: the one test (buried.py) with twice auto's rays: with 16 rays more of the darkest
# unburied points fail it and leave the fit, white birch MAE 0.047 against 0.046.
BURIED_RAYS = 2 * _buried.BURIED_RAYS
MIN_GROUP = 96           # sample points a group needs for its own fit
def _own_ids_from(bases):
    """ids(item, idx, key) for the rung's own tracer: the rows' (key "vertex_ids") or the
    triangles' ("triangle_ids") place in its merged mesh (bases: {id(item): its first vertex
    and first triangle there}; a part of an item is its own mesh there)."""
    def ids(item, idx, key="vertex_ids"):
        first = bases[id(item)][key == "triangle_ids"]
        return (np.asarray(idx, np.int64) + first).astype(np.int32)
    return ids


class RegressionRung:
    """The fitted rung for one scene: build once (grid, sweeps, calibration sample, fits), then
    :meth:`ao` for any receiver points of an item, in any number of calls.

    items: SceneItems (roles upper case; IGNORE skipped). distance: the AO distance of the
    calibration rays (0 = unlimited). points × samples: the calibration sample's largest size
    (calibration_size shrinks it on small scenes); resolution: the grid's. The sample is traced
    against every non-ignored triangle with each point's own vertex named, so a receiver skips
    only the triangles it starts on (as Cycles); cards: a card vertex is sampled where the
    bake's takes its AO, at its card's opaque part (card_ao.sample_points; Plan.carry_cards).
    tracer, ids: the plan's ray tracer over the same triangles and ids(item, idx, key) -> its
    ids of those rows (key "vertex_ids") or triangles ("triangle_ids"; ladder.sample_ids): one
    BVH a bake; None = the rung's own. meshes: the unsplit items when ``items`` are split per
    tree (scene.parts), for the leaf tables (LeafTable) by item name; None = the items.
    patches: the GROUND patches (walls.build of the unsplit items, Plan.walls) whose visibility
    the fit divides out and :meth:`ao`'s caller multiplies back; None = built here from meshes
    (or items)."""

    _bounded = False  # a live frame's copy holds its features to the sample's range

    def __init__(self, items, distance=0.0, points=1024, samples=128, resolution=64,
                 directions=24, seed=0, tracer=None, ids=None, meshes=None, cards=False,
                 patches=None):
        _core = native.require()
        t0 = time.perf_counter()
        items = [it for it in items if it.role != "IGNORE"]
        occ = [it for it in items if it.role in OCCLUDER_ROLES]
        if not occ:
            raise CanopyAOError("method 'regression' needs a CANOPY, TRUNK or GRASS object")
        receivers = [it for it in items if it.role in RECEIVER_ROLES and len(it.positions)]
        n_recv = sum(len(it.positions) for it in receivers)
        points, samples = calibration_size(n_recv, points, samples)
        self.patches = list(patches) if patches is not None else walls.build(
            meshes if meshes is not None else items)
        self._features, self._leaves, self._scene_frame, self._frames = _geometry(
            items, occ, meshes, resolution, directions)
        t_grid = time.perf_counter()

        # Calibration sample, stratified by (tree, role); traced with each point's own vertex.
        own_tracer = tracer is None
        if own_tracer:
            bases, base, tbase = {}, 0, 0
            traced = occ + [it for it in items if it.role == "GROUND"]
            for it in traced:
                bases[id(it)] = (base, tbase)
                base, tbase = base + len(it.positions), tbase + len(it.triangles)
            tracer = _core.RayTracer(*merged(traced), **bake_shading(traced))  # bake points
            ids = _own_ids_from(bases)
        t_tracer = time.perf_counter()
        groups = {}
        for it in receivers:
            groups.setdefault((it.tree, it.role), []).append(it)
        picks = _sample({g: sum(len(it.positions) for it in its) for g, its in groups.items()},
                        points, seed)
        d = ray_length(distance)
        sample = {}
        for g, idx in picks.items():
            its = groups[g]
            offs = np.cumsum([0] + [len(it.positions) for it in its])
            owner = np.searchsorted(offs, idx, side="right") - 1
            P = np.concatenate([it.positions for it in its])[idx]
            N = np.concatenate([it.normals for it in its])[idx]
            own = np.full(len(idx), -1, np.int32)
            for k, it in enumerate(its):
                m = owner == k
                got = ids(it, idx[m] - offs[k]) if m.any() else None
                if got is not None:
                    own[m] = got
            # a card vertex at its card's opaque part (its triangle its own), as the bake shows it
            tri, own_tri = card_ao.move_to_cards(its if cards else (), owner, idx - offs[owner],
                                                 P, N, own, ids)
            diag = np.array([_buried.size(it.positions) for it in its])[owner]
            ground = self.ground(g[1], P, N, d)
            ao = _trace(tracer, P, N, samples, d, seed + 1, own, own_tri)
            buried = _buried_mask(tracer, P, N, diag, own, own_tri)
            F = np.zeros((len(idx), NATIVE + LeafTable.COUNT), np.float32)
            for k, it in enumerate(its):
                m = owner == k
                if m.any():
                    rows = idx[m] - offs[k]
                    whole = it.vertex_map[rows] if it.vertex_map is not None else rows
                    F[m] = self._compute(it.tree, P[m], N[m], it.name, {
                        "vertex_ids": np.where(tri[m] < 0, whole, -1), "triangle_ids": tri[m]})
            sample[g] = dict(features=F[~buried], ao=ao[~buried], ground=ground[~buried],
                             buried=int(buried.sum()))
        t_cal = time.perf_counter()
        # Fit per group, falling back to the role's pooled sample, then to everything.
        by_role = {}
        for g, s_ in sample.items():
            by_role.setdefault(g[1], []).append(s_)

        def pool(ss):
            return tuple(np.concatenate([s_[k] for s_ in ss]) for k in ("features", "ao",
                                                                          "ground"))

        self._models, self.fits, cache = {}, {}, {}
        for g in groups:
            s_ = sample.get(g)
            if s_ is not None and len(s_["ao"]) >= MIN_GROUP:
                src, (F, y, v) = "own", (s_["features"], s_["ao"], s_["ground"])
            elif sum(len(t["ao"]) for t in by_role.get(g[1], [])) >= MIN_GROUP:
                src, (F, y, v) = f"role {g[1]}", pool(by_role[g[1]])
            else:
                src, (F, y, v) = "scene", pool(list(sample.values()))
            if len(y) < 8:
                raise CanopyAOError("method 'regression': fewer than 8 unburied calibration "
                                    "points (is every receiver buried inside geometry?)")
            ck = g if src == "own" else src
            if ck not in cache:
                cache[ck] = _fit(F, y, v)
            m = self._models[g] = cache[ck]
            self.fits[f"{g[0] or '-'}/{g[1]}"] = dict(
                source=src, points=int(m.n), lam=float(m.lam), cv_mae=round(float(m.cv_mae), 4),
                piece_features=m.pieces, buried=int(s_["buried"]) if s_ else 0)
        self._fallback = cache[next(iter(cache))] if cache else None
        t_fit = time.perf_counter()
        self.report = dict(method="regression", groups=self.fits, resolution=resolution,
                           directions=directions, calibration_samples=samples,
                           calibration_points=int(sum(len(v) for v in picks.values())),
                           calibration_rays=int(samples * sum(len(v) for v in picks.values())),
                           receivers=int(n_recv),
                           shared_tracer=not own_tracer,
                           leaves={k: int(len(v.size)) for k, v in self._leaves.items() if v},
                           timings=dict(grid=t_grid - t0, tracer=t_tracer - t_grid,
                                        calibration=t_cal - t_tracer, fit=t_fit - t_cal))

    def at_frame(self, items, meshes=None):
        """A copy on a frame of the same meshes deformed (live AO): _geometry redone, fit kept."""
        out = copy.copy(self)
        items = [it for it in items if it.role != "IGNORE"]
        occ = [it for it in items if it.role in OCCLUDER_ROLES]  # the first frame's: not none
        # The leaf tables only where a model reads them (a fit that kept the piece columns):
        # rebuilding them costs 5-10 ms per 100k vertices a frame.
        pieces = any(m.pieces for m in self._models.values())
        out._features, out._leaves, out._scene_frame, out._frames = _geometry(
            items, occ, meshes, self.report["resolution"], self.report["directions"],
            self._leaves, tables=pieces)
        out._bounded = True  # features held to the first frame's sample (Model.predict)
        return out

    def _compute(self, tree, p, n, name=None, own=None, pieces=True):
        """Features of points p, n: the NATIVE columns, then (pieces) the LeafTable's."""
        frame = self._frames.get(tree, self._scene_frame)
        p = np.ascontiguousarray(p, np.float32)
        f = np.asarray(self._features.compute(p, np.ascontiguousarray(n, np.float32), *frame))
        if not pieces:
            return f
        leaves = self._leaves.get(name)
        extra = (leaves.features(p, leaves.labels_of(own, len(p)), frame) if leaves is not None
                 else np.zeros((len(p), LeafTable.COUNT), np.float32))
        return np.concatenate([f, extra], axis=1)

    def ground(self, role, p, n, distance):
        """float32 (N,): the GROUND patches' visibility of points p, n of this role, as
        lighting.walls_ao gives it (1 for a grass blade, whose traced AO holds its ground)."""
        if not self.patches or role == "GRASS":
            return np.ones(len(p), np.float32)
        return np.asarray(walls.visibility(self.patches, p, n, distance), np.float32)

    def ao(self, role, tree, p, n, name=None, own=None):
        """AO of receiver points p, n (float32 (N, 3)) of an item with this role and tree,
        without the GROUND patches, which the caller multiplies in (rungs/regression.py:
        lighting.walls_ao, as for the proxy rungs; a live frame the ground held).
        name, own: the item's name and {"vertex_ids" | "triangle_ids"} of each point in it
        (-1 = none), so a leaf's points know their leaf (LeafTable); without them a point
        reads as its leaf's centre."""
        if len(p) == 0:
            return np.ones(0, np.float32)
        model = self._models.get((tree, role))
        if model is None:  # an item the sample did not see: its role's fit, else any
            model = next((m for (t, r), m in self._models.items() if r == role), self._fallback)
        return model.predict(self._compute(tree, p, n, name, own, pieces=model.pieces),
                             bounded=self._bounded)


class OpenSky:
    """The ray-free rung of a scene whose own objects occlude nothing, its trees all instanced
    (a ground under a forest): 1 for every receiver, which the forest's shells then darken as
    they do every rung's but the exact one (lighting.evaluate_points)."""

    def __init__(self):
        self.report = dict(method="regression", groups={},
                           note="no occluder but instanced trees")

    def ao(self, role, tree, p, n, name=None, own=None):
        return np.ones(len(p), np.float32)

    def at_frame(self, items, meshes=None):
        return self


def occludes(items) -> bool:
    """Whether any item is a CANOPY, TRUNK or GRASS one the rung's grid would voxelise."""
    return any(it.role in OCCLUDER_ROLES for it in items)


def bake(items, distance=0.0, **options):
    """({item name: float32 AO}, report) for every item by the regression rung (a one-off
    RegressionRung; IGNORE items get 1)."""
    t0 = time.perf_counter()
    rung = RegressionRung(items, distance, **options)
    d = ray_length(distance)
    out = {it.name: (rung.ao(it.role, it.tree, it.positions, it.normals, it.name,
                             {"vertex_ids": np.arange(len(it.positions))})
                     * rung.ground(it.role, it.positions, it.normals, d)
                     if it.role in RECEIVER_ROLES else np.ones(len(it.positions), np.float32))
           for it in items}
    rung.report["timings"]["total"] = time.perf_counter() - t0
    return out, rung.report


def _own(ids, tris, m=slice(None)):
    """RayTracer.ao's own-primitive arguments of rows m: vertex ids, and triangle ids (a card
    vertex's receiver on its card) when any."""
    out = {"vertex_ids": np.ascontiguousarray(ids[m], np.int32)}
    if tris is not None:
        out["triangle_ids"] = np.ascontiguousarray(tris[m], np.int32)
    return out


def _trace(tracer, P, N, samples, distance, seed, ids, tris=None):
    """Traced AO; points with an own vertex id (>= 0) skip only their own triangles, those with
    an own triangle id (tris, >= 0) that triangle."""
    P, N = np.ascontiguousarray(P, np.float32), np.ascontiguousarray(N, np.float32)
    return np.asarray(tracer.ao(P, N, samples=int(samples), distance=distance, seed=int(seed),
                                **_own(ids, tris)))


def _buried_mask(tracer, P, N, diag, ids, tris=None):
    """bool: the points buried (buried.enclosed) in their object, of diagonal ``diag``."""
    out = np.zeros(len(P), bool)
    for dg in np.unique(diag):
        m = diag == dg
        if dg <= 0:
            continue
        out[m] = _buried.enclosed(tracer, P[m], N[m], dg, BURIED_RAYS, 7, **_own(ids, tris, m))
    return out
