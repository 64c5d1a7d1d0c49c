"""The ground under an instanced forest, every rung against rays that trace the instances.

    blender -b --factory-startup --python bench/forest_ground.py -- \
        [--trees 50] [--ground-vertices 10000] [--side 50] [--samples 256]

(with the add-on installed, or BLENDER_USER_SCRIPTS pointing at a folder whose addons/ links
addon/canopy_ao, as in the README). The scene is examples/forest_scene.py's (two prototype trees
scattered by hair particles over a ground grid, AO distance unlimited). The reference is the
exact rung at --samples rays per face corner, whose rays hit every instance's triangles; each
rung then bakes the ground as a user's bake does (run_bake, τ calibrated: the default), and the
script prints its MAE and bias against that reference, its τ factor for the forest
(core/forest_tau.py, docs/DESIGN.md 'How each role is lit') and its seconds. Exits non-zero on
failure.
"""
from __future__ import annotations

import os
import sys
import time

import bpy
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # Blender does not add it
import harness  # noqa: E402  (addon/ and examples/ on sys.path)

import forest_scene as fs  # noqa: E402

RUNGS = ["sphere", "ellipsoid", "shells", "medium", "grid", "regression", "auto"]


def main(argv):
    ap = harness.parser(__doc__, prog="forest_ground.py")
    ap.add_argument("--trees", type=int, default=50)
    ap.add_argument("--ground-vertices", type=float, default=1e4)
    ap.add_argument("--side", type=float, default=50.0)
    ap.add_argument("--samples", type=int, default=256)
    args = ap.parse_args(argv)
    harness.enable_addon()
    from canopy_ao.blender import mesh_io, properties
    from canopy_ao.blender.job import run_bake

    g = fs.build(args.trees, args.ground_vertices, args.side)

    def bake(method, samples=64):
        opts = properties.scene_options(bpy.context.scene)
        opts.update(method=method, tau=None, distance=0.0, samples=samples, show_proxies=False,
                    overwrite=True)
        t0 = time.perf_counter()
        _job, rep = run_bake(bpy.context, ["Ground"], opts)
        return mesh_io.read_ao_attribute(g, opts["attribute"]), rep, time.perf_counter() - t0

    ref, _rep, dt = bake("raytrace", args.samples)
    print(f"forest_ground: {args.trees} trees on {args.side:g} m, {len(ref)} ground vertices; "
          f"reference: rays {args.samples} ({dt:.1f} s), mean AO {ref.mean():.3f}")
    print(f"{'method':12s} {'MAE':>7s} {'bias':>7s} {'forest τ ×':>10s} {'seconds':>8s}  chose")
    for m in RUNGS:
        ao, rep, dt = bake(m)
        fit = (rep.get("calibration") or {}).get("forest") or {}
        scale = f"{fit['tau_scale']:.3g}" if fit else "-"
        print(f"{m:12s} {np.abs(ao - ref).mean():7.4f} {(ao - ref).mean():+7.4f} {scale:>10s} "
              f"{dt:8.2f}  {rep['method']}", flush=True)


if __name__ == "__main__":
    fs.run(main)
