"""Foliage as artists make it, built with Blender's own tools (issue #38 item 6), for the tests
and the benchmark:

- ``card_tree``: a Sapling tree whose rectangular leaves carry an alpha-textured card material
  (a lens-shaped leaf on a transparent card), bark and leaves in two objects, over a ground;
- ``card_tree_joined``: the same tree joined into one mesh (two material slots);
- ``card_birch``: a larger tree for pictures (the README's): a Sapling white birch at the
  preset's own resolution, twice its leaves at 1.5 times their size, with the same cards;
- ``opaque_tree``: the same tree with opaque leaves of the card's opaque area (each card shrunk
  about its centre by √(opaque fraction));
- ``sapling_joined``: the plain Sapling tree (no materials) joined into one mesh;
- ``ivy_wall``: IvyGen ivy on a wall over a ground (Blender ≤ 4.1 bundles IvyGen);
- ``gn_cards``: leaf cards scattered on a crown by Geometry Nodes (Instance on Points on an
  icosphere's faces, realised with ``--realize``) over a trunk and a ground;
- ``particle_cards``: the same cards scattered by a hair particle system drawn as objects.

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
          "gn_cards", "particle_cards")
PICTURES = ("card_birch",)  # for pictures, not benchmarks (bench/foliage.py bakes SCENES)
# The card's leaf: a lens |2u − 1|² / w² + |2v − 1|² < 1 of half-width w across the card.
LEAF_WIDTH = 0.6
TREE = dict(preset="quaking_aspen", seed=5, leaf_factor=0.25)
# card_birch: dense and leafy enough to read as a tree at a glance (its leaves 1.5 × the
# preset's 0.2, so the cards' cut-out shows at 900 × 600).
BIRCH = dict(preset="white_birch", seed=5, leaf_factor=2.0, coarse=False, leafScale=0.3)


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
                      preset=TREE["preset"], seed=TREE["seed"], leaf_factor=TREE["leaf_factor"],
                      coarse=True, **extra):
    """A Sapling tree with rectangular leaves: {role: object}. cards: the leaves carry the
    alpha-textured card material; opaque_area: instead, opaque leaves each shrunk to the card's
    opaque area; joined: bark and leaves joined into one mesh ("Tree"); materials: bark and
    leaf materials at all (without, the tree has none, as Sapling makes it); coarse: Sapling's
    coarsest branch resolution; extra: Sapling settings over the preset's."""
    import addon_utils
    import sapling_scenes
    addon_utils.enable("add_curve_sapling", default_set=False)
    branches, leaves = sapling_scenes.sapling_tree(preset, seed, (0, 0), "Tree", leaf_factor,
                                                   col, coarse=coarse, leafShape="rect",
                                                   **extra)
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
        # One UV map name for both, or the join keeps two maps and the leaves' would not be
        # the one that renders (the card's image would be read at UV (0, 0), Cycles too).
        if leaves.data.uv_layers:
            leaves.data.uv_layers[0].name = (branches.data.uv_layers[0].name
                                             if branches.data.uv_layers else "UVMap")
        return {"tree": join([branches, leaves], "Tree")}
    return {"trunk": branches, "canopy": leaves}


def leaf_card_object(col, name="LeafCard", size=0.2, named_uv=True):
    """One leaf card (a quad, UVs [0, 1]², the card material) hidden from renders, to be
    instanced. named_uv: its material reads the map through a UV Map node (realised by
    geometry nodes in Blender 3.4, a UV map is an attribute Cycles finds only by name)."""
    import bpy
    h = 0.5 * size
    me = bpy.data.meshes.new(name)
    me.from_pydata([[-h, 0, 0], [h, 0, 0], [h, 0, size], [-h, 0, size]], [], [[0, 1, 2, 3]])
    uv = me.uv_layers.new(name="UVMap")
    uv.data.foreach_set("uv", np.float32([[0, 0], [1, 0], [1, 1], [0, 1]]).ravel())
    img, _frac = leaf_card_image(f"{name}Image", 32)
    mat = card_material(f"{name} card", img)
    if named_uv:
        node = mat.node_tree.nodes.new("ShaderNodeUVMap")
        node.uv_map = "UVMap"
        tex = next(n for n in mat.node_tree.nodes if n.type == "TEX_IMAGE")
        mat.node_tree.links.new(node.outputs[0], tex.inputs["Vector"])
    me.materials.append(mat)
    ob = bpy.data.objects.new(name, me)
    col.objects.link(ob)
    ob.hide_render = True  # only its instances render
    ob.location = (0.0, 0.0, -10.0 * size)  # out of the way (instances keep their own place)
    return ob


