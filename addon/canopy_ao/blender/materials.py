"""Wire baked AO into materials and render passes (docs/DESIGN.md, 'The product').

Every node we add carries ``node["canopy_ao"] = <role>`` so wiring is idempotent (a second call
reuses the nodes) and ``unwire`` removes exactly what we added. The original Base Color link is
kept on our Mix node's A input, so unwire restores it from there; a Base Color that was unlinked
keeps its default value untouched, so there is nothing else to remember.

Roles: "source" (Color Attribute or Image Texture), "uv" (UV Map, texel only), "present" (the
attribute's AO where a mesh has it, 1 where it has none: vertex only), "mix" (multiply into
Base Color), "aov" (AOV Output).
"""
import bpy

__all__ = ["wire_vertex_ao", "wire_texel_ao", "unwire", "without_colour",
           "ensure_view_layer_aov", "remove_view_layer_aov", "check_aov_name",
           "RESERVED_PASS_NAMES"]

TAG = "canopy_ao"
# Material the add-on creates for an object that has none; marked so unwire can delete it.
OWN_MATERIAL_TAG = "canopy_ao"
# On the object: how we attached our own material ("append" or "fill"), for unwire.
OBJ_MATERIAL_KEY = "canopy_ao_material"

# Render Layers output sockets that Cycles/Eevee already use. A view-layer AOV with one of these
# names collides with the built-in socket (docs/DESIGN.md, 'Facts measured in Blender': "AO" does).
RESERVED_PASS_NAMES = frozenset({
    "Image", "Alpha", "Depth", "Mist", "Normal", "Vector", "UV", "Position", "AO", "Shadow",
    "Emit", "Env", "IndexOB", "IndexMA", "Noisy Image", "Noisy Shadow Catcher",
    "Shadow Catcher", "Denoising Normal", "Denoising Albedo", "Denoising Depth",
    "DiffDir", "DiffInd", "DiffCol", "GlossDir", "GlossInd", "GlossCol",
    "TransDir", "TransInd", "TransCol", "VolumeDir", "VolumeInd",
    "BloomCol", "CryptoObject", "CryptoMaterial", "CryptoAsset",
})

# Blender 5.x: every material has a node tree and Material.use_nodes is deprecated (always
# True); before, a material could be without nodes and we turned them on (and off again).
NODES_OPTIONAL = bpy.app.version < (5, 0, 0)


def uses_nodes(mat):
    return not NODES_OPTIONAL or mat.use_nodes


def enable_nodes(mat):
    if NODES_OPTIONAL:
        mat.use_nodes = True


_BASE_COLOR_INPUTS = ("Base Color", "Color")  # Principled (3.x and 4.x) / Diffuse-like shaders


def check_aov_name(aov_name):
    """Raise ValueError if aov_name cannot be used as a render-pass name."""
    if not aov_name or not aov_name.strip():
        raise ValueError("AOV name is empty; use e.g. 'BakedAO'")
    if aov_name in RESERVED_PASS_NAMES:
        raise ValueError(
            f"AOV name '{aov_name}' collides with Blender's own '{aov_name}' render pass "
            "(the Render Layers node already has a socket with that name); "
            "choose another name, e.g. 'BakedAO'")


# === Node helpers

def is_ours(node):
    """True for a node wire_* added. A node the user duplicated from ours (Shift+D copies its
    custom properties) has another name than the one recorded, and is the user's to keep. The
    name is read from the node's path: in 3.4 an AOV Output's `name` is the AOV it writes."""
    if node.get(TAG) is None:
        return False
    path = node.path_from_id()
    return node.get(TAG + "_node", path) == path


def _ours(nt, role):
    return [n for n in nt.nodes if n.get(TAG) == role and is_ours(n)]


def _new(nt, bl_idname, role, label, location):
    node = nt.nodes.new(bl_idname)
    node[TAG] = role
    node[TAG + "_node"] = node.path_from_id()
    node.label = label
    node.location = location
    return node


def _remove(nt, node):
    nt.nodes.remove(node)


def _output_node(nt):
    outs = [n for n in nt.nodes if n.bl_idname == "ShaderNodeOutputMaterial"]
    for n in outs:
        if n.is_active_output:
            return n
    return outs[0] if outs else None


# Nodes that pass shaders through: the wiring looks behind them (a foliage material is often
# Principled and Translucent mixed) for every shader's colour.
_PASS_THROUGH = {"NodeReroute": (0,), "ShaderNodeMixShader": (1, 2), "ShaderNodeAddShader": (0, 1)}


