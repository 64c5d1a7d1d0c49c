"""Foliage as artists make it, built with Blender's own tools (issue #38 item 6), for the tests
and the benchmark:

- ``card_tree``: a Sapling tree whose rectangular leaves carry an alpha-textured card material
  (a lens-shaped leaf on a transparent card), bark and leaves in two objects, over a ground;
- ``card_tree_joined``: the same tree joined into one mesh (two material slots);
- ``opaque_tree``: the same tree with opaque leaves of the card's opaque area (each card shrunk
  about its centre by √(opaque fraction));
- ``sapling_joined``: the plain Sapling tree (no materials) joined into one mesh;
- ``ivy_wall``: IvyGen ivy on a wall over a ground (Blender ≤ 4.1 bundles IvyGen);
- ``gn_cards``: leaf cards scattered on a crown by Geometry Nodes (Instance on Points on a
  sphere's faces, realised with ``--realize``), with a Sapling trunk.

    blender -b --factory-startup --python-exit-code 1 --python examples/foliage_scenes.py -- \\
        --scene card_tree_joined --blend /tmp/card_tree_joined.blend

Sapling and IvyGen must be bundled (Blender ≤ 4.1); the script fails with a message otherwise.
"""
import argparse
import math
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

import numpy as np  # noqa: E402

SCENES = ("card_tree", "card_tree_joined", "opaque_tree", "sapling_joined", "ivy_wall",
          "gn_cards")
# The card's leaf: a lens |2u − 1|² / w² + |2v − 1|² < 1 of half-width w across the card.
LEAF_WIDTH = 0.6
TREE = dict(preset="quaking_aspen", seed=5, leaf_factor=0.25)


# === Materials ===============================================================================

def leaf_card_image(name, res=64, width=LEAF_WIDTH, centre=0.0, length=1.0):
    """A packed RGBA image: a green lens-shaped leaf, alpha 1 inside and 0 outside: in card
    coordinates x = 2u − 1, y = 2v − 1, (x / width)² + ((y − centre) / length)² < 1. Returns
    (image, opaque fraction of its texels)."""
    import bpy
    c = (np.arange(res) + 0.5) / res * 2.0 - 1.0
    u, v = np.meshgrid(c, c)  # row = v
    inside = (u / width) ** 2 + ((v - centre) / length) ** 2 < 1.0
    px = np.zeros((res, res, 4), np.float32)
    px[..., 1] = 0.4
    px[..., 3] = inside
    img = bpy.data.images.new(name, res, res, alpha=True)
    img.pixels.foreach_set(px.reshape(-1))
    img.pack()
    return img, float(inside.mean())


def card_material(name, image):
    """A Principled BSDF whose Alpha is the image's alpha (read through the UV map)."""
    import bpy
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    mat.blend_method = 'CLIP'
    nt = mat.node_tree
    bsdf = nt.nodes["Principled BSDF"]
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = image
    tex.interpolation = 'Closest'  # the texel the UV falls in: a sharp leaf edge
    nt.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    nt.links.new(tex.outputs["Alpha"], bsdf.inputs["Alpha"])
    return mat


def plain_material(name, color):
    import bpy
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (*color, 1.0)
    return mat


# === Objects =================================================================================

def _collection(name):
    import bpy
    col = bpy.data.collections.new(name)
    bpy.context.scene.collection.children.link(col)
    return col


def shrink_pieces(ob, factor):
    """Scale each loose piece of ob's mesh about its centroid by ``factor`` (in place)."""
    from canopy_ao.core.roles import connected_components
    me = ob.data
    n = len(me.vertices)
    co = np.empty(3 * n, np.float32)
    me.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3).astype(np.float64)
    me.calc_loop_triangles()
    t = np.empty(3 * len(me.loop_triangles), np.int32)
    me.loop_triangles.foreach_get("vertices", t)
    lab = connected_components(n, t.reshape(-1, 3))
    k = int(lab.max()) + 1
    cnt = np.bincount(lab, minlength=k)[:, None]
    mean = np.stack([np.bincount(lab, co[:, i], k) for i in range(3)], 1) / cnt
    co = mean[lab] + factor * (co - mean[lab])
    me.vertices.foreach_set("co", co.astype(np.float32).reshape(-1))
    me.update()


