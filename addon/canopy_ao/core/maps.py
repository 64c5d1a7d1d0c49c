"""Maps beyond AO (no bpy): the canopy thickness from the fitted proxies, and bent normals
from the ray tracer (docs/DESIGN.md, 'Maps' and 'Bent normals').

Thickness of a point x in its tree's canopy, from the tree's fitted crown ellipsoid (the
minimum-volume enclosing ellipsoid of its canopy points, the ellipsoid rung's shell; the same
whichever rung lit the bake, so the map does not change when auto picks another rung; the
sphere rung fits no ellipsoid and its enclosing sphere stands in):

    ρ(x) = |diag(1/r) Qᵀ (x − C)|      (1 on the crown's surface, 0 at its centre)
    thickness(x) = clamp(1 − ρ(x), 0, 1)

0 on the crown's outer surface and outside it, rising inward to 1 at its centre. It is
scale-free (ρ is measured in the crown's own unit frame), and in the uniform leaf medium of
docs/DESIGN.md, 'The method ladder' (τ = σR) it is the optical depth of the straight way out
along the crown's radius divided by τ: τ · thickness = σ · (R − |x − C|), the Reeves–Blau depth
made unitless. The k-means shells are not used: each shell's centre would be a "deepest"
point, and the crown's centre, where shells meet, would read as shallow.
"""

from __future__ import annotations


import numpy as np

from . import lighting, ray_budget
from .native import CanopyAOError
from .rungs import base as rungs
from .scene import Plan, SceneItem, own_primitives


def shell_depth(shells, points) -> np.ndarray:
    """max over shells of clamp(1 − ρ_s, 0, 1) for points float (N, 3) (ρ_s as ρ above, in
    shell s's frame; 0 only outside or on the union's outer surface); 0 without shells."""
    # float32 throughout, the centre taken off first (a world far from the origin loses no
    # precision inside a crown); ~70 ms per million points on this 2-core machine.
    p = np.asarray(points, np.float32).reshape(-1, 3)
    out = np.zeros(len(p), np.float32)
    for e in shells:
        frame = (np.asarray(e.axes, np.float64) / np.asarray(e.radii, np.float64)).astype(
            np.float32)  # column j: axis j / r_j
        q = (p - np.asarray(e.center, np.float32)) @ frame
        rho = np.sqrt(np.einsum("ij,ij->i", q, q))
        np.maximum(out, 1.0 - rho, out=out)
    return np.clip(out, 0.0, 1.0, out=out)


def thickness(plan: Plan, item: SceneItem, positions, vertices=None) -> np.ndarray:
    """Canopy thickness float32 (N,) in [0, 1] of receivers on item (its vertices, a chunk of
    them, or texels). A receiver of a tree with a crown is measured in that crown (an item
    holding several trees: the vertex's own tree, else every tree's); a receiver with none
    (ground, grass, a stem alone) in every tree's, so a crown reaching down to it counts."""
    crowns = {tree: [fit[1]] for tree, fit in plan.fits.items()}
    every = [e for shells in crowns.values() for e in shells]
    names = item.tree_names if item.tree_labels is not None and len(item.tree_names) > 1 \
        else None
    if names is None or vertices is None:
        own = crowns.get(item.tree) if names is None else None
        return shell_depth(own or every, positions)
    p = np.asarray(positions).reshape(-1, 3)
    labels = item.tree_labels[vertices]
    out = np.zeros(len(p), np.float32)
    for k, tree in enumerate(names):
        sel = np.flatnonzero(labels == k)
        if len(sel):
            out[sel] = shell_depth(crowns.get(tree) or every, p[sel])
    return out


# === Bent normals (docs/DESIGN.md, 'Bent normals')

def ensure_tracer(plan: Plan, items) -> None:
    """Build the plan's ray tracer over items (the bake's whole items, as prepare() does) when
    the chosen rung did not need one: bent normals are ray-traced whichever rung lit the AO.
    Raises CanopyAOError when the scene has no triangles."""
    protos = plan.forest.prototypes if plan.forest is not None else None
    if plan.tracer is None:
        plan.tracer = lighting.build_tracer(items, plan.tracer_bases, protos)
        plan.tracer_items = list(items)  # the receivers the bent normals' rays are spread over
        plan.notes.append("bent normals: built the ray tracer (the AO's method traces none)")
    if protos and not lighting.traces_instances(plan) and not any(
            n.startswith("bent normals: rays do not") for n in plan.notes):
        plan.notes.append("bent normals: rays do not see the instanced trees (the ray tracer "
                          "has only the scene's own triangles)")


