"""Where geometry touches: our ray tracer against Cycles' own vertex AO bake, in Blender.

    BLENDER_USER_SCRIPTS=<dir with addons/canopy_ao> blender -b --factory-startup \\
        --python bench/cycles_contact.py -- [--samples 1024]

A 100 m ground grid; three 2 cm blades standing on it (upright, leaning back 25° so their normal
tilts up, leaning forward so it tilts down); a 16-sided trunk with both ends capped, its bottom
cap in the ground plane. Cycles bakes AO per vertex (the add-on's cycles_check, AO distance 20);
RayTracer traces the same vertices at Cycles' bake point (given the vertex normals and faces:
the add-on's path), with their own triangles skipped from a hair off the vertex (the rule
before), and with the old normal offset. Prints the mean per group of vertices (blade roots,
blade tips, the trunk's bottom and top rings). Closed forms for the roots: a plane through the
receiver blocks (1 − n·up)/2 of its hemisphere, so AO = (1 + n·up)/2.
"""
import math
import os
import sys

import bpy
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # Blender does not add it
import harness  # noqa: E402

harness.enable_addon()
from canopy_ao import _core  # noqa: E402
from canopy_ao.blender import cycles_check  # noqa: E402


def mesh(name, verts, faces):
    me = bpy.data.meshes.new(name)
    me.from_pydata(verts, [], faces)
    me.update()
    ob = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(ob)
    for p in me.polygons:
        p.use_smooth = True
    return ob


def build():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    n = 10
    gv = [(-50 + 100 * i / n, -50 + 100 * j / n, 0.0) for j in range(n + 1) for i in range(n + 1)]
    gf = [(j * (n + 1) + i, j * (n + 1) + i + 1, (j + 1) * (n + 1) + i + 1, (j + 1) * (n + 1) + i)
          for j in range(n) for i in range(n)]
    objs = [mesh("Ground", gv, gf)]
    for k, beta in enumerate((0.0, 25.0, -25.0)):
        b, x, y = math.radians(beta), 0.37 + 3 * k, 0.23
        up = (0.0, math.sin(b), math.cos(b))
        v = [(x - 0.01, y, 0.0), (x + 0.01, y, 0.0), (x + 0.01, y + 0.3 * up[1], 0.3 * up[2]),
             (x - 0.01, y + 0.3 * up[1], 0.3 * up[2])]
        objs.append(mesh(f"Blade{k}", v, [(0, 1, 2, 3)]))
    s = 16
    v = [(10 + 0.2 * math.cos(2 * math.pi * i / s), 0.2 * math.sin(2 * math.pi * i / s), 3.0 * e)
         for e in range(2) for i in range(s)]
    f = [(i, (i + 1) % s, (i + 1) % s + s, i + s) for i in range(s)]
    f += [tuple(range(s))[::-1], tuple(range(s, 2 * s))]
    objs.append(mesh("Trunk", v, f))
    return objs


def arrays(ob):
    me = ob.data
    me.calc_loop_triangles()
    v = np.array([x.co[:] for x in me.vertices], np.float32)
    nrm = np.array([x.normal[:] for x in me.vertices], np.float32)
    t = np.array([lt.vertices[:] for lt in me.loop_triangles], np.int32)
    faces = np.array([lt.polygon_index for lt in me.loop_triangles], np.int32)
    return v, nrm, t, faces


def main():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    samples = int(argv[argv.index("--samples") + 1]) if "--samples" in argv else 1024
    objs = build()
    cycles = cycles_check.bake_cycles_vertex_ao(bpy.context, objs, 20.0, samples)
    if isinstance(cycles, tuple):
        cycles = cycles[0]
    data = {o.name: arrays(o) for o in objs}
    verts, tris, base = [], [], {}
    count = 0
    for name, (v, _n, t, _f) in data.items():
        base[name] = count
        verts.append(v)
        tris.append(t + count)
        count += len(v)
    tracer = _core.RayTracer(np.ascontiguousarray(np.concatenate(verts)),
                             np.ascontiguousarray(np.concatenate(tris), np.int32))
    bake = _core.RayTracer(np.ascontiguousarray(np.concatenate(verts)),
                           np.ascontiguousarray(np.concatenate(tris), np.int32),
                           normals=np.ascontiguousarray(np.concatenate(
                               [n for _v, n, _t, _f in data.values()]), np.float32),
                           polygons=np.ascontiguousarray(np.concatenate(
                               [f + 1_000_000 * k for k, (_v, _n, _t, f) in
                                enumerate(data.values())]), np.int32))
    print(f"Cycles {samples} samples vs RayTracer {samples} rays, AO distance 20")
    print(f"{'vertices':28s} {'Cycles':>8s} {'bake point':>11s} {'own skipped':>12s} "
          f"{'old offset':>11s} {'closed form':>12s}")
    for name, (v, nrm, _t, _f) in data.items():
        if name == "Ground":
            continue
        ids = np.ascontiguousarray(base[name] + np.arange(len(v), dtype=np.int32))
        new = tracer.ao(v, nrm, samples=samples, distance=20.0, vertex_ids=ids)
        bp = bake.ao(v, nrm, samples=samples, distance=20.0, vertex_ids=ids)
        old = tracer.ao(v, nrm, samples=samples, distance=20.0)
        cyc = np.asarray(cycles[name], np.float32)
        low = v[:, 2] < 1e-6
        groups = ([("roots", low), ("tips", ~low)] if name.startswith("Blade")
                  else [("bottom ring", low), ("top ring", ~low)])
        for label, sel in groups:
            form = (f"{(1 + float(nrm[sel][:, 2].mean())) / 2:12.3f}"
                    if name.startswith("Blade") and label == "roots" else f"{'':12s}")
            print(f"{name + ' ' + label:28s} {cyc[sel].mean():8.3f} {bp[sel].mean():11.3f} "
                  f"{new[sel].mean():12.3f} "
                  f"{old[sel].mean():11.3f} {form}")


main()
