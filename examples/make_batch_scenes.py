"""Build several variants (seeds 0..N-1) of one example scene into a folder, in one Blender
process: inputs for the batch bake (tests, bench/batch_throughput.py, the README's example).

    blender -b --factory-startup --python examples/make_batch_scenes.py -- \\
        --out /tmp/scenes --count 8 [--scene round_tree] [--quick] [--leaves N]

Files are named <scene>_<seed>.blend. --leaves overrides the leaf count of tree scenes (tiny
scenes for tests). Exits non-zero (message on stderr) on a bad argument or failure.
"""
import argparse
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))


def main(argv):
    import bpy
    from canopy_scenes import SCENES, make_scene
    from make_scene import build

    ap = argparse.ArgumentParser(prog="make_batch_scenes.py")
    ap.add_argument("--out", required=True)
    ap.add_argument("--count", type=int, default=4)
    ap.add_argument("--scene", default="round_tree", choices=sorted(SCENES))
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--leaves", type=int, default=None)
    a = ap.parse_args(argv)
    if a.count < 1 or (a.leaves is not None and a.leaves < 1):
        ap.error("--count and --leaves must be >= 1")
    os.makedirs(a.out, exist_ok=True)
    extra = {} if a.leaves is None else {"leaves": a.leaves}
    for seed in range(a.count):
        bpy.ops.wm.read_factory_settings(use_empty=True)
        build(make_scene(a.scene, seed=seed, quick=a.quick, **extra))
        path = os.path.join(os.path.abspath(a.out), f"{a.scene}_{seed}.blend")
        bpy.ops.wm.save_as_mainfile(filepath=path)
        print(f"make_batch_scenes: saved {path}")
    return 0


if __name__ == "__main__":
    from blender_script import run
    run(main, "make_batch_scenes")
