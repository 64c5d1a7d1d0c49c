"""What a rung costs, predicted from counted work (no clock), so "auto" makes the same choice
on a quiet machine and under load (docs/DESIGN.md, 'Auto mode').

Work per receiver, counted from the plan:
- sphere, ellipsoid, reeves_blau: 1 in-shell evaluation + one per occluder (every other
  shell and every trunk solid in the scene: an upper bound, the occluder grid skips far ones);
- shells: k in-shell evaluations (its tree's shells) + the occluders;
- medium: as shells, each a medium-table lookup (a costlier unit);
- grid: DensityAOOptions.directions line integrals, each ~kExactVoxels + 2 log2(resolution)
  voxel steps (exact DDA near, mip steps growing with distance: density_grid.h);
- raytrace: Cycles' rays (samples at each face corner of a vertex at its bake point), spread
  evenly over the bake's vertices (ray_budget.py: each vertex the multiple of its corners
  nearest to samples × their mean), counted vertex by vertex over the receivers (a texel
  casts samples, shared by its anti-aliasing sub-samples), each ~log2(triangles) BVH steps;
- regression: one trilinear look-up of the swept optical depth per feature direction
  (occlusion_features.h), counted as a voxel step each;
- hybrid: the rays of raytrace (short, but each still descends the BVH) plus grid's steps;
- every rung but raytrace and hybrid, when the plan has a tracer: its buried test
  (bake._zero_buried), buried.BURIED_RECEIVER_RAYS short rays per leaf or branch receiver,
  each counted as a full ray's log2(triangles) BVH steps (an upper bound: they stop within 1 %
  of the object's size).
Predicted seconds = Σ work × the unit's constant / threads; the constants are seconds per
unit on one core of the machine that measured them, fixed here (machine speed scales them all
alike; the choice depends on their ratios and on the time budget).
"""

from __future__ import annotations

import math

from . import ray_budget, texel_budget
from .buried import BURIED_RECEIVER_RAYS, BURIED_ROLES
from .native import _core
from .rungs.base import Proxy, exact as exact_rung, get as rung_of
from .scene import RECEIVER_ROLES, receiver_items

# Seconds per unit of work on one core. Ratios measured with
#   nice /usr/bin/python3 bench/cost_constants.py
# (round tree, 90,372 receivers, 64 rays, each rung's evaluation of every receiver timed best
# of 3 on one thread, divided by the units counted below): 1.2e-8-2.6e-8 per shell (sphere to
# shells), 4.7e-8 per medium shell, 4.9e-8 per voxel step, 4.8e-8 per BVH step, 2026-12-01 on
# the shared 2-core machine at load average 10. Scaled by 0.36 to a quiet machine: the same
# tree's rays took 0.70 s for 80,000 vertices × 64 rays on 2 threads quiet (the README's
# example bake), 1.74e-8 per BVH step against 4.8e-8 under that load. Re-measure when a kernel
# changes speed by 2×. (Since the exact rung starts each vertex at Cycles' bake point in a
# ROBUST scene its rays take 1.24× as long — README, 'Speed' — within the model's margin, so
# the constant stands. Re-measured 2026-12-01 with rays at every face corner, counted so:
# 1.57e-8 per BVH step on one thread of the quiet machine, `bench/cost_constants.py --quick`,
# within 11 % of it.)
SECONDS_PER_UNIT = {
    "shell": 6.0e-9,         # one analytic shell evaluation (in-shell model or occluder)
    "medium": 1.7e-8,        # one medium-table shell evaluation
    "voxel_step": 1.8e-8,    # one step of a density-grid line integral
    "bvh_step": 1.75e-8,     # one BVH level of one Embree ray (rays: samples × corners × log2 M)
}
FORMULA = ("seconds = work × seconds_per_unit / threads; work per receiver: analytic 1 + "
           "occluders (shells of every tree + trunks), shells/medium k + occluders, grid "
           "directions × (exact voxels + 2 log2 resolution), regression feature directions, raytrace "
           "samples × the receivers' face corners per vertex (1 per texel) × log2 triangles, "
           "hybrid raytrace + grid; the approximate rungs add their buried test, 8 rays per "
           "leaf or branch receiver × log2 triangles in BVH steps")
GRID_DIRECTIONS = 32         # DensityAOOptions.directions (the add-on's default)
GRID_RESOLUTION = 48         # DensityGridOptions.resolution (the add-on's default)
GRID_EXACT_VOXELS = 4        # DensityGrid::kExactVoxels
FEATURE_DIRECTIONS = 24      # OcclusionFeatures' default directions (core/regression.py)


def receiver_count(plan, items) -> int:
    """The receivers a bake with this plan evaluates: its targets' vertices or texels
    (plan.targets), or without targets every receiver item's vertices."""
    if plan.targets:
        return sum(int(t[1]) for t in plan.targets.values())
    return sum(len(it.positions) for it in items if it.role in RECEIVER_ROLES)


def corners(plan, names=None, samples=None) -> float:
    """Rays per sample a receiver of this plan casts with the exact rung at ``samples`` rays
    per corner (None: the settings'): the mean face corners per receiver over the items named
    ``names`` (None: the plan's targets, else every receiver the tracer holds), counted by the
    tracer: at Cycles' bake point its rays spread evenly over the bake's vertices
    (ray_budget.object_rays), else RayTracer.vertex_rays (its per-vertex cap included); a
    texel has one corner, and so has a vertex the tracer does not hold by name."""
    tracer = plan.tracer
    if tracer is None:
        return 1.0
    samples = int(plan.settings.samples if samples is None else samples)
    even = ray_budget.spreads(plan)  # vertex rays spread evenly over the bake's vertices
    rays = count = 0
    for it, kind, n in receiver_items(plan, names):
        base = plan.tracer_bases.get(it.name)
        if kind == "texel":  # a texel's sub-samples share its rays (texel_budget.texel_rays)
            group = plan.targets[it.name][2]
            rays += n * texel_budget.texel_rays(samples, group) / group
        elif base is None:
            rays += n * samples
        elif even:
            rays += ray_budget.object_rays(plan, it.name, samples)
        else:
            rays += int(tracer.vertex_rays(base[0], n, samples))
        count += n
    if count == 0:  # no receiver held by name: the mesh's mean
        return float(tracer.corners_per_vertex)
    return rays / (count * samples)


