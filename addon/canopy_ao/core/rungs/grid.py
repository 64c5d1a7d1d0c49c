"""grid: the leaf density voxelised, rays marched through it (physical density: no τ)."""
from .. import cost, lighting
from .base import Rung


def _evaluate(rung, plan, role, tree, grass_key, p, n, tau, own, group):
    return lighting.grid_ao(plan, role, grass_key, p, n)


def _work(rung, plan, receivers, names=None, samples=None):
    return "voxel_step", cost.grid_work(receivers)


RUNG = Rung("grid", "Density grid", "Leaf density voxelised, rays marched through it",
            evaluate=_evaluate, work=_work, needs_triangles=True, needs_grid=True,
            climbs=lambda plan: plan.grid is not None, number=6)
