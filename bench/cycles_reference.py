"""Cycles' per-vertex AO bake of a benchmark scene, cached on disk (bench/README.md).

Run inside Blender:

    blender -b --factory-startup --python bench/cycles_reference.py -- \
        --scene round_tree --samples 1 4 16 64 256 1024 [--quick] [--force]

For each sample count it builds the scene (examples/canopy_scenes.py, identical arrays to the
native bench), bakes Cycles AO into a FLOAT_COLOR POINT attribute of every object with denoising
and adaptive sampling off and world.light_settings.distance = the scene's AO distance (its bbox
diagonal: docs/DESIGN.md, 'Facts measured in Blender'), and saves
bench/out/cache/cycles_<scene>[_quick]_<samples>.npz with:

    ao/<part name>   float32 (V,)  baked AO per vertex
    seconds          wall time of the bake call (scene sync + BVH + samples)
    samples, distance, geometry (sha1 of the scene's vertex and triangle bytes), blender version

Existing cache files with the same geometry hash are kept unless --force. Uses
addon/canopy_ao/blender/cycles_check.py's bake_cycles_vertex_ao when that module exists, else the
minimal implementation below. Exits non-zero with a message on failure.
"""
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # Blender does not add it
import harness  # noqa: E402  (addon/ and examples/ on sys.path)

HERE, REPO = harness.HERE, harness.REPO

import numpy as np  # noqa: E402

CACHE = harness.CACHE


def cache_path(scene_name: str, quick: bool, samples: int) -> str:
    return os.path.join(CACHE, f"cycles_{scene_name}{'_quick' if quick else ''}_{samples}.npz")


def _bake_minimal(context, objects, distance, samples):
    """Cycles AO bake into a FLOAT_COLOR POINT attribute per object; {name: float32 (V,)}."""
    import bpy
    scene = context.scene
    scene.render.engine = "CYCLES"
    cy = scene.cycles
    cy.device = "CPU"
    cy.samples = int(samples)
    cy.use_denoising = False          # no OIDN in Debian's build → zeros
    cy.use_adaptive_sampling = False  # stops early on vertex bakes
    if scene.world is None:
        scene.world = bpy.data.worlds.new("World")
    scene.world.light_settings.distance = float(distance)
    attrs = {}
    for ob in objects:
        me = ob.data
        old = me.color_attributes.get("canopy_ao_cycles")
        if old is not None:
            me.color_attributes.remove(old)
        a = me.color_attributes.new("canopy_ao_cycles", "FLOAT_COLOR", "POINT")
        me.color_attributes.active_color = a
        attrs[ob.name] = a.name
    for ob in context.view_layer.objects:
        ob.select_set(False)
    for ob in objects:
        ob.select_set(True)
    context.view_layer.objects.active = objects[0]
    res = bpy.ops.object.bake(type="AO", target="VERTEX_COLORS", use_clear=True, margin=0)
    if "FINISHED" not in res:
        raise RuntimeError(f"Cycles bake returned {res}")
    out = {}
    for ob in objects:
        me = ob.data
        buf = np.empty(4 * len(me.vertices), np.float32)
        me.color_attributes[attrs[ob.name]].data.foreach_get("color", buf)
        out[ob.name] = buf[0::4].copy()
    return out


def bake_function():
    try:
        from canopy_ao.blender.cycles_check import bake_cycles_vertex_ao
        return bake_cycles_vertex_ao, "canopy_ao.blender.cycles_check"
    except Exception:
        return _bake_minimal, "bench minimal"


def main(argv):
    import bpy
    from canopy_scenes import SCENES, geometry_hash, make_scene
    from blender_scene import build_blender

    ap = harness.parser(__doc__, prog="cycles_reference.py")
    ap.add_argument("--scene", required=True, choices=sorted(SCENES))
    ap.add_argument("--samples", type=int, nargs="+", default=[256])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--force", action="store_true")
    a = ap.parse_args(argv)
    os.makedirs(CACHE, exist_ok=True)

    scene = make_scene(a.scene, seed=a.seed, quick=a.quick)
    ghash = geometry_hash(scene)
    todo = []
    for s in a.samples:
        path = cache_path(a.scene, a.quick, s)
        if os.path.exists(path) and not a.force:
            with np.load(path) as z:
                if str(z["geometry"]) == ghash:
                    print(f"cycles_reference: cached {path}")
                    continue
        todo.append(s)
    if not todo:
        return 0
    for ob in list(bpy.data.objects):
        bpy.data.objects.remove(ob)
    objs = build_blender(scene)
    objects = [objs[p.name] for p in scene]
    distance = scene.ao_distance()
    bake, which = bake_function()
    for s in todo:
        t0 = time.perf_counter()
        res = bake(bpy.context, objects, distance, s)
        dt = time.perf_counter() - t0
        arrays = {f"ao/{k}": np.asarray(v, np.float32) for k, v in res.items()}
        for p in scene:
            v = arrays.get(f"ao/{p.name}")
            if v is None or v.shape != (p.n_vertices,):
                raise RuntimeError(f"{p.name}: baked {None if v is None else v.shape}, "
                                   f"expected ({p.n_vertices},)")
        path = cache_path(a.scene, a.quick, s)
        np.savez_compressed(path, seconds=dt, samples=s, distance=distance, geometry=ghash,
                            blender=bpy.app.version_string, implementation=which, **arrays)
        means = ", ".join(f"{k[3:]}={v.mean():.3f}" for k, v in arrays.items())
        print(f"cycles_reference: {a.scene} {s} samples: {dt:.2f} s ({which}); mean AO {means}")
        sys.stdout.flush()
    return 0


if __name__ == "__main__":
    from blender_script import run
    run(main, "cycles_reference")
