"""Maps beyond AO computed from the fitted proxies (no bpy): the canopy thickness
(docs/DESIGN.md, 'Maps').

Thickness of a point x in its tree's canopy, from the shells the bake lit with (plan.proxies:
the chosen rung's sphere, ellipsoid or k-means shells; the ellipsoid for the rays and the grid):

    ρ_s(x) = |diag(1/r_s) Q_sᵀ (x − C_s)|      (1 on shell s's surface, 0 at its centre)
    thickness(x) = max_s clamp(1 − ρ_s(x), 0, 1)

0 on the outer surface of the union of the shells and outside it, rising inward to 1 at a
shell's centre. It is scale-free (ρ is measured in the shell's own unit frame), and in the
uniform leaf medium of docs/DESIGN.md, 'The method ladder' (τ = σR) it is the optical depth of
the straight way out along the shell's radius divided by τ: τ · thickness = σ · (R − |x − C|),
the Reeves–Blau depth made unitless.
"""

from __future__ import annotations

import numpy as np

from .scene import Plan, SceneItem


def shell_depth(shells, points) -> np.ndarray:
    """max over shells of clamp(1 − ρ_s, 0, 1) for points float (N, 3); 0 without shells."""
    p = np.asarray(points, np.float64).reshape(-1, 3)
    out = np.zeros(len(p), np.float64)
    for e in shells:
        q = (p - np.asarray(e.center, np.float64)) @ np.asarray(e.axes, np.float64)
        q /= np.asarray(e.radii, np.float64)
        np.maximum(out, 1.0 - np.sqrt(np.einsum("ij,ij->i", q, q)), out=out)
    return np.clip(out, 0.0, 1.0).astype(np.float32)


def thickness(plan: Plan, item: SceneItem, positions, vertices=None) -> np.ndarray:
    """Canopy thickness float32 (N,) in [0, 1] of receivers on item (its vertices, a chunk of
    them, or texels). A receiver of a tree with shells is measured in that tree's shells (an
    item holding several trees: the vertex's own tree, else every tree's); a receiver with
    none (ground, grass, a stem alone) in every tree's, so a crown reaching down to it counts."""
    every = [e for shells in plan.proxies.values() for e in shells]
    names = item.tree_names if item.tree_labels is not None and len(item.tree_names) > 1 \
        else None
    if names is None or vertices is None:
        own = plan.proxies.get(item.tree) if names is None else None
        return shell_depth(own or every, positions)
    p = np.asarray(positions).reshape(-1, 3)
    labels = item.tree_labels[vertices]
    out = np.zeros(len(p), np.float32)
    for k, tree in enumerate(names):
        sel = np.flatnonzero(labels == k)
        if len(sel):
            out[sel] = shell_depth(plan.proxies.get(tree) or every, p[sel])
    return out
