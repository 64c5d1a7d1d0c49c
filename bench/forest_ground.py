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

import argparse
import os
import sys
import time

import bpy
import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(REPO, "examples"))

import canopy_scenes as cs  # noqa: E402
import forest_scene as fs  # noqa: E402

RUNGS = ["sphere", "ellipsoid", "shells", "medium", "grid", "regression", "auto"]


def build(trees, ground_vertices, side):
    """examples/forest_scene.py's scene: (ground object)."""
    for ob in list(bpy.data.objects):
        bpy.data.objects.remove(ob, do_unlink=True)
    protos = [fs.prototype(cs.round_tree(seed=1, leaves=8000, ground=False), "RoundTree"),
              fs.prototype(cs.conifer(seed=2, leaves=8000, ground=False), "Conifer")]
    g = fs.ground(ground_vertices, side)
    s = side / 2
    emitter = bpy.data.objects.new("Emitter", fs.mesh_from_arrays(
        "Emitter", np.float32([[-s, -s, 0], [s, -s, 0], [s, s, 0], [-s, s, 0]]),
        np.int32([[0, 1, 2], [0, 2, 3]])))
    emitter.canopy_ao.role = 'IGNORE'
    emitter.show_instancer_for_render = emitter.show_instancer_for_viewport = False
    bpy.context.scene.collection.objects.link(emitter)
    half = trees // 2
    fs.scatter(emitter, protos[0], trees - half, 1)
    fs.scatter(emitter, protos[1], half, 2)
    bpy.context.view_layer.update()
    return g


def main(argv):
    ap = argparse.ArgumentParser(prog="forest_ground.py")
    ap.add_argument("--trees", type=int, default=50)
    ap.add_argument("--ground-vertices", type=float, default=1e4)
    ap.add_argument("--side", type=float, default=50.0)
    ap.add_argument("--samples", type=int, default=256)
    args = ap.parse_args(argv)
    import addon_utils
    if addon_utils.enable("canopy_ao", default_set=True) is None:
        raise SystemExit("the canopy_ao add-on could not be enabled")
    from canopy_ao.blender import mesh_io, properties
    from canopy_ao.blender.job import run_bake

    g = build(args.trees, args.ground_vertices, args.side)

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
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    try:
        main(argv)
    except SystemExit as e:
        if e.code not in (None, 0):
            print(e.code if isinstance(e.code, str) else f"exit {e.code}", file=sys.stderr)
            sys.exit(1)
    except Exception:
        import traceback
        traceback.print_exc()
        sys.exit(1)