def gn_scatter(crown, card, density=30.0, realize=False, seed=0):
    """Geometry Nodes on ``crown``: Distribute Points on Faces, Instance on Points of ``card``
    (Object Info, original space) at random rotations, and Realize Instances when asked."""
    import bpy
    ng = bpy.data.node_groups.new("Scatter leaves", "GeometryNodeTree")
    for io in ("INPUT", "OUTPUT"):
        if hasattr(ng, "interface"):  # Blender 4.0+
            ng.interface.new_socket(name="Geometry", in_out=io, socket_type="NodeSocketGeometry")
        else:
            (ng.inputs if io == "INPUT" else ng.outputs).new("NodeSocketGeometry", "Geometry")
    n, link = ng.nodes, ng.links.new
    gin, gout = n.new("NodeGroupInput"), n.new("NodeGroupOutput")
    dist = n.new("GeometryNodeDistributePointsOnFaces")
    dist.inputs["Density"].default_value = density
    dist.inputs["Seed"].default_value = seed
    inst = n.new("GeometryNodeInstanceOnPoints")
    info = n.new("GeometryNodeObjectInfo")
    info.inputs[0].default_value = card
    info.transform_space = 'ORIGINAL'
    rot = n.new("FunctionNodeRandomValue")
    rot.data_type = 'FLOAT_VECTOR'
    rot.inputs["Max"].default_value = (2 * math.pi,) * 3
    link(gin.outputs[0], dist.inputs["Mesh"])
    link(dist.outputs["Points"], inst.inputs["Points"])
    link(info.outputs["Geometry"], inst.inputs["Instance"])
    link(rot.outputs[0], inst.inputs["Rotation"])
    out = inst.outputs[0]
    if realize:
        real = n.new("GeometryNodeRealizeInstances")
        link(out, real.inputs[0])
        out = real.outputs[0]
    link(out, gout.inputs[0])
    crown.modifiers.new("Scatter leaves", "NODES").node_group = ng


def particle_scatter(crown, card, count=800, seed=0):
    """A hair particle system on ``crown`` drawing ``card`` at each particle (random
    rotations); the crown itself is not rendered."""
    crown.modifiers.new("Leaves", "PARTICLE_SYSTEM")
    ps = crown.particle_systems[0]
    ps.seed = seed
    st = ps.settings
    st.type = 'HAIR'
    st.count = count
    st.hair_length = 0.2
    st.render_type = 'OBJECT'
    st.instance_object = card
    st.particle_size = 1.0
    st.use_rotations = True
    st.rotation_mode = 'NOR'
    st.rotation_factor_random = 1.0
    crown.show_instancer_for_render = False
    crown.show_instancer_for_viewport = False


def scatter_tree(col, how="gn", made_real=False):
    """A trunk (a cylinder) and a crown (an icosphere) whose leaf cards are scattered by
    ``how``: "gn" (instances), "gn_realized" (Realize Instances) or "particles". made_real: the
    scattered cards then made into a plain mesh object ("Leaves", as Object > Apply > Visual
    Geometry to Mesh or Make Instances Real and Join would). Returns {name: object}."""
    import bpy
    bpy.ops.mesh.primitive_cylinder_add(radius=0.15, depth=3.0, location=(0, 0, 1.5))
    trunk = bpy.context.active_object
    trunk.name = trunk.data.name = "Trunk"
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=3, radius=1.5, location=(0, 0, 3.2))
    crown = bpy.context.active_object
    crown.name = crown.data.name = "Crown"
    for ob in (trunk, crown):
        for c in list(ob.users_collection):
            c.objects.unlink(ob)
        col.objects.link(ob)
    card = leaf_card_object(col)
    if how == "particles":
        particle_scatter(crown, card)
    else:
        gn_scatter(crown, card, realize=how == "gn_realized")
    bpy.context.view_layer.update()
    if made_real:
        crown = _made_real(crown, how)
    return {"trunk": trunk, "crown": crown, "card": card}


def _made_real(crown, how):
    """The crown's scattered cards as one plain mesh object named "Leaves" (the crown goes)."""
    import bpy
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    crown.select_set(True)
    bpy.context.view_layer.objects.active = crown
    if how == "particles":
        before = set(bpy.data.objects)
        bpy.ops.object.duplicates_make_real()
        made = [o for o in bpy.data.objects if o not in before]
        for o in made:
            o.hide_render = False
        leaves = join(made, "Leaves")
        bpy.data.objects.remove(crown)
    else:
        gn_realize(crown)
        bpy.ops.object.convert(target='MESH')
        leaves = bpy.context.view_layer.objects.active
        leaves.name = leaves.data.name = "Leaves"
    bpy.context.view_layer.update()
    return leaves


