"""Per-frame cost of live AO on an animated tree, and the frame rate it allows (bench/README.md).

    blender -b --factory-startup --python bench/live_speed.py -- \
        [--vertices 100000 1000000] [--methods sphere ellipsoid shells medium] [--frames 6]

Builds a crown of leaf quads (bench/blender_bake_speed.py's leaf mesh) swaying in the wind (a
Simple Deform bend whose angle is keyed over the frames) above a ground plane, starts live AO
with each rung and a given τ, then steps the frames with scene.frame_set, as playback and an
animation render do. Prints per rung and size, as the median over the frames:

- live: the handler's own work per frame (read the evaluated meshes, refit, evaluate, write
  the attribute), split into those stages;
- frame: the whole frame_set with live AO on (Blender's deform, our handler, and the second
  evaluation the attribute write causes), and the frame rate it allows;
- blender only: the same frame_set with live AO off (the deform alone).

The machine is shared: the load average is printed with the numbers.
"""

import os
import statistics
import sys
import time

import bpy

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # Blender does not add it
import harness  # noqa: E402  (addon/ and examples/ on sys.path)
from blender_bake_speed import leaf_mesh  # noqa: E402


def animated_tree(n_vertices):
    """Leaves (CANOPY, tree "Tree") bent by a keyed Simple Deform, and a Ground plane."""
    for ob in list(bpy.data.objects):
        bpy.data.objects.remove(ob, do_unlink=True)
    scene = bpy.context.scene
    leaves = leaf_mesh("Leaves", n_vertices)
    leaves.canopy_ao.role, leaves.canopy_ao.tree = 'CANOPY', "Tree"
    wind = leaves.modifiers.new("Wind", 'SIMPLE_DEFORM')
    wind.deform_method, wind.deform_axis = 'BEND', 'Y'
    for frame, angle in ((1, 0.0), (25, 0.35), (50, -0.35)):
        wind.angle = angle
        wind.keyframe_insert("angle", frame=frame)
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=100, y_subdivisions=100, size=30)
    ground = bpy.context.object
    ground.name = "Ground"
    ground.canopy_ao.role = 'GROUND'
    scene.frame_set(1)
    return scene, [leaves.name, ground.name]


def _median(xs):
    return statistics.median(xs) if xs else float("nan")


def run(n_vertices, method, frames):
    from canopy_ao.blender import job, live, properties
    scene, names = animated_tree(n_vertices)
    opts = dict(properties.scene_options(scene), method=method, tau=1.5, distance=0.0,
                show_proxies=False, live=True)
    t0 = time.perf_counter()
    job.run_bake(bpy.context, names, opts)
    first = time.perf_counter() - t0
    session = live.session_of(scene)
    stages, totals = {}, []
    for f in range(2, 2 + frames):
        t0 = time.perf_counter()
        scene.frame_set(f)
        totals.append(time.perf_counter() - t0)
        for k, v in session.timings.items():
            stages.setdefault(k, []).append(v)
    assert session.frames == frames, "the handler did not run on every frame"
    live.stop(scene)
    blender_only = []
    for f in range(2 + frames, 2 + 2 * frames):
        t0 = time.perf_counter()
        scene.frame_set(f)
        blender_only.append(time.perf_counter() - t0)
    ms = {k: 1000.0 * _median(v) for k, v in stages.items()}
    frame_ms = 1000.0 * _median(totals)
    print(f"{n_vertices:>9,} vertices  {method:<9}  live {ms['total']:7.1f} ms "
          f"(read {ms['read']:.1f}, fit {ms['fit']:.1f}, evaluate {ms['evaluate']:.1f}, "
          f"write {ms['write']:.1f})  frame {frame_ms:7.1f} ms = {1000.0 / frame_ms:5.1f} fps  "
          f"blender only {1000.0 * _median(blender_only):6.1f} ms  (first bake {first:.2f} s)",
          flush=True)


def main(argv):
    ap = harness.parser(__doc__, prog="live_speed.py")
    ap.add_argument("--vertices", type=int, nargs="+", default=[100_000, 1_000_000])
    ap.add_argument("--methods", nargs="+", default=["sphere", "ellipsoid", "shells", "medium"])
    ap.add_argument("--frames", type=int, default=6)
    a = ap.parse_args(argv)
    harness.enable_addon()
    print(f"live AO per frame, median of {a.frames} frames; {harness.load_note()}; "
          f"Blender {bpy.app.version_string}")
    for n in a.vertices:
        for m in a.methods:
            run(n, m, a.frames)


if __name__ == "__main__":
    try:
        main(harness.blender_args())
    except Exception as exc:  # noqa: BLE001
        import traceback
        traceback.print_exc()
        print(f"live_speed: error: {exc}", file=sys.stderr)
        sys.stdout.flush()
        os._exit(1)
    sys.stdout.flush()
    os._exit(0)  # no teardown: the live session's handlers stay registered
