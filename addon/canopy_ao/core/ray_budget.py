"""The exact rung's rays at vertices: Cycles' number of rays, spread evenly over the vertices.

Cycles' vertex bake samples every face corner of a vertex with the full count S and gives the
vertex the corners' mean (docs/DESIGN.md, 'Rays against Cycles' samples'), so a vertex on four
quads casts 4 S rays and a leaf card's corner S. But the corners of a vertex are one point
(its bake points lie a hair apart): its error is that of one stratified estimate from all its
rays, falling as R^-α with its rays R, whatever its corners. For the same rays in all, Σ_v R_v
fixed, the sum of the vertices' errors Σ R_v^-α is least when every R_v is the same. So a bake
at S samples casts Cycles' rays — S × k̄ per vertex, k̄ the mean corners per vertex over the
bake's vertex receivers (scene.receiver_items: its targets, else every receiver) — and deals
them evenly: each vertex casts the multiple of its own corners k nearest to S k̄ (at least k),
one lattice dealt out to its corners in turn (ray s to corner s mod k: each corner has the same
weight, so the estimate stays the corners' mean, unbiased). On the Sapling trees that moves
rays from branches (four faces a vertex) to leaves and needles (one), where the error is.

Deterministic: k̄ is counted by the tracer (RayTracer.vertex_rays) over the bake's receivers,
once per plan; each vertex's rays depend on its id, its corners, k̄ and the seed — never on the
split into chunks, the thread count or the load. Texels (one corner each) and points keep S.
"""
from __future__ import annotations

import math

import numpy as np

from .scene import ray_length, receiver_items


def spreads(plan) -> bool:
    """Whether the plan's vertex receivers start at Cycles' bake point (a tracer with vertex
    normals: each has corners), where their rays are spread evenly."""
    return plan.tracer is not None and plan.tracer.has_vertex_normals


def applies(plan, name, own) -> bool:
    """Whether these receivers of object ``name`` are spread evenly (spreads): every one its
    own vertex (own: the tracer-mesh ids, lighting.own_ids), the object in the tracer."""
    ids = (own or {}).get("vertex_ids")
    return (spreads(plan) and ids is not None and plan.tracer_bases.get(name) is not None
            and bool(np.all(ids >= 0)) and any(it.name == name for it in plan.tracer_items))


def mean_corners(plan) -> float:
    """k̄: the mean corners per vertex over the bake's vertex receivers (1.0 without any),
    counted once per plan and tracer."""
    key = ("mean corners", id(plan.tracer))
    got = plan.ray_shares.get(key)
    if got is None:
        corners = vertices = 0
        for it, kind, _count in receiver_items(plan):
            base = plan.tracer_bases.get(it.name)
            if kind == "vertex" and base is not None and len(it.positions):
                corners += plan.tracer.vertex_rays(base[0], len(it.positions), 1)
                vertices += len(it.positions)
        got = plan.ray_shares[key] = corners / vertices if vertices else 1.0
    return got


def vertex_rays(corners, per_vertex) -> np.ndarray:
    """int32: each vertex's rays, the multiple of its corners (int (N,), ≥ 1) nearest to
    ``per_vertex``, at least one per corner."""
    k = np.maximum(np.asarray(corners, np.int64), 1)
    return (k * np.maximum(1, np.rint(per_vertex / k))).astype(np.int32)


def corners_of(tracer, ids) -> np.ndarray:
    """int64 (N,): each tracer vertex's corners (RayTracer.vertex_corners) at ids."""
    return tracer.vertex_corners(0, tracer.vertex_count).astype(np.int64)[ids]


def object_corners(plan, name) -> np.ndarray:
    """int64 (V,): the corners of each vertex of object ``name`` (held by the tracer under
    that name), counted once per plan and tracer."""
    key = ("corners", name, id(plan.tracer))
    got = plan.ray_shares.get(key)
    if got is None:
        item = next(it for it in plan.tracer_items if it.name == name)
        got = plan.ray_shares[key] = plan.tracer.vertex_corners(
            plan.tracer_bases[name][0], len(item.positions)).astype(np.int64)
    return got


def object_rays(plan, name, samples) -> int:
    """The rays the exact rung casts at the vertices of object ``name`` at ``samples``: each
    vertex vertex_rays(its corners, samples × mean_corners) (the cost model's count)."""
    return int(vertex_rays(object_corners(plan, name), samples * mean_corners(plan)).sum())


def trace_even(tracer, p, n, ids, samples, per_vertex, seed=0, distance=math.inf,
               corners=None, **extra):
    """AO float32 (N,) of tracer vertices ids (int32 (N,)) at p, n, each casting
    vertex_rays(its corners, per_vertex) rays dealt out to its corners (corners: theirs, else
    counted here; extra: more RayTracer.ao arguments, bent_normals=True)."""
    rays = vertex_rays(corners_of(tracer, ids) if corners is None else corners, per_vertex)
    return tracer.ao(np.ascontiguousarray(p, np.float32), np.ascontiguousarray(n, np.float32),
                     samples=int(samples), distance=distance, seed=int(seed),
                     vertex_ids=np.ascontiguousarray(ids, np.int32), per_corner=False,
                     point_samples=rays, **extra)


def trace_mesh(tracer, p, n, samples, seed=0, distance=math.inf, rows=slice(None)):
    """AO float32 of the tracer's own vertices ``rows`` (p, n: every vertex's, as the
    tracer's mesh) when every vertex is a receiver: Cycles' rays at ``samples``, spread evenly
    over all of them (the benchmarks' call; a bake spreads over its receivers: trace)."""
    ids = np.arange(tracer.vertex_count, dtype=np.int32)[rows]
    per_vertex = samples * tracer.corners_per_vertex
    return np.asarray(trace_even(tracer, np.asarray(p)[rows], np.asarray(n)[rows], ids,
                                 samples, per_vertex, seed, distance), np.float32)


def trace(plan, name, p, n, own, **extra):
    """The exact rung's AO float32 (N,) of object ``name``'s vertex receivers (own: the
    tracer-mesh ids, lighting.own_ids) at the plan's samples, spread evenly (module doc)."""
    s = plan.settings
    d = ray_length(s.distance)
    ids = own["vertex_ids"]
    corners = object_corners(plan, name)[ids.astype(np.int64) - plan.tracer_bases[name][0]]
    return trace_even(plan.tracer, p, n, ids, s.samples, s.samples * mean_corners(plan),
                      s.seed, d, corners=corners, **extra)
