"""How each role is lit: AO of receiver points against the plan's proxies, trunks, grass law,
ray tracer or density grid (docs/DESIGN.md, 'How each role is lit').

- CANOPY / TRUNK of tree t: points inside t's shells get the in-shell model (sphere, ellipsoid or
  several shells, Hegeman Eq. 4-6); points outside them see t's shells as occluders; every other
  tree's shells and trunks are occluders.
- GROUND: every tree's shells (as semi-transparent occluders) and every trunk (a solid ellipsoid
  fitted to the trunk) are occluders.
- GRASS: the field's blade layer (grass_layer.blade_layer; Hegeman Eq. 9 without one) with
  ground level and blade height found from the blades (connected components) × the same
  occluders as the ground.
- method "raytrace": Embree rays against every non-ignored triangle of the scene.

The analytic rungs' composition is the native scene plan's (_core.ScenePlan, scene_plan.h),
built once per bake from the fitted proxies and the grass layers, with the instanced forest
attached to it (Lights): one call per set of receivers; this module only chooses the call.
"""

from __future__ import annotations

import numpy as np

from . import card_area, ray_budget, texel_budget, walls
from .forest import tracer_instances
from .meshes import bake_shading, scene_triangles
from .native import CanopyAOError, _core
from .rungs.base import get as rung_of, plan_method
from .scene import Plan, ray_length, scaled_tau, tau_of


class Lights:
    """The scene's lighting as data: the native ScenePlan (every tree's crown proxies and solid
    trunks with their occluder grids, and the grass layers over the ground, built once per
    bake; the instanced forest attached to it) and the tree names its indices stand for.
    Calibration's τ search and every item's evaluation reuse it."""

    def __init__(self, plan: Plan):
        # Crowns first, in plan.fits order (a receiver inside two crowns takes the first's
        # model), then trees that have a trunk but no leaves.
        self.trees = list(plan.fits) + [t for t in plan.trunks if t not in plan.fits]
        self.index = {t: i for i, t in enumerate(self.trees)}
        d = plan.settings.distance
        self.native = _core.ScenePlan([plan.fits.get(t) for t in self.trees],
                                      [list(plan.trunks.get(t, ())) for t in self.trees],
                                      distance=ray_length(d),
                                      grass_covers=[g.native for g in plan.grass_layers])
        self.forest = None  # the forest.Forest attached to self.native (lights)
        self.key = _lights_key(plan)

    def taus(self, tau) -> list:
        """One τ per tree of the plan (tau_of)."""
        return [tau_of(tau, t) for t in self.trees]

    def tree_ids(self, tree):
        """The plan's index of a tree name (-1: none), or for (names, labels) — receivers of an
        item holding several trees, labels indexing names — an int32 index per receiver."""
        if not isinstance(tree, tuple):
            return self.index.get(tree, -1)
        names, labels = tree
        ids = np.array([self.index.get(t, -1) for t in names], np.int32)
        return np.ascontiguousarray(ids[np.asarray(labels, np.intp)])


def _lights_key(plan: Plan):
    """What Lights is built from: the proxies' and grass layers' identities, the AO distance."""
    return (tuple((t, id(f)) for t, f in plan.fits.items()),
            tuple((t, tuple(map(id, es))) for t, es in plan.trunks.items()),
            tuple(map(id, plan.grass_layers)), plan.settings.distance)


def lights(plan: Plan) -> Lights:
    """plan.lights, built on first use after the proxies are fitted (bake.prepare builds it
    there) and again only if the proxies, the grass layers or the AO distance changed since.
    plan.forest (attach_forest may come after the plan was built) is attached to it as it is
    now, without rebuilding the trees' occluder grids."""
    if plan.lights is None or plan.lights.key != _lights_key(plan):
        plan.lights = Lights(plan)
    lit = plan.lights
    if lit.forest is not plan.forest:
        lit.native.set_forest(plan.forest.native if plan.forest is not None else None)
        lit.forest = plan.forest
    return lit


def evaluate_points(plan: Plan, role: str, tree: str, grass_key: str | None,
                    p: np.ndarray, n: np.ndarray, method: str, tau: float,
                    own=None, group=1) -> np.ndarray:
    """AO for receiver points p, n of an item: the scene's own objects (below) times the
    instanced trees of attach_forest, if any (V = Π (1 − occ), so the fields multiply).
    tree: the item's tree, or for the analytic rungs (names, labels): a tree per receiver.
    own: None, or {"vertex_ids" | "triangle_ids": int32 (N,)}, each point's vertex or triangle
    in its item (-1 = none), so the exact rung's rays skip only what they start on.
    group: consecutive points forming one receiver, a texel's sub-samples (ray_args)."""
    rung = rung_of(method)
    ao = _evaluate_scene_points(plan, role, tree, grass_key, p, n, rung, tau, own, group)
    # The analytic rungs' scene plan multiplies the forest in its own call; the exact rung's
    # rays already hit the instanced trees when its tracer holds them.
    if (plan.forest is not None and len(p) and not rung.scene_plan
            and not (rung.rays_see_instances and traces_instances(plan))):
        ao = np.clip(ao * plan.forest.ao(p, n), 0.0, 1.0).astype(np.float32, copy=False)
    return ao


