"""Auto's honest frontier (docs/DESIGN.md, 'Auto mode'; core/frontier.py): the exact rung
weighed at several sample counts with a predicted error, and a choice no other candidate beats
on both predicted time and error. Scenes: the fixed-seed generators of
examples/canopy_scenes.py."""
import math

import canopy_scenes as cs
import pytest

from canopy_ao import core
from canopy_ao.core import frontier
from canopy_ao.core.rungs import base
from test_auto import items


def auto(scene, **kw):
    plan = core.prepare(items(scene), core.BakeSettings(method="auto", tau=None, **kw))
    return plan, plan.calibration


def test_ray_counts_are_the_halvings_down_to_the_fewest():
    assert frontier.ray_counts(64) == [4, 8, 16, 32, 64]
    assert frontier.ray_counts(100) == [6, 12, 25, 50, 100]
    assert frontier.ray_counts(5) == [5]
    assert frontier.ray_counts(1) == [1]


@pytest.mark.parametrize("alpha", [0.3, 0.5, 0.65, 1.0])
def test_the_ray_error_model_recovers_its_exponent(alpha):
    """Two counts' MSE made by the model with a known α and v give back that α and v, and
    predict the counts between; the reference's own noise is not mistaken for the rung's."""
    v, ref = 0.2, 128
    truth = frontier.RayError(v=v, alpha=alpha, reference=ref)
    got = frontier.fit_ray_error({4: truth.mse(4), 64: truth.mse(64)}, ref)
    assert got.alpha == pytest.approx(alpha, rel=1e-6) and got.v == pytest.approx(v, rel=1e-6)
    for s in (8, 16, 32):
        assert got.mse(s) == pytest.approx(truth.mse(s), rel=1e-6)


def test_the_ray_error_model_on_degenerate_samples():
    """One count, or an error of 0 (every point open sky): the default exponent, the measured
    value kept, no division by zero; a ratio outside the range is clamped, not extrapolated."""
    one = frontier.fit_ray_error({8: 0.01}, 128)
    assert one.alpha == frontier.ALPHA_DEFAULT and one.mse(8) == pytest.approx(0.01)
    zero = frontier.fit_ray_error({4: 0.0, 64: 0.0}, 128)
    assert zero.mse(16) == 0.0
    flat = frontier.fit_ray_error({4: 0.01, 64: 0.01}, 128)  # fewer rays no worse: noise
    assert flat.alpha == frontier.ALPHA_RANGE[0]
    steep = frontier.fit_ray_error({4: 1.0, 64: 1e-9}, 128)
    assert steep.alpha == frontier.ALPHA_RANGE[1]


def test_the_front_and_the_walk():
    c = [dict(method="a", seconds=1.0, mse=0.04, rank=(0, 0)),
         dict(method="b", seconds=1.0, mse=0.05, rank=(1, 0)),   # tie in time: no win
         dict(method="c", seconds=2.0, mse=0.05, rank=(2, 0)),   # beaten by a on both
         dict(method="d", seconds=3.0, mse=0.039, rank=(3, 0)),  # < 10 % better than a
         dict(method="e", seconds=4.0, mse=0.01, rank=(4, 0))]
    on = frontier.front(c)
    assert [x["method"] for x in on] == ["a", "b", "d", "e"]
    assert frontier.walk(on, 0.0, 0.0)[0]["method"] == "e"
    chosen, skipped = frontier.walk(on, 0.0, 3.5)
    assert chosen["method"] == "a" and [x["method"] for x in skipped] == ["e"]
    assert frontier.walk(on, 0.21, 0.0)[0]["method"] == "a"  # a meets the target


def _undominated(cal, plan):
    """The chosen candidate's frontier entry, after checking no candidate beats it on both."""
    samples = plan.settings.samples if base.get(plan.method).exact else None
    mine = next(c for c in cal["frontier"]
                if c["method"] == plan.method and c["samples"] == samples)
    assert mine["on_front"], cal["why"]
    for c in cal["frontier"]:
        assert not (c["predicted_seconds"] < mine["predicted_seconds"]
                    and c["rmse"] < mine["rmse"]), (c, mine, cal["why"])
    return mine