def rung_is_the_trace(plan: Plan, item: SceneItem) -> bool:
    """Whether item's AO under the plan's rung is the very trace bent_normals makes (the exact
    rung, one call for the whole item, no analytic forest multiplied in), so one trace gives
    both (bent_normals(..., with_ao=True))."""
    return (rungs.get(plan.method).exact and item.role != "IGNORE"
            and (item.tree_labels is None or len(item.tree_names) <= 1)
            and (plan.forest is None or lighting.traces_instances(plan)))


def bent_normals(plan: Plan, item: SceneItem, positions, normals, vertices=None,
                 triangles=None, with_ao=False, group=1):
    """World-space bent normals float32 (N, 3) of receivers on item (as
    bake.evaluate_receivers: its vertices, a chunk of them, or texels with their triangles):
    the cosine-weighted mean unoccluded direction of settings.samples rays per face corner,
    normalised, against the plan's tracer (ensure_tracer). Every ray blocked: the unit normal;
    a zero normal: (0, 0, 0) (raytrace.h, "Bent normals"). with_ao: (the trace's AO float32
    (N,), bent normals); the AO is the exact rung's where rung_is_the_trace. group: receivers
    per texel, its anti-aliasing sub-samples, which deal the texel's Samples among them as the
    AO's do (lighting.ray_args): each point's bent normal is its share's."""
    if plan.tracer is None:
        raise CanopyAOError("bent normals need the ray tracer (maps.ensure_tracer)")
    p = np.ascontiguousarray(positions, dtype=np.float32).reshape(-1, 3)
    n = np.ascontiguousarray(normals, dtype=np.float32).reshape(-1, 3)
    own = lighting.own_ids(plan, item.name, own_primitives(item, vertices, triangles))
    if ray_budget.applies(plan, item.name, own):  # the exact rung's rays (ray_budget.py)
        ao, bent = ray_budget.trace(plan, item.name, p, n, own, bent_normals=True)
    else:
        ao, bent = lighting.trace(plan, p, n, own=own, bent_normals=True,
                                  **lighting.ray_args(plan, group))
    bent = np.asarray(bent, np.float32)
    return (np.asarray(ao, np.float32), bent) if with_ao else bent


def to_tangent(bent, normals, tangents, signs) -> np.ndarray:
    """Bent normals float (N, 3) in the tangent frame (T, B, N) of each receiver: N its unit
    normal, T its tangent made orthogonal to N (Gram–Schmidt), B = sign · N × T (Blender's
    and MikkTSpace's bitangent), so a bent normal equal to the normal is (0, 0, 1). A tangent
    parallel to N or zero (no UV gradient there) is replaced by any unit vector orthogonal to
    N. Returns float32 (N, 3); (0, 0, 0) stays (0, 0, 0)."""
    b = np.asarray(bent, np.float64).reshape(-1, 3)
    n = np.asarray(normals, np.float64).reshape(-1, 3)
    n = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
    t = np.asarray(tangents, np.float64).reshape(-1, 3)
    t = t - n * np.einsum("ij,ij->i", t, n)[:, None]
    tl = np.linalg.norm(t, axis=1)
    bad = ~(tl > 1e-6)
    if bad.any():  # any vector orthogonal to n: n × (the axis least aligned with it)
        axis = np.eye(3)[np.argmin(np.abs(n[bad]), axis=1)]
        t[bad] = np.cross(n[bad], axis)
        tl[bad] = np.linalg.norm(t[bad], axis=1)
    t /= tl[:, None]
    s = np.where(np.asarray(signs, np.float64).reshape(-1) < 0, -1.0, 1.0)
    bt = s[:, None] * np.cross(n, t)
    return np.stack([np.einsum("ij,ij->i", b, t), np.einsum("ij,ij->i", b, bt),
                     np.einsum("ij,ij->i", b, n)], axis=1).astype(np.float32)


def encode(bent) -> np.ndarray:
    """Unit vectors float (N, 3) as colours 0.5 + 0.5 · v in [0, 1] (a normal map's
    encoding: (0, 0, 1) is (0.5, 0.5, 1)), float32 (N, 3)."""
    return np.clip(0.5 + 0.5 * np.asarray(bent, np.float32), 0.0, 1.0)
