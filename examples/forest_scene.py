"""A forest in Blender: thousands of instanced trees on a 1M-vertex ground, baked headless.

    blender -b --factory-startup --python-exit-code 1 --python examples/forest_scene.py -- \
        [--trees 10000] [--ground-vertices 1e6] [--side 1000] [--method ellipsoid] \
        [--tau auto|T] [--epsilon 1e-2] [--save /tmp/forest.blend]

(with the add-on installed, or BLENDER_USER_SCRIPTS pointing at a folder whose addons/ links
addon/canopy_ao, as in the README). Two prototype trees from examples/canopy_scenes.py (the
round tree and the conifer) each live in their own collection, excluded from the view layer;
two hair particle systems on an emitter plane (role Ignore, instancer hidden) scatter them over
the ground, half each, whole collection per particle, upright, random heading and ±20 % size.
The ground is a grid of --ground-vertices vertices. One bake (canopy_ao's run_bake, as the
operator does) of the Ground alone: each prototype is fitted once (its own AO is not baked:
neither it nor its emitter is a target), the ground gets every instance's shells as occluders
(cut-off ε and the core's spatial grid). Prints the time of each step and the ground's AO
statistics; exits non-zero on failure.
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import time

import bpy
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

import canopy_scenes as cs  # noqa: E402
from blender_scene import mesh_from_arrays  # noqa: E402


def prototype(scene, name):
    """The scene's parts as objects in collection ``name``, excluded from the view layer."""
    coll = bpy.data.collections.new(name)
    bpy.context.scene.collection.children.link(coll)
    for part in scene:
        ob = bpy.data.objects.new(f"{name}_{part.role}", mesh_from_arrays(part.name, part.vertices,
                                                                          part.triangles))
        ob["canopy_ao_role"] = part.role
        ob["canopy_ao_tree"] = name
        coll.objects.link(ob)
    bpy.context.view_layer.layer_collection.children[name].exclude = True
    return coll


