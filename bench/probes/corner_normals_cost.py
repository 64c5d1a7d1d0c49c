"""Probe, answered: reading a target's corner normals costs a smooth mesh one look at its faces' shading (docs/DESIGN.md, 'Rays against Cycles' samples', "Cycles' bake point").

What `mesh_io.evaluated_arrays(corners=...)` adds to a mesh read: on a smooth UV sphere (every
corner normal its vertex's, so none is read: `corner_io.may_differ`) and on the same sphere
flat-shaded (every corner read, transformed and compared).

    blender -b --factory-startup --python bench/probes/corner_normals_cost.py -- [--faces 100000]

The add-on is found as in scripts/test.sh (BLENDER_USER_SCRIPTS with addons/canopy_ao) or,
without it, from this repository's addon/. The median of 9 rounds, each timing the read
without and with corners in turn. The machine is shared: the load average is printed with
the numbers.
"""

import os
import statistics
import sys
import time

import bpy

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # bench/
import harness  # noqa: E402  (addon/ and examples/ on sys.path)


def main(argv):
    faces = int(argv[argv.index("--faces") + 1]) if "--faces" in argv else 100_000
    harness.enable_addon()
    from canopy_ao.blender import mesh_io
    for ob in list(bpy.data.objects):
        bpy.data.objects.remove(ob)
    rings = max(3, int((faces / 1.6) ** 0.5))
    bpy.ops.mesh.primitive_uv_sphere_add(segments=int(1.6 * rings), ring_count=rings)
    sphere = bpy.context.object
    for smooth in (True, False):
        for p in sphere.data.polygons:
            p.use_smooth = smooth
        dg = bpy.context.evaluated_depsgraph_get()
        rounds = {"without": [], "with": []}
        for _ in range(9):
            for key, kw in (("without", {}), ("with", {"corners": []})):
                t0 = time.perf_counter()
                mesh_io.evaluated_arrays(sphere, dg, polygons=[], **kw)
                rounds[key].append(time.perf_counter() - t0)
        off, on = (statistics.median(rounds[k]) * 1e3 for k in ("without", "with"))
        print(f"{'smooth' if smooth else 'flat'} {len(sphere.data.polygons)} faces: read "
              f"{off:.2f} ms, with corner normals {on:.2f} ms (+{on - off:.2f})")
    print(f"load average {os.getloadavg()[0]:.2f}, Blender {bpy.app.version_string}")


if __name__ == "__main__":
    harness.run_and_exit(main, "corner_normals_cost")