def _base_color_sockets(nt):
    """The colour inputs of the surface shaders we multiply AO into (maybe none), behind every
    Material Output: one for Eevee and one for Cycles each render their own."""
    found, todo, seen = [], [], set()
    for out in nt.nodes:
        if out.bl_idname == "ShaderNodeOutputMaterial" and "Surface" in out.inputs:
            todo.extend(out.inputs["Surface"].links)
    while todo:
        node = todo.pop(0).from_node
        if node.name in seen:
            continue
        seen.add(node.name)
        if node.bl_idname in _PASS_THROUGH:
            for i in _PASS_THROUGH[node.bl_idname]:
                todo.extend(node.inputs[i].links)
            continue
        sock = next((node.inputs.get(name) for name in _BASE_COLOR_INPUTS
                     if node.inputs.get(name) is not None
                     and node.inputs.get(name).type == "RGBA"), None)
        if sock is not None:
            found.append(sock)
    return found


def without_colour(obj):
    """Names of obj's node materials with no surface shader colour to multiply the AO into
    (nor a multiply of ours): wiring gives them the AOV only."""
    names = []
    for slot in obj.material_slots:
        mat = slot.material
        if (mat is not None and mat.node_tree is not None and uses_nodes(mat)
                and mat.name not in names and not _ours(mat.node_tree, "mix")
                and not _base_color_sockets(mat.node_tree)):
            names.append(mat.name)
    return names


def _mix_sockets(node):
    """(A, B, Result) colour sockets of a ShaderNodeMix (3.4+) or ShaderNodeMixRGB."""
    if node.bl_idname == "ShaderNodeMix":
        a = next(s for s in node.inputs if s.identifier == "A_Color")
        b = next(s for s in node.inputs if s.identifier == "B_Color")
        r = next(s for s in node.outputs if s.identifier == "Result_Color")
        return a, b, r
    return node.inputs["Color1"], node.inputs["Color2"], node.outputs["Color"]


def _new_mix(nt, location, role="mix", label="Canopy AO multiply", blend="MULTIPLY"):
    if hasattr(bpy.types, "ShaderNodeMix"):
        node = _new(nt, "ShaderNodeMix", role, label, location)
        node.data_type = "RGBA"
        node.blend_type = blend
        node.clamp_result = False
    else:  # Blender < 3.4
        node = _new(nt, "ShaderNodeMixRGB", role, label, location)
        node.blend_type = blend
    _factor_socket(node).default_value = 1.0
    return node


def _factor_socket(node):
    if node.bl_idname == "ShaderNodeMix":
        return next(s for s in node.inputs if s.identifier == "Factor_Float")
    return node.inputs["Fac"]


def _where_baked(nt, src, location):
    """The AO where the mesh has the attribute, 1 where it has none: an object that shares the
    material but was not baked reads a missing attribute as black (0, alpha 0 too, in Cycles);
    ours has alpha 1, so mix(1, colour, alpha) is its AO there and 1 elsewhere. Returns the
    colour socket to use (node role "present")."""
    nodes = _ours(nt, "present")
    for extra in nodes[1:]:
        _remove(nt, extra)
    node = nodes[0] if nodes else _new_mix(nt, location, "present", "Canopy AO where baked",
                                           "MIX")
    a, b, r = _mix_sockets(node)
    a.default_value = (1.0, 1.0, 1.0, 1.0)
    _link_once(nt, src.outputs["Alpha"], _factor_socket(node))
    _link_once(nt, src.outputs["Color"], b)
    return r, int(not nodes)


def _set_aov_target(node, aov_name):
    # 3.4: the AOV Output node's RNA has two `name` properties and Python reaches the node's
    # own one, the AOV it writes (the node keeps its tree name "AOV Output"; docs/DESIGN.md,
    # 'Facts measured in Blender').
    # 4.x: `aov_name`.
    if hasattr(node, "aov_name"):
        node.aov_name = aov_name
    else:
        node.name = aov_name


def _aov_target(node):
    return node.aov_name if hasattr(node, "aov_name") else node.name


def _link_once(nt, from_socket, to_socket):
    for link in to_socket.links:
        if link.from_socket == from_socket:
            return
    nt.links.new(from_socket, to_socket)


# === Materials of an object

