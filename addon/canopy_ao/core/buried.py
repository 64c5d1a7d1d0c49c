"""Buried receivers: points enclosed by the surface they sit on (a leaf's base inside its twig),
where rays and Cycles read 0 whatever a model says (docs/DESIGN.md, 'Buried receivers'). The
one test, used by auto's calibration sample (ladder.calibrate), the instanced forest's
(forest_tau), the ray-free rung's sample (regression.py) and the bake's receivers of the rungs
that do not find them by themselves (bake._zero_buried, Rung.finds_buried)."""

from __future__ import annotations

import numpy as np

from .scene import Plan

# A point is buried when every one of BURIED_RAYS rays stops within BURIED_SCALE of its
# object's size (bounding-box diagonal): scale-free; an open crevice lets some rays out. On
# Sapling leaves (bench/out/real, 3000 vertices each) 1e-2 finds 89-98 % of the vertices whose
# 64-ray AO is 0 (1e-3: 2-95 %, the twigs are thicker than that), and none it finds is lit.
BURIED_RAYS = 16
BURIED_SCALE = 1e-2
# The bake's own test of its receivers (bake._zero_buried): the rungs that do not find buried
# points by themselves, on leaves and branches, 8 rays per vertex (dealt out to its corners).
# On the nine Sapling tree scenes (bench/real_assets.py prints it) it finds 97.3-99.7 % of the
# vertices the benchmark's test (32 rays at every corner) finds, and 5-80 % more besides, all
# but closed in (their reference AO 0.001-0.026 on average); it takes 0.017-0.056x the time of
# a 64-sample bake (its printed figures, 2026-12-02).
BURIED_ROLES = ("CANOPY", "TRUNK")
BURIED_RECEIVER_RAYS = 8


def size(positions) -> float:
    """An object's size: its bounding-box diagonal (0 for no points)."""
    p = np.asarray(positions)
    return float(np.linalg.norm(np.ptp(p, axis=0))) if len(p) else 0.0


def enclosed(tracer, p, n, object_size, rays, seed, **ids) -> np.ndarray:
    """bool (N,): every one of ``rays`` rays from p, n (RayTracer.ao at ``seed``; ids: its
    vertex_ids / triangle_ids / per_corner arguments) stops within BURIED_SCALE ×
    object_size."""
    ao = tracer.ao(np.ascontiguousarray(p, np.float32), np.ascontiguousarray(n, np.float32),
                   samples=int(rays), distance=BURIED_SCALE * object_size, seed=int(seed),
                   **ids)
    return np.asarray(ao) <= 0.0


def buried(plan: Plan, item, p, n, own=None, rays=BURIED_RAYS, per_corner=True) -> np.ndarray:
    """bool (N,): points p, n of item buried (module doc), by a trace of ``rays`` rays (at
    every face corner, or with per_corner=False dealt out to a vertex's corners) with the
    plan's tracer and seed; own: the points' tracer-mesh ids (lighting.own_ids)."""
    if not len(p) or plan.tracer is None:
        return np.zeros(len(p), bool)
    s = size(item.positions)
    if not s > 0:
        return np.zeros(len(p), bool)
    return enclosed(plan.tracer, p, n, s, rays, plan.settings.seed, **(own or {}),
                    per_corner=per_corner)
