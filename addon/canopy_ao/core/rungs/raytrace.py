"""raytrace: the exact rung, Embree rays against every triangle (Cycles' AO bake's estimate)."""
from .. import cost, lighting
from .base import Rung


def _evaluate(rung, plan, role, tree, grass_key, p, n, tau, own, group):
    return lighting.exact_ao(plan, grass_key, p, n, own, group)


def _work(rung, plan, receivers, names=None, samples=None):
    return "bvh_step", cost.ray_work(plan, receivers, names, samples)


RUNG = Rung("raytrace", "Ray-traced", "Exact: Embree rays against every triangle (slowest)",
            evaluate=_evaluate, work=_work, needs_triangles=True, needs_tracer=True,
            rays_see_instances=True, finds_buried=True, uses_samples=True, exact=True,
            # The exact rung tops the ladder: on small or sparse scenes a few rays per vertex
            # beat every proxy within the time budget; on big ones the budget rules it out.
            climbs=lambda plan: plan.tracer is not None and not plan.settings.ray_free,
            number=9)