def _evaluate_scene_points(plan: Plan, role: str, tree: str, grass_key: str | None,
                           p: np.ndarray, n: np.ndarray, rung, tau: float,
                           own=None, group=1) -> np.ndarray:
    """AO for receiver points p, n (float32 (N, 3)) of an item with this role and tree: the
    rung's own evaluate (rungs/base.py), called here so every rung sees the same empty case."""
    if len(p) == 0:
        return np.ones(0, np.float32)
    return rung.evaluate(rung, plan, role, tree, grass_key, p, n, tau, own, group)


def exact_ao(plan: Plan, grass_key, p, n, own=None, group=1) -> np.ndarray:
    """The exact rung's AO: Embree rays at settings.samples (a vertex's spread evenly over the
    bake's vertices where that applies: ray_budget.py)."""
    ids = own_ids(plan, grass_key, own)
    if ray_budget.applies(plan, grass_key, ids):
        return ray_budget.trace(plan, grass_key, p, n, ids)
    return trace(plan, p, n, own=ids, **ray_args(plan, group))


def grid_ao(plan: Plan, role, grass_key, p, n) -> np.ndarray:
    """The density grid's AO times the grass (a blade's own law, the layers over the ground)."""
    ao = _grid_ao(plan, p, n)
    if plan.walls:
        ao = ao * walls_ao(plan, p, n, role)
    return _grass(plan, role, grass_key, p, n, ao)


def scene_plan_ao(rung, plan: Plan, role, tree, grass_key, p, n, tau, own=None, group=1):
    """The analytic rungs' evaluate. Any receiver inside a tree's shells (its own canopy, a
    trunk, but also ground or grass that a low crown reaches down to) gets that tree's
    in-shell model; every shell it is outside of is an occluder. Trunks are solid occluders
    for everything but their own tree's canopy and trunk (which sit inside or on them). The
    whole per-receiver composition, grass layers and forest included, is one native call
    (docs/DESIGN.md, 'How each role is lit')."""
    if plan.role_scale.get(role, 1.0) != 1.0:
        tau = scaled_tau(tau, plan.role_scale[role])
    lit = lights(plan)
    grass = None
    if role == "GRASS":
        ground, blade, layer = _blades(plan, grass_key, p)
        grass = (ground, blade) if layer is None else (ground, blade, layer)
    ao = lit.native.evaluate(p, n, role, lit.tree_ids(tree), plan_method(rung),
                             lit.taus(tau), grass=grass)
    return ao * walls_ao(plan, p, n, role) if plan.walls else ao


def walls_ao(plan: Plan, p, n, role=None, near=0.0) -> np.ndarray:
    """float32 (N,): the GROUND surfaces (a wall, a rock, the ground under them) as opaque
    occluders of the ray-free proxy rungs, from `near` out to the AO distance (core/walls.py;
    docs/DESIGN.md, 'How each role is lit'). All ones without GROUND triangles, and for a
    GRASS blade, whose grass law holds the ground it stands on."""
    if role == "GRASS":
        return np.ones(len(p), np.float32)
    return walls.visibility(plan.walls, p, n, ray_length(plan.settings.distance), near)


def _blades(plan: Plan, grass_key, p):
    """(ground height, blade height, blade layer or None) of a grass item: its blades' lowest
    point, their height and its field's measured layer (grass_layer.blade_layer); the points'
    lowest point, 1 and None when it was not seen when the plan was made."""
    ground, blade = plan.grass.get(grass_key, (float(p[:, 2].min()), 1.0))
    layer = next((g.layer for g in plan.grass_layers if g.name == grass_key), None)
    return float(ground), float(blade), layer


def _grass_law(plan: Plan, grass_key, p, n):
    """float32 (N,): a blade's own AO (native ao_grass: its field's layer, else Eq. 9)."""
    ground, blade, layer = _blades(plan, grass_key, p)
    return _core.ao_grass(p, n, ground, blade, layer=layer)


def _ground_layers(plan: Plan, role, p, ao):
    """ao (a fresh float32 array, changed in place) times every grass layer over the ground
    (grass_layer.py, the core's GrassCover) for a ground point, clipped to [0, 1]: the rungs
    the scene plan does not light."""
    if role == "GROUND" and plan.grass_layers:
        for layer in plan.grass_layers:
            ao *= layer.ground_visibility(p)
        np.clip(ao, 0.0, 1.0, out=ao)
    return ao


def _grass(plan: Plan, role, grass_key, p, n, ao):
    """ao times the grass, for the rungs the scene plan does not light: the blade layer for a
    blade, the grass layers for a ground point. Returns a new float32 array in [0, 1]."""
    ao = np.array(ao, dtype=np.float32)
    if role == "GRASS":
        ao *= _grass_law(plan, grass_key, p, n)
    return np.clip(_ground_layers(plan, role, p, ao), 0.0, 1.0, out=ao)


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


