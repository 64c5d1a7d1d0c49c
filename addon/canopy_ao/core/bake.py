"""The bake's entry points (no bpy): prepare a plan, evaluate items with it, report.

Input: scene items (name, role, tree, world positions, world normals, triangles) and
BakeSettings. Output: one float32 AO array per item (1 = open sky) and a report: fitted
proxies per tree, τ, the method chosen and why, timings.

The work is split so a modal operator can do one piece per tick: prepare() fits the proxies
and calibrates; evaluate_item() bakes one item; bake() does both.
"""

from __future__ import annotations

import time

import numpy as np

from . import buried as _buried
from . import cost, forest_tau, ladder, lighting, native, opacity, proxies, regression, trees, walls
from . import forest as _forest
from .native import CanopyAOError, refusals_are_user_errors
from .scene import RECEIVER_ROLES, ItemResult, Plan, SceneItem, own_primitives, split_trees
from .ladder import DEFAULT_TAU
from .rungs import base as rungs
from .settings import BakeSettings, validate


@refusals_are_user_errors
def prepare(items, settings: BakeSettings, prototypes=None, targets=None,
            carry_cards=False, live=False) -> Plan:
    """Fit the proxies, build the ray tracer if needed, calibrate. Raises CanopyAOError.

    targets: {item name: ("vertex" | "texel", count[, group])}, the receivers the bake will
    evaluate (an item's vertices, or the texels of its image: one face corner each, `group`
    receivers a texel, its anti-aliasing sub-samples, sharing its rays); None = every receiver
    item at its vertices. Auto's cost model counts them (cost.py). carry_cards: the bake's
    card vertices will carry their opaque part's AO (card_carry.carry, as the add-on's bake loop
    does; evaluate_item does not), so the calibration samples take them there (Plan.carry_cards).

    prototypes: instanced trees (forest.Prototype list, see attach_forest) that occlude every
    receiver. Given here rather than attached afterwards, the ray tracer traces their meshes
    at every instance, so the exact rung and auto's calibration (the reference rays and every
    candidate, whose occluders then include the instances' shells) see them.

    live: the first bake of live AO. It is lit as any bake (every GROUND plane a patch); its
    frames rebuild the patches only where a wall is and hold a ground alone's occlusion from
    this bake (Plan.every_ground False; core/live.py, held_ground)."""
    native.require()
    validate(settings)
    items = list(items)
    t_start = time.perf_counter()
    plan = Plan(settings=settings, method=settings.method,
                tau=settings.tau if settings.tau is not None else DEFAULT_TAU,
                targets=_targets(targets), carry_cards=bool(carry_cards))
    t0 = time.perf_counter()
    trees.resolve(items)  # trees only a collection groups: told apart by where they stand
    plan.timings["trees"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    whole, items = items, split_trees(items)  # the rays see whole meshes, the rest per tree
    plan.notes.extend(opacity.notes(whole))
    proxies.fit_scene(plan, items)
    plan.every_ground = not live
    plan.walls = walls.build(whole)  # GROUND surfaces occluding (proxies), every plane a patch
    plan.timings["fit"] = time.perf_counter() - t0
    rung = rungs.get(settings.method)
    if (rung.scene_plan or rung.chooses) and (plan.fits or plan.trunks):
        t0 = time.perf_counter()
        lighting.lights(plan)  # the native scene plan: built once, calibration reuses it
        plan.timings["scene_plan"] = time.perf_counter() - t0

    if prototypes:
        _forest.attach(plan, prototypes, None)
    # Grass has no proxies to calibrate, nor has a ground under instanced trees alone, but
    # auto still weighs their laws against rays.
    proxyless_auto = (rung.chooses and not plan.fits
                      and (any(it.role == "GRASS" for it in items)
                           or bool(_forest.traced_meshes(prototypes))))
    needs_tracer = rung.needs_tracer or proxyless_auto or (
        rung.chooses or settings.tau is None) and bool(plan.fits) or (
        settings.tau is None and rung.tracer_holds_instances
        and bool(_forest.traced_meshes(prototypes)))
    if needs_tracer:
        t0 = time.perf_counter()
        try:
            # The hybrid's far field is the density grid of the scene's own triangles, so
            # instanced trees stay its analytic occluders (near rays must not see them twice).
            plan.tracer = lighting.build_tracer(
                whole, plan.tracer_bases, prototypes if rung.tracer_holds_instances else None)
            plan.tracer_items = whole
        except CanopyAOError as exc:
            if rung.needs_tracer:
                raise
            plan.notes.append(f"calibration skipped: {exc}")
        plan.timings["tracer"] = time.perf_counter() - t0

    if _wants_regression(plan, items, settings):
        t0 = time.perf_counter()
        try:
            shared = {} if plan.tracer is None else dict(  # one BVH for the bake
                tracer=plan.tracer,
                ids=lambda it, idx, key="vertex_ids": (ladder.sample_ids(plan, it, idx, key)
                                                       or {}).get(key))
            if plan.forest is not None and not regression.occludes(items):
                plan.regression = regression.OpenSky()
                plan.notes.append("regression: the only occluders are instanced trees, "
                                  "which light the ground by their shells")
            else:
                plan.regression = regression.RegressionRung(
                    items, settings.distance, points=regression.POINTS,
                    samples=settings.calibration_samples, seed=settings.seed, meshes=whole,
                    cards=plan.carry_cards, patches=plan.walls, **shared)
        except CanopyAOError as exc:
            if rung.needs_regression:
                raise
            plan.notes.append(f"regression rung not considered: {exc}")
        if rung.needs_regression:
            plan.calibration = plan.regression.report
        plan.timings["regression"] = time.perf_counter() - t0
    if rung.needs_grid:
        t0 = time.perf_counter()
        plan.grid = lighting.build_grid(whole)
        plan.timings["grid"] = time.perf_counter() - t0
    elif rung.chooses and plan.fits and plan.tracer is not None:
        t0 = time.perf_counter()
        try:  # the top rung of the ladder: only worth it if it beats the shells (calibrate)
            plan.grid = lighting.build_grid(whole)
        except CanopyAOError as exc:
            plan.notes.append(f"density grid not considered: {exc}")
        plan.timings["grid"] = time.perf_counter() - t0

    ladder.choose(plan, items, proxyless_auto)
    if forest_tau.wanted(plan):  # the instances' τ, fitted on the receivers they shade
        t0 = time.perf_counter()
        got = forest_tau.calibrate(plan, items)
        if got is not None:
            plan.calibration = {**(plan.calibration or {}), "forest": got}
        plan.timings["forest_tau"] = time.perf_counter() - t0
    plan.proxies = {t: proxies.own_shells(plan, t, plan.method) for t in plan.fits}
    plan.timings["prepare"] = time.perf_counter() - t_start
    return plan


def _targets(targets) -> dict:
    """prepare's targets checked: {name: (kind, count ≥ 0, group ≥ 1)}, group the receivers
    per texel (its anti-aliasing sub-samples; 1 when not given)."""
    out = {}
    for name, (kind, count, *group) in (targets or {}).items():
        group = int(group[0]) if group else 1
        if kind not in ("vertex", "texel") or int(count) < 0 or group < 1:
            raise CanopyAOError(f"target {name!r}: {kind!r} × {count} is not a vertex or "
                                "texel count")
        out[str(name)] = (kind, int(count), group)
    return out


def _wants_regression(plan: Plan, items, settings) -> bool:
    """Whether prepare builds the ray-free rung: asked for, --ray-free, or auto where rays are
    over the time budget (a big tree: on real trees the ray-free rung is the best one short of
    rays, docs/DESIGN.md 'Auto mode'). Decided from counted work, never a clock."""
    rung = rungs.get(settings.method)
    if rung.needs_regression:
        return True
    if not rung.chooses or not plan.fits or plan.tracer is None:
        return False
    if settings.ray_free:
        return True
    receivers = cost.receiver_count(plan, items)
    exact = rungs.exact()
    return (settings.time_budget > 0
            and cost.predict(plan, exact, receivers)["seconds"] > settings.time_budget)


@refusals_are_user_errors
def evaluate_receivers(plan: Plan, item: SceneItem, positions, normals,
                       vertices=None, triangles=None, group=1) -> np.ndarray:
    """AO float32 (N,) in [0, 1] of receivers on ``item`` (its vertices, a chunk of them, or
    texels of its UV layout: points float32 (N, 3) and unit normals) with the plan's method
    and τ. Receivers are independent, so any split into chunks gives the same AO (the exact
    rung's rays follow a vertex's id, a texel's index in the call).

    An item holding several trees (item.tree_names) lights each receiver with its own tree's:
    ``vertices`` (an index array or slice of the item's vertices the receivers are) picks the
    vertex's tree; without it (texels) each receiver takes the tree whose fitted crown is
    nearest (in the crown's own unit frame). ``triangles`` (int32 (N,), texels: the item's
    triangle each lies on, -1 = unknown) lets the exact rung's rays skip only that one.
    ``group``: receivers per texel, its anti-aliasing sub-samples, consecutive (a chunk never
    splits them): the exact rung's and the hybrid's near rays deal a texel's Samples out over
    them (lighting.ray_args)."""
    p = np.ascontiguousarray(positions, dtype=np.float32).reshape(-1, 3)
    n = np.ascontiguousarray(normals, dtype=np.float32).reshape(-1, 3)
    if item.role == "IGNORE":
        return np.ones(len(p), np.float32)
    own = own_primitives(item, vertices, triangles)
    if item.tree_labels is None or len(item.tree_names) <= 1:
        ao = lighting.evaluate_points(plan, item.role, item.tree, item.name, p, n, plan.method,
                                      plan.taus(), own, group)
    else:
        labels = (item.tree_labels[vertices] if vertices is not None
                  else _nearest_crown(plan, item.tree_names, p))
        if rungs.get(plan.method).scene_plan:  # one call, a tree per receiver
            ao = lighting.evaluate_points(plan, item.role, (item.tree_names, labels), item.name,
                                          p, n, plan.method, plan.taus(), own, group)
        else:
            if group > 1 and len(labels) % group == 0:  # a texel's sub-samples stay together
                labels = np.repeat(labels[::group], group)
            ao = np.ones(len(p), np.float32)
            for k, tree in enumerate(item.tree_names):
                sel = np.flatnonzero(labels == k)
                if len(sel):
                    ao[sel] = lighting.evaluate_points(
                        plan, item.role, tree, item.name, np.ascontiguousarray(p[sel]),
                        np.ascontiguousarray(n[sel]), plan.method, plan.taus(),
                        {k: v[sel] for k, v in own.items()} if own else None, group)
    if ao.shape != (len(p),) or not np.all(np.isfinite(ao)):
        raise CanopyAOError(f"{item.name}: the {plan.method} model gave invalid values")
    _zero_buried(plan, item, p, n, own, vertices, ao)
    return ao


# The approximate rungs model a leaf whose base sits inside its twig like any other point,
# where rays (and Cycles) read 0: on Sapling trees 5-23 % of leaf and branch vertices, which
# doubled their MAE over all vertices. Their receivers on leaves and branches are tested as
# auto's calibration tests its sample (buried.py: every ray stops within 1 % of the
# object's size), with a few short rays per vertex dealt out to its corners,
# and read 0 (docs/DESIGN.md, 'Buried receivers'). The exact rung and the hybrid's near rays
# find them by themselves. (Which rungs: Rung.finds_buried; roles and rays: buried.BURIED_ROLES,
# BURIED_RECEIVER_RAYS, beside the calibration's own test.)
def _zero_buried(plan: Plan, item: SceneItem, p, n, own, vertices, ao) -> None:
    """Set ao to 0 at receivers buried inside the surface they sit on (above), traced with the
    plan's tracer; without one (a given τ builds none; a live frame), a vertex keeps what an
    earlier bake with this plan found (plan.buried), else nothing is tested."""
    if (rungs.get(plan.method).finds_buried or item.role not in _buried.BURIED_ROLES
            or not len(p)):
        return
    if plan.tracer is not None:
        t0 = time.perf_counter()
        mask = _buried.buried(plan, item, p, n, lighting.own_ids(plan, item.name, own),
                              rays=_buried.BURIED_RECEIVER_RAYS, per_corner=False)
        plan.timings["buried_test"] = (plan.timings.get("buried_test", 0.0)
                                       + time.perf_counter() - t0)
        if vertices is not None:  # kept for the frames of a live bake
            whole = plan.buried.setdefault(item.name, np.zeros(len(item.positions), bool))
            whole[vertices] = mask
    elif vertices is not None and item.name in plan.buried \
            and len(plan.buried[item.name]) == len(item.positions):
        mask = plan.buried[item.name][vertices]
    else:
        return
    ao[mask] = 0.0
    plan.buried_count[item.name] = plan.buried_count.get(item.name, 0) + int(mask.sum())


def _nearest_crown(plan: Plan, names, p) -> np.ndarray:
    """Index into names of the tree whose fitted ellipsoid is nearest each point (|x'| in its
    unit frame); trees without a crown (a stem alone) are never nearest unless none has one."""
    best = np.zeros(len(p), np.int64)
    dist = np.full(len(p), np.inf)
    for k, tree in enumerate(names):
        if tree not in plan.fits:
            continue
        e = plan.fits[tree][1]
        q = (np.asarray(p, np.float64) - np.asarray(e.center, np.float64)) @ \
            np.asarray(e.axes, np.float64) / np.asarray(e.radii, np.float64)  # columns = axes
        d = np.einsum("ij,ij->i", q, q)
        better = d < dist
        best[better], dist[better] = k, d[better]
    return best


def evaluate_item(plan: Plan, item: SceneItem) -> ItemResult:
    """Bake one item's vertices with the plan's method and τ."""
    t0 = time.perf_counter()
    ao = evaluate_receivers(plan, item, item.positions, item.normals, vertices=slice(None))
    return ItemResult(item.name, item.role, item.tree, plan.method, ao,
                      time.perf_counter() - t0, item.tree_source, item.tree_why)


@refusals_are_user_errors
def attach_forest(plan: Plan, prototypes, epsilon=None) -> None:
    """Make instanced trees occlude every item evaluate_item() bakes with this plan.

    prototypes: forest.Prototype list (shells in the prototype's space, instance matrices,
    and the prototype's mesh for the ray tracer). Attached after prepare(): the proxies see
    the instances' shells, and an exact-rung plan's tracer is rebuilt with the instances, but
    a calibration already done did not see them; prepare(items, settings, prototypes) does
    (the add-on's bake job passes them there)."""
    _forest.attach(plan, prototypes, epsilon)
    if (plan.forest is not None and rungs.get(plan.method).rays_see_instances
            and plan.tracer is not None
            and not lighting.traces_instances(plan) and _forest.traced_meshes(prototypes)):
        t0 = time.perf_counter()
        bases = {}
        plan.tracer = lighting.build_tracer(plan.tracer_items, bases, prototypes)
        plan.tracer_bases = bases
        plan.timings["tracer"] = plan.timings.get("tracer", 0.0) + time.perf_counter() - t0
    if plan.forest is not None and plan.calibration and not plan.calibration.get(
            "instances_traced"):
        # Calibration traced the scene's own triangles only: say so rather than imply the
        # choice was checked under the forest.
        plan.notes.append("the method and τ were chosen against rays that do not see the "
                          "instanced trees (attached after prepare: pass them to prepare)")


def report(plan: Plan, results) -> dict:
    """A JSON-ready summary of a bake."""
    return {
        "method": plan.method,
        "requested_method": plan.settings.method,
        "tau": plan.tau,
        "tau_by_tree": dict(plan.tau_by_tree),
        "tau_role_scale": dict(plan.role_scale),
        "distance": plan.settings.distance,
        "samples": plan.settings.samples,
        "proxies": proxies.proxy_dicts(plan),
        "calibration": plan.calibration,
        "timings": dict(plan.timings),
        "notes": list(plan.notes),
        "objects": {r.name: {"role": r.role, "tree": r.tree, "tree_source": r.tree_source,
                             "tree_why": r.tree_why, "method": r.method,
                             "vertices": r.vertices, "seconds": r.seconds,
                             "predicted_seconds": _predicted(plan, r),
                             "buried_set_to_0": int(plan.buried_count.get(r.name, 0)),
                             "ao_mean": float(r.ao.mean()) if r.vertices else None}
                    for r in results},
    }


def _predicted(plan: Plan, r: ItemResult):
    """The cost model's seconds for this result's receivers (cost.py), None off the model."""
    try:
        return cost.predict(plan, r.method, r.vertices, names=(r.name,))["seconds"]
    except (ValueError, KeyError):
        return None


def bake(items, settings: BakeSettings, progress=None):
    """prepare + evaluate every item. progress(i, n, name) is called before each item.
    Returns (list[ItemResult], report dict)."""
    items = list(items)
    plan = prepare(items, settings)
    results = []
    for i, it in enumerate(items):
        if progress is not None:
            progress(i, len(items), it.name)
        results.append(evaluate_item(plan, it))
    return results, report(plan, results)
