"""The bake's data: scene items (world-space arrays), the plan prepare() makes, results."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from . import roles as _roles
from .native import CanopyAOError

RECEIVER_ROLES = ("CANOPY", "TRUNK", "GROUND", "GRASS")
# Receivers whose τ calibration fits apart from the leaves' (ladder.calibrate), each group one
# factor on every tree's τ (Plan.role_scale): the ground and grass see the crowns from outside,
# through their whole depth; the trunk and branches from within, where the in-shell medium is
# uniform and a crown may not be: cards scattered over a crown's surface leave it hollow, and
# the leaves' τ (fitted on the shell, where they are) made its inside 0.17 too dark
# (docs/studies/foliage.md). On the Sapling trees the trunk's own factor moves the MAE by
# -0.002 to +0.002 (bench/probes/ground_patch.py --trunk-scale).
SCALED_ROLES = (("GROUND", "GRASS"), ("TRUNK",))


@dataclass
class SceneItem:
    """One mesh object in world space: positions, normals float32 (N, 3); triangles int32 (M, 3)."""

    name: str
    role: str
    tree: str
    positions: np.ndarray
    normals: np.ndarray
    triangles: np.ndarray
    # Where the tree came from: "set" (the user's or a generator's name, a parent chain) is
    # kept; "collection" or "scene" (a group, not a tree) is split by trees.resolve().
    tree_source: str = "set"
    # An item holding several trees (one mesh of a grove's leaves): tree_names[tree_labels[v]]
    # is vertex v's tree; None when the whole item is one tree.
    tree_labels: np.ndarray | None = None
    tree_names: tuple = ()
    tree_why: str = ""
    # A part of an item (scene.parts): its vertices' indices in the item it was cut from, so a
    # ray can still name its receiver's vertex in the tracer's mesh (built from whole items).
    vertex_map: np.ndarray | None = None
    # Each triangle's face (polygon) in the mesh, int32 (M,), or None: a vertex of a quad's
    # diagonal or an n-gon's fan is one face corner, as Cycles bakes it (native raytrace.h,
    # 'Origins'); None counts every triangle a corner.
    polygons: np.ndarray | None = None
    # Each triangle corner's own (split) normal, float32 (M, 3, 3), or None: every corner's is
    # its vertex's. Cycles bakes a face corner with it (flat faces, sharp edges, custom normals;
    # native raytrace.h, BakeShading); the exact rung's bake points follow it.
    corner_normals: np.ndarray | None = None
    # opacity.ItemOpacity: which of its triangles rays may pass (their material's alpha), or
    # None: every triangle opaque
    opacity: object = None

    def __post_init__(self):
        self.positions = np.ascontiguousarray(self.positions, dtype=np.float32).reshape(-1, 3)
        self.normals = np.ascontiguousarray(self.normals, dtype=np.float32).reshape(-1, 3)
        self.triangles = np.ascontiguousarray(self.triangles, dtype=np.int32).reshape(-1, 3)
        if self.role not in _roles.ROLES:
            raise CanopyAOError(f"{self.name}: unknown role {self.role!r} (one of {_roles.ROLES})")
        if self.tree_labels is not None and len(self.tree_labels) != len(self.positions):
            raise CanopyAOError(f"{self.name}: {len(self.tree_labels)} tree labels for "
                                f"{len(self.positions)} vertices")
        if self.polygons is not None:
            self.polygons = np.ascontiguousarray(self.polygons, dtype=np.int32).reshape(-1)
            if len(self.polygons) != len(self.triangles):
                raise CanopyAOError(f"{self.name}: {len(self.polygons)} polygon ids for "
                                    f"{len(self.triangles)} triangles")
        if self.corner_normals is not None:
            self.corner_normals = np.ascontiguousarray(self.corner_normals,
                                                       dtype=np.float32).reshape(-1, 3, 3)
            if len(self.corner_normals) != len(self.triangles):
                raise CanopyAOError(f"{self.name}: corner normals for {len(self.corner_normals)}"
                                    f" triangles, not {len(self.triangles)}")
        if len(self.positions) != len(self.normals):
            raise CanopyAOError(f"{self.name}: {len(self.positions)} positions but "
                                f"{len(self.normals)} normals")


def receiver_items(plan, names=None):
    """(item, kind, count) of each receiver item the tracer holds that a bake with this plan
    evaluates: named in ``names`` (None: every one) and, when the plan has targets, one of them
    (its kind, "vertex" or "texel", and count from the target; else every vertex)."""
    for it in plan.tracer_items:
        if it.role not in RECEIVER_ROLES or (names is not None and it.name not in names):
            continue
        if plan.targets and it.name not in plan.targets:
            continue
        kind, n, _group = plan.targets.get(it.name, ("vertex", len(it.positions), 1))
        yield it, kind, int(n)



def tau_of(tau, tree):
    """τ of one tree: ``tau`` is one number for every tree or {tree: τ} (calibrated per tree;
    a tree missing from it takes the value under None)."""
    if isinstance(tau, dict):
        return float(tau.get(tree, tau.get(None, 1.0)))
    return float(tau)


def scaled_tau(tau, scale):
    """``tau`` (one number, or {tree: τ} with None for the rest) with every τ times scale."""
    if isinstance(tau, dict):
        return {t: float(v) * scale for t, v in tau.items()}
    return float(tau) * scale


def ray_length(distance) -> float:
    """The bake's AO distance as a ray length: 0 (or None), the add-on's spelling of
    'unlimited', is math.inf. Every model and tracer takes its cut-off from here. Cycles' World
    distance 0 means something else (no occlusion at all: AO 1.0 everywhere) and never reaches
    a bake: blender/gather.py's world_ao_distance refuses it."""
    d = float(distance or 0.0)
    return d if d > 0 else math.inf


