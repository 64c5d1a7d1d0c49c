"""The frame cache of a frame-range bake (frames.py; docs/DESIGN.md, 'Live and per-frame AO').

The cache: one POINT-domain FLOAT attribute per frame, ``<attribute>_<frame>`` (CanopyAO_1,
CanopyAO_2, ...), each owned by Canopy AO under mesh_io's rules; 4 bytes per vertex per frame.
The read-back: a modifier "Canopy AO Frames" at the end of the stack whose node group takes
the scene frame, clamped to the baked range, spells the attribute's name with Replace String
("<attribute>_#", # = the frame), reads it with Named Attribute and stores it as the FLOAT_COLOR
attribute ``<attribute>`` that the material and the AOV read, so the file renders its per-frame
AO in any Blender, with or without the add-on (Replace String, not Join Strings: a multi-input
socket's order is not the order its links were made in).
"""

import bpy

from . import mesh_io
from ..core.native import CanopyAOError

MODIFIER = "Canopy AO Frames"
GROUP_TAG = "canopy_ao_frames"  # the node group's custom property: the attribute it reads


def cache_name(attribute, frame):
    return f"{attribute}_{int(frame)}"


def _sockets(sockets, name):
    """The enabled sockets called ``name`` (3.x lists one per data type, 4.x one)."""
    return [s for s in sockets if s.name == name and s.enabled]


def node_group(attribute, start, end, txn):
    """The node group reading ``<attribute>_<frame>`` for the scene frame clamped to
    [start, end] into the FLOAT_COLOR attribute ``<attribute>``; new, removed on rollback."""
    ng = bpy.data.node_groups.new(f"{MODIFIER} {attribute} {start}-{end}", 'GeometryNodeTree')
    txn.add(lambda: bpy.data.node_groups.remove(ng))
    ng[GROUP_TAG] = attribute
    for io in ('INPUT', 'OUTPUT'):
        if hasattr(ng, "interface"):  # 4.0+
            ng.interface.new_socket(name="Geometry", in_out=io, socket_type='NodeSocketGeometry')
        else:
            (ng.inputs if io == 'INPUT' else ng.outputs).new('NodeSocketGeometry', "Geometry")
    nodes, link = ng.nodes, ng.links.new
    gin, gout = nodes.new('NodeGroupInput'), nodes.new('NodeGroupOutput')
    time_node = nodes.new('GeometryNodeInputSceneTime')
    clamp = nodes.new('ShaderNodeClamp')
    clamp.inputs["Min"].default_value, clamp.inputs["Max"].default_value = start, end
    text = nodes.new('FunctionNodeValueToString')  # 0 decimals: the frame rounded
    spell = nodes.new('FunctionNodeReplaceString')
    spell.inputs["String"].default_value = f"{attribute}_#"
    spell.inputs["Find"].default_value = "#"
    read = nodes.new('GeometryNodeInputNamedAttribute')
    read.data_type = 'FLOAT'
    store = nodes.new('GeometryNodeStoreNamedAttribute')
    store.data_type, store.domain = 'FLOAT_COLOR', 'POINT'
    store.inputs["Name"].default_value = attribute
    link(time_node.outputs["Frame"], clamp.inputs["Value"])
    link(clamp.outputs[0], text.inputs["Value"])
    link(text.outputs[0], spell.inputs["Replace"])
    link(spell.outputs[0], read.inputs["Name"])
    link(_sockets(read.outputs, "Attribute")[0], _sockets(store.inputs, "Value")[0])
    link(gin.outputs[0], store.inputs[0])
    link(store.outputs[0], gout.inputs[0])
    return ng


def cache_modifier(obj):
    """obj's frame-cache modifier: the one named MODIFIER whose node group is ours, or None. A
    modifier of the user's that has that name is theirs: never repointed nor removed."""
    mod = obj.modifiers.get(MODIFIER)
    if (mod is not None and mod.type == 'NODES' and mod.node_group is not None
            and mod.node_group.get(GROUP_TAG) is not None):
        return mod
    return None


def check_modifier(obj):
    """Why obj cannot take a frame cache (a modifier of the user's has its name), or None."""
    if obj.modifiers.get(MODIFIER) is not None and cache_modifier(obj) is None:
        return (f"{obj.name}: its modifier '{MODIFIER}' is not Canopy AO's frame cache; "
                "rename it to bake frames")
    return None


def attach(obj, group, txn):
    """Point obj's "Canopy AO Frames" modifier (added last if missing) at ``group``."""
    why = check_modifier(obj)
    if why:
        raise CanopyAOError(why)
    mod = obj.modifiers.get(MODIFIER)
    if mod is None:
        mod = obj.modifiers.new(MODIFIER, 'NODES')
        txn.add(lambda: obj.modifiers.remove(obj.modifiers[MODIFIER]))
    else:
        old = mod.node_group
        txn.add(lambda: setattr(obj.modifiers[MODIFIER], "node_group", old))
    mod.node_group = group


def clear(obj):
    """Remove obj's frame cache: its modifier and every ``<attribute>_<frame>`` attribute
    Canopy AO made for the attribute the modifier reads. Returns the attributes removed."""
    mod = cache_modifier(obj)
    if mod is None:
        return 0
    group = mod.node_group
    attribute = group.get(GROUP_TAG) if group is not None else None
    obj.modifiers.remove(mod)
    removed = 0
    if isinstance(attribute, str):
        prefix = attribute + "_"
        for name in mesh_io.owned_attributes(obj):
            if name.startswith(prefix) and name[len(prefix):].lstrip("-").isdigit():
                removed += mesh_io.remove_owned_attribute(obj, name)
    if group is not None and group.users == 0:
        bpy.data.node_groups.remove(group)
    return removed