def ground(vertices, side):
    k = int(round(math.sqrt(vertices)))
    x = np.linspace(-side / 2, side / 2, k, dtype=np.float32)
    X, Y = np.meshgrid(x, x)
    v = np.stack([X.ravel(), Y.ravel(), np.zeros(k * k, np.float32)], 1)
    i = np.arange((k - 1) * (k - 1))
    a = (i // (k - 1)) * k + i % (k - 1)
    t = np.concatenate([np.stack([a, a + 1, a + k + 1], 1), np.stack([a, a + k + 1, a + k], 1)])
    ob = bpy.data.objects.new("Ground", mesh_from_arrays("Ground", v, t.astype(np.int32)))
    ob["canopy_ao_role"] = "ground"
    bpy.context.scene.collection.objects.link(ob)
    return ob


def scatter(emitter, coll, count, seed):
    mod = emitter.modifiers.new(coll.name, 'PARTICLE_SYSTEM')
    psys = mod.particle_system
    psys.seed = seed
    ps = psys.settings
    ps.type = 'HAIR'
    ps.count = count
    ps.hair_length = 1.0
    ps.use_advanced_hair = True
    ps.use_rotations = True
    ps.rotation_mode = 'NONE'  # upright (hair would lay the tree's x axis along the hair)
    ps.phase_factor_random = 2.0  # any heading
    ps.render_type = 'COLLECTION'
    ps.instance_collection = coll
    ps.use_whole_collection = True
    ps.particle_size = 1.0
    ps.size_random = 0.2
    ps.distribution = 'RAND'
    ps.use_even_distribution = True


def build(trees, ground_vertices, side):
    """The scene (module docstring) in the current file, replacing every object; returns the
    ground object."""
    for ob in list(bpy.data.objects):
        bpy.data.objects.remove(ob, do_unlink=True)
    protos = [prototype(cs.round_tree(seed=1, leaves=8000, ground=False), "RoundTree"),
              prototype(cs.conifer(seed=2, leaves=8000, ground=False), "Conifer")]
    g = ground(ground_vertices, side)
    s = side / 2
    emitter = bpy.data.objects.new("Emitter", mesh_from_arrays(
        "Emitter", np.float32([[-s, -s, 0], [s, -s, 0], [s, s, 0], [-s, s, 0]]),
        np.int32([[0, 1, 2], [0, 2, 3]])))
    emitter.canopy_ao.role = 'IGNORE'
    emitter.show_instancer_for_render = emitter.show_instancer_for_viewport = False
    bpy.context.scene.collection.objects.link(emitter)
    half = trees // 2
    scatter(emitter, protos[0], trees - half, 1)
    scatter(emitter, protos[1], half, 2)
    bpy.context.view_layer.update()
    return g


def run(main):
    """Run main(the arguments after --) as a Blender script: exit 1 on failure (Blender's
    own exit code ignores an exception in a --python script)."""
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


def main(argv):
    ap = argparse.ArgumentParser(prog="forest_scene.py")
    ap.add_argument("--trees", type=int, default=10000)
    ap.add_argument("--ground-vertices", type=float, default=1e6)
    ap.add_argument("--side", type=float, default=1000.0, help="ground side, m")
    ap.add_argument("--method", default="ellipsoid")
    ap.add_argument("--tau", default="auto", help="optical depth, or auto = calibrate τ per "
                                                  "prototype (default)")
    ap.add_argument("--epsilon", type=float, default=1e-2, help="forest cut-off ε")
    ap.add_argument("--save", default="")
    args = ap.parse_args(argv)

    import addon_utils
    if addon_utils.enable("canopy_ao", default_set=True) is None:
        raise SystemExit("the canopy_ao add-on could not be enabled")
    from canopy_ao.blender import mesh_io, properties
    from canopy_ao.blender.job import run_bake

    t0 = time.perf_counter()
    g = build(args.trees, args.ground_vertices, args.side)
    t_build = time.perf_counter() - t0
    print(f"scene: {len(g.data.vertices)} ground vertices, {args.trees} trees "
          f"({args.trees - args.trees // 2} round, {args.trees // 2} conifer) on {args.side:g} m, built in "
          f"{t_build:.1f} s", flush=True)

    opts = properties.scene_options(bpy.context.scene)
    from canopy_ao.core.settings import BY_NAME
    opts.update(method=args.method, tau=BY_NAME["tau"].parse(args.tau), distance=0.0,
                show_proxies=False, forest_epsilon=args.epsilon, overwrite=True)
    t0 = time.perf_counter()
    job, rep = run_bake(bpy.context, ["Ground"], opts)
    total = time.perf_counter() - t0
    for line in job.lines:
        print(line)
    for note in rep["notes"]:
        print("note:", note)
    ao = mesh_io.read_ao_attribute(g, opts["attribute"])
    gr = rep["objects"]["Ground"]
    print("prototypes self-baked: " + (", ".join(
        f"{n} ({p['vertices']} v, {p['seconds']:.2f} s)"
        for n, p in rep["instances"]["prototypes"].items()) or "none (the Ground alone)"))
    stages = rep.get("stage_seconds") or rep["timings"]
    print(f"stages: {', '.join(f'{k} {v:.2f} s' for k, v in stages.items())}")
    print(f"ground: {gr['vertices']} vertices in {gr['seconds']:.1f} s "
          f"({gr['seconds'] / max(gr['vertices'], 1) * 1e9:.0f} ns/vertex); AO mean "
          f"{ao.mean():.3f}, min {ao.min():.3f}, 5th pct {np.percentile(ao, 5):.3f}")
    print(f"whole bake: {total:.1f} s for {rep['instances']['instances']} instances")
    if rep["instances"]["instances"] != args.trees:
        raise SystemExit(f"expected {args.trees} instances, found {rep['instances']['instances']}")
    if args.save:
        bpy.ops.wm.save_as_mainfile(filepath=os.path.abspath(args.save))
        print("saved", args.save)


if __name__ == "__main__":
    run(main)
