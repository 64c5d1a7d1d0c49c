"""Auto's honest frontier (docs/DESIGN.md, 'Auto mode'): the exact rung weighed at several
sample counts, each with an error predicted from the calibration rays, and the Pareto front of
every candidate's predicted time and error, the only candidates auto chooses from.

The exact rung's estimate at S rays per corner is unbiased with a variance v·S^-2α; the
calibration reference (R rays, another seed) has the same estimator's v·R^-2α, independent, so
the sample MSE of rays at S against it is v·(S^-2α + R^-2α). α is 1/2 for independent rays and
more for stratified ones; it and v are solved from two measured counts of the same calibration
points (the most and the fewest auto weighs), so no constant is tuned to a scene.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

# The fewest rays per corner auto weighs the exact rung at: on real trees 4-8 rays can beat
# the ray-free rung on both time and error (issue #39), so they are weighed, not assumed.
FEWEST_RAYS = 4
# α is searched in this range (1/2: independent rays; 1: the variance of a perfectly
# stratified estimator of a smooth integrand falls no faster in practice).
ALPHA_RANGE = (0.25, 1.5)
ALPHA_DEFAULT = 0.5  # with one measured count (samples ≤ FEWEST_RAYS) or an error of 0


def ray_counts(samples: int) -> list[int]:
    """The rays per corner auto weighs the exact rung at: ``samples`` halved while at least
    FEWEST_RAYS, ascending ([samples] alone when it is fewer)."""
    k, out = int(samples), []
    while k >= FEWEST_RAYS or not out:
        out.append(k)
        k //= 2
    return sorted(set(out))


@dataclass(frozen=True)
class RayError:
    """Predicted sample MSE of the exact rung at s rays per corner against the calibration
    reference at ``reference`` rays: v·(s^-2α + reference^-2α) (module docstring)."""

    v: float
    alpha: float
    reference: int

    def mse(self, s) -> float:
        x = 2.0 * self.alpha
        return self.v * (float(s) ** -x + float(self.reference) ** -x)


def fit_ray_error(measured: dict, reference: int) -> RayError:
    """RayError through the measured {rays per corner: sample MSE} (one or two counts): α from
    the two counts' ratio (bisection; g below rises with α), clamped to ALPHA_RANGE; v through
    the highest count, so its prediction is its measurement."""
    counts = sorted(measured)
    hi = counts[-1]
    alpha = ALPHA_DEFAULT
    if len(counts) > 1 and measured[hi] > 0 and measured[counts[0]] > 0:
        lo, ratio, r = counts[0], measured[counts[0]] / measured[hi], float(reference)

        def g(a):
            return (lo ** (-2 * a) + r ** (-2 * a)) / (hi ** (-2 * a) + r ** (-2 * a))
        a0, a1 = ALPHA_RANGE
        if ratio <= g(a0):
            alpha = a0
        elif ratio >= g(a1):
            alpha = a1
        else:
            for _ in range(60):
                mid = 0.5 * (a0 + a1)
                a0, a1 = (mid, a1) if g(mid) < ratio else (a0, mid)
            alpha = 0.5 * (a0 + a1)
    x = 2.0 * alpha
    v = measured[hi] / (hi ** -x + float(reference) ** -x)
    return RayError(v=v, alpha=alpha, reference=int(reference))


def beats(a: dict, b: dict) -> bool:
    """Whether candidate ``a`` beats ``b`` on both predicted time and predicted error (both
    strictly: a tie in time is no win, so the simpler rung keeps its place)."""
    return a["seconds"] < b["seconds"] and a["mse"] < b["mse"]


def front(candidates: list) -> list:
    """The candidates (dicts with "seconds", "mse" and "rank", their place on the ladder) no
    other beats on both, cheapest first (ties in time: the ladder's order). Deterministic."""
    on = [c for c in candidates if not any(beats(o, c) for o in candidates)]
    return sorted(on, key=lambda c: (c["seconds"], c["rank"]))


def walk(on: list, target_rmse: float, budget: float):
    """Auto's choice on the front (cheapest first): from the cheapest, a costlier candidate
    only while the current one misses ``target_rmse``, if it cuts the MSE below 0.81× (RMSE
    down by more than 10 %) and its predicted time fits ``budget`` (0: no limit). Returns
    (chosen, [candidates skipped for the budget])."""
    chosen, skipped = on[0], []
    for c in on[1:]:
        if math.sqrt(chosen["mse"]) <= target_rmse:
            break
        if c["mse"] < 0.81 * chosen["mse"]:
            if budget > 0 and c["seconds"] > budget:
                skipped.append(c)
                continue
            chosen = c
    return chosen, skipped
