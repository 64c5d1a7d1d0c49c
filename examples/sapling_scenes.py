"""Real-generator benchmark scenes: Blender's own Sapling Tree Gen trees, a grass field, a grove.

    blender -b --factory-startup --python-exit-code 1 --python examples/sapling_scenes.py -- [--scenes NAME ...]
        [--quick] [--out-dir bench/out/real] [--bake-cycles N ...] [--cycles-seed K] [--blend DIR]
        [--force] [--list]

``--scenes`` also takes held-out scenes no benchmark lists: ``sap_<preset>_s<seed>`` (any
bundled preset, any seed ≥ 1) and ``sap_grove_s<seed>`` (four presets in one collection).

Each tree is built the way a user builds one: ``bpy.ops.curve.tree_add`` (the add-on
``add_curve_sapling`` bundled with Blender 3.4) with one of its bundled presets, a fixed seed and
leaves on; the branch curve is then converted to a mesh beside the leaves mesh (many
disconnected tubes: Sapling bevels each branch separately), and the tree stands on a ground mesh
(its trunk base touches it). The grass field's blades stand on the ground mesh
(examples/canopy_scenes.py's blades); the grove is several Sapling trees in **one** collection on
one ground, so nothing but their geometry tells them apart.

Every scene is exported to ``<out-dir>/<scene>[_quick].npz`` so benchmarks run without Blender:

    names                    str (K,)   object names, in scene order
    <name>/positions         float32 (V, 3) world space
    <name>/normals           float32 (V, 3) Blender's vertex normals (smooth shading: a vertex
                             has one normal, as a POINT-domain Cycles bake sees it)
    <name>/triangles         int32 (M, 3)
    <name>/role              str: the role a user would give it (canopy, trunk, ground, grass)
    <name>/tree              str: the tree it belongs to ("" for ground and grass)
    distance                 float: the AO distance, the scene's bounding-box diagonal
    geometry                 sha1 of names, positions and triangles (cache key for references)
    info                     str: JSON with presets, seeds and the leaf factor

``--bake-cycles N`` also bakes Cycles' own AO per vertex at N samples (denoising and adaptive
sampling off, AO distance as above; not ``--cycles``, which Blender's Cycles add-on claims) into ``<out-dir>/<scene>[_quick]_cycles_<N>.npz`` (``ao/<name>``,
``seconds``, ``samples``, ``seed``, ``geometry``); ``--cycles-seed K`` bakes with Cycles' seed K
instead of 0, into ``..._cycles_<N>_seed<K>.npz`` (a reference whose noise is independent of
the seed-0 bakes at fewer samples, which are the first samples of seed 0's own 1024).
``--blend DIR`` saves each scene's .blend there.
Presets and seeds are fixed, so the same command gives the same bytes. Exits non-zero on failure.
"""
import argparse
import ast
import hashlib
import json
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.join(REPO, "addon"))

import numpy as np  # noqa: E402

DEFAULT_OUT = os.path.join(REPO, "bench", "out", "real")
# Leaf count per branch = the preset's x this factor; quick also bevels branches with the
# coarsest resolution Sapling offers (resU 1, bevelRes 0): small enough for tests.
LEAF_FACTOR = {True: 0.25, False: 1.0}
GRASS_BLADES = {True: 5000, False: 20000}

# scene -> [(preset, seed, (x, y)), ...]. The first three were looked at while designing the
# ray-free rung (bench/real_assets.py); every other scene (presets and seeds) is held out.
TREES = {
    "sap_callistemon": [("callistemon", 1, (0, 0))],
    "sap_white_birch": [("white_birch", 1, (0, 0))],
    "sap_small_maple": [("small_maple", 1, (0, 0))],
    "sap_douglas_fir": [("douglas_fir", 2, (0, 0))],
    "sap_small_pine": [("small_pine", 3, (0, 0))],
    "sap_weeping_willow": [("weeping_willow", 4, (0, 0))],
    "sap_quaking_aspen": [("quaking_aspen", 5, (0, 0))],
    "sap_japanese_maple": [("japanese_maple", 6, (0, 0))],
    "sap_grove": [("quaking_aspen", 7, (-9, -6)), ("small_maple", 8, (8, -5)),
                  ("white_birch", 9, (-4, 9)), ("callistemon", 10, (7, 8))],
}
DESIGN_SCENES = ("sap_callistemon", "sap_white_birch", "sap_small_maple")
SCENES = tuple(TREES) + ("grass_field_real",)
# Beside those, a held-out check on any bundled preset and seed: ``sap_<preset>_s<seed>`` is
# that tree alone, ``sap_grove_s<seed>`` a grove of four presets (the bundled list rotated by the
# seed) with seeds seed..seed+3, at the grove's offsets.
PRESETS = ("callistemon", "douglas_fir", "japanese_maple", "quaking_aspen", "small_maple",
           "small_pine", "weeping_willow", "white_birch", "willow")
