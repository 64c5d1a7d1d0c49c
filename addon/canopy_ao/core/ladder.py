"""The method ladder and how a rung is chosen: τ calibrated against ray-traced samples, and
"auto" climbing from the cheapest rung while it pays (docs/DESIGN.md, 'The method ladder').

Rungs, cheapest first: one sphere, one ellipsoid, k shells, the shells as a uniform random
medium (exact expected AO, tabulated), the leaf-density grid; Reeves-Blau is the paper's
baseline and ray tracing the reference.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from . import card_ao, cost, frontier, native
from .buried import BURIED_RAYS, BURIED_SCALE, buried
from .lighting import evaluate_points, own_ids, trace, traces_instances
from .rungs import auto, base as rungs, registry  # noqa: F401  (registry: fills the ladder)
from .scene import RECEIVER_ROLES, SCALED_ROLES, Plan
from .taufit import MIN_SPLIT_POINTS, TAU_RANGE, golden_min, tau_per_tree  # noqa: F401

# (name, label, help) of each rung, in the ladder's order (rungs/registry.py); settings.OPTIONS
# offers them in this order.
RUNGS = tuple((r.name, r.label, r.help) for r in rungs.ladder())
METHODS = rungs.names()
# The rungs auto always weighs (the analytic ones; the others only where the plan has their
# input: Rung.climbs).
ANALYTIC_METHODS = tuple(r.name for r in rungs.ladder() if r.climbs is rungs.always)
DEFAULT_TAU = 1.5  # τ when it is neither given nor calibrated
# Rungs that take τ (the density grid has physical density; rays are exact).
TAU_METHODS = tuple(r.name for r in rungs.ladder() if r.takes_tau and not r.chooses)


def available_methods() -> tuple[str, ...]:
    """Methods the loaded core can run: all of them, or none but "auto" without the module."""
    return rungs.names() if native.core_status()[0] else tuple(
        r.name for r in rungs.ladder() if r.chooses)


def triangles_needed(method: str, tau, role: str) -> bool:
    """Whether an item's triangles take part in a bake (the add-on skips fetching them
    otherwise: Blender's loop triangulation costs more than positions and normals together).
    They are rays' targets (the exact rung, and the calibration of auto or of any method with
    tau None), the density grid's input, grass blades (connected components) and GROUND
    surfaces (every proxy rung's opaque patches: core/walls.py); the analytic models with a
    given τ need the other roles' positions and normals only (Rung.needs_triangles)."""
    if role == "IGNORE":
        return False
    if rungs.get(method).needs_triangles or tau is None:
        return True
    return role in ("GRASS", "GROUND")


def sample_receivers(items, count, seed):
    """Up to ``count`` receiver points spread over the items in proportion to their size, at
    least a few per item so small objects (a trunk) are represented."""
    rng = np.random.default_rng(seed)
    receivers = [it for it in items if it.role in RECEIVER_ROLES and len(it.positions)]
    total = sum(len(it.positions) for it in receivers)
    picks = []
    for it in receivers:
        m = min(len(it.positions), max(16, int(round(count * len(it.positions) / max(total, 1)))))
        idx = np.sort(rng.choice(len(it.positions), size=m, replace=False))
        picks.append((it, idx))
    return picks


def sample_ids(plan: Plan, item, idx, key="vertex_ids"):
    """The tracer-mesh ids of an item's sample vertices idx (a part of an item names the whole
    item's vertices: scene.parts), or with key "triangle_ids" of its triangles idx, or None."""
    whole = item.vertex_map[idx] if item.vertex_map is not None and key == "vertex_ids" else idx
    return own_ids(plan, item.name, {key: whole})


def _sample_points(item, idx, cards):
    """[(positions, normals, the item's own ids)] of its sample vertices idx: the vertices as
    they are, a leaf card's (with ``cards``: Plan.carry_cards) at its card's opaque part with
    that triangle (card_ao.sample_points: where the bake's card vertices take their AO, so τ
    is fitted to the card the bake shows)."""
    whole = item.vertex_map[idx] if item.vertex_map is not None else idx
    cards = card_ao.sample_points(item, idx) if cards and item.vertex_map is None else None
    if cards is None:
        return [(np.ascontiguousarray(item.positions[idx]),
                 np.ascontiguousarray(item.normals[idx]), {"vertex_ids": whole})]
    card, p, n, tri = cards
    rest = np.delete(idx, card)
    out = [(np.ascontiguousarray(item.positions[rest]), np.ascontiguousarray(item.normals[rest]),
            {"vertex_ids": rest})] if len(rest) else []
    return out + [(p, n, {"triangle_ids": tri})]


def calibrate(plan: Plan, items, candidates, tau_fixed=None):
    """Pick τ (unless fixed) and a method among ``candidates`` against ray-traced samples.

    Traces a few hundred receiver points, then for each candidate finds the τ that minimises
    the mean squared error (golden-section search on log τ in [0.02, 50]; the density grid has
    no τ) and walks up the ladder while the RMSE drops by more than 10 %, stays above
    ``target_rmse`` and the richer rung's predicted time (cost.py: counted work × fixed
    constants, never a clock, so the choice does not depend on the machine's load) fits
    ``time_budget``. Returns (method, tau, info dict).
    """
    s = plan.settings
    picks = sample_receivers(items, s.calibration_points, s.seed)
    t0 = time.perf_counter()
    refs, groups = [], []
    for it, idx in picks:
        # The rungs' own ids of the points (item vertices, or a card's triangle; the
        # regression's leaf features) and the tracer's.
        for p, n, local in _sample_points(it, idx, plan.carry_cards):
            own = own_ids(plan, it.name, local)
            refs.append(trace(plan, p, n, s.calibration_samples, own=own))
            groups.append((it, p, n, own, local))
    ref = np.concatenate(refs) if refs else np.zeros(0, np.float32)
    # Buried points (a leaf's base inside its twig): kept out of the fit, which they would
    # darken everything else to match (docs/DESIGN.md, 'Auto mode').
    keep = ~np.concatenate([buried(plan, it, p, n, own) for it, p, n, own, _ in groups]) \
        if groups else np.zeros(0, bool)
    # The ground sees the crowns from outside, the leaves from inside: one τ for both left the
    # ground 0.06-0.2 too dark. τ is fitted on the leaves' and branches' points, then each
    # SCALED_ROLES group its own factor on theirs, where both sides have enough points.
    role_of = np.concatenate([np.full(len(p), it.role, object)
                              for it, p, _n, _o, _l in groups]) if groups else np.zeros(0, object)
    leaves = keep & ~np.isin(role_of, sum(SCALED_ROLES, ()))
    scaled = [(roles, keep & np.isin(role_of, roles)) for roles in SCALED_ROLES]
    scaled = [(r, w) for r, w in scaled if w.sum() >= MIN_SPLIT_POINTS]
    if leaves.sum() < MIN_SPLIT_POINTS:
        scaled = []
    t_trace = time.perf_counter() - t0

    batches = _batches(groups)

    n_receivers = cost.receiver_count(plan, items)
    exact = rungs.exact().name
    # The exact rung is measured at the most rays per corner auto may bake it at within the
    # budget and at the fewest it weighs; every count between is predicted (frontier.py).
    rays = cost.affordable_samples(plan, n_receivers) if exact in candidates else s.samples
    counts = frontier.ray_counts(s.samples) if exact in candidates else []

    def err(method, tau, scale=None, where=None, samples=None):
        plan.role_scale = scale or {}
        sel = keep if where is None else where
        rung = rungs.get(method)
        if rung.exact:
            # As the bake casts them (each vertex's rays spread evenly: ray_budget.py), with
            # its own noise, not the reference's: another seed than the reference traced with.
            saved = plan.settings
            plan.settings = dataclasses.replace(saved, samples=int(samples or rays),
                                                seed=s.seed + 7919)
            try:
                got = [evaluate_points(plan, it.role, it.tree, it.name, p, n, method, tau,
                                       local) for it, p, n, _own, local in groups]
            finally:
                plan.settings = saved
        elif rung.scene_plan:  # the scene plan: one call per role, a tree per point
            got = [np.empty(len(ref), np.float32)]
            for (role, key), (trees, p, n, where) in batches.items():
                got[0][where] = evaluate_points(plan, role, trees, key, p, n, method, tau)
        else:
            got = [evaluate_points(plan, it.role, it.tree, it.name, p, n, method, tau, local)
                   for it, p, n, _own, local in groups]
        got = np.concatenate(got) if got else np.zeros(0, np.float32)
        return float(np.mean((got[sel] - ref[sel]) ** 2)) if sel.any() else 0.0

    results, predicted, scales = {}, {}, {}
    for m in candidates:
        if not rungs.get(m).takes_tau:  # physical density / exact: no τ to fit
            tau = float(tau_fixed or DEFAULT_TAU)
        elif tau_fixed is not None:
            tau = float(tau_fixed)
        else:
            fit = leaves if scaled else keep
            lt, _e = golden_min(lambda x: err(m, math.exp(x), None, fit), *TAU_RANGE)
            tau = math.exp(lt)
            if len(plan.fits) > 1:
                tau = tau_per_tree(plan, m, tau, lambda mm, t: err(mm, t, None, fit))
            scales[m] = {}
            for roles, where in scaled:  # a group's receivers see no other group's τ
                ls, _e = golden_min(lambda x: err(m, tau, dict.fromkeys(roles, math.exp(x)),
                                                  where), *TAU_RANGE)
                scales[m].update(dict.fromkeys(roles, math.exp(ls)))
        results[m] = (tau, err(m, tau, scales.get(m)))
        # Counted work × fixed constants (cost.py): the same prediction whatever the load.
        predicted[m] = cost.predict(plan, m, n_receivers,
                                    samples=rays if rungs.get(m).exact else None)
    ray_model, options = None, []
    for i, m in enumerate(candidates):
        if not rungs.get(m).exact:
            options.append({"method": m, "samples": None, "mse": results[m][1],
                            "seconds": predicted[m]["seconds"], "rank": (i, 0),
                            "measured": True})
            continue
        measured = {rays: results[m][1]}
        if counts[0] < rays:
            measured[counts[0]] = err(m, results[m][0], samples=counts[0])
        ray_model = frontier.fit_ray_error(measured, s.calibration_samples)
        for k in counts:
            options.append({"method": m, "samples": k,
                            "mse": measured.get(k, ray_model.mse(k)),
                            "seconds": cost.predict(plan, m, n_receivers, samples=k)["seconds"],
                            "rank": (i, k), "measured": k in measured})
    # Only the Pareto front of predicted time and error (frontier.py), cheapest first: a
    # costlier candidate only while the current one misses the target, if it cuts the RMSE by
    # more than 10 % and fits the time budget.
    # Fewer rays than the budget affords only prune the front (a ray-free rung 8 rays beat on
    # both is off it): the exact rung is baked at the most rays on the front the budget fits.
    on = frontier.front(options)
    fits = [c["samples"] for c in on if c["samples"] is not None
            and (s.time_budget <= 0 or c["seconds"] <= s.time_budget)]
    if fits:  # (none fits: the walk skips them all and says so)
        on = [c for c in on if c["samples"] in (None, max(fits))]
    best, skipped = frontier.walk(on, s.target_rmse, s.time_budget)
    chosen = best["method"]
    if best["samples"] is not None:  # the exact rung at the count chosen
        results[chosen] = (results[chosen][0], best["mse"])
        predicted[chosen] = cost.predict(plan, chosen, n_receivers, samples=best["samples"])
        rays = best["samples"]
    plan.role_scale = dict(scales.get(chosen) or {})
    rmse = math.sqrt(results[chosen][1])
    why = (f"{_label(best)}: sample RMSE {rmse:.3f}; no costlier candidate on the front of "
           "time and error cut it by more than 10 %"
           if rmse > s.target_rmse else f"{_label(best)}: sample RMSE {rmse:.3f} meets the "
           f"target {s.target_rmse}")
    if skipped:
        why += (f" within the {s.time_budget:g} s budget (over it: "
                f"{', '.join(_label(c) for c in skipped)})")
    if rungs.get(chosen).exact and rays != s.samples:
        full = cost.predict(plan, chosen, n_receivers)["seconds"]
        why += (f"; at {rays} rays per corner, not the {s.samples} asked ({full:.2g} s "
                f"predicted at those)")
    info = {
        "points": int(keep.sum()),
        "buried_points_left_out": int(len(ref) - keep.sum()),
        "buried_test": (f"every one of {BURIED_RAYS} rays stops within {BURIED_SCALE:g} of "
                        "the object's bounding-box diagonal"),
        "reference_samples": s.calibration_samples,
        # The rays (reference and exact rung) hit the instanced trees too (lighting.build_tracer).
        "instances_traced": traces_instances(plan),
        "trace_seconds": t_trace,
        "seconds": time.perf_counter() - t0,
        "candidates": {m: {"tau": _scene_tau(t), "tau_by_tree": _tree_taus(t),
                           "rmse": math.sqrt(e), "predicted_seconds": predicted[m]["seconds"],
                           **({"role_scale": scales[m]} if scales.get(m) else {}),
                           "cost": predicted[m], **({"samples": rays} if rungs.get(m).exact
                                                    else {})}
                       for m, (t, e) in results.items()},
        "chosen": chosen,
        "why": why,
        # Every candidate weighed (the exact rung at each count), its predicted time and error
        # (measured on the sample, or predicted by the ray-error model) and whether it is on
        # the front; the exact rung's model: v, α, the reference's rays.
        "frontier": [{"method": c["method"], "samples": c["samples"],
                      "rmse": math.sqrt(c["mse"]), "predicted_seconds": c["seconds"],
                      "measured": c["measured"], "on_front": any(c is o for o in on)} for c in options],
        "ray_error": None if ray_model is None else {
            "v": ray_model.v, "alpha": ray_model.alpha, "reference_samples": ray_model.reference,
            "formula": "MSE(S) = v (S^-2α + reference^-2α)"},
        "cost_model": {"seconds_per_unit": dict(cost.SECONDS_PER_UNIT),
                       "threads": cost.threads(), "receivers": n_receivers,
                       "formula": cost.FORMULA},
    }
    return chosen, results[chosen][0], info


def _label(c) -> str:
    """A frontier candidate's name in the report: the rung, with its rays per corner."""
    return c["method"] if c["samples"] is None else f"{c['method']} at {c['samples']} rays"


def _batches(groups):
    """The calibration sample as one batch per role (and per grass item, whose blade height
    is its own): {(role, grass item or None): ((tree names, label per point), positions,
    normals, the points' indices in the sample)}, for the scene plan's tree per receiver."""
    parts, start = {}, 0
    for it, p, n, *_ in groups:
        key = (it.role, it.name if it.role == "GRASS" else None)
        parts.setdefault(key, []).append((it.tree, p, n, np.arange(start, start + len(p))))
        start += len(p)
    out = {}
    for key, rows in parts.items():
        names = sorted({t for t, *_ in rows})
        labels = np.concatenate([np.full(len(p), names.index(t), np.int32)
                                 for t, p, _n, _w in rows])
        out[key] = ((tuple(names), labels), np.concatenate([r[1] for r in rows]),
                    np.concatenate([r[2] for r in rows]), np.concatenate([r[3] for r in rows]))
    return out


def _scene_tau(tau):
    return float(tau[None]) if isinstance(tau, dict) else float(tau)


def _tree_taus(tau):
    return {t: float(v) for t, v in tau.items() if t is not None} if isinstance(tau, dict) \
        else {}


def _bake_samples(plan: Plan) -> None:
    """Bake with the rays per corner calibrate() chose the exact rung at (fewer than asked
    where those are over the time budget, or fewer meet the target or are all the front
    affords): plan.settings becomes a copy, the caller's settings stay as given."""
    k = (plan.calibration or {}).get("candidates", {}).get(plan.method, {}).get("samples")
    if rungs.get(plan.method).exact and k is not None and int(k) != int(plan.settings.samples):
        plan.notes.append(f"auto: rays at {int(k)} per corner, not the "
                          f"{plan.settings.samples} asked (auto's choice on the calibration sample)")
        plan.settings = dataclasses.replace(plan.settings, samples=int(k))


def choose(plan: Plan, items, proxyless_auto: bool) -> None:
    """Set plan.method and plan.tau for the requested method: calibrated when "auto" or τ is
    not given and a tracer exists, else the requested rung (or "ellipsoid" for "auto").
    proxyless_auto: "auto" on a scene with no tree of its own but grass or instanced trees
    (bake.prepare): their laws are weighed against rays on the same sample."""
    settings = plan.settings
    asked = rungs.get(settings.method)
    analytic = asked.takes_tau
    fallback = auto.FALLBACK if asked.chooses else settings.method
    plan.method = settings.method
    if analytic and plan.fits:
        candidates = ([r.name for r in rungs.ladder() if r.climbs is not None and r.climbs(plan)]
                      if asked.chooses else [settings.method])
        if plan.tracer is not None and (asked.chooses or settings.tau is None):
            plan.method, tau, plan.calibration = calibrate(plan, items, candidates,
                                                           settings.tau)
            plan.tau, plan.tau_by_tree = _scene_tau(tau), _tree_taus(tau)
        else:
            plan.method = fallback
            if settings.tau is None:
                plan.notes.append(f"tau not calibrated; using the default {DEFAULT_TAU}")
    elif analytic:
        plan.method = fallback
        if plan.forest is None:  # all its trees may be instances: then it is no news
            plan.notes.append("no CANOPY object: no proxies fitted")
        if proxyless_auto and plan.tracer is not None and not settings.ray_free:
            # The grass law (Hegeman Eq. 9) and the instances' shells against the exact rung
            # (whose tracer holds the instances), on the same sample.
            exact = rungs.exact().name
            plan.method, plan.tau, plan.calibration = calibrate(
                plan, items, [auto.FALLBACK, exact], DEFAULT_TAU)
    _bake_samples(plan)
