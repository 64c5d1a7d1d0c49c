"""Probe, answered: trunk solids fitted to the bole's pieces, and the ray-free rung with the GROUND patches multiplied in, lower the error on the real trees (no scene's MAE over all vertices up by more than 0.0001).

What two changes to how the ground and what stands on it are lit do on the real-generator
scenes, each rung baked both ways in one run:

    /usr/bin/python3 bench/probes/ground_under_trees.py [--scenes sap_quaking_aspen ...] [--rungs sphere regression ...]

- the proxy rungs (sphere, ellipsoid, shells, medium, reeves_blau): "whole", one solid
  ellipsoid fitted to every trunk point outside the crown, against "pieces", the bake's
  (core/proxies.py, bole_solids): the connected pieces with fewer than MIN_BOLE points outside
  left to the crown, one ellipsoid over the rest unless it is larger than theirs together,
  then one per piece;
- regression: "bare", its fit and AO without the GROUND patches, against "patched", fitted as
  g(features) × the patches' visibility and multiplied by it (core/regression.py).

Per scene, rung and way: MAE over all vertices / with buried ones left out
(bench/real_scenes.buried) and the bias (buried left out) per role and over every vertex,
against Embree at 1024 rays (bench/real_scenes.reference, cached beside the export). Scenes:
the exports in bench/out/real (examples/sapling_scenes.py --quick).
"""
from __future__ import annotations

import dataclasses
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # bench/
import harness  # noqa: E402  (addon/, examples/ and bench/ on sys.path)

import numpy as np  # noqa: E402

import real_scenes as rs  # noqa: E402
from canopy_ao import core  # noqa: E402
from canopy_ao.core import proxies, regression  # noqa: E402

RUNGS = ("sphere", "ellipsoid", "shells", "medium", "reeves_blau", "regression")
ROLES = ("trunk", "canopy", "ground", "grass")


def bake(items, method, distance, old):
    """AO over all vertices of one bake; old: the bole as one piece, or the ray-free rung
    without the GROUND patches."""
    bole, ground = proxies.bole, regression.RegressionRung.ground
    if old:  # a trunk without faces is one piece: every point outside the crown
        proxies.bole = lambda plan, it: bole(plan, dataclasses.replace(
            it, triangles=np.zeros((0, 3), np.int32), polygons=None))
        regression.RegressionRung.ground = lambda self, role, p, n, d: np.ones(len(p),
                                                                                np.float32)
    try:
        plan = core.prepare(items, core.BakeSettings(method=method, distance=distance))
        if old and method == "regression":
            plan.walls = []  # nor multiplied in
        return np.concatenate([core.evaluate_item(plan, it).ao for it in items])
    finally:
        proxies.bole, regression.RegressionRung.ground = bole, ground


def run_scene(name, rungs):
    sc = rs.load(name)
    ref = rs.reference(sc)[0]
    keep = ~rs.buried(sc)
    items = sc.engine_items()
    roles = [r for r in ROLES if (sc.role == r).any()] + ["all"]
    print(f"\n== {name}: {sc.n_vertices} vertices, against Embree 1024")
    print("| rung | way | " + " | ".join(f"{r}: MAE all / unburied, bias" for r in roles) + " |")
    print("|---|---|" + "---|" * len(roles))
    for m in rungs:
        for old in (True, False):
            way = ("bare" if old else "patched") if m == "regression" else \
                ("whole" if old else "pieces")
            e = bake(items, m, sc.distance, old) - ref
            cells = []
            for r in roles:
                w = np.ones(len(e), bool) if r == "all" else sc.role == r
                cells.append(f"{np.abs(e[w]).mean():.4f} / {np.abs(e[w & keep]).mean():.4f}, "
                             f"{e[w & keep].mean():+.3f}")
            print(f"| {m} | {way} | " + " | ".join(cells) + " |", flush=True)


def main(argv=None):
    ap = harness.parser(__doc__, prog="ground_under_trees.py")
    ap.add_argument("--scenes", nargs="+", default=harness.real_names(),
                    help="exports in bench/out/real (default: every one there)")
    ap.add_argument("--rungs", nargs="+", default=list(RUNGS))
    a = ap.parse_args(argv)
    for name in a.scenes:
        run_scene(name, a.rungs)
    return 0


if __name__ == "__main__":
    sys.exit(main())
