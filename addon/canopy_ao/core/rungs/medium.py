"""medium: the shells filled with randomly oriented leaves, the exact expected AO of a uniform
medium (tabulated), lit by the native scene plan; a shell costs a medium-table look-up."""
import functools

from .. import cost, lighting
from .base import Proxy, Rung, always

RUNG = Rung("medium", "Leaf medium", "The shells filled with randomly oriented leaves: exact "
            "expected AO of a uniform medium (tabulated)",
            evaluate=lighting.scene_plan_ao,
            work=functools.partial(cost.analytic_work, unit="medium"), takes_tau=True,
            scene_plan=True, native="medium", proxy=Proxy.SHELLS, live=True, climbs=always,
            ground_patches=True, number=4)
