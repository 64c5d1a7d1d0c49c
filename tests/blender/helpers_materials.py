"""Small scene builders for the materials / AOV / Cycles-check / texel tests.

They build their own tiny scenes (no dependency on conftest fixtures) and make
`import canopy_ao` work when the harness has not put the add-on on sys.path.
"""
import pathlib
import sys

import bpy
import numpy as np

ADDON_DIR = pathlib.Path(__file__).resolve().parents[2] / "addon"
if str(ADDON_DIR) not in sys.path:
    sys.path.insert(0, str(ADDON_DIR))


def empty_scene():
    """A fresh empty file; every test starts from here. read_homefile, not
    read_factory_settings: the latter also resets preferences and so disables the add-on the
    harness enabled for the whole session."""
    bpy.ops.wm.read_homefile(use_empty=True)
    return bpy.context.scene


def add_plane(size=2.0, subdivisions=0, location=(0, 0, 0), name=None):
    bpy.ops.mesh.primitive_plane_add(size=size, location=location)
    obj = bpy.context.object
    if subdivisions:
        bpy.ops.object.mode_set(mode="EDIT")
        bpy.ops.mesh.subdivide(number_cuts=subdivisions)
        bpy.ops.object.mode_set(mode="OBJECT")
    if name:
        obj.name = name
    return obj


def leaves_over_ground(ground, leaves, image_dir):
    """Name leaves "Leaves" and give the roles CANOPY over ground GROUND, nothing
    selected; the fixture dict of the bake pipeline tests."""
    leaves.name = "Leaves"
    ground.canopy_ao.role, leaves.canopy_ao.role = 'GROUND', 'CANOPY'
    for ob in bpy.context.scene.objects:
        ob.select_set(False)
    bpy.context.view_layer.update()
    return dict(ground=ground, leaves=leaves, image_dir=str(image_dir))


def add_material(obj, name="UserMat", color=(0.8, 0.5, 0.2, 1.0)):
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = color
    obj.data.materials.append(mat)
    return mat


def tree_snapshot(mat):
    """Names/types of nodes and the set of links, to compare before/after."""
    nt = mat.node_tree
    nodes = sorted((n.name, n.bl_idname) for n in nt.nodes)
    links = sorted((l.from_node.name, l.from_socket.identifier, l.to_node.name,
                    l.to_socket.identifier) for l in nt.links)
    return nodes, links


def set_point_color(obj, name, values):
    """A FLOAT_COLOR POINT attribute with grey `values` (scalar or (N,))."""
    me = obj.data
    attr = me.color_attributes.get(name) or me.color_attributes.new(name, "FLOAT_COLOR", "POINT")
    n = len(me.vertices)
    rgba = np.ones((n, 4), dtype=np.float32)
    rgba[:, :3] = np.broadcast_to(np.asarray(values, dtype=np.float32).reshape(-1, 1), (n, 3))
    attr.data.foreach_set("color", rgba.ravel())
    return attr
