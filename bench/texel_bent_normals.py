"""Bent normals per texel with their rays dealt over the anti-aliasing sub-samples
(docs/DESIGN.md, 'Texel anti-aliasing and memory').

    blender -b --factory-startup --python bench/texel_bent_normals.py -- \
        [--resolution 64] [--samples 16,64] [--aa 1,2,3] [--reference 4096]

The test scene's ground (tests/python/tree_scene.py: 20 × 20 m under a leaf ball, Smart UV
Project) baked per texel with bent normals in world space, each texel casting Samples rays
whatever its N × N sub-samples. The reference is the same bake at ``--reference`` samples and
4 × 4 sub-samples (the texel's footprint). Printed per S and N: the mean angle to the
reference over the covered texels, with the sub-samples' directions weighted by their open
rays (the bake's) and plainly averaged, and the ratio of the two. ~5 s. The add-on is found
in this repository's addon/ folder. Exits non-zero (message on stderr) on failure.
"""

import argparse
import os
import sys
import tempfile

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def main(argv):
    p = argparse.ArgumentParser(prog="texel_bent_normals.py")
    p.add_argument("--resolution", type=int, default=64)
    p.add_argument("--samples", default="16,64")
    p.add_argument("--aa", default="1,2,3")
    p.add_argument("--reference", type=int, default=4096)
    a = p.parse_args(argv)
    import bpy
    import addon_utils
    sys.path[:0] = [os.path.join(REPO, "addon"), os.path.join(REPO, "tests", "python")]
    addon_utils.enable("canopy_ao", default_set=True, handle_error=None)
    import tree_scene
    from canopy_ao.blender import properties, texel_target
    from canopy_ao.blender.job import run_bake
    from canopy_ao.core.native import _core
    for ob in list(bpy.data.objects):
        bpy.data.objects.remove(ob, do_unlink=True)
    for name, (pos, tris) in tree_scene.scene(True).items():
        me = bpy.data.meshes.new(name)
        me.from_pydata(np.asarray(pos).tolist(), [], np.asarray(tris).tolist())
        ob = bpy.data.objects.new(name, me)
        bpy.context.scene.collection.objects.link(ob)
    ground = bpy.data.objects["Ground"]
    bpy.context.view_layer.objects.active = ground
    ground.select_set(True)
    bpy.ops.object.mode_set(mode='EDIT')
    bpy.ops.mesh.select_all(action='SELECT')
    bpy.ops.uv.smart_project()
    bpy.ops.object.mode_set(mode='OBJECT')
    folder = tempfile.mkdtemp(prefix="canopy_ao_bent_")

    def bent(samples, aa, weighted=True):
        made = texel_target.texel_bent
        if not weighted:
            texel_target.texel_bent = lambda b, w, k: made(b, None, k)
        try:
            o = dict(properties.scene_options(bpy.context.scene), mode='TEXEL',
                     resolution=a.resolution, texel_aa=aa, method="sphere", tau=2.0,
                     distance=0.0, samples=samples, show_proxies=False, image_dir=folder,
                     bent_normals="WORLD", overwrite=True)
            _job, rep = run_bake(bpy.context, ["Ground"], o)
        finally:
            texel_target.texel_bent = made
        path = rep["objects"]["Ground"]["texel"]["bent_normals_path"]
        return _core.read_image(path)[:, :, :3].reshape(-1, 3) * 2.0 - 1.0

    ref = bent(a.reference, 4)
    covered = np.linalg.norm(ref, axis=1) > 0.5  # empty texels are encoded grey (0, 0, 0)

    def angle(b):
        u = b[covered] / np.linalg.norm(b[covered], axis=1, keepdims=True)
        r = ref[covered] / np.linalg.norm(ref[covered], axis=1, keepdims=True)
        return float(np.degrees(np.arccos(np.clip((u * r).sum(1), -1, 1))).mean())

    print(f"{covered.sum()} texels, reference {a.reference} samples at 4 x 4; mean angle, deg")
    for s in (int(x) for x in a.samples.split(",")):
        for n in (int(x) for x in a.aa.split(",")):
            w, plain = angle(bent(s, n)), angle(bent(s, n, weighted=False))
            print(f"S {s:5d}  N {n}: weighted {w:.2f}  plain {plain:.2f}  "
                  f"weighted / plain {w / plain:.3f}")


if __name__ == "__main__":
    try:
        main(sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else [])
    except Exception as exc:  # noqa: BLE001 (the message, and a non-zero exit)
        print(f"texel_bent_normals.py: {exc}", file=sys.stderr)
        sys.exit(1)
