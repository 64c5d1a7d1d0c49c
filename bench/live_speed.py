"""Per-frame cost of live AO on an animated tree, and the frame rate it allows (bench/README.md).

    blender -b --factory-startup --python bench/live_speed.py -- \
        [--vertices 100000 1000000] [--methods sphere ellipsoid shells medium regression]
        [--trees crown sapling] [--frames 6] [--accuracy] [--cpu]

Builds a tree swaying in the wind (a Simple Deform bend whose angle is keyed over the frames)
above a ground plane, starts live AO with each rung and a given τ, then steps the frames with
scene.frame_set, as playback and an animation render do. The trees (--trees):
- crown: a crown of leaf quads (bench/blender_bake_speed.py's leaf mesh) alone;
- sapling: a Sapling Tree Gen quaking aspen (examples/sapling_scenes.py's sapling_tree, seed 1),
  its branches as the TRUNK mesh and its leaves as the CANOPY one, the leaf count scaled so the
  two hold the given vertices; one bend about the trunk's base, over the heights both span,
  sways both alike.
Prints per tree, rung and size, as the median over the frames:

- live: the handler's own work per frame (read the evaluated meshes, refit, evaluate, write
  the attribute), split into those stages;
- frame: the whole frame_set with live AO on (Blender's deform, our handler, and the second
  evaluation the attribute write causes), and the frame rate it allows;
- blender only: the same frame_set with live AO off (the deform alone);
- with/without: the whole frame with live AO over the frame without (issue #39 asks ≤ 2).
  Headless, nothing draws, so Blender's own frame computes no vertex normals; live AO reads
  them (a viewport's draw computes the same ones, which live AO then shares).
With --cpu, also the CPU seconds per frame (process time, every thread summed: what a shared
machine's load does not inflate as it does the wall clock): the refit alone (the fit stage),
the whole frame with live AO and without, and their difference, live AO's own.
With --accuracy, also the mean absolute error at the last frame of live AO and of a static
bake of the same rung at that frame (and of one with the next seed, whose difference is the
calibration's own noise), each against a ray-traced bake of that frame.

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


def _wind(obj, origin):
    """A Simple Deform bend of obj about ``origin`` whose angle sways over frames 1-50."""
    wind = obj.modifiers.new("Wind", 'SIMPLE_DEFORM')
    wind.deform_method, wind.deform_axis, wind.origin = 'BEND', 'Y', origin
    for frame, angle in ((1, 0.0), (25, 0.35), (50, -0.35)):
        wind.angle = angle
        wind.keyframe_insert("angle", frame=frame)


def _same_bend(*objs):
    """Bend every obj along the same stretch of height: a Simple Deform bend spreads its angle
    over its limits, fractions of each object's own height, so branches and leaves of unequal
    heights would bend unequally and the leaves leave their twigs (0.31 on average at frame 25
    against a 0.07 leaf-to-twig gap); the heights all objects share, from each one's own."""
    import numpy as np
    spans = []
    for ob in objs:
        z = np.empty(len(ob.data.vertices) * 3, np.float32)
        ob.data.vertices.foreach_get("co", z)
        spans.append((float(z[2::3].min()), float(z[2::3].max())))
    lo, hi = max(a for a, _b in spans), min(b for _a, b in spans)
    for ob, (a, b) in zip(objs, spans):
        ob.modifiers["Wind"].limits = ((lo - a) / (b - a), (hi - a) / (b - a))


def sapling_tree(n_vertices, preset="quaking_aspen"):
    """A Sapling tree (branches TRUNK, leaves CANOPY, tree "Tree") of about n_vertices, swayed
    by one keyed bend about its base (_same_bend), and a Ground plane under it."""
    import addon_utils
    from sapling_scenes import sapling_tree as make
    for ob in list(bpy.data.objects):
        bpy.data.objects.remove(ob, do_unlink=True)
    addon_utils.enable("add_curve_sapling", default_set=False)
    scene = bpy.context.scene
    col = scene.collection
    b, l = make(preset, 1, (0, 0), "probe", 1.0, col)  # leaves per unit of leaf factor
    per_factor, trunk = len(l.data.vertices), len(b.data.vertices)
    for ob in (b, l):
        bpy.data.objects.remove(ob, do_unlink=True)
    factor = max(1.0, (n_vertices - trunk) / per_factor)
    branches, leaves = make(preset, 1, (0, 0), "Tree", factor, col)
    base = bpy.data.objects.new("Tree base", None)
    col.objects.link(base)
    for ob, role in ((branches, 'TRUNK'), (leaves, 'CANOPY')):
        ob.canopy_ao.role, ob.canopy_ao.tree = role, "Tree"
        _wind(ob, base)
    _same_bend(branches, leaves)
    size = 4.0 * max(leaves.dimensions.x, leaves.dimensions.y, 1.0)
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=100, y_subdivisions=100, size=size)
    ground = bpy.context.object
    ground.name = "Ground"
    ground.canopy_ao.role = 'GROUND'
    scene.frame_set(1)
    return scene, [branches.name, leaves.name, ground.name]


TREES = {"crown": animated_tree, "sapling": sapling_tree}


def _median(xs):
    return statistics.median(xs) if xs else float("nan")


