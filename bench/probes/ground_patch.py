"""Probe, answered: every GROUND plane a patch in static bakes (core/walls.py, docs/DESIGN.md's walls bullet): it lowers every proxy rung's error on the real trees.

What the ground's own patch does to each rung of a static bake on the real-generator scenes:

    /usr/bin/python3 bench/probes/ground_patch.py [--scenes sap_callistemon ...] [--rungs sphere grid ...]
    /usr/bin/python3 bench/probes/ground_patch.py --trunk-scale [--scenes ...] [--rungs ...]

Per scene and rung, baked twice, the GROUND planes as patches only where a wall is (live AO's
rule: the patches kept where walls.has_wall) and every GROUND plane a patch (a bake's): MAE over all
vertices / with buried ones left out (bench/real_scenes.buried) against the highest-sample
Cycles bake cached beside the scene (else Embree at 1024 rays), per role too, and the whole
bake's seconds (one run each: compare within a row). auto and regression calibrate against rays
with the patches in place (τ, the regression's fit), so they absorb part of the difference.

--trunk-scale: instead, every ground a patch, each rung's τ calibrated with the trunk's points
in the leaves' fit ("leaves") and with a factor of their own (scene.SCALED_ROLES, "own").
"""
from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # bench/
import harness  # noqa: E402  (addon/, examples/ and bench/ on sys.path)

import numpy as np  # noqa: E402

import real_scenes as rs  # noqa: E402
from canopy_ao import core  # noqa: E402
from canopy_ao.core import ladder, walls  # noqa: E402

RUNGS = ("sphere", "ellipsoid", "shells", "medium", "reeves_blau", "grid", "regression",
         "hybrid", "auto")
SCENES = ("sap_callistemon", "sap_white_birch", "sap_small_maple", "sap_quaking_aspen")


def bake(items, method, distance, every_ground, trunk_scale=True):
    """(AO over all vertices, seconds, τ) of one static bake, GROUND patches as asked, the
    trunk's τ factor its own or the leaves'."""
    build, scaled = walls.build, ladder.SCALED_ROLES
    if not every_ground:  # a live frame's rule: patches only where a wall is
        walls.build = lambda its: (lambda pt: pt if walls.has_wall(pt) else [])(build(its))
    if not trunk_scale:
        ladder.SCALED_ROLES = tuple(r for r in scaled if "TRUNK" not in r)
    try:
        (res, rep), dt = harness.timed(lambda: core.bake(items, core.BakeSettings(
            method=method, distance=distance)))
    finally:
        walls.build, ladder.SCALED_ROLES = build, scaled
    return np.concatenate([r.ao for r in res]), dt, rep.get("tau", float("nan"))


def run_scene(name, rungs, trunk_scale=False):
    sc = rs.load(name)
    cyc = rs.cycles_runs(sc)
    ref = cyc[max(cyc)][0] if cyc else rs.reference(sc)[0]
    keep = ~rs.buried(sc)
    items = sc.engine_items()
    core.bake(items, core.BakeSettings(method="medium", distance=sc.distance))  # warm up
    print(f"\n== {name}: {sc.n_vertices} vertices, reference "
          f"{'cycles %d' % max(cyc) if cyc else 'embree 1024'}, buried {(~keep).sum()}")
    roles = sorted(set(sc.role))
    print(f"{'rung':12s} {'trunk τ' if trunk_scale else 'patches':8s} {'MAE all':>8s} {'unburied':>8s} " +
          " ".join(f"{r[:7]:>7s}" for r in roles) + f" {'seconds':>8s} {'tau':>6s}")
    print(f"{'constant':12s} {'':8s} {np.abs(np.median(ref[keep]) - ref).mean():8.3f} "
          f"{np.abs(np.median(ref[keep]) - ref[keep]).mean():8.3f}")
    for m in rungs:
        for every in (False, True):
            ao, dt, tau = bake(items, m, sc.distance, True, every) if trunk_scale else \
                bake(items, m, sc.distance, every)
            err = np.abs(ao - ref)
            per = " ".join(f"{err[(sc.role == r) & keep].mean():7.3f}" for r in roles)
            label = ("own" if every else "leaves") if trunk_scale else (
                "every" if every else "walls")
            print(f"{m:12s} {label:8s} {err.mean():8.3f} "
                  f"{err[keep].mean():8.3f} {per} {dt:8.2f} {float(tau):6.3f}", flush=True)


def main(argv=None):
    ap = harness.parser(__doc__, prog="ground_patch.py")
    ap.add_argument("--scenes", nargs="+", default=list(SCENES))
    ap.add_argument("--rungs", nargs="+", default=list(RUNGS))
    ap.add_argument("--trunk-scale", action="store_true",
                    help="compare the trunk's own τ factor with the leaves' (every ground a patch)")
    a = ap.parse_args(argv)
    print(f"load: {harness.load_note()}")
    for s in a.scenes:
        run_scene(s, a.rungs, a.trunk_scale)
    return 0


if __name__ == "__main__":
    sys.exit(main())
