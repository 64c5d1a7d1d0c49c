"""Texel anti-aliasing against Cycles' own texel bake (bench/README.md, 'Texel anti-aliasing').

    blender -b --factory-startup --python bench/texel_aa.py -- \
        [--resolution 64] [--samples 16,64] [--aa 1,2,4] [--reference 4096]

A ground (4 × 4 m, UV-mapped) under a small tree (a trunk and a crown of 600 leaf quads) with
a rock (a 0.5 m cube sunk 5 cm, turned off the texel grid) beside it, roles set explicitly. The
reference is Cycles' AO baked into the ground's UV layout at ``--reference`` samples (seed 1,
so no other bake shares its noise); Cycles' texel bake spreads its samples over each texel's
footprint, so the reference is the footprint's mean. Printed per sample count S: the error
(MAE over the texels Cycles covers, and over the edge texels where the reference steps) of
Cycles at S samples (seed 0) and of ours by rays (``--method raytrace``) at S samples with
each anti-aliasing N (a texel's S rays dealt over its N × N sub-samples: equal rays when N²
divides S). The AO distance is 2 m. ~40 s at the defaults. The add-on is
found through BLENDER_USER_SCRIPTS (addons/canopy_ao) or in this repository's addon/ folder.
Exits non-zero (message on stderr) on failure.
"""

import os
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # Blender does not add it
import harness  # noqa: E402  (addon/ and examples/ on sys.path)

REPO = harness.REPO
DISTANCE = 2.0


def _args(argv):
    p = harness.parser(__doc__, prog="texel_aa.py")
    p.add_argument("--resolution", type=int, default=64)
    p.add_argument("--samples", default="16,64")
    p.add_argument("--aa", default="1,2,4")
    p.add_argument("--reference", type=int, default=4096)
    return p.parse_args(argv)


def build_scene():
    """The ground (Ground) under a trunk (Trunk) and a crown of leaf quads (Leaves), a rock
    (Rock) beside it."""
    import bpy
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.mesh.primitive_plane_add(size=4.0)
    ground = bpy.context.object
    ground.name = "Ground"
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.subdivide(number_cuts=7)
    bpy.ops.object.mode_set(mode="OBJECT")
    bpy.ops.mesh.primitive_cylinder_add(vertices=12, radius=0.08, depth=1.4,
                                        location=(0.2, -0.1, 0.7))
    trunk = bpy.context.object
    trunk.name = "Trunk"
    # A rock on the ground, turned off the texel grid: sharp contact edges to alias.
    bpy.ops.mesh.primitive_cube_add(size=0.5, location=(-0.9, 0.6, 0.2),
                                    rotation=(0.0, 0.0, 0.5))
    rock = bpy.context.object
    rock.name = "Rock"
    rock.canopy_ao.role = 'TRUNK'
    rng = np.random.default_rng(3)
    n = 600
    centre = np.array([0.2, -0.1, 1.8])
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    c = centre + d * (0.9 * rng.random(n) ** (1 / 3))[:, None] * np.array([1.0, 1.0, 0.7])
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(u, rng.normal(size=(n, 3)))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    s = 0.09
    verts = np.stack([c - s * u - s * v, c + s * u - s * v, c + s * u + s * v,
                      c - s * u + s * v], axis=1).reshape(-1, 3)
    faces = np.arange(4 * n).reshape(n, 4)
    me = bpy.data.meshes.new("Leaves")
    me.from_pydata(verts.tolist(), [], faces.tolist())
    leaves = bpy.data.objects.new("Leaves", me)
    bpy.context.scene.collection.objects.link(leaves)
    ground.canopy_ao.role, trunk.canopy_ao.role = 'GROUND', 'TRUNK'
    leaves.canopy_ao.role = 'CANOPY'
    bpy.context.view_layer.update()
    return ground


EDGE_STEP = 0.15


def _edges(ref, mask):
    """bool (H, W): covered texels whose reference differs from a covered 4-neighbour's by more
    than EDGE_STEP (the rock's and the trunk's contact edges), where a texel's footprint
    straddles a step."""
    edge = np.zeros_like(mask)
    for axis in (0, 1):
        step = np.abs(np.diff(ref, axis=axis)) > EDGE_STEP
        both = np.logical_and(np.take(mask, range(1, mask.shape[axis]), axis=axis),
                              np.take(mask, range(0, mask.shape[axis] - 1), axis=axis))
        step &= both
        lo = [slice(None)] * 2
        hi = [slice(None)] * 2
        lo[axis], hi[axis] = slice(0, -1), slice(1, None)
        edge[tuple(lo)] |= step
        edge[tuple(hi)] |= step
    return edge & mask


def _mae(got, ref, mask, edge):
    err = np.abs(got - ref)
    return f"{err[mask].mean():.4f} / {err[edge].mean():.4f}"


def ours(res, samples, aa, image_dir):
    """Our texel bake of Ground by rays at `samples` rays per texel, aa × aa sub-samples: its
    texel target (rx.pixels, ao)."""
    import bpy
    from canopy_ao.blender import job, properties
    opts = dict(properties.scene_options(bpy.context.scene), mode='TEXEL', method="raytrace",
                samples=samples, texel_aa=aa, resolution=res, margin=0, distance=DISTANCE,
                use_world_distance=False, show_proxies=False, image_dir=image_dir,
                overwrite=True)
    done, _rep = job.run_bake(bpy.context, ["Ground"], opts)
    return done.targets[0]


def main(argv):
    import bpy
    harness.enable_addon()
    from canopy_ao.blender import cycles_check
    a = _args(argv)
    res = a.resolution
    ground = build_scene()
    t0 = time.perf_counter()
    ref, mask = cycles_check.bake_cycles_texel_ao(bpy.context, ground, None, res, DISTANCE,
                                                  a.reference, return_mask=True, seed=1)
    print(f"ground under a small tree, {res} x {res} texels ({int(mask.sum())} covered), "
          f"AO distance {DISTANCE} m; reference: Cycles at {a.reference} samples, seed 1 "
          f"({time.perf_counter() - t0:.1f} s)")
    edge = _edges(ref, mask)
    print(f"MAE against the reference (all covered texels / the {int(edge.sum())} edge texels, "
          f"where the reference steps by more than {EDGE_STEP} to a neighbour), equal rays per "
          "texel:")
    with tempfile.TemporaryDirectory() as tmp:
        for s in (int(x) for x in a.samples.split(",")):
            cyc = cycles_check.bake_cycles_texel_ao(bpy.context, ground, None, res, DISTANCE,
                                                    s, seed=0)
            line = [f"  S = {s:4d}: Cycles {_mae(cyc, ref, mask, edge)}"]
            for n in (int(x) for x in a.aa.split(",")):
                t = ours(res, s, n, tmp)
                img = np.zeros(res * res, np.float32)
                img[t.rx.pixels] = t.ao
                line.append(f"ours AA {n}x{n} {_mae(img.reshape(res, res), ref, mask, edge)}")
            print(", ".join(line), flush=True)


if __name__ == "__main__":
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    try:
        main(argv)
    except Exception as exc:  # a benchmark run: the message, a non-zero exit
        import traceback
        traceback.print_exc()
        sys.stderr.write(f"texel_aa.py: {exc}\n")
        sys.exit(1)
