"""shells: several ellipsoid shells per tree (k-means clusters), lit by the native scene plan."""
from .. import cost, lighting
from .base import Proxy, Rung, always

RUNG = Rung("shells", "Shells", "Several ellipsoid shells per tree (k-means clusters)",
            evaluate=lighting.scene_plan_ao, work=cost.analytic_work, takes_tau=True,
            scene_plan=True, native="shells", proxy=Proxy.SHELLS, live=True, climbs=always,
            ground_patches=True, number=3)
