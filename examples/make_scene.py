"""Build a Canopy AO example scene in Blender and save it.

    blender -b --factory-startup --python examples/make_scene.py -- --scene round_tree --out /tmp/x.blend
    blender -b --factory-startup --python examples/make_scene.py -- --list

Options: --seed N, --quick (smaller leaf counts), --keep-default (keep the startup cube/camera/light).
Exits non-zero (message on stderr) on a bad argument or failure.
"""
import argparse
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))


def build(scene):
    """The scene's objects in the current Blender scene, with the World's AO distance set to
    the scene's diagonal, so nothing in it is out of reach (as the benchmark's references
    use): the add-on and Cycles both take it from the World. Returns {part name: object}."""
    import bpy
    import numpy as np
    from blender_scene import build_blender

    objs = build_blender(scene)
    pts = np.concatenate([p.vertices for p in scene]) if len(scene) else np.zeros((1, 3))
    diagonal = float(np.linalg.norm(pts.max(0) - pts.min(0)))
    world = bpy.context.scene.world or bpy.data.worlds.new("World")
    bpy.context.scene.world = world
    world.light_settings.distance = max(diagonal, 1e-3)
    return objs


def main(argv):
    import bpy
    from canopy_scenes import SCENES, make_scene

    ap = argparse.ArgumentParser(prog="make_scene.py")
    ap.add_argument("--scene", default="round_tree", choices=sorted(SCENES))
    ap.add_argument("--out", help="where to save the .blend (default: don't save)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--keep-default", action="store_true")
    ap.add_argument("--list", action="store_true")
    a = ap.parse_args(argv)
    if a.list:
        print("\n".join(sorted(SCENES)))
        return 0
    if not a.keep_default:
        for ob in list(bpy.data.objects):
            if ob.name in ("Cube",):
                bpy.data.objects.remove(ob)
    t0 = time.perf_counter()
    scene = make_scene(a.scene, seed=a.seed, quick=a.quick)
    t1 = time.perf_counter()
    objs = build(scene)
    world = bpy.context.scene.world
    t2 = time.perf_counter()
    print(scene.summary())
    print(f"make_scene: World AO distance {world.light_settings.distance:.3g} (the scene's diagonal)")
    print(f"make_scene: generated in {t1 - t0:.2f} s, built {len(objs)} objects in {t2 - t1:.2f} s")
    if a.out:
        bpy.ops.wm.save_as_mainfile(filepath=os.path.abspath(a.out))
        print(f"make_scene: saved {a.out}")
    return 0


if __name__ == "__main__":
    from blender_script import run
    run(main, "make_scene")