GROVE_OFFSETS = tuple(o for _, _, o in TREES["sap_grove"])


def scene_trees(scene):
    """[(preset, seed, (x, y)), ...] of a Sapling scene, or None if the name is not one."""
    if scene in TREES:
        return TREES[scene]
    if not scene.startswith("sap_"):
        return None
    head, _, tail = scene[len("sap_"):].rpartition("_s")
    if not tail.isdigit() or int(tail) < 1:
        return None
    seed = int(tail)
    if head == "grove":
        k = seed % len(PRESETS)
        picked = (PRESETS[k:] + PRESETS[:k])[:len(GROVE_OFFSETS)]
        return [(p, seed + i, o) for i, (p, o) in enumerate(zip(picked, GROVE_OFFSETS))]
    return [(head, seed, (0, 0))] if head in PRESETS else None


def scene_name(value):
    """argparse type: a listed scene or a held-out one (see scene_trees)."""
    if value in SCENES or scene_trees(value) is not None:
        return value
    raise argparse.ArgumentTypeError(
        f"unknown scene {value!r}: one of {', '.join(SCENES)}, or sap_<preset>_s<seed> / "
        f"sap_grove_s<seed> with a preset of {', '.join(PRESETS)}")


def cache_path(out_dir, scene, quick, suffix=""):
    return os.path.join(out_dir, f"{scene}{'_quick' if quick else ''}{suffix}.npz")


def load_preset(preset):
    path = os.path.join("/usr/share/blender/scripts/addons/add_curve_sapling/presets",
                        f"{preset}.py")
    import bpy
    for d in bpy.utils.script_paths(subdir="addons"):
        p = os.path.join(d, "add_curve_sapling", "presets", f"{preset}.py")
        if os.path.exists(p):
            path = p
            break
    with open(path) as f:
        text = f.read()
    settings = ast.literal_eval(text[text.index("{"):])
    # An older preset (willow) as Sapling's own preset menu reads it (ImportData): a scalar
    # attractUp, leaf angles taken from the last level's. (The menu also zeroes the leaf bend:
    # the operator's default, and no bundled preset sets another.)
    if isinstance(settings.get("attractUp"), float):
        settings["attractUp"] = [0, 0, settings["attractUp"], settings["attractUp"]]
    if "leafDownAngle" not in settings and "levels" in settings:
        level = min(int(settings["levels"]), 3)
        for leaf, branch in (("leafDownAngle", "downAngle"), ("leafDownAngleV", "downAngleV"),
                             ("leafRotate", "rotate"), ("leafRotateV", "rotateV")):
            settings[leaf] = settings[branch][level]
    return settings


# === Building in Blender =====================================================================

def _clear():
    import bpy
    for ob in list(bpy.data.objects):
        bpy.data.objects.remove(ob)
    for me in list(bpy.data.meshes):
        bpy.data.meshes.remove(me)
    for cu in list(bpy.data.curves):
        bpy.data.curves.remove(cu)
    for col in list(bpy.data.collections):
        bpy.data.collections.remove(col)


def _smooth(ob):
    me = ob.data
    me.polygons.foreach_set("use_smooth", np.ones(len(me.polygons), bool))
    me.update()