@dataclass
class Plan:
    """What prepare() decided: proxies per tree, method, τ, and the shared state for the bake."""

    settings: object  # settings.BakeSettings
    method: str
    tau: float
    fits: dict = field(default_factory=dict)  # tree -> (Sphere, Ellipsoid, [Ellipsoid] shells)
    proxies: dict = field(default_factory=dict)  # tree -> [Ellipsoid] the chosen method's shells
    trunks: dict = field(default_factory=dict)  # tree -> list of _core.Ellipsoid (solid)
    grass: dict = field(default_factory=dict)  # item name -> (ground_height, blade_height)
    grass_layers: list = field(default_factory=list)  # grass_layer.GrassLayer per grass field
    walls: list = field(default_factory=list)  # walls.Patch: the GROUND surfaces as occluders
    # False: a live bake's, whose frames rebuild the patches only where a wall is and hold a
    # ground alone's occlusion from this bake (live.refit, live.held_ground)
    every_ground: bool = True
    tracer: object = None
    tracer_items: list = field(default_factory=list)  # the items the tracer's mesh holds
    # item name -> (its first vertex, its first triangle) in the tracer's mesh, or None when two
    # items share the name (lighting.own_ids: a ray skips only its receiver's own triangles)
    tracer_bases: dict = field(default_factory=dict)
    grid: object = None
    regression: object = None  # regression.RegressionRung, method "regression"
    calibration: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    forest: object = None  # forest.Forest: instanced trees occluding every receiver (attach_forest)
    tau_by_tree: dict = field(default_factory=dict)  # τ calibrated per tree (else plan.tau)
    # role -> factor on every tree's τ with which the analytic rungs light that role's
    # receivers (SCALED_ROLES; calibrated apart from the leaves: ladder.calibrate); absent = 1
    role_scale: dict = field(default_factory=dict)
    # The bake's card vertices carry their opaque part's AO (card_carry.carry: the add-on's bake
    # loop, not evaluate_item, live AO, a frame range or bent normals): the calibration
    # samples take them there too.
    carry_cards: bool = False
    # tree -> int32 (N,): the k-means shell of each of its canopy points (kept by live AO)
    shell_labels: dict = field(default_factory=dict)
    # tree -> {shell or -1: _core.EllipsoidWarmStart}: live AO's ellipsoid fits start from
    # the previous frame's (proxies.fit_tree; a live session's own dict); None for a bake,
    # which fits afresh
    fit_warm: dict = None
    # lighting.Lights: the native scene plan of fits and trunks, built once (lighting.lights)
    lights: object = None
    # item name -> ("vertex" | "texel", count): the receivers the bake evaluates (its
    # targets), or empty: every receiver item at its vertices (what the cost model counts)
    targets: dict = field(default_factory=dict)
    # item name -> bool (V,): its vertices found buried (Rung.finds_buried False; kept for live
    # frames, which have no tracer), and -> how many receivers a bake set to 0 so
    buried: dict = field(default_factory=dict)
    buried_count: dict = field(default_factory=dict)
    # ray_budget's counts, per tracer: ("mean corners", id(tracer)) -> the mean corners per
    # vertex of the bake's vertex receivers (the exact rung's rays per vertex over the
    # samples), ("corners", name, id(tracer)) -> int64 (V,) each of that object's vertices'
    # corners
    ray_shares: dict = field(default_factory=dict)

    def taus(self):
        """What lighting takes as τ: plan.tau, or {tree: τ, None: plan.tau} per tree."""
        return {**self.tau_by_tree, None: self.tau} if self.tau_by_tree else self.tau


