"""The baked AO where Blender's own glTF exporter finds it (docs/DESIGN.md, 'glTF').

Per texel: the exporter (io_scene_gltf2 of Blender 3.4 to 5.2) makes a material's
occlusionTexture from the "Occlusion" input of a group node whose node group is named
"glTF Material Output" (or the older "glTF Settings"), following links back to an Image
Texture; a Separate Color output on the way names the channel it takes (Red, Green, Blue; the
texture's Alpha output: A), which it writes into R of the exported image, where glTF reads
occlusion. We add Image Texture (through a UV Map node) -> Separate Color -> that group node's
Occlusion in each material; a material that already has such a group node keeps it, and only its
Occlusion input is linked. Our nodes carry materials.TAG, so materials.unwire removes them.

Per vertex: every one of those exporters writes the mesh's render color attribute as COLOR_0
(3.4 with Colors on, its default; 4.2 on with Use Vertex Color: Active, export_vertex_color=
'ACTIVE', and on 5.x Export All Vertex Colors off), so we make the AO attribute the render
color attribute.
"""
import bpy

from . import materials
from ..core.native import CanopyAOError

GROUP = "glTF Material Output"  # the name the exporters create and look for first
_GROUP_NAMES = ("gltf material output", "gltf settings")  # matched case-blind, as they do
_OUTPUT = {"RGBA": "Red", "R": "Red", "G": "Green", "B": "Blue"}  # Separate Color's


def _is_gltf_group(tree):
    return (tree is not None and tree.bl_idname == "ShaderNodeTree"
            and tree.name.lower().startswith(_GROUP_NAMES))


def _group_inputs(tree):
    """Names of a node group's inputs (Blender 4.0 moved them into tree.interface)."""
    if hasattr(tree, "interface"):
        return [i.name for i in tree.interface.items_tree
                if getattr(i, "in_out", "") == "INPUT"]
    return [i.name for i in tree.inputs]


def _group_nodes(nt):
    return [n for n in nt.nodes if n.bl_idname == "ShaderNodeGroup" and _is_gltf_group(n.node_tree)]


def check(obj):
    """Why obj's materials cannot take the occlusion wiring (None when they can): a glTF group
    node whose Occlusion input another node than ours already feeds (the user's occlusion,
    not replaced), or a glTF group without an Occlusion input."""
    for slot in obj.material_slots:
        mat = slot.material
        if mat is None or mat.node_tree is None or not materials.uses_nodes(mat):
            continue
        for node in _group_nodes(mat.node_tree):
            sock = node.inputs.get("Occlusion")
            if sock is None:
                return (f"material '{mat.name}' of '{obj.name}': its node group "
                        f"'{node.node_tree.name}' has no Occlusion input for the glTF exporter")
            for link in sock.links:
                if not materials.is_ours(link.from_node):
                    return (f"material '{mat.name}' of '{obj.name}': node '{node.name}' already "
                            f"feeds its Occlusion from '{link.from_node.name}'; unlink it to "
                            "export the baked AO (nothing was changed)")
    return None


def _group(txn):
    """The glTF node group: an existing one with an Occlusion input, else a new one (removed
    again if the bake is undone)."""
    for tree in bpy.data.node_groups:
        if _is_gltf_group(tree) and "Occlusion" in _group_inputs(tree):
            return tree
    tree = bpy.data.node_groups.new(GROUP, "ShaderNodeTree")
    if hasattr(tree, "interface"):  # Blender 4.0+
        tree.interface.new_socket("Occlusion", in_out="INPUT", socket_type="NodeSocketFloat")
    else:
        tree.inputs.new("NodeSocketFloat", "Occlusion")
    tree.nodes.new("NodeGroupInput")
    tree.nodes.new("NodeGroupOutput")
    txn.add(lambda: bpy.data.node_groups.remove(tree)
            if tree.name in bpy.data.node_groups else None)
    return tree


def wire_occlusion(obj, image, channel, uv_map, txn):
    """Feed the Occlusion input of a glTF group node in each of obj's materials from ``image``'s
    ``channel`` ('RGBA' grey: its red) read through UV map ``uv_map``. Idempotent: a second
    call reuses our nodes. Returns the number of nodes added."""
    why = check(obj)
    if why:
        raise CanopyAOError(why)
    added = 0
    for mat in materials._object_materials(obj):
        nt = mat.node_tree
        out = materials._output_node(nt)
        x0, y0 = (out.location.x, out.location.y) if out is not None else (0.0, 0.0)

        def node(bl_idname, role, label, dx, dy):
            nonlocal added
            found = materials._ours(nt, role)
            if found:
                return found[0]
            added += 1
            return materials._new(nt, bl_idname, role, label, (x0 + dx, y0 + dy))
        groups = _group_nodes(nt)
        group = groups[0] if groups else node("ShaderNodeGroup", "gltf_output",
                                              "glTF Material Output", 0, -600)
        if group.node_tree is None:
            group.node_tree = _group(txn)
        uv = node("ShaderNodeUVMap", "gltf_uv", "Canopy AO UV (glTF)", -900, -600)
        uv.uv_map = uv_map or ""
        tex = node("ShaderNodeTexImage", "gltf_source", "Canopy AO (glTF)", -700, -600)
        tex.image = image
        tex.interpolation = "Linear"
        tex.extension = "EXTEND"
        materials._link_once(nt, uv.outputs["UV"], tex.inputs["Vector"])
        for link in list(group.inputs["Occlusion"].links):
            nt.links.remove(link)  # ours, from an earlier bake (check() refused any other)
        if channel == "A":
            nt.links.new(tex.outputs["Alpha"], group.inputs["Occlusion"])
            continue
        sep = node("ShaderNodeSeparateColor", "gltf_separate", "Canopy AO channel", -300, -600)
        materials._link_once(nt, tex.outputs["Color"], sep.inputs["Color"])
        nt.links.new(sep.outputs[_OUTPUT[channel]], group.inputs["Occlusion"])
    return added


def set_color_export(obj, attribute, txn):
    """Make obj's color attribute ``attribute`` the render color attribute, which the glTF
    exporters write as COLOR_0; undone with the bake."""
    colors = obj.data.color_attributes
    index = colors.find(attribute)
    if index < 0:
        raise CanopyAOError(f"'{obj.name}' has no color attribute '{attribute}' to export")
    old = colors[colors.render_color_index].name if colors.render_color_index >= 0 else None

    def undo():
        i = colors.find(old) if old is not None else -1
        if i >= 0:
            colors.render_color_index = i
    txn.add(undo)
    colors.render_color_index = index