def _tracer(plan: Plan):
    """The plan's ray tracer, or CanopyAOError when the scene gave it no triangles."""
    if plan.tracer is None:
        raise CanopyAOError("ray tracing needs the scene's triangles; none were given")
    return plan.tracer


def ray_args(plan: Plan, group=1) -> dict:
    """RayTracer.ao's ray arguments for receivers in groups of `group` points (a texel's
    anti-aliasing sub-samples): one set of Samples per group, rounded up to a multiple of the
    group, dealt out to its points in turn (point_group). Every point then casts as many rays,
    so the plain mean of its points' AO is the texel's one stratified estimate."""
    if group <= 1:
        return {"samples": int(plan.settings.samples)}
    return {"samples": texel_budget.texel_rays(plan.settings.samples, group),
            "point_group": int(group)}


def trace(plan: Plan, p, n, samples, seed=None, own=None, distance=None, **extra):
    """Ray-traced AO of points p, n against the scene's triangles (the exact rung). own: the
    tracer-mesh ids of own_ids, so each ray skips only its receiver's own triangles, as Cycles'
    does (docs/DESIGN.md, 'The method ladder'). distance: the AO distance (default: the
    settings'; 0 = unlimited). extra: more RayTracer.ao arguments (bent_normals=True)."""
    d = plan.settings.distance if distance is None else distance
    return _tracer(plan).ao(p, n, samples=int(samples), distance=ray_length(d),
                          seed=plan.settings.seed if seed is None else int(seed), **(own or {}),
                          **extra)


def _grid_ao(plan, p, n):
    if plan.grid is None:  # no leaves or branches to voxelise (a grass field): nothing above
        return np.ones(len(p), np.float32)
    return np.asarray(plan.grid.ao(p, n, distance=ray_length(plan.settings.distance)),
                      dtype=np.float32)


# The hybrid's near distance in voxels of the density grid: the grid resolves occlusion beyond
# a few voxels, rays the contact shadows inside them (scale-free: the voxel is the grid's box /
# its resolution). Chosen on the design Sapling trees, bench/real_assets.py.
HYBRID_VOXELS = 2.0


def hybrid_ao(plan, p, n, own=None, group=1):
    """Near exact, far statistical (native ao_near_far): settings.samples rays out to
    HYBRID_VOXELS grid voxels, started as the exact rung's (own: the tracer ids of own_ids, a
    vertex at Cycles' bake point), times the density grid's transmittance beyond
    (docs/DESIGN.md, 'The near/far hybrid'). A scene with no leaves or branches has no grid:
    the caller traces the whole distance instead (the rays see the grass themselves)."""
    far = ray_length(plan.settings.distance)
    near = min(HYBRID_VOXELS * float(plan.grid.voxel_size), far)
    ao = np.asarray(_core.ao_near_far(_tracer(plan), plan.grid, p, n, near, distance=far,
                                      seed=int(plan.settings.seed), **ray_args(plan, group),
                                      **(own or {})),
                    dtype=np.float32)
    # The far field holds the leaves and branches only: the GROUND surfaces beyond the near
    # rays occlude as walls_ao's patches.
    return ao * walls_ao(plan, p, n, near=near) if plan.walls else ao


def build_tracer(items, bases=None, prototypes=None):
    """The Embree ray tracer over every non-ignored item's triangles; bases as
    meshes.scene_triangles. prototypes: forest.Prototype list whose meshes are traced at every
    instance matrix (Embree instances: each prototype's BVH built once), so the exact rung and
    calibration see instanced trees as the real triangles they are (docs/DESIGN.md, 'How each
    role is lit'). A scene of instances alone (a ground is a receiver with triangles, so this
    is rare) still gets a tracer. Vertex receivers start where Cycles' vertex bake starts them
    (its bake point, from the items' vertex normals and faces: native raytrace.h, 'Origins')."""
    inst = tracer_instances(prototypes)
    shading = {}
    try:
        mesh = scene_triangles(items, bases, shading)
    except CanopyAOError:
        if not inst:
            raise
        mesh = (np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int32))
        shading = bake_shading([])
    return _core.RayTracer(*mesh, **shading, **inst)


def traces_instances(plan: Plan) -> bool:
    """Whether the plan's ray tracer holds the forest's instanced trees (build_tracer)."""
    return plan.tracer is not None and int(plan.tracer.instance_count) > 0


def build_grid(items):
    """The leaf-density grid (docs/DESIGN.md, 'The method ladder') from the leaves and branches
    (CANOPY and TRUNK triangles). Not the ground: as density its area would fill the voxel layer
    a ground receiver's grazing rays travel in (round tree: ground AO 0.67 against 0.92 traced).
    Returns None when there are none (a grass field alone: its blades and the ground under
    them follow the grass laws, as under every other rung)."""
    wood_and_leaves = [it for it in items if it.role in ("CANOPY", "TRUNK") and len(it.triangles)]
    if not wood_and_leaves:
        return None
    # cards by their opaque area, where opaque (card_area.counted_item)
    return _core.DensityGrid(*scene_triangles([card_area.counted_item(it)
                                               for it in wood_and_leaves]))
