"""The bake's math and data, in numpy and the native core; imports no bpy, so plain pytest
tests all of it. One module per concern (docs/DESIGN.md, 'Architecture'):

    native    the one import of _core, core_status(), CanopyAOError
    settings  every option declared once (OPTIONS), BakeSettings made from them
    scene     SceneItem, Plan, ItemResult
    proxies   fitted shells and trunks per tree
    lighting  how each role is lit (AO of receiver points)
    rungs     each rung of the method ladder as an object (rungs/base.py: ask it, by name)
    ladder    the method ladder: calibration and "auto"
    bake      prepare / evaluate_item / report / bake
    roles, forest, metrics   role guesses, instanced trees, error metrics

The names below are the public API.
"""

from .bake import attach_forest, bake, evaluate_item, evaluate_receivers, prepare, report
from .ladder import (ANALYTIC_METHODS, DEFAULT_TAU, METHODS, available_methods, calibrate,
                     triangles_needed)
from .native import CanopyAOError, core_status
from .proxies import proxy_dicts
from .rungs.base import Rung, get as rung
from .scene import RECEIVER_ROLES, ItemResult, Plan, SceneItem
from .settings import OPTIONS, BakeSettings
