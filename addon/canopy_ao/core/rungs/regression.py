"""regression: ray-free, a ridge fit of ray-traced points on cheap per-vertex features of the
density grid and the tree's shape (core/regression.py)."""
from .. import cost, lighting
from .base import Rung


def _evaluate(rung, plan, role, tree, grass_key, p, n, tau, own, group):
    # The GROUND patches multiplied in as the proxy rungs do (lighting.walls_ao): the fit
    # divided them out of its sample (core/regression.py).
    ao = plan.regression.ao(role, tree, p, n, grass_key, own)
    return ao * lighting.walls_ao(plan, p, n, role) if plan.walls else ao


def _work(rung, plan, receivers, names=None, samples=None):
    return "voxel_step", receivers * float(cost.FEATURE_DIRECTIONS)


RUNG = Rung("regression", "Regression", "Ray-free: up to 1024 ray-traced points fitted on "
            "cheap per-vertex features of the density grid and the tree's shape; no rays "
            "beyond them, cost independent of the leaf count",
            evaluate=_evaluate, work=_work, needs_triangles=True, needs_regression=True,
            live=True, ground_patches=True, reads_proxies=False,
            frame_triangle_roles=("GRASS", "GROUND", "CANOPY", "TRUNK"),
            climbs=lambda plan: plan.regression is not None, number=7)