def gn_realize(crown):
    """Put a Realize Instances node before the crown's node-group output, if none is there."""
    ng = crown.modifiers[-1].node_group
    out = next(n for n in ng.nodes if n.type == "GROUP_OUTPUT")
    src = out.inputs[0].links[0].from_node
    if src.type == "REALIZE_INSTANCES":
        return
    real = ng.nodes.new("GeometryNodeRealizeInstances")
    ng.links.new(src.outputs[0], real.inputs[0])
    ng.links.new(real.outputs[0], out.inputs[0])


def ivy_wall(col, thick=0.0, length=3.0, seed=3):
    """IvyGen ivy grown from the foot of a 3 m × 2 m wall (a quad, or a slab ``thick`` deep)
    standing on an 8 m ground: {"wall", "ground", and IvyGen's objects}. Needs IvyGen (bundled
    up to Blender 4.1)."""
    import addon_utils
    import bpy
    addon_utils.enable("add_curve_ivygen", default_set=False)
    if thick:
        bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0, 0, 1))
        bpy.context.active_object.scale = (3, thick, 2)
    else:
        bpy.ops.mesh.primitive_plane_add(size=1.0, location=(0, 0, 1), rotation=(math.pi / 2, 0, 0))
        bpy.context.active_object.scale = (3, 2, 1)
    wall = bpy.context.active_object
    wall.name = "Wall"
    bpy.ops.object.transform_apply(location=True, rotation=True, scale=True)
    bpy.ops.mesh.primitive_plane_add(size=8.0)
    ground = bpy.context.active_object
    ground.name = "Ground"
    bpy.ops.object.select_all(action='DESELECT')
    wall.select_set(True)
    bpy.context.view_layer.objects.active = wall
    before = set(bpy.data.objects)
    bpy.context.scene.cursor.location = (0.0, -thick / 2 - 0.01, 0.02)
    props = bpy.context.window_manager.ivy_gen_props
    props.maxIvyLength, props.randomSeed = length, seed
    if bpy.ops.curve.ivy_gen(updateIvy=True) != {'FINISHED'}:
        raise RuntimeError("IvyGen did not grow the ivy")
    bpy.context.scene.cursor.location = (0.0, 0.0, 0.0)
    out = {"wall": wall, "ground": ground}
    out.update({o.name: o for o in bpy.data.objects if o not in before})
    for ob in out.values():
        for c in list(ob.users_collection):
            c.objects.unlink(ob)
        col.objects.link(ob)
    return out


def build(scene, realize=False):
    """Build ``scene`` (SCENES) in the current file, emptied of objects, meshes, curves,
    collections, materials, images, node groups and particle settings first. Returns {role or
    name: object}."""
    import bpy
    import sapling_scenes
    sapling_scenes._clear()
    for data in (bpy.data.materials, bpy.data.images, bpy.data.node_groups,
                 bpy.data.particles):
        for block in list(data):
            data.remove(block)
    col = _collection(scene)
    out = {}
    if scene in ("card_tree", "card_tree_joined", "opaque_tree", "sapling_joined"):
        out.update(sapling_card_tree(col, cards=scene.startswith("card"),
                                     opaque_area=scene == "opaque_tree",
                                     joined=scene.endswith("joined"),
                                     materials=scene != "sapling_joined"))
        out["ground"] = ground(col)
    elif scene == "card_birch":
        out.update(sapling_card_tree(col, **BIRCH))
        out["ground"] = ground(col)
    elif scene == "ivy_wall":
        out.update(ivy_wall(col))
    elif scene == "gn_cards":
        out.update(scatter_tree(col, "gn_realized" if realize else "gn"))
        out["ground"] = ground(col)
    elif scene == "particle_cards":
        out.update(scatter_tree(col, "particles"))
        out["ground"] = ground(col)
    else:
        raise ValueError(f"unknown scene {scene!r} (one of {', '.join(SCENES + PICTURES)})")
    world = bpy.data.worlds.new("World")
    bpy.context.scene.world = world
    world.light_settings.distance = 10.0
    bpy.context.view_layer.update()
    return out


def main(argv):
    import bpy
    ap = argparse.ArgumentParser(prog="foliage_scenes.py")
    ap.add_argument("--scene", choices=SCENES + PICTURES, required=True)
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
