"""Where the seconds of a forest's ground bake go, stage by stage (issue #39 item 5).

    blender -b --factory-startup --python-exit-code 1 --python bench/forest_stages.py -- \
        [--trees 200] [--ground-vertices 10000] [--side 50] [--methods auto sphere shells] \
        [--samples 64] [--reference 256] [--bakes ground everything]

(with the add-on installed, or BLENDER_USER_SCRIPTS pointing at a folder whose addons/ links
addon/canopy_ao, as in the README). The scene is examples/forest_scene.py's, as
bench/forest_ground.py bakes it (the ground alone, τ calibrated, AO distance unlimited). Per
method: the bake's wall and CPU seconds (every thread: steadier on a shared machine), its
stages (BakeJob.timings: "instances" is the prototypes' own bake, "evaluate" the ground's), the
plan's (forest_tau: the forest's τ fit) and the native core's (the rays' tracing and sampling as
the CPU seconds their threads ran: native stage_clock.h). With --reference N (0: none), the
ground is first baked with rays at N samples and each method's MAE against it is printed
(deterministic: the rays are seeded per receiver). "prototypes written" counts the prototype
meshes the bake wrote its attribute into. --bakes: "ground" bakes the Ground alone (as
`--objects Ground`: the prototypes are fitted and occlude, their own AO is not baked),
"everything" bakes with no names and nothing selected (as `--all`: the Ground, and each
prototype's own AO). Exits non-zero on failure.

Measured with 200 trees on 50 m, 10,000 ground vertices (load 4-7): auto chose the exact rung;
the Ground alone took 3.9-4.3 CPU s, nearly all the ground's rays through the instances
(3.4-4.0), the bake of everything 6.9 (the prototypes' own bake on top); the ground's AO is the
same in both (MAE 0.01198 against rays at 256). Sphere 1.0 and shells 1.2 CPU s (the bake of
everything), each mostly the forest's τ fit. Tracing a flattened copy of the instances (3.6M
triangles in one BVH) took 5.4 CPU s against 3.8 for Embree's instances, and neither Embree's
HIGH build quality nor a non-ROBUST build of the prototypes changed the tracing's CPU seconds
(5.87 / 6.13 / 6.08).
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

import forest_scene as fs  # noqa: E402


def main(argv):
    ap = argparse.ArgumentParser(prog="forest_stages.py")
    ap.add_argument("--trees", type=int, default=200)
    ap.add_argument("--ground-vertices", type=float, default=1e4)
    ap.add_argument("--side", type=float, default=50.0)
    ap.add_argument("--methods", nargs="+", default=["auto", "sphere", "shells"])
    ap.add_argument("--samples", type=int, default=64)
    ap.add_argument("--reference", type=int, default=0)
    ap.add_argument("--bakes", nargs="+", choices=["ground", "everything"], default=["ground"])
    args = ap.parse_args(argv)
    import addon_utils
    if addon_utils.enable("canopy_ao", default_set=True) is None:
        raise SystemExit("the canopy_ao add-on could not be enabled")
    from canopy_ao.blender import mesh_io, properties
    from canopy_ao.blender.job import run_bake
    from canopy_ao.core.native import require

    g = fs.build(args.trees, args.ground_vertices, args.side)
    core = require()
    previous = core.set_stage_profiling(True)
    def options(method, samples):
        opts = properties.scene_options(bpy.context.scene)
        opts.update(method=method, tau=None, distance=0.0, samples=samples,
                    show_proxies=False, overwrite=True)
        return opts

    protos = [o for c in ("RoundTree", "Conifer")  # forest_scene.build's prototypes
              for o in bpy.data.collections[c].objects]
    try:
        print(f"forest_stages: {args.trees} trees on {args.side:g} m, "
              f"{len(g.data.vertices)} ground vertices, load {os.getloadavg()[0]:.1f}")
        ref = None
        if args.reference:
            opts = options("raytrace", args.reference)
            run_bake(bpy.context, ["Ground"], opts)
            ref = mesh_io.read_ao_attribute(g, opts["attribute"])
            print(f"reference: rays at {args.reference} samples, mean AO {ref.mean():.4f}")
        for m, bake in ((m, b) for m in args.methods for b in args.bakes):
            opts = options(m, args.samples)
            for o in bpy.context.view_layer.objects:
                o.select_set(False)
            for o in protos:  # what this bake writes, not an earlier one
                if opts["attribute"] in o.data.attributes:
                    o.data.attributes.remove(o.data.attributes[opts["attribute"]])
            core.take_stage_seconds()
            t0, c0 = time.perf_counter(), time.process_time()
            _job, rep = run_bake(bpy.context, ["Ground"] if bake == "ground" else [], opts)
            wall, cpu = time.perf_counter() - t0, time.process_time() - c0
            native = core.take_stage_seconds()
            ao = mesh_io.read_ao_attribute(g, opts["attribute"])
            mae = f", MAE {np.abs(ao - ref).mean():.5f}" if ref is not None else ""
            written = sum(opts["attribute"] in o.data.attributes for o in protos)
            print(f"\n{m} ({bake}) -> {rep['method']}: {wall:.2f} s wall, {cpu:.2f} CPU s, "
                  f"ground mean AO {ao.mean():.4f}{mae}, prototypes written {written} of "
                  f"{len(protos)}")
            for title, table in (("bake", rep["stage_seconds"]), ("plan", rep["timings"]),
                                 ("native", {k: v[0] for k, v in native.items()})):
                for k, v in table.items():
                    if v >= 0.001:
                        print(f"  {title + ': ' + k:<44} {v:8.3f}")
    finally:
        core.set_stage_profiling(previous)


if __name__ == "__main__":
    fs.run(main)
