"""sphere: one fitted sphere per tree (Hegeman Eq. 4-6), lit by the native scene plan."""
from .. import cost, lighting
from .base import Proxy, Rung, always

RUNG = Rung("sphere", "Sphere", "One fitted sphere per tree (Hegeman Eq. 4-6)",
            evaluate=lighting.scene_plan_ao, work=cost.analytic_work, takes_tau=True,
            scene_plan=True, native="sphere", proxy=Proxy.SPHERE, live=True, climbs=always,
            ground_patches=True, number=1)