@dataclass
class ItemResult:
    name: str
    role: str
    tree: str
    method: str
    ao: np.ndarray
    seconds: float
    tree_source: str = "set"
    tree_why: str = ""

    @property
    def vertices(self) -> int:
        return int(len(self.ao))


def parts(item: SceneItem):
    """[(part, vertex indices)] of an item holding several trees: each part a SceneItem of one
    tree (its vertices, and the triangles wholly among them); [(item, None)] otherwise."""
    if item.tree_labels is None or len(item.tree_names) <= 1:
        return [(item, None)]
    out = []
    tri_tree = item.tree_labels[item.triangles[:, 0]] if len(item.triangles) else None
    for k, tree in enumerate(item.tree_names):
        idx = np.flatnonzero(item.tree_labels == k)
        tris, polys, corners = np.zeros((0, 3), np.int32), None, None
        if tri_tree is not None:
            keep = (tri_tree == k) & (item.tree_labels[item.triangles[:, 1]] == k) \
                & (item.tree_labels[item.triangles[:, 2]] == k)
            remap = np.full(len(item.positions), -1, np.int64)
            remap[idx] = np.arange(len(idx))
            tris = remap[item.triangles[keep]]
            polys = item.polygons[keep] if item.polygons is not None else None
            corners = item.corner_normals[keep] if item.corner_normals is not None else None
        out.append((SceneItem(item.name, item.role, tree, item.positions[idx],
                              item.normals[idx], tris, tree_source=item.tree_source,
                              tree_why=item.tree_why, vertex_map=idx, polygons=polys,
                              corner_normals=corners), idx))
    return out


def split_trees(items):
    """Every item, those holding several trees replaced by one part per tree."""
    return [part for it in items for part, _idx in parts(it)]


def own_primitives(item: SceneItem, vertices=None, triangles=None):
    """What receivers on item lie on, for the ray tracer (lighting.own_ids shifts it into the
    tracer's mesh): {"vertex_ids": ...} for its vertices ``vertices`` (an index array or
    slice), else {"triangle_ids": ...} for texels on ``triangles`` (int32 (N,), -1 =
    unknown), else None."""
    if isinstance(vertices, slice):  # a chunk of the item's vertices: its ids, made alone
        return {"vertex_ids": np.arange(*vertices.indices(len(item.positions)), dtype=np.int32)}
    if vertices is not None:
        return {"vertex_ids": np.arange(len(item.positions), dtype=np.int32)[vertices]}
    if triangles is not None:
        return {"triangle_ids": np.asarray(triangles, np.int32)}
    return None