@pytest.mark.parametrize("scene,budget", [
    (lambda: cs.round_tree(leaves=800), 0.0), (lambda: cs.round_tree(leaves=800), 0.02),
    (lambda: cs.conifer(leaves=1000, ground=False), 0.02),
    (lambda: cs.weeping_tree(leaves=4000), 0.05), (lambda: cs.grass_field(), 0.05),
    (lambda: cs.ideal_ellipsoid(), 0.02)],
    ids=["round-free", "round-tight", "conifer", "weeping", "grass", "ellipsoid"])
def test_the_choice_is_never_dominated(scene, budget):
    plan, cal = auto(scene(), time_budget=budget)
    mine = _undominated(cal, plan)
    if budget > 0 and mine["predicted_seconds"] > budget:  # only the cheapest may be over it
        assert mine["predicted_seconds"] == min(c["predicted_seconds"] for c in cal["frontier"])
    # The exact rung is weighed at every count, two of them traced on the sample.
    counts = [c["samples"] for c in cal["frontier"] if c["method"] == "raytrace"]
    assert counts == frontier.ray_counts(64)
    assert sum(c["measured"] for c in cal["frontier"] if c["method"] == "raytrace") in (1, 2)


def test_few_rays_beat_the_ray_free_rung():
    """On a small tree the ray-free rung's fit is poor (its sample is ~the scene), and 8 rays
    per corner cut its error by more than 10 % within a budget 16 rays are over: auto bakes
    the rays at 8 (the halving floor of 16 left it the ray-free rung)."""
    scene = cs.round_tree(leaves=800)
    plan, cal = auto(scene, time_budget=0.0, target_rmse=0.0)
    t8 = next(c["predicted_seconds"] for c in cal["frontier"] if c["samples"] == 8)
    plan, cal = auto(scene, time_budget=t8 * 1.01, target_rmse=0.0)
    c = cal["candidates"]
    assert "regression" in c, cal["why"]
    assert plan.method == "raytrace" and plan.settings.samples == 8, cal["why"]
    mine = _undominated(cal, plan)
    assert mine["rmse"] ** 2 < 0.81 * c["regression"]["rmse"] ** 2
    assert 0.5 <= cal["ray_error"]["alpha"] <= 1.0  # rays at least as good as independent


def test_few_samples_asked():
    """Samples below the fewest weighed: one count, measured, no model to extrapolate."""
    plan, cal = auto(cs.round_tree(leaves=800), samples=2, time_budget=0.0)
    rays = [c for c in cal["frontier"] if c["method"] == "raytrace"]
    assert [(c["samples"], c["measured"]) for c in rays] == [(2, True)]
    assert cal["ray_error"]["alpha"] == frontier.ALPHA_DEFAULT
    _undominated(cal, plan)


def test_the_frontier_is_deterministic():
    scene = cs.round_tree(leaves=800)
    _p1, a = auto(scene, time_budget=0.03)
    _p2, b = auto(scene, time_budget=0.03)
    assert a["frontier"] == b["frontier"] and a["chosen"] == b["chosen"]
    assert all(math.isfinite(c["rmse"]) for c in a["frontier"])


def test_rays_are_baked_at_the_count_the_budget_affords():
    """Fewer rays only prune the front: with no budget, auto that climbs to the exact rung bakes
    it at the asked samples, even where fewer would meet the target error (an artist asking for
    64 rays within budget gets 64, not 16 that are 'good enough')."""
    scene = cs.round_tree(leaves=800)
    plan, cal = auto(scene, time_budget=0.0, target_rmse=0.0, samples=64)
    assert plan.method == "raytrace" and plan.settings.samples == 64, cal["why"]
    plan, cal = auto(scene, time_budget=0.0, target_rmse=0.045, samples=64)
    assert plan.settings.samples in (64,) or plan.method != "raytrace", cal["why"]