def buried_test_rays(plan, receivers: int, names=None) -> float:
    """The rays the bake's buried test casts for ``receivers`` points of a rung that does not
    find buried points itself (Rung.finds_buried False; bake._zero_buried): BURIED_RECEIVER_RAYS
    per receiver on a leaf or branch item (their share of the targets, or of the tracer's
    receiver items), none without a tracer."""
    if plan.tracer is None or receivers <= 0:
        return 0.0
    tested = total = 0
    for it, _kind, n in receiver_items(plan, names):
        total += n
        tested += n if it.role in BURIED_ROLES else 0
    return float(receivers) * (tested / total if total else 0.0) * BURIED_RECEIVER_RAYS


def work(plan, method, receivers: int, names=None, samples=None) -> tuple[str, float]:
    """(unit, count) of the work ``method`` (a rung or its name) does for ``receivers`` points
    of this plan (names: the items they are on, for the rays' corner count; None = every
    receiver; samples: the exact rung's rays per corner, None = the settings'), the buried
    test's rays included (converted to the method's unit by the constants' ratio)."""
    rung = rung_of(method)
    unit, count = _work(plan, rung, receivers, names, samples)
    if not rung.finds_buried:
        rays = buried_test_rays(plan, receivers, names)
        if rays:
            depth = math.log2(max(int(plan.tracer.triangle_count), 2))
            count += rays * depth * SECONDS_PER_UNIT["bvh_step"] / SECONDS_PER_UNIT[unit]
    return unit, count


def _work(plan, method, receivers: int, names=None, samples=None) -> tuple[str, float]:
    """work() without the buried test: the rung's own count (Rung.work)."""
    rung = rung_of(method)
    if rung.work is None:
        raise ValueError(f"no cost model for method {rung.name!r}")
    return rung.work(rung, plan, receivers, names, samples)


def analytic_work(rung, plan, receivers: int, names=None, samples=None, unit="shell"):
    """The analytic rungs' work: per receiver its in-shell evaluations (1, or k of its tree's
    shells for a rung lit by k shells) + one per occluder (every tree's shells as this rung
    lights them, every trunk solid), each a ``unit``."""
    solids = sum(len(es) for es in plan.trunks.values())
    shells = {t: len(rung.own_shells(plan, t)) for t in plan.fits}
    total = sum(shells.values())
    if rung.proxy is not Proxy.SHELLS:
        return unit, receivers * float(1 + total + solids)
    k = max(shells.values(), default=1)
    return unit, receivers * float(k + total + solids)


def ray_work(plan, receivers: int, names=None, samples=None) -> float:
    """BVH steps of the exact rung's rays: samples × the receivers' corners × log2 triangles."""
    tracer = plan.tracer
    m = tracer.triangle_count if tracer is not None else 1
    depth = math.log2(max(int(m), 2))
    k = plan.settings.samples if samples is None else samples
    return receivers * float(k) * corners(plan, names, k) * depth


def grid_work(receivers: int) -> float:
    """Voxel steps of the density grid's line integrals for ``receivers`` points."""
    steps = GRID_EXACT_VOXELS + 2 * math.log2(GRID_RESOLUTION)
    return receivers * float(GRID_DIRECTIONS) * steps


def threads() -> int:
    """Worker threads the native calls use (set_max_threads caps them)."""
    return max(1, int(_core.max_threads())) if _core is not None else 1


def predict(plan, method, receivers: int, names=None, samples=None) -> dict:
    """{"unit", "work", "seconds_per_unit", "threads", "seconds"} for ``method`` (a rung or its
    name) on
    ``receivers`` points (on the items named ``names``; None = every receiver) at ``samples``
    rays per corner for the rays' rungs (None: the settings'): the cost model above, no
    timing."""
    unit, count = work(plan, method, receivers, names, samples)
    c = SECONDS_PER_UNIT[unit]
    n = threads()
    return {"unit": unit, "work": count, "seconds_per_unit": c, "threads": n,
            "seconds": count * c / n}


# The most rays per corner auto traces the calibration sample at to measure the exact rung
# (frontier.py predicts every count from it and the fewest): the samples halved until they fit
# the time budget, never below AUTO_MIN_RAYS (a count it is measured at is one it may bake
# and the model's anchor; the counts below it are weighed all the same) (docs/DESIGN.md,
# 'Auto mode').
AUTO_MIN_RAYS = 16


def affordable_samples(plan, receivers: int) -> int:
    """Rays per corner auto measures the exact rung at on the calibration sample:
    settings.samples when predicted within the time budget (or there is none), else the
    largest halving of it, at least AUTO_MIN_RAYS, predicted within it; settings.samples if
    none is. Counted work × fixed constants: no clock."""
    s = plan.settings
    k = int(s.samples)
    if s.time_budget <= 0:
        return k
    exact = exact_rung()
    while predict(plan, exact, receivers, samples=k)["seconds"] > s.time_budget:
        if k // 2 < AUTO_MIN_RAYS:
            return int(s.samples)
        k //= 2
    return k