def sapling_tree(preset, seed, offset, name, leaf_factor, collection, coarse=False, **extra):
    """One Sapling tree: (branches mesh object, leaves mesh object) linked to ``collection``.
    extra: Sapling settings over the preset's (leafShape="rect": rectangular leaf cards)."""
    import bpy
    params = load_preset(preset)
    props = bpy.ops.curve.tree_add.get_rna_type().properties.keys()
    params = {k: v for k, v in params.items() if k in props}
    params.update(seed=int(seed), showLeaves=True, useArm=False, makeMesh=False,
                  leaves=max(1, int(round(params.get("leaves", 25) * leaf_factor))))
    if coarse:
        params.update(resU=1, bevelRes=0)
    params.update(extra)
    before = set(bpy.data.objects)
    res = bpy.ops.curve.tree_add(**params)
    if "FINISHED" not in res:
        raise RuntimeError(f"Sapling {preset}: tree_add returned {res}")
    new = [o for o in bpy.data.objects if o not in before]
    curve = next(o for o in new if o.type == "CURVE")
    leaves = next((o for o in new if o.type == "MESH"), None)
    if leaves is None:
        raise RuntimeError(f"Sapling {preset}: no leaves mesh")
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    curve.select_set(True)
    bpy.context.view_layer.objects.active = curve
    bpy.ops.object.convert(target="MESH")
    branches = bpy.context.view_layer.objects.active
    for o, suffix in ((branches, "branches"), (leaves, "leaves")):
        o.name = f"{name}_{suffix}"
        o.data.name = o.name
        _smooth(o)
        for c in list(o.users_collection):
            c.objects.unlink(o)
        collection.objects.link(o)
    branches.location = (offset[0], offset[1], 0.0)
    bpy.context.view_layer.update()
    return branches, leaves


def ground_object(name, center, size, n, collection):
    import bpy
    from blender_scene import mesh_from_arrays
    from canopy_scenes import ground_grid
    v, t, uv = ground_grid(size=size, n=n, center=center)
    me = mesh_from_arrays(name, v, t, uv)
    ob = bpy.data.objects.new(name, me)
    collection.objects.link(ob)
    return ob


def build(scene, quick):
    """Build ``scene`` in the current Blender file: [(object, role, tree)], info dict."""
    import addon_utils
    import bpy
    _clear()
    col = bpy.data.collections.new(scene)
    bpy.context.scene.collection.children.link(col)
    info = {"scene": scene, "quick": bool(quick)}
    objs = []
    if scene == "grass_field_real":
        from blender_scene import mesh_from_arrays
        from canopy_scenes import grass_field
        sc = grass_field(seed=3, blades=GRASS_BLADES[quick])
        for p in sc:
            ob = bpy.data.objects.new(p.name, mesh_from_arrays(p.name, p.vertices, p.triangles,
                                                               p.uvs))
            col.objects.link(ob)
            objs.append((ob, p.role, ""))
        info.update(generator="examples/canopy_scenes.py grass_field", seed=3,
                    blades=GRASS_BLADES[quick])
        return objs, info
    addon_utils.enable("add_curve_sapling", default_set=False)
    info.update(generator="Sapling Tree Gen (add_curve_sapling)", trees=[],
                leaf_factor=LEAF_FACTOR[quick])
    for i, (preset, seed, offset) in enumerate(scene_trees(scene)):
        tree = f"{preset}_{seed}"
        b, l = sapling_tree(preset, seed, offset, tree, LEAF_FACTOR[quick], col, coarse=quick)
        objs += [(b, "trunk", tree), (l, "canopy", tree)]
        info["trees"].append({"preset": preset, "seed": seed, "offset": list(offset)})
    lo, hi = _bbox([o for o, _, _ in objs])
    extent = float(max(hi[0] - lo[0], hi[1] - lo[1]))
    center = (0.5 * float(lo[0] + hi[0]), 0.5 * float(lo[1] + hi[1]))
    g = ground_object("ground", center, 2.0 * extent, 64, col)
    objs.append((g, "ground", ""))
    return objs, info


def _world_arrays(ob):
    import bpy
    dg = bpy.context.evaluated_depsgraph_get()
    ev = ob.evaluated_get(dg)
    me = ev.to_mesh()
    try:
        n = len(me.vertices)
        co = np.empty(3 * n, np.float32)
        me.vertices.foreach_get("co", co)
        no = np.empty(3 * n, np.float32)
        me.vertices.foreach_get("normal", no)
        me.calc_loop_triangles()
        tri = np.empty(3 * len(me.loop_triangles), np.int32)
        me.loop_triangles.foreach_get("vertices", tri)
        faces = np.empty(len(me.loop_triangles), np.int32)
        me.loop_triangles.foreach_get("polygon_index", faces)
    finally:
        ev.to_mesh_clear()
    m = np.array(ob.matrix_world, np.float64)
    co = co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]
    nrm = no.reshape(-1, 3) @ np.linalg.inv(m[:3, :3])
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-12)
    return co.astype(np.float32), nrm.astype(np.float32), tri.reshape(-1, 3), faces


def _bbox(objects):
    pts = np.concatenate([_world_arrays(o)[0] for o in objects])
    return pts.min(0), pts.max(0)


