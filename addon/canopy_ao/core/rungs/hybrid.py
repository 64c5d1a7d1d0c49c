"""hybrid: rays out to a few density-grid voxels, the grid beyond (lighting.hybrid_ao)."""
from .. import cost, lighting
from . import grid, raytrace
from .base import Rung


def _evaluate(rung, plan, role, tree, grass_key, p, n, tau, own, group):
    # With nothing to voxelise (a grass field alone) no far field, so the exact rung; a blade
    # takes the grass law (the whole layer) and the grid, as the grid rung.
    if plan.grid is None:
        return raytrace.RUNG.evaluate(raytrace.RUNG, plan, role, tree, grass_key, p, n, tau,
                                      own, group)
    if role == "GRASS":
        return grid.RUNG.evaluate(grid.RUNG, plan, role, tree, grass_key, p, n, tau, own,
                                  group)
    # The near rays see the blades around a ground point: a grass layer on top would count
    # them twice (round tree on a grass field: ground bias -0.13 against rays, now +0.02).
    return lighting.hybrid_ao(plan, p, n, lighting.own_ids(plan, grass_key, own), group)


def _work(rung, plan, receivers, names=None, samples=None):
    """In BVH steps: the rays of the exact rung plus the grid's voxel steps converted by
    their costs."""
    rays = cost.ray_work(plan, receivers, names, samples)
    steps = cost.grid_work(receivers)
    ratio = cost.SECONDS_PER_UNIT["voxel_step"] / cost.SECONDS_PER_UNIT["bvh_step"]
    return "bvh_step", rays + steps * ratio


RUNG = Rung("hybrid", "Near/far hybrid", "Rays out to a few density-grid voxels, the grid "
            "beyond", evaluate=_evaluate, work=_work, needs_triangles=True, needs_tracer=True,
            needs_grid=True, finds_buried=True, uses_samples=True,
            # Its far field is the density grid of the scene's own triangles, so instanced
            # trees stay its analytic occluders (near rays must not see them twice).
            tracer_holds_instances=False, number=8)
