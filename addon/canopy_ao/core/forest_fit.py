"""The fit of an instanced prototype whose own AO nobody bakes (no bpy): what its instances
occlude with, and nothing more (docs/DESIGN.md, 'How each role is lit').

instances.Prototypes bakes a prototype's self-AO only when it, or an object that instances it,
is a target of the bake, or the bake is of everything. Otherwise the prototype is needed only
as an occluder: its shells, trunks and τ (forest.prototype_from_plan). A fixed rung fits it as
its bake would (bake.prepare: its τ, calibrated or not, is the prototype's own); auto skips
the prototype's calibration (:func:`fit_only`).
"""

from __future__ import annotations

import time

from . import native, proxies, trees
from .ladder import DEFAULT_TAU
from .rungs import auto, base as rungs
from .scene import Plan, split_trees


def fit_only(items, settings):
    """The Plan of a prototype nobody bakes when the bake's method is auto, or None (another
    method: bake.prepare, whose τ, calibrated or not, is the prototype's own). It holds only
    the fit its instances occlude with (plan.proxies, plan.trunks), at auto's fallback rung
    (ellipsoid) and the given τ, else the default one: no scene plan, tracer or calibration.
    Auto would calibrate on the prototype's own vertices, from inside its crown, which is not
    where its instances are seen from; the bake's own calibration weighs the instances on its
    receivers (auto's proxyless candidates against rays that trace them, forest_tau's κ)."""
    if not rungs.get(settings.method).chooses:
        return None
    native.require()
    plan = Plan(settings=settings, method=auto.FALLBACK,
                tau=settings.tau if settings.tau is not None else DEFAULT_TAU)
    t0 = time.perf_counter()
    items = list(items)
    trees.resolve(items)
    proxies.fit_scene(plan, split_trees(items))
    plan.proxies = {t: proxies.own_shells(plan, t, plan.method) for t in plan.fits}
    plan.timings["fit"] = plan.timings["prepare"] = time.perf_counter() - t0
    return plan
