"""Fitting τ: the one-dimensional search calibration runs, and τ per tree. No bpy.

Calibration (ladder.calibrate) fits τ on log τ by golden section against ray-traced samples;
a scene of several trees then gives each tree its own τ when it pays (tau_per_tree).
"""

from __future__ import annotations

import math

from .scene import Plan


def golden_min(f, lo, hi, iters=16):
    """Minimise a unimodal f on [lo, hi] by golden-section search; returns (x, f(x))."""
    g = (math.sqrt(5) - 1) / 2
    a, b = lo, hi
    c, d = b - g * (b - a), a + g * (b - a)
    fc, fd = f(c), f(d)
    for _ in range(iters):
        if fc < fd:
            b, d, fd = d, c, fc
            c = b - g * (b - a)
            fc = f(c)
        else:
            a, c, fc = c, d, fd
            d = a + g * (b - a)
            fd = f(d)
    return (c, fc) if fc < fd else (d, fd)


TAU_RANGE = (math.log(0.02), math.log(50.0))  # log τ searched (and the outside factor's)
# Fewest sample points on each side (leaves and branches; the ground) to fit their τ apart.
MIN_SPLIT_POINTS = 16


def tau_per_tree(plan: Plan, method, tau, err):
    """{tree: τ, None: tau}: one golden-section pass per tree (others held) from the scene-wide
    τ. A sparse tree and a dense one have different optical depths; one τ for both darkens
    the sparse one's leaves. A tree keeps the scene-wide τ unless its own cuts the sample's
    squared error by more than 1 %."""
    taus = {t: tau for t in plan.fits}
    taus[None] = tau
    base = err(method, taus)
    for t in sorted(plan.fits):
        def f(x, t=t):
            return err(method, {**taus, t: math.exp(x)})
        lt, e = golden_min(f, *TAU_RANGE)
        if e < 0.99 * base:
            taus[t], base = math.exp(lt), e
    return taus