def _object_materials(obj):
    """Unique node-based materials of obj; give it one of ours when it has none."""
    if obj.type != "MESH":
        raise ValueError(f"Object '{obj.name}' is a {obj.type.lower()}, not a mesh; "
                         "AO can only be wired into mesh materials")
    mats = []
    for slot in obj.material_slots:
        if slot.material is not None and slot.material not in mats:
            mats.append(slot.material)
    if not mats:
        mat = bpy.data.materials.new(f"{obj.name}_CanopyAO")
        mat[OWN_MATERIAL_TAG] = True
        enable_nodes(mat)
        if len(obj.material_slots) == 0:
            obj.data.materials.append(mat)
            obj[OBJ_MATERIAL_KEY] = "append"
        else:  # slots exist but are empty: fill them, unwire empties them again
            for slot in obj.material_slots:
                slot.material = mat
            obj[OBJ_MATERIAL_KEY] = "fill"
        mats = [mat]
    for mat in mats:
        if not uses_nodes(mat):
            # Turning nodes on replaces the material's simple colour by a default Principled
            # tree; remember so unwire can turn them off again.
            enable_nodes(mat)
            mat[TAG + "_enabled_nodes"] = True
    return mats


def _wire_material(mat, make_source, source_kind, aov_name, uv_map=None):
    """Add (or reuse) source → multiply → Base Color and source → AOV. Returns nodes added."""
    nt = mat.node_tree
    added = 0
    out = _output_node(nt)
    x0, y0 = (out.location.x, out.location.y) if out is not None else (0.0, 0.0)

    # Source node: reuse if it is the same kind, replace otherwise (vertex <-> texel switch).
    src = None
    for node in _ours(nt, "source"):
        if node.get(TAG + "_kind") == source_kind and src is None:
            src = node
        else:
            _remove(nt, node)
    if source_kind != "texel":
        for node in _ours(nt, "uv"):
            _remove(nt, node)
    if src is None:
        src = make_source(nt, (x0 - 900, y0 - 300))
        src[TAG + "_kind"] = source_kind
        added += 1
    color_out = src.outputs["Color"]
    if source_kind == "vertex":
        color_out, more = _where_baked(nt, src, (x0 - 700, y0 - 300))
        added += more
    else:
        for node in _ours(nt, "present"):
            _remove(nt, node)
    if source_kind == "texel":
        uv_nodes = _ours(nt, "uv")
        if not uv_nodes:
            uv = _new(nt, "ShaderNodeUVMap", "uv", "Canopy AO UV", (x0 - 1100, y0 - 300))
            added += 1
        else:
            uv = uv_nodes[0]
            for extra in uv_nodes[1:]:
                _remove(nt, extra)
        uv.uv_map = uv_map or ""
        _link_once(nt, uv.outputs["UV"], src.inputs["Vector"])

    # Multiply into the surface shader's Base Color, where there is one.
    # One multiply per shader colour on the first wiring; later ones reuse what is left of ours
    # (a multiply the user unplugged stays unplugged).
    mixes = _ours(nt, "mix")
    if not mixes:
        for i, target in enumerate(_base_color_sockets(nt)):
            mix = _new_mix(nt, (x0 - 500, y0 - 100 + 220 * i))
            added += 1
            a, _b, r = _mix_sockets(mix)
            if target.is_linked:
                nt.links.new(target.links[0].from_socket, a)
            else:
                a.default_value = target.default_value
            nt.links.new(r, target)
            mixes.append(mix)
    for mix in mixes:
        _a, b, _r = _mix_sockets(mix)
        _link_once(nt, color_out, b)

    # AOV Output: both inputs fed, so a VALUE or a COLOR view-layer AOV reads the AO (a grey
    # colour converts to the same float).
    aovs = _ours(nt, "aov")
    if aovs:
        aov = aovs[0]
    else:
        aov = _new(nt, "ShaderNodeOutputAOV", "aov", "Canopy AO pass", (x0, y0 - 300))
        added += 1
    _set_aov_target(aov, aov_name)
    _link_once(nt, color_out, aov.inputs["Color"])
    _link_once(nt, color_out, aov.inputs["Value"])
    return added


def wire_vertex_ao(obj, attribute_name, aov_name="BakedAO"):
    """Multiply the colour attribute `attribute_name` into every material of obj and write it to
    the AOV `aov_name`. Idempotent. Returns the number of nodes added."""
    check_aov_name(aov_name)

    def make(nt, loc):
        node = _new(nt, "ShaderNodeVertexColor", "source", "Canopy AO", loc)
        return node

    added = 0
    for mat in _object_materials(obj):
        added += _wire_material(mat, make, "vertex", aov_name)
        for node in _ours(mat.node_tree, "source"):
            node.layer_name = attribute_name
    return added


