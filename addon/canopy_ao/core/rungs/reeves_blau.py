"""reeves_blau: the paper's baseline, exp(-τ depth) inside one ellipsoid (scene plan)."""
from .. import cost, lighting
from .base import Proxy, Rung

RUNG = Rung("reeves_blau", "Reeves-Blau", "Baseline exp(-tau depth) inside one ellipsoid",
            evaluate=lighting.scene_plan_ao, work=cost.analytic_work, takes_tau=True,
            scene_plan=True, native="reeves_blau", proxy=Proxy.ELLIPSOID, live=True,
            ground_patches=True, number=5)
