"""Probe, answered: roles and trees guessed on the Sapling exports, and calibration without buried points and with τ per tree against calibration as it was (the leaf bias).

Roles, trees and calibration on scenes exported from Blender's Sapling Tree Gen.

    /usr/bin/python3 bench/probes/real_trees.py [--dir bench/out/real] [--scenes sap_grove ...]

Reads <dir>/<scene>_quick.npz (names; <name>/positions, normals, triangles, role, tree;
distance) and its 1024-ray reference <scene>_quick_embree_1024.npz (ao: every vertex, in name
order), as examples/sapling_scenes.py writes them. Prints, per scene: each object's given and
guessed role (and why), the trees found when every object is loose in one collection, and the
calibrated ellipsoid's leaf bias against the reference over all leaf vertices and over the
unburied ones (reference AO > 0.02), for calibration as it is (buried points left out, τ per
tree) and as it was (every sample point in the fit, one τ for the scene).
"""
import argparse
import json
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # bench/
import harness  # noqa: E402  (addon/, examples/ and bench/ on sys.path)

import numpy as np  # noqa: E402

from canopy_ao import core  # noqa: E402
from canopy_ao.core import ladder, roles, trees  # noqa: E402

BURIED = 0.02  # reference AO at or below this: a vertex buried inside other geometry


def load(path, source):
    d = np.load(path, allow_pickle=True)
    items = [core.SceneItem(str(n), str(d[f"{n}/role"]).upper(),
                            "Collection" if source == "collection" else str(d[f"{n}/tree"]),
                            d[f"{n}/positions"], d[f"{n}/normals"], d[f"{n}/triangles"],
                            tree_source=source) for n in d["names"]]
    return items, float(d["distance"])


def leaf_bias(items, ref, distance, old):
    """(all, unburied) mean bias of the calibrated ellipsoid on CANOPY vertices."""
    keep_buried, keep_tree = ladder.buried, ladder.tau_per_tree
    if old:  # calibration as it was: every point in the fit, one τ
        ladder.buried = lambda plan, it, p, n: np.zeros(len(p), bool)
        ladder.tau_per_tree = lambda plan, m, tau, err: tau
    try:
        res, rep = core.bake(items, core.BakeSettings(method="ellipsoid", tau=None,
                                                      distance=distance))
    finally:
        ladder.buried, ladder.tau_per_tree = keep_buried, keep_tree
    got = np.concatenate([r.ao for r in res])
    leaf = np.concatenate([np.full(len(r.ao), r.role == "CANOPY") for r in res])
    open_ = leaf & (ref > BURIED)
    start, per = 0, {}
    for r in res:  # unburied bias per leaf object (per tree)
        sl = slice(start, start + len(r.ao))
        start += len(r.ao)
        if r.role == "CANOPY" and open_[sl].any():
            per[r.name] = round(float(np.mean((got[sl] - ref[sl])[open_[sl]])), 3)
    rep["leaf_bias_by_object"] = per
    return float(np.mean(got[leaf] - ref[leaf])), float(np.mean(got[open_] - ref[open_])), rep


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dir", default=harness.REAL)
    ap.add_argument("--scenes", nargs="+", default=["sap_grove", "sap_douglas_fir",
                                                    "sap_small_pine", "sap_quaking_aspen"])
    args = ap.parse_args()
    for name in args.scenes:
        path = os.path.join(args.dir, f"{name}_quick.npz")
        ref_path = os.path.join(args.dir, f"{name}_quick_embree_1024.npz")
        if not (os.path.exists(path) and os.path.exists(ref_path)):
            print(f"{name}: not exported (run examples/sapling_scenes.py), skipped")
            continue
        items, distance = load(path, "set")
        ref = np.asarray(np.load(ref_path)["ao"], np.float32)
        print(f"== {name}: {sum(len(it.positions) for it in items)} vertices, AO distance "
              f"{distance:.3g}")
        for it in items:
            got, why = roles.guess_role(it.positions, it.triangles)
            print(f"  {it.name:28s} given {it.role:6s} guessed {got:6s} ({why})")
        loose, _ = load(path, "collection")
        trees.resolve(loose)
        found = sorted({t for it in loose if it.role in ("CANOPY", "TRUNK")
                        for t in (it.tree_names or (it.tree,))})
        given = sorted({it.tree for it in items if it.role in ("CANOPY", "TRUNK")})
        pairs = {(g.tree, lo.tree) for g, lo in zip(items, loose) if g.role in ("CANOPY", "TRUNK")}
        print(f"  trees, all loose in one collection: {len(found)} found, {len(given)} given; "
              f"objects grouped as given: {len(pairs) == len(given) == len(found)}")
        for old in (True, False):
            b_all, b_open, rep = leaf_bias(items, ref, distance, old)
            cal = rep["calibration"]
            what = "as before (all points, one τ)" if old else "now (buried out, τ per tree)"
            taus = json.dumps({k: round(v, 3) for k, v in rep["tau_by_tree"].items()})
            print(f"  calibrated ellipsoid {what:30s}: leaf bias {b_all:+.3f} all, "
                  f"{b_open:+.3f} unburied; τ {rep['tau']:.3f} {taus}; "
                  f"{cal.get('buried_points_left_out', 0)} sample points left out")
            if len(rep["leaf_bias_by_object"]) > 1:
                print(f"    unburied leaf bias per object: {rep['leaf_bias_by_object']}")


if __name__ == "__main__":
    main()
