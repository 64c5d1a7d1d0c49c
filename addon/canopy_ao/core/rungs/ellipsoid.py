"""ellipsoid: one fitted ellipsoid per tree, lit by the native scene plan."""
from .. import cost, lighting
from .base import Proxy, Rung, always

RUNG = Rung("ellipsoid", "Ellipsoid", "One fitted ellipsoid per tree",
            evaluate=lighting.scene_plan_ao, work=cost.analytic_work, takes_tau=True,
            scene_plan=True, native="ellipsoid", proxy=Proxy.ELLIPSOID, live=True,
            ground_patches=True, climbs=always, number=2)