def wire_texel_ao(obj, image, uv_map, aov_name="BakedAO"):
    """Same as wire_vertex_ao with an Image Texture node reading `image` through UV map
    `uv_map`. Returns the number of nodes added."""
    check_aov_name(aov_name)

    def make(nt, loc):
        node = _new(nt, "ShaderNodeTexImage", "source", "Canopy AO", loc)
        return node

    added = 0
    for mat in _object_materials(obj):
        nt = mat.node_tree
        added += _wire_material(mat, make, "texel", aov_name, uv_map)
        for node in _ours(nt, "source"):
            node.image = image
            node.interpolation = "Linear"
            node.extension = "EXTEND"
    return added


def _unwire_material(mat):
    nt = mat.node_tree
    if nt is None:
        return 0
    removed = 0
    for mix in _ours(nt, "mix"):
        a, _b, r = _mix_sockets(mix)
        original = a.links[0].from_socket if a.is_linked else None
        targets = [link.to_socket for link in r.links]
        if original is not None:
            for t in targets:
                nt.links.new(original, t)
    for node in [n for n in nt.nodes if is_ours(n)]:
        nt.nodes.remove(node)
        removed += 1
    if mat.get(TAG + "_enabled_nodes"):
        if NODES_OPTIONAL:
            mat.use_nodes = False
        del mat[TAG + "_enabled_nodes"]
    return removed


def _remove_slots(obj, mats):
    # mesh.materials.pop() leaves the object's slot count stale in 3.4; the operator keeps
    # object and mesh in step.
    keep_index = obj.active_material_index
    with bpy.context.temp_override(object=obj, active_object=obj):
        for i in reversed(range(len(obj.material_slots))):
            if obj.material_slots[i].material in mats:
                obj.active_material_index = i
                bpy.ops.object.material_slot_remove()
    obj.active_material_index = min(keep_index, max(len(obj.material_slots) - 1, 0))


def unwire(obj):
    """Remove every node wire_* added to obj's materials and restore the original links (and
    drop the material we created, if we did). Returns the number of nodes removed."""
    removed = 0
    mats = []
    for slot in obj.material_slots:
        if slot.material is not None and slot.material not in mats:
            mats.append(slot.material)
    for mat in mats:
        removed += _unwire_material(mat)
    mode = obj.get(OBJ_MATERIAL_KEY)
    if mode is not None:
        ours = [m for m in mats if m.get(OWN_MATERIAL_TAG)]
        if ours:
            if mode == "append":
                _remove_slots(obj, ours)
            else:
                for slot in obj.material_slots:
                    if slot.material in ours:
                        slot.material = None
            for mat in ours:
                if mat.users == 0:
                    bpy.data.materials.remove(mat)
        del obj[OBJ_MATERIAL_KEY]
    return removed


# === View layer

def ensure_view_layer_aov(scene, aov_name, aov_type="VALUE", view_layer=None):
    """Add a shader AOV named aov_name to the view layer(s) if missing (all of the scene's view
    layers unless one is given). Returns the list of AOVs (existing or new)."""
    check_aov_name(aov_name)
    if aov_type not in ("VALUE", "COLOR"):
        raise ValueError(f"AOV type must be 'VALUE' or 'COLOR', not {aov_type!r}")
    layers = [view_layer] if view_layer is not None else list(scene.view_layers)
    result = []
    for vl in layers:
        aov = next((a for a in vl.aovs if a.name == aov_name), None)
        if aov is None:
            aov = vl.aovs.add()
            aov.name = aov_name
            aov.type = aov_type
        result.append(aov)
    return result


def remove_view_layer_aov(scene, aov_name, view_layers=None):
    """Remove the view-layer AOV named aov_name from every view layer (or those named in
    view_layers). Returns how many."""
    n = 0
    for vl in scene.view_layers:
        if view_layers is not None and vl.name not in view_layers:
            continue
        while True:
            idx = next((i for i, a in enumerate(vl.aovs) if a.name == aov_name), None)
            if idx is None:
                break
            if hasattr(vl.aovs, "remove"):  # 4.x
                vl.aovs.remove(vl.aovs[idx])
            else:  # 3.4 has no collection remove(); the operator removes the active AOV
                vl.active_aov_index = idx
                before = len(vl.aovs)
                with bpy.context.temp_override(scene=scene, view_layer=vl):
                    bpy.ops.scene.view_layer_remove_aov()
                if len(vl.aovs) == before:
                    raise RuntimeError(f"Could not remove AOV '{aov_name}' from view layer "
                                       f"'{vl.name}'; remove it in View Layer > Shader AOV")
            n += 1
    return n
