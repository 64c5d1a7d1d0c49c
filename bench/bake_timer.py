"""In Blender: Cycles' AO bake and ours on the open .blend, timed in turn (bench/equal_error.py).

    blender -b SCENE.blend --python-exit-code 1 --python bench/bake_timer.py -- \\
        [--roles EXPORT.npz] [--bake-cycles S ...] [--ours raytrace:16 regression ...]
        [--repeats 3] [--json OUT.json] [--ao OUT.npz] [--save-roles OUT.blend] [--write --save]

Bakes every mesh of the file. Contenders: ``cycles:S`` is Cycles' own per-vertex AO bake at S
samples (Cycles' seed 0, canopy_ao.blender.cycles_check: its scene sync, BVH, samples and the
read-back), ``METHOD[:S]`` is the add-on's bake (``job.run_bake``, as the operator and the CLI
run it: read the meshes, bake, write the attribute), both with the World's AO distance. They
are timed round after round, the order rotated each round (bench/harness.interleave): the
seconds of every round go to ``--json``, so the ratios are of one run. ``--roles`` sets each
object's role and tree from a Sapling export (examples/sapling_scenes.py) before anything is
timed, and ``--save-roles`` saves that file for whole-process runs. ``--ao`` writes Cycles' AO
of the last round per contender (``<contender>/<object>``). ``--write --save``: one Cycles
bake (the single ``--bake-cycles`` given), its AO written into a FLOAT_COLOR attribute ``CyclesAO``
of each mesh and the .blend saved: Cycles' side of a whole process (Blender started, scene
loaded, baked, written).
"""
import json
import os
import sys

import bpy

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

import numpy as np  # noqa: E402


def parse(argv):
    ap = harness.parser(__doc__, prog="bake_timer.py", repeats=3)
    ap.add_argument("--roles", help="a Sapling export (.npz) naming each object's role and tree")
    ap.add_argument("--bake-cycles", type=int, nargs="*", default=[], metavar="S", dest="cycles",
                    help="Cycles' sample counts (not --cycles, which Blender's Cycles add-on claims)")
    ap.add_argument("--ours", nargs="*", default=[], metavar="METHOD[:S]")
    ap.add_argument("--json")
    ap.add_argument("--ao")
    ap.add_argument("--save-roles", metavar="OUT.blend")
    ap.add_argument("--write", action="store_true", help="write Cycles' AO into 'CyclesAO'")
    ap.add_argument("--save", action="store_true", help="save the .blend afterwards")
    a = ap.parse_args(argv)
    if any(s < 1 for s in a.cycles):
        ap.error("--bake-cycles: sample counts must be ≥ 1")
    if a.write and len(a.cycles) != 1:
        ap.error("--write bakes once: give exactly one --bake-cycles S")
    return a


def set_roles(path):
    """Each object's role and tree as the export has them (the role a user would give it)."""
    with np.load(path) as z:
        for n in z["names"]:
            ob = bpy.data.objects.get(str(n))
            if ob is None:
                raise RuntimeError(f"{path} names {n!r}, which this .blend does not have")
            ob.canopy_ao.role = str(z[f"{n}/role"]).upper()
            ob.canopy_ao.tree = str(z[f"{n}/tree"])


def write_cycles(ao):
    """AO into a FLOAT_COLOR POINT attribute 'CyclesAO' per mesh (grey, alpha 1)."""
    for name, values in ao.items():
        me = bpy.data.objects[name].data
        attr = (me.color_attributes.get("CyclesAO")
                or me.color_attributes.new("CyclesAO", "FLOAT_COLOR", "POINT"))
        rgba = np.repeat(np.asarray(values, np.float32)[:, None], 4, axis=1)
        rgba[:, 3] = 1.0
        attr.data.foreach_set("color", rgba.ravel())
        me.update()


def main(argv):
    a = parse(argv)
    if not a.write:
        harness.enable_addon()  # before canopy_ao is imported from addon/ below
    from canopy_ao.blender import cycles_check
    scene = bpy.context.scene
    objects = [o for o in scene.objects if o.type == "MESH" and o.visible_get()]
    names = [o.name for o in objects]
    distance = scene.world.light_settings.distance if scene.world else 0.0
    if not distance > 0:
        raise RuntimeError("the World's AO distance is 0: set the distance Cycles bakes with")

    if a.write:
        ao = cycles_check.bake_cycles_vertex_ao(bpy.context, objects, distance, a.cycles[0],
                                                seed=0)
        write_cycles(ao)
        if a.save:
            bpy.ops.wm.save_mainfile()
        return 0

    from canopy_ao.blender import job, properties
    if a.roles:
        set_roles(a.roles)
    if a.save_roles:
        bpy.ops.wm.save_as_mainfile(filepath=os.path.abspath(a.save_roles), copy=True)

    def cycles(s):
        return lambda: cycles_check.bake_cycles_vertex_ao(bpy.context, objects, distance, s,
                                                          seed=0)

    def ours(method, s):
        opts = dict(properties.scene_options(scene), method=method, distance=distance,
                    show_proxies=False)
        if s:
            opts["samples"] = s
        return lambda: job.run_bake(bpy.context, names, opts)[1]

    contenders = {f"cycles:{s}": cycles(s) for s in a.cycles}
    for spec in a.ours:
        method, _, s = spec.partition(":")
        contenders[spec] = ours(method, int(s) if s else 0)
    if not contenders:
        raise RuntimeError("nothing to time: give --bake-cycles and/or --ours")
    runs = harness.interleave(contenders, a.repeats)
    for n, t in runs.items():
        print(f"bake_timer: {n}: min {t.min:.3f} s, median {t.median:.3f} s "
              f"({len(t.seconds)} rounds)", flush=True)
    if a.json:
        with open(a.json, "w") as fh:
            json.dump({"seconds": {n: t.seconds for n, t in runs.items()},
                       "load": harness.load_note(), "vertices": sum(len(o.data.vertices)
                                                                     for o in objects)}, fh)
    if a.ao:
        np.savez_compressed(a.ao, **{f"{n}/{o}": v for n, t in runs.items()
                                     if n.startswith("cycles:") for o, v in t.result.items()})
    if a.save:
        bpy.ops.wm.save_mainfile()
    return 0


if __name__ == "__main__":
    harness.run_in_blender(main, "bake_timer")
