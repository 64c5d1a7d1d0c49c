"""Foliage as artists make it (issue #38): every rung on examples/foliage_scenes.py's scenes,
in Blender, against our own rays at 256 samples (which honour the cards' alpha), per role:
MAE and bias, beside a constant (each object's mean reference AO), and the issue's targets:

- a tree joined into one object against the same tree in two objects, rung by rung (MAE);
- the trunk's and the ground's bias under the card tree against under the same tree with opaque
  leaves of the cards' opaque area (difference per rung);
- ivy on a wall: the ray-free rung's MAE, and any rung worse than the constant.

    blender -b --factory-startup --python-exit-code 1 --python bench/foliage.py -- \\
        --out bench/out/foliage.md
    blender -b --factory-startup --python-exit-code 1 --python bench/foliage.py -- --speed

Exits non-zero on failure (not when a target is missed: the table says so).
"""
import argparse
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, os.path.join(REPO, "examples"))
sys.path.insert(0, os.path.join(REPO, "addon"))

import numpy as np  # noqa: E402

RUNGS = ("sphere", "ellipsoid", "shells", "medium", "reeves_blau", "grid", "regression",
         "hybrid", "auto")
REF_SAMPLES = 256


def _bake(method, samples=64):
    """{object: AO (V,)}, {object: role} of one bake of every visible mesh."""
    import bpy
    from canopy_ao.blender import mesh_io, properties
    from canopy_ao.blender.job import run_bake
    for ob in bpy.context.scene.objects:
        ob.select_set(False)
    opts = properties.scene_options(bpy.context.scene)
    opts.update(method=method, samples=samples, overwrite=True)
    _job, rep = run_bake(bpy.context, [], opts)
    ao = {n: mesh_io.read_ao_attribute(bpy.data.objects[n], opts["attribute"])
          for n in rep["objects"]}
    return ao, {n: e["role"] for n, e in rep["objects"].items()}


def scene_rungs(scene):
    """{"ref": ..., rung: ...} of (ao, roles) bakes of ``scene``."""
    import foliage_scenes
    foliage_scenes.build(scene)
    out = {"ref": _bake("raytrace", REF_SAMPLES)}
    for m in RUNGS:
        out[m] = _bake(m)
    return out


def _by_role(ao, roles, names=None):
    got = {}
    for n, a in ao.items():
        if names is None or n in names:
            got.setdefault(roles[n], []).append(a)
    return {r: np.concatenate(v) for r, v in got.items()}


def table(scene, res):
    """Markdown rows: per rung and role, MAE and bias against the reference; the constant."""
    ref_ao, roles = res["ref"]
    ref = _by_role(ref_ao, roles)
    const = _by_role({n: np.full_like(a, a.mean()) for n, a in ref_ao.items()}, roles)
    lines = [f"### {scene}", "", "| rung | " + " | ".join(f"{r} MAE / bias" for r in ref) + " |",
             "|---|" + "---|" * len(ref)]
    worse = []
    for m in ("constant",) + RUNGS:
        got = const if m == "constant" else _by_role(res[m][0], roles)
        cells = []
        for r, want in ref.items():
            e = float(np.abs(got[r] - want).mean())
            b = float((got[r] - want).mean())
            cells.append(f"{e:.3f} / {b:+.3f}")
            if m != "constant" and e > float(np.abs(const[r] - want).mean()):
                worse.append(f"{m} on {r}")
        lines.append(f"| {m} | " + " | ".join(cells) + " |")
    lines += ["", "worse than the constant: " + (", ".join(worse) or "none"), ""]
    return lines


def speed(repeats=3):
    """Lines: per rung, the seconds of a bake of the card tree (leaves at the preset's full
    count) with its card vertices carrying their opaque part's AO (core/card_ao.py) over the
    same bake without, best of ``repeats``, as a ratio (one run: compare ratios, not times)."""
    import time
    import bpy
    import foliage_scenes
    from canopy_ao.core import card_ao
    foliage_scenes.build("card_tree")  # an empty file with its World, then the bigger tree
    for ob in list(bpy.data.objects):
        bpy.data.objects.remove(ob)
    col = bpy.data.collections.new("Speed")
    bpy.context.scene.collection.children.link(col)
    foliage_scenes.sapling_card_tree(col, leaf_factor=1.0)
    foliage_scenes.ground(col)
    bpy.context.view_layer.update()
    carry, out = card_ao.carry, []
    for m in ("ellipsoid", "grid", "raytrace"):
        best = {}
        for on in (True, False):
            card_ao.carry = carry if on else (lambda *a, **k: None)
            for _ in range(repeats):
                t0 = time.perf_counter()
                _bake(m)
                best[on] = min(best.get(on, 1e9), time.perf_counter() - t0)
        card_ao.carry = carry
        out.append(f"| {m} | {best[True]:.2f} | {best[False]:.2f} | "
                   f"{best[True] / best[False]:.2f} |")
    return ["### Card vertices' AO: cost", "", "| rung | with (s) | without (s) | ratio |",
            "|---|---|---|---|"] + out + [""]


def main(argv):
    ap = argparse.ArgumentParser(prog="foliage.py")
    ap.add_argument("--out", default=os.path.join(REPO, "bench", "out", "foliage.md"))
    ap.add_argument("--speed", action="store_true",
                    help="only time the card vertices' AO (with over without, per rung)")
    a = ap.parse_args(argv)
    import addon_utils
    if addon_utils.enable("canopy_ao", default_set=True, handle_error=None) is None:
        raise RuntimeError("the canopy_ao add-on did not enable")
    if a.speed:
        print("\n".join(speed()))
        return 0
    import foliage_scenes
    res = {}
    for scene in foliage_scenes.SCENES:
        res[scene] = scene_rungs(scene)
        print(f"foliage: {scene} baked", flush=True)
    lines = ["# Foliage scenes: every rung against rays at 256 samples", ""]
    for scene, r in res.items():
        lines += table(scene, r)
    lines += ["### Targets", "", "| rung | joined vs split MAE | trunk bias card − opaque | "
              "ground bias card − opaque |", "|---|---|---|---|"]
    split, joined = res["card_tree"], res["card_tree_joined"]
    card, opaque = res["card_tree"], res["opaque_tree"]

    def bias(r, m, name):
        return float((r[m][0][name] - r["ref"][0][name]).mean())
    for m in ("ref",) + RUNGS:
        s = np.concatenate([split[m][0]["Tree_branches"], split[m][0]["Tree_leaves"]])
        j = joined[m][0]["Tree"]
        row = f"| {m if m != 'ref' else 'raytrace 256'} | {float(np.abs(s - j).mean()):.4f} |"
        if m != "ref":
            row += (f" {bias(card, m, 'Tree_branches') - bias(opaque, m, 'Tree_branches'):+.3f} |"
                    f" {bias(card, m, 'Ground') - bias(opaque, m, 'Ground'):+.3f} |")
        else:
            row += " | |"
        lines.append(row)
    text = "\n".join(lines) + "\n"
    os.makedirs(os.path.dirname(os.path.abspath(a.out)), exist_ok=True)
    with open(a.out, "w", encoding="utf-8") as f:
        f.write(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.path.insert(0, os.path.join(REPO, "examples"))
    from blender_script import run
    run(main, "foliage")
