"""Whole-bake wall time in Blender for a large leaf mesh (bench/README.md).

    blender -b --factory-startup --python bench/blender_bake_speed.py -- \
        [--vertices 1000000] [--method sphere] [--tau 1.5|auto] [--repeats 3] \
        [--scene leaves|large_tree]

The add-on is found through BLENDER_USER_SCRIPTS (addons/canopy_ao) or, failing that, in this
repository's addon/ folder. Builds one leaf mesh (quads, 4 vertices each, smooth shaded, role
set explicitly to Canopy so no guessing is paid) — or, with ``--scene large_tree``, the round
tree of examples/canopy_scenes.py with ~``--vertices`` leaf vertices plus its trunk and ground
(roles set explicitly too) — then:

- times ``bpy.ops.canopy_ao.bake`` end to end: one warm-up, best of ``--repeats``, and beside it
  Blender's floor for the same objects (positions and normals read, one FLOAT_COLOR attribute
  written, the meshes re-evaluated, with bpy alone), and the ratio of the two, in wall time and
  in CPU time (the process's, all threads: steadier when other jobs load the machine);
- prints the bake's own per-stage times: the same bake through ``job.run_bake`` (what the
  operator runs), best of ``--repeats``, whose report returns them (``stage_seconds``);
- times each bpy / numpy / core primitive on its own, including the ones the operator skips
  for this method (loop triangles, role guessing), and one memfile undo push of the scene.

The machine is shared: the load average is printed with the numbers. Exits non-zero (message
on stderr) on failure.
"""

import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # Blender does not add it
import harness  # noqa: E402  (addon/ and examples/ on sys.path)


