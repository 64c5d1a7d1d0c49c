"""The instanced forest's τ, calibrated where the forest is seen: on the receivers it shades.
No bpy. (docs/DESIGN.md, 'How each role is lit': the forest's τ.)

A prototype's τ is fitted by its own self-bake, on its own leaves and branches: from inside
its crown. The ground sees every instance's crown from outside, through its whole depth, and
the rungs that calibrate no τ (the density grid, the ray-free rung) lit the forest with the
default one. On examples/forest_scene.py (50 trees, 50 m) that left every analytic rung too
dark on the ground against rays that trace the instances: bias −0.08 (ellipsoid) to −0.25
(sphere), −0.16 under the grid and the ray-free rung.

So, when τ is calibrated (the default) and the plan's tracer sees the instances, one factor κ
on every prototype's τ is fitted to the bake's own receivers: a calibration sample (buried
points left out, as ladder.calibrate), traced with the instances, against the plan's method
without the forest times the forest at κ (the fields multiply: lighting.evaluate_points).
Golden section on log κ; κ is kept only if it cuts the sample's squared error by more than
1 %. Its cost: the sample's rays (calibration_points × calibration_samples) and one rebuild
of the forest's occluder index per step, on the transformed shells kept from the first.
"""

from __future__ import annotations

import math
import time

import numpy as np

from . import ladder
from .buried import buried
from .lighting import evaluate_points, trace, traces_instances
from .rungs import base as rungs
from .scene import Plan
from .taufit import TAU_RANGE

KEEP = 0.99  # κ replaces 1 only if it cuts the sample's squared error by more than 1 %
SEED_OFFSET = 104729  # the sample's own draw (not the ladder's points)


def wanted(plan: Plan) -> bool:
    """Whether prepare() calibrates the forest: τ calibrated, an analytic rung (the exact one
    traces the instances themselves; the hybrid's near rays do not see them), and a tracer
    that holds the instances (their meshes)."""
    return (plan.forest is not None and plan.settings.tau is None
            and not rungs.get(plan.method).needs_tracer
            and plan.tracer is not None and traces_instances(plan))


def calibrate(plan: Plan, items) -> dict | None:
    """Fit κ (module docstring) and set plan.forest to the forest at κ when it pays. Returns
    the report entry, or None when there is no receiver to fit on."""
    s = plan.settings
    t0 = time.perf_counter()
    picks = ladder.sample_receivers(items, s.calibration_points, s.seed + SEED_OFFSET)
    forest, plan.forest = plan.forest, None  # the plan's method without the forest
    try:
        P, N, ref, own_ao, keep = [], [], [], [], []
        for it, idx in picks:
            p = np.ascontiguousarray(it.positions[idx])
            n = np.ascontiguousarray(it.normals[idx])
            own = ladder.sample_ids(plan, it, idx)
            local = {"vertex_ids": it.vertex_map[idx] if it.vertex_map is not None else idx}
            ref.append(trace(plan, p, n, s.calibration_samples, own=own))
            own_ao.append(evaluate_points(plan, it.role, it.tree, it.name, p, n, plan.method,
                                          plan.taus(), local))
            keep.append(~buried(plan, it, p, n, own))
            P.append(p)
            N.append(n)
    finally:
        plan.forest = forest
    if not P:
        return None
    keep = np.concatenate(keep)
    if not keep.any():
        return None
    P = np.ascontiguousarray(np.concatenate(P)[keep])
    N = np.ascontiguousarray(np.concatenate(N)[keep])
    ref = np.concatenate(ref)[keep].astype(np.float64)
    own_ao = np.concatenate(own_ao)[keep].astype(np.float64)

    def err(scale, f=None):
        f = f if f is not None else forest.scaled(scale)
        return float(np.mean((np.clip(own_ao * f.ao(P, N), 0.0, 1.0) - ref) ** 2))

    base = err(1.0, forest)
    x, e = ladder.golden_min(lambda v: err(math.exp(v)), *TAU_RANGE)
    scale = math.exp(x)
    kept = e < KEEP * base
    if kept:
        plan.forest = forest.scaled(scale)
    out = {"tau_scale": scale if kept else 1.0, "fitted_scale": scale,
           "points": int(len(ref)), "rmse_before": math.sqrt(base),
           "rmse_after": math.sqrt(min(e, base)), "seconds": time.perf_counter() - t0}
    plan.notes.append(
        f"forest τ × {out['tau_scale']:.3g}, fitted on {len(ref)} receivers against rays "
        f"that trace the instances (sample RMSE {out['rmse_before']:.3f} → "
        f"{out['rmse_after']:.3f})")
    return out