def join(objects, name):
    """Join ``objects`` into the first (Object > Join), renamed ``name``."""
    import bpy
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    for o in objects:
        o.select_set(True)
    bpy.context.view_layer.objects.active = objects[0]
    bpy.ops.object.join()
    ob = bpy.context.view_layer.objects.active
    ob.name = ob.data.name = name
    return ob


def ground(col, size=16.0):
    import bpy
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=48, y_subdivisions=48, size=size)
    g = bpy.context.active_object
    g.name = g.data.name = "Ground"
    for c in list(g.users_collection):
        c.objects.unlink(g)
    col.objects.link(g)
    return g


def sapling_card_tree(col, cards=True, opaque_area=False, joined=False, materials=True,
                      preset=TREE["preset"], seed=TREE["seed"], leaf_factor=TREE["leaf_factor"]):
    """A Sapling tree with rectangular leaves: {role: object}. cards: the leaves carry the
    alpha-textured card material; opaque_area: instead, opaque leaves each shrunk to the card's
    opaque area; joined: bark and leaves joined into one mesh ("Tree"); materials: bark and
    leaf materials at all (without, the tree has none, as Sapling makes it)."""
    import addon_utils
    import sapling_scenes
    addon_utils.enable("add_curve_sapling", default_set=False)
    branches, leaves = sapling_scenes.sapling_tree(preset, seed, (0, 0), "Tree", leaf_factor,
                                                   col, coarse=True, leafShape="rect")
    if materials:
        branches.data.materials.append(plain_material("Bark", (0.3, 0.2, 0.1)))
        if cards or opaque_area:
            img, frac = leaf_card_image("LeafCard")
            if cards:
                leaves.data.materials.append(card_material("Leaf card", img))
            else:
                leaves.data.materials.append(plain_material("Leaves", (0.1, 0.4, 0.1)))
                shrink_pieces(leaves, math.sqrt(frac))
        else:
            leaves.data.materials.append(plain_material("Leaves", (0.1, 0.4, 0.1)))
    if joined:
        return {"tree": join([branches, leaves], "Tree")}
    return {"trunk": branches, "canopy": leaves}


def build(scene, realize=False):
    """Build ``scene`` (SCENES) in an empty file. Returns {name: object}."""
    import bpy
    import sapling_scenes
    sapling_scenes._clear()
    col = _collection(scene)
    out = {}
    if scene in ("card_tree", "card_tree_joined", "opaque_tree", "sapling_joined"):
        out.update(sapling_card_tree(col, cards=scene.startswith("card"),
                                     opaque_area=scene == "opaque_tree",
                                     joined=scene.endswith("joined"),
                                     materials=scene != "sapling_joined"))
        out["ground"] = ground(col)
    else:
        raise ValueError(f"unknown scene {scene!r} (one of {', '.join(SCENES)})")
    world = bpy.data.worlds.new("World")
    bpy.context.scene.world = world
    world.light_settings.distance = 10.0
    bpy.context.view_layer.update()
    return out


def main(argv):
    import bpy
    ap = argparse.ArgumentParser(prog="foliage_scenes.py")
    ap.add_argument("--scene", choices=SCENES, required=True)
    ap.add_argument("--realize", action="store_true", help="gn_cards: realise the instances")
    ap.add_argument("--blend", required=True, help="save the scene to this .blend")
    a = ap.parse_args(argv)
    objs = build(a.scene, a.realize)
    bpy.ops.wm.save_as_mainfile(filepath=os.path.abspath(a.blend))
    print(f"foliage_scenes: {a.scene}: {', '.join(o.name for o in objs.values())} -> {a.blend}")
    return 0


if __name__ == "__main__":
    sys.path.insert(0, os.path.join(os.path.dirname(HERE), "addon"))
    from blender_script import run
    run(main, "foliage_scenes")
