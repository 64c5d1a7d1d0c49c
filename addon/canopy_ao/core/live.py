"""AO that follows animated vegetation (no bpy): the proxies refitted to each frame's deformed
leaves and evaluated with what the first bake decided (docs/DESIGN.md, 'Live and per-frame AO').

Hegeman et al. evaluate their canopy shells per frame for trees moving in the wind, because a
fit and an analytic evaluation cost little. Here a frame keeps from the first bake everything
that does not move: the rung, τ (scene and per tree, from its calibration), every item's role
and tree (and the tree labels of a mesh holding several), the triangles (the topology of a
deformed mesh does not change; grass blades and the ray-free rung's grid need them), the
leaves' partition into k-means shells and the ray-free rung's fitted models. It redoes what
moves: the fits (sphere, ellipsoid, each shell to its own leaves, trunks, grass heights), the
ray-free rung's features and the evaluation; each ellipsoid's fit starts from the previous
frame's (a session's plan.fit_warm: proxies.fit_tree). For the one-proxy rungs a frame's AO is
therefore the AO of a full bake of that frame with the same rung and τ (the ellipsoids within
a bake's fit tolerance: live fits solve to proxies.LIVE_TOLERANCE); for shells and the medium it is that bake with the first frame's partition
(clustering every frame afresh flips leaves between shells: up to 0.6 AO from one frame to
the next on the test tree).
"""

from __future__ import annotations

import numpy as np

from . import proxies, walls
from .native import CanopyAOError, refusals_are_user_errors
from .rungs import base as rungs
from .scene import Plan, SceneItem, ray_length, split_trees



def live_methods() -> tuple:
    """The rungs that refit and evaluate fast enough per frame (Rung.live): the analytic proxy
    models (the Reeves-Blau baseline is analytic too) and the ray-free rung, whose fit to its
    calibration rays is the first bake's and whose features are recomputed per frame (no ray).
    The density grid and the rays rebuild a grid or a BVH over every triangle and trace each
    frame, which is a full bake, not a live update."""
    return tuple(r.name for r in rungs.ladder() if r.live)


def check_method(method: str, by_auto: bool = False) -> None:
    """CanopyAOError unless ``method`` (a rung, or what auto chose: ``by_auto``) can run
    live."""
    if not rungs.get(method).live:
        which = f"auto chose the {method} rung, which" if by_auto else f"the {method} rung"
        raise CanopyAOError(
            "live and per-frame AO run the analytic rungs only, or the ray-free one "
            f"({', '.join(live_methods())}); "
            f"{which} rebuilds its grid or ray tracer from every triangle each frame: choose "
            "one of those methods (or bake single frames)")


def frame_items(template, positions, normals) -> list:
    """This frame's SceneItems: each template item (the first bake's, role and tree resolved)
    with the frame's positions and normals {name: float32 (V, 3)}. Raises CanopyAOError when a
    mesh's vertex count changed (its topology is not the first bake's)."""
    out = []
    for it in template:
        p, n = positions[it.name], normals[it.name]
        if len(p) != len(it.positions):
            raise CanopyAOError(f"{it.name}: {len(p)} vertices at this frame, "
                                f"{len(it.positions)} at the first bake (the topology changed; "
                                "bake again)")
        out.append(SceneItem(it.name, it.role, it.tree, p, n, it.triangles,
                             tree_source="set", tree_labels=it.tree_labels,
                             tree_names=it.tree_names, tree_why=it.tree_why))
    return out


@refusals_are_user_errors
def refit(base: Plan, items) -> Plan:
    """A plan for this frame's items: base's rung, τ and instanced forest, proxies refitted
    (each ellipsoid from the previous frame's when base.fit_warm holds a dict: proxies.fit_tree);
    the ray-free rung's features moved to the frame, its fit kept (RegressionRung.at_frame)."""
    check_method(base.method)
    plan = Plan(settings=base.settings, method=base.method, tau=base.tau,
                tau_by_tree=dict(base.tau_by_tree), role_scale=dict(base.role_scale),
                forest=base.forest,
                shell_labels=dict(base.shell_labels), buried=base.buried,
                fit_warm=base.fit_warm)
    # The GROUND surfaces as they stand at this frame where the first bake found a wall (then
    # every plane a patch, as there); a ground alone makes none per frame, its occlusion held
    # from the first bake (held_ground), and is not hashed per frame.
    plan.every_ground = base.every_ground
    plan.walls = walls.build(items) if base.every_ground or walls.has_wall(base.walls) else []
    parts = split_trees(items)
    rung = rungs.get(base.method)
    # A rung that reads no proxy (the ray-free one) skips their fits: an ellipsoid at the live
    # tolerance costs as much as its whole grid (DESIGN, 'Live and per-frame AO').
    if rung.reads_proxies:
        proxies.fit_scene(plan, parts)
    if base.regression is not None and rung.needs_regression:
        plan.regression = base.regression.at_frame(parts, items)
    plan.proxies = {t: proxies.own_shells(plan, t, plan.method) for t in plan.fits}
    return plan


def held_ground(base: Plan, items, names) -> dict:
    """{name: float32 (V,)}: what a ground alone occludes of each item named in ``names`` at the
    first bake (its patches' visibility, walls.visibility), which live frames multiply in
    rather than evaluate the patches per frame (tens of times a proxy rung's own cost: DESIGN,
    'Live and per-frame AO'). Empty where frames make their own patches (a wall: refit), where
    the first bake made none, and for rungs that do not use them (Rung.ground_patches); a grass
    blade's law holds its ground (lighting.walls_ao)."""
    if (base.every_ground or not base.walls or walls.has_wall(base.walls)
            or not rungs.get(base.method).ground_patches):
        return {}
    distance = ray_length(base.settings.distance)
    return {it.name: walls.visibility(base.walls, it.positions, it.normals, distance)
            for it in items if it.name in names and it.role != "GRASS"}


def template_items(items, method=None) -> list:
    """The first bake's items as a frame's template: positions kept only for their count,
    triangles where ``method``'s frames need them (Rung.frame_triangle_roles)."""
    keep = rungs.get(method).frame_triangle_roles if method else ("GRASS", "GROUND")
    return [SceneItem(it.name, it.role, it.tree, it.positions, it.normals,
                      it.triangles if it.role in keep else np.zeros((0, 3), np.int32),
                      tree_source="set", tree_labels=it.tree_labels, tree_names=it.tree_names,
                      tree_why=it.tree_why) for it in items]