def leaf_mesh(name, n_vertices, seed=0):
    """A crown of random leaf quads (4 vertices each) in an ellipsoid 5 × 5 × 4 m, as a mesh
    built with vertices.add + foreach_set (from_pydata would take minutes at 1M vertices)."""
    import bpy
    from canopy_scenes import leaf_quads

    rng = np.random.default_rng(seed)
    n_leaves = max(1, n_vertices // 4)
    d = rng.normal(size=(n_leaves, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r = rng.uniform(0.0, 1.0, size=(n_leaves, 1)) ** (1.0 / 3.0)
    anchors = d * r * np.array([2.5, 2.5, 2.0]) + np.array([0.0, 0.0, 4.0])
    facing = d + 0.6 * rng.normal(size=(n_leaves, 3))
    facing /= np.linalg.norm(facing, axis=1, keepdims=True)
    verts, _tris, _uv = leaf_quads(anchors, facing, rng)
    verts = np.ascontiguousarray(verts, dtype=np.float32)

    me = bpy.data.meshes.new(name)
    me.vertices.add(len(verts))
    me.vertices.foreach_set("co", verts.ravel())
    me.loops.add(4 * n_leaves)
    me.loops.foreach_set("vertex_index", np.arange(4 * n_leaves, dtype=np.int32))
    me.polygons.add(n_leaves)
    me.polygons.foreach_set("loop_start", np.arange(0, 4 * n_leaves, 4, dtype=np.int32))
    try:  # writable in 3.x; derived from loop_start in 4.x
        me.polygons.foreach_set("loop_total", np.full(n_leaves, 4, dtype=np.int32))
    except (AttributeError, TypeError, RuntimeError):
        pass
    me.polygons.foreach_set("use_smooth", np.ones(n_leaves, dtype=bool))
    me.update(calc_edges=True)
    ob = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(ob)
    return ob


def _best(fn, repeats):
    return _best_wall_cpu(fn, repeats)[0]


def _best_wall_cpu(fn, repeats):
    """(best wall seconds, best CPU seconds of this process, all threads) of ``repeats`` runs.
    On a loaded machine the CPU time is the steadier of the two: what the work costs, not how
    long it waited for a core."""
    wall, cpu = [], []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return min(wall), min(cpu)


def blender_floor(objects, repeats):
    """Best of ``repeats`` seconds for what any per-vertex bake must do in Blender, with bpy
    alone: read each object's positions and normals (float32), write one FLOAT_COLOR POINT
    attribute, and let Blender re-evaluate the edited meshes. The bake's floor."""
    import bpy
    bufs = []
    for ob in objects:
        me = ob.data
        n = len(me.vertices)
        attr = me.color_attributes.get("CanopyAO_floor") or me.color_attributes.new(
            "CanopyAO_floor", 'FLOAT_COLOR', 'POINT')
        bufs.append((me, attr.name, np.empty(n * 3, np.float32), np.empty(n * 3, np.float32),
                     np.ones(n * 4, np.float32)))

    def run():
        for me, name, co, nor, rgba in bufs:
            me.vertices.foreach_get("co", co)
            if hasattr(me, "vertex_normals"):
                me.vertex_normals.foreach_get("vector", nor)
            else:
                me.vertices.foreach_get("normal", nor)
            me.attributes[name].data.foreach_set("color", rgba)
            me.update_tag()
        bpy.context.view_layer.update()
    best = _best_wall_cpu(run, repeats)
    for me, name, *_ in bufs:
        me.attributes.remove(me.attributes[name])
    return best


def primitives(ob, method, tau, repeats):
    """Each stage on its own, best of ``repeats``: {stage: seconds}."""
    import bpy
    from canopy_ao import core
    from canopy_ao.core import roles
    from canopy_ao.blender import mesh_io

    out = {}
    dg = bpy.context.evaluated_depsgraph_get()
    me = ob.data
    n = len(me.vertices)
    out["evaluated object (depsgraph, no copy)"] = _best(
        lambda: ob.evaluated_get(bpy.context.evaluated_depsgraph_get()).data, repeats)

    def copy():
        oe = ob.evaluated_get(dg)
        oe.to_mesh()
        oe.to_mesh_clear()
    out["evaluated mesh copy (to_mesh)"] = _best(copy, repeats)
    co = np.empty(n * 3, np.float32)
    out["positions foreach_get (float32)"] = _best(lambda: me.vertices.foreach_get("co", co),
                                                   repeats)
    co64 = np.empty(n * 3, np.float64)
    out["positions foreach_get (float64)"] = _best(lambda: me.vertices.foreach_get("co", co64),
                                                   1)
    nor = np.empty(n * 3, np.float32)
    if hasattr(me, "vertex_normals"):
        out["normals vertex_normals 'vector'"] = _best(
            lambda: me.vertex_normals.foreach_get("vector", nor), repeats)
    out["normals vertices 'normal'"] = _best(lambda: me.vertices.foreach_get("normal", nor),
                                             repeats)

    def tris():
        me.calc_loop_triangles()
        t = np.empty(len(me.loop_triangles) * 3, np.int32)
        me.loop_triangles.foreach_get("vertices", t)
        return t
    out["triangles (calc_loop_triangles + get)"] = _best(tris, 1)
    t = tris().reshape(-1, 3)
    p = co.reshape(-1, 3)
    nv = nor.reshape(-1, 3)
    out["role guessing (not paid: role set)"] = _best(lambda: roles.guess_role(p, t), 1)
    s = core.BakeSettings(method=method, tau=tau)
    item = core.SceneItem(ob.name, "CANOPY", "Tree", p, nv, np.zeros((0, 3), np.int32))
    plan = None

    def prep():
        nonlocal plan
        plan = core.prepare([item], s)
    out["fit (core.prepare)"] = _best(prep, repeats)
    out["evaluate (core.evaluate_item)"] = _best(lambda: core.evaluate_item(plan, item),
                                                   repeats)
    ao = core.evaluate_item(plan, item).ao
    name = "CanopyAO_bench"
    out["attribute write (FLOAT_COLOR, float32)"] = _best(
        lambda: mesh_io.write_ao_attribute(ob, name, ao), repeats)
    attr = me.attributes[name]
    rgba64 = np.ones(n * 4, np.float64)
    out["  same from float64 (avoided)"] = _best(lambda: attr.data.foreach_set("color", rgba64), 1)
    me.attributes.remove(me.attributes[name])
    proxies = core.proxy_dicts(plan)
    out["proxies (show_proxies)"] = _best(lambda: mesh_io.show_proxies(bpy.context.scene,
                                                                       proxies), repeats)
    def reeval():
        me.update_tag()
        bpy.context.view_layer.update()
    out["depsgraph re-evaluation of the changed mesh"] = _best(reeval, repeats)
    try:
        bpy.ops.ed.undo_push(message="bench")
        out["undo push, nothing changed"] = _best(
            lambda: bpy.ops.ed.undo_push(message="bench"), repeats)
        pushes = []
        for _ in range(repeats):  # what a bake's undo step costs: the mesh has changed
            mesh_io.write_ao_attribute(ob, name, ao)
            t0 = time.perf_counter()
            bpy.ops.ed.undo_push(message="bench")
            pushes.append(time.perf_counter() - t0)
        out["undo push after an attribute write"] = min(pushes)
    except RuntimeError as exc:
        print(f"undo push not measurable here: {exc}")
    return out


def main(argv):
    import bpy

    ap = harness.parser(__doc__, prog="blender_bake_speed.py")
    ap.add_argument("--vertices", type=int, default=1_000_000)
    ap.add_argument("--method", default="sphere")
    ap.add_argument("--tau", default="1.5", help="a number, or 'auto' to calibrate (traces)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--scene", choices=("leaves", "large_tree"), default="leaves")
    a = ap.parse_args(argv)

    harness.enable_addon()
    from canopy_ao.blender import job, properties

    for ob in list(bpy.data.objects):
        bpy.data.objects.remove(ob, do_unlink=True)
    t0 = time.perf_counter()
    if a.scene == "leaves":
        ob = leaf_mesh("Leaves", a.vertices)
        ob.canopy_ao.role = 'CANOPY'
        ob.canopy_ao.tree = "Tree"
        names = [ob.name]
    else:
        from blender_scene import build_blender
        from canopy_scenes import round_tree
        objs = build_blender(round_tree(0, leaves=max(1, a.vertices // 4)))
        for part_ob in objs.values():
            part_ob.canopy_ao.role = part_ob["canopy_ao_role"].upper()
        ob = max(objs.values(), key=lambda o: len(o.data.vertices))
        names = list(objs)
    n = sum(len(bpy.data.objects[nm].data.vertices) for nm in names)
    print(f"built {a.scene}: {n} vertices in {len(names)} object(s) in "
          f"{time.perf_counter() - t0:.2f} s")
    bpy.context.view_layer.update()

    kw = dict(objects=",".join(names), method=a.method, attribute="CanopyAO",
              show_proxies=True)
    if a.tau != "auto":
        kw["tau"] = float(a.tau)
    else:
        bpy.context.scene.canopy_ao.calibrate_tau = True

    def bake():
        r = bpy.ops.canopy_ao.bake(**kw)
        if r != {'FINISHED'}:
            raise RuntimeError(f"bake returned {r}")

    bake()  # warm-up: first-call imports, first attribute creation
    times, cpu = [], []
    for _ in range(a.repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        bake()
        times.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    best = int(np.argmin(times))
    floor, floor_cpu = blender_floor([bpy.data.objects[nm] for nm in names], a.repeats)
    # The same bake without the operator: its report says where the time goes.
    opts = dict(properties.scene_options(bpy.context.scene), method=a.method,
                attribute="CanopyAO", show_proxies=True)
    if a.tau != "auto":
        opts["tau"] = float(a.tau)
    runs = []
    for _ in range(a.repeats):
        # Blender re-evaluates the mesh the last bake wrote before the next bake can read it:
        # outside the job's stages here, inside bpy.ops' time above.
        bpy.context.view_layer.update()
        runs.append(job.run_bake(bpy.context, names, opts)[1])
    stage_best = min(runs, key=lambda rep: rep["seconds"])["stage_seconds"]
    load = os.getloadavg()
    print(f"\nbpy.ops.canopy_ao.bake, {n} vertices, method {a.method}, tau {a.tau}: "
          f"best {times[best]:.3f} s of {a.repeats} (all: "
          f"{', '.join(f'{t:.3f}' for t in times)}); load average {load[0]:.2f} {load[1]:.2f}")
    print(f"Blender's floor for the same work (positions, normals, one FLOAT_COLOR write, "
          f"re-evaluation; bpy alone): {floor:.3f} s; the bake takes {times[best] / floor:.2f}× "
          "that")
    print(f"CPU time (all threads, best of {a.repeats}): the bake {min(cpu):.3f} s, the floor "
          f"{floor_cpu:.3f} s, {min(cpu) / floor_cpu:.2f}× (steadier than wall time under load)")
    if stage_best:
        print("\n| bake stage (job.run_bake, best run) | ms |\n|---|---:|")
        for k, v in stage_best.items():
            print(f"| {k} | {1e3 * v:.1f} |")
        top = ("gather (total)", "prepare (fit, calibrate)", "evaluate", "write",
               "report, extras", "proxies")
        total = sum(stage_best.get(k, 0.0) for k in top)
        print(f"| operator, sum of gather + later stages | {1e3 * total:.1f} |")
        print(f"| bpy.ops overhead + Blender's re-evaluation of the changed mesh "
              f"| {1e3 * (times[best] - total):.1f} |")

    print("\n| primitive, on its own (best of 3 unless slow) | ms |\n|---|---:|")
    tau = None if a.tau == "auto" else float(a.tau)
    for k, v in primitives(ob, a.method, tau, a.repeats).items():
        print(f"| {k} | {1e3 * v:.1f} |")
    load = os.getloadavg()
    print(f"\nload average at the end: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
    return 0


if __name__ == "__main__":
    from blender_script import run
    run(main, "blender_bake_speed")
