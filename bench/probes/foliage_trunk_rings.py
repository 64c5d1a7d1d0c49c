"""Probe, answered: on the scattered-card scenes the proxy rungs read both rings of the cylinder trunk as rays do, the ring on the ground occluded by the ground's patch (core/walls.py), the ring inside the hollow crown lit with the trunk's own factor on τ (scene.SCALED_ROLES; docs/studies/foliage.md).

The mean AO of the trunk's two vertex rings (examples/foliage_scenes.py's gn_cards and
particle_cards: a 32-sided cylinder, one ring at z = 0 on the ground, one at z = 3 inside the
crown of cards) per rung, beside our rays at 256 samples:

    blender -b --factory-startup --python-exit-code 1 --python bench/probes/foliage_trunk_rings.py -- \\
        [--scenes gn_cards particle_cards]
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import harness  # noqa: E402  (addon/ and examples/ on sys.path)

import numpy as np  # noqa: E402

RUNGS = ("raytrace", "sphere", "medium", "grid", "regression")


def main(argv):
    import bpy
    ap = harness.parser(__doc__, prog="foliage_trunk_rings.py",
                        scenes=["gn_cards", "particle_cards"])
    a = ap.parse_args(argv)
    harness.enable_addon()
    import foliage
    import foliage_scenes
    for scene in a.scenes:
        foliage_scenes.build(scene)
        trunk = bpy.data.objects["Trunk"]
        z = np.array([(trunk.matrix_world @ v.co).z for v in trunk.data.vertices])
        for m in RUNGS:
            ao, _roles = foliage._bake(m, foliage.REF_SAMPLES if m == "raytrace" else 64)
            a_t = ao["Trunk"]
            print(f"{scene} {m if m != 'raytrace' else 'rays 256'}: ground ring (z "
                  f"{z.min():.1f}) {a_t[z < z.mean()].mean():.3f}, crown ring (z {z.max():.1f}) "
                  f"{a_t[z > z.mean()].mean():.3f}", flush=True)
    return 0


if __name__ == "__main__":
    harness.run_in_blender(main, "foliage_trunk_rings")
