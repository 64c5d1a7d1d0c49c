"""Maps beyond AO computed from the fitted proxies (no bpy): the canopy thickness
(docs/DESIGN.md, 'Maps').

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

from .scene import Plan, SceneItem


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