def _accuracy(scene, names, opts, frame, live_ao):
    """(MAE of live AO at ``frame``, of a static bake of the same rung there, of that bake with
    another seed: how far two calibrations of one frame differ), each against that frame's
    rays, over every vertex of the targets (live_ao: {name: AO})."""
    import numpy as np
    from canopy_ao.blender import job, mesh_io
    scene.frame_set(frame)

    def bake(**kw):
        job.run_bake(bpy.context, names, dict(opts, live=False, overwrite=True, **kw))
        return np.concatenate([mesh_io.read_ao_attribute(scene.objects[n], kw["attribute"])
                               for n in names])
    rays = bake(method="raytrace", attribute="Rays")
    static = bake(attribute="Static")
    reseeded = bake(attribute="Static", seed=opts["seed"] + 1)
    live_all = np.concatenate([live_ao[n] for n in names])
    return tuple(float(np.abs(x - rays).mean()) for x in (live_all, static, reseeded))


def _cpu_of_refit():
    """(undo, seconds): core.live.refit made to add its process CPU seconds to seconds[0]."""
    from canopy_ao.core import live as core_live
    refit, seconds = core_live.refit, [0.0]

    def timed(*args, **kwargs):
        t0 = time.process_time()
        try:
            return refit(*args, **kwargs)
        finally:
            seconds[0] += time.process_time() - t0
    core_live.refit = timed

    def undo():
        core_live.refit = refit
    return undo, seconds


def run(n_vertices, method, frames, tree="crown", accuracy=False, cpu=False):
    from canopy_ao.blender import job, live, properties
    scene, names = TREES[tree](n_vertices)
    n_vertices = sum(len(scene.objects[n].data.vertices) for n in names[:-1])  # the tree's
    opts = dict(properties.scene_options(scene), method=method, tau=1.5, distance=0.0,
                show_proxies=False, live=True)
    t0 = time.perf_counter()
    job.run_bake(bpy.context, names, opts)
    first = time.perf_counter() - t0
    session = live.session_of(scene)
    stages, totals = {}, []
    undo, fit_cpu = _cpu_of_refit()
    c0 = time.process_time()
    for f in range(2, 2 + frames):
        t0 = time.perf_counter()
        scene.frame_set(f)
        totals.append(time.perf_counter() - t0)
        for k, v in session.timings.items():
            stages.setdefault(k, []).append(v)
    live_cpu = (time.process_time() - c0) / frames
    undo()
    assert session.frames == frames, "the handler did not run on every frame"
    live.stop(scene)  # the originals then hold the last frame's AO (Session.flush)
    if accuracy:
        from canopy_ao.blender import mesh_io
        live_ao = {n: mesh_io.read_ao_attribute(scene.objects[n], opts["attribute"])
                   for n in names}
    blender_only = []
    c0 = time.process_time()
    for f in range(2 + frames, 2 + 2 * frames):
        t0 = time.perf_counter()
        scene.frame_set(f)
        blender_only.append(time.perf_counter() - t0)
    alone_cpu = (time.process_time() - c0) / frames
    ms = {k: 1000.0 * _median(v) for k, v in stages.items()}
    frame_ms = 1000.0 * _median(totals)
    alone_ms = 1000.0 * _median(blender_only)
    print(f"{tree:<7} {n_vertices:>9,} vertices  {method:<10}  live {ms['total']:7.1f} ms "
          f"(read {ms['read']:.1f}, fit {ms['fit']:.1f}, evaluate {ms['evaluate']:.1f}, "
          f"write {ms['write']:.1f})  frame {frame_ms:7.1f} ms = {1000.0 / frame_ms:5.1f} fps  "
          f"blender only {alone_ms:6.1f} ms  with/without {frame_ms / alone_ms:5.2f}  "
          f"(first bake {first:.2f} s)", flush=True)
    if cpu:
        print(f"{'':<7} {'':>9}           {method:<10}  CPU per frame: fit "
              f"{1000.0 * fit_cpu[0] / frames:.1f} ms, frame with live {1000.0 * live_cpu:.1f} ms, "
              f"without {1000.0 * alone_cpu:.1f} ms, live's own "
              f"{1000.0 * (live_cpu - alone_cpu):.1f} ms", flush=True)
    if accuracy:
        got, static, reseeded = _accuracy(scene, names, opts, 1 + frames, live_ao)
        print(f"{'':<7} {'':>9}           {method:<10}  MAE against frame {1 + frames}'s rays: "
              f"live {got:.4f}, static bake {static:.4f} (live - static {got - static:+.4f}; "
              f"static with seed {opts['seed'] + 1}: {reseeded:.4f})", flush=True)


def main(argv):
    ap = harness.parser(__doc__, prog="live_speed.py")
    ap.add_argument("--vertices", type=int, nargs="+", default=[100_000, 1_000_000])
    ap.add_argument("--methods", nargs="+",
                    default=["sphere", "ellipsoid", "shells", "medium", "regression"])
    ap.add_argument("--trees", nargs="+", choices=sorted(TREES), default=["crown", "sapling"])
    ap.add_argument("--frames", type=int, default=6)
    ap.add_argument("--accuracy", action="store_true",
                    help="also the live AO's error at the last frame against that frame's "
                         "rays, beside a static bake's of the same rung there")
    ap.add_argument("--cpu", action="store_true",
                    help="also the CPU seconds per frame (every thread summed), which a shared "
                         "machine's load does not inflate")
    a = ap.parse_args(argv)
    harness.enable_addon()
    print(f"live AO per frame, median of {a.frames} frames; {harness.load_note()}; "
          f"Blender {bpy.app.version_string}")
    for tree in a.trees:
        for n in a.vertices:
            for m in a.methods:
                run(n, m, a.frames, tree, a.accuracy, a.cpu)


if __name__ == "__main__":
    harness.run_and_exit(main, "live_speed")