def export(path, objs, info):
    arrays, names = {}, []
    h = hashlib.sha1()
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for ob, role, tree in objs:
        p, n, t, f = _world_arrays(ob)
        names.append(ob.name)
        arrays[f"{ob.name}/positions"] = p
        arrays[f"{ob.name}/normals"] = n
        arrays[f"{ob.name}/triangles"] = t
        arrays[f"{ob.name}/polygons"] = f  # each triangle's face (not hashed: not geometry)
        arrays[f"{ob.name}/role"] = np.array(role)
        arrays[f"{ob.name}/tree"] = np.array(tree)
        h.update(ob.name.encode())
        h.update(p.tobytes())
        h.update(t.tobytes())
        lo, hi = np.minimum(lo, p.min(0)), np.maximum(hi, p.max(0))
    distance = float(np.linalg.norm(hi - lo))
    os.makedirs(os.path.dirname(path), exist_ok=True)
    np.savez_compressed(path, names=np.array(names), distance=distance, geometry=h.hexdigest(),
                        info=json.dumps(info), **arrays)
    return distance, h.hexdigest()


# === Entry ===================================================================================

def main(argv):
    import bpy
    ap = argparse.ArgumentParser(prog="sapling_scenes.py")
    ap.add_argument("--scenes", nargs="+", default=list(SCENES), type=scene_name,
                    help="the listed scenes (--list), or held-out trees sap_<preset>_s<seed> "
                         "and groves sap_grove_s<seed>")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out-dir", default=DEFAULT_OUT)
    ap.add_argument("--bake-cycles", type=int, nargs="*", default=[], dest="cycles")
    ap.add_argument("--cycles-seed", type=int, default=0,
                    help="Cycles' seed for --bake-cycles (0: _cycles_<N>.npz; K > 0: "
                         "_cycles_<N>_seed<K>.npz, noise independent of seed 0's)")
    ap.add_argument("--blend", help="also save each scene's .blend in this folder")
    ap.add_argument("--force", action="store_true", help="rebuild scenes already exported")
    ap.add_argument("--list", action="store_true")
    a = ap.parse_args(argv)
    if a.list:
        print("\n".join(SCENES))
        return 0
    if a.cycles_seed < 0:
        ap.error("--cycles-seed must be ≥ 0")
    seed_tag = f"_seed{a.cycles_seed}" if a.cycles_seed else ""
    for scene in a.scenes:
        path = cache_path(a.out_dir, scene, a.quick)
        todo_cycles = [s for s in a.cycles
                       if a.force or not os.path.exists(cache_path(a.out_dir, scene, a.quick,
                                                                   f"_cycles_{s}{seed_tag}"))]
        if os.path.exists(path) and not a.force and not todo_cycles and not a.blend:
            print(f"sapling_scenes: cached {path}")
            continue
        t0 = time.perf_counter()
        objs, info = build(scene, a.quick)
        t1 = time.perf_counter()
        distance, ghash = export(path, objs, info)
        nv = sum(len(o.data.vertices) for o, _, _ in objs)
        print(f"sapling_scenes: {scene}: {len(objs)} objects, {nv} vertices, built in "
              f"{t1 - t0:.1f} s, AO distance {distance:.3g} -> {path}", flush=True)
        world = bpy.context.scene.world or bpy.data.worlds.new("World")
        bpy.context.scene.world = world
        world.light_settings.distance = distance
        if a.blend:
            os.makedirs(a.blend, exist_ok=True)
            bpy.ops.wm.save_as_mainfile(filepath=os.path.join(
                os.path.abspath(a.blend), f"{scene}{'_quick' if a.quick else ''}.blend"))
        for s in todo_cycles:
            from canopy_ao.blender.cycles_check import bake_cycles_vertex_ao
            t2 = time.perf_counter()
            res = bake_cycles_vertex_ao(bpy.context, [o for o, _, _ in objs], distance, s,
                                        seed=a.cycles_seed)
            dt = time.perf_counter() - t2
            cpath = cache_path(a.out_dir, scene, a.quick, f"_cycles_{s}{seed_tag}")
            np.savez_compressed(cpath, seconds=dt, samples=s, seed=a.cycles_seed, geometry=ghash,
                                **{f"ao/{k}": np.asarray(v, np.float32) for k, v in res.items()})
            print(f"sapling_scenes: {scene}: Cycles {s} samples in {dt:.1f} s -> {cpath}",
                  flush=True)
    return 0


if __name__ == "__main__":
    from blender_script import run
    run(main, "sapling_scenes")
