"""materials.py: wiring is idempotent and unwire restores the material exactly."""
import bpy
import pytest

import helpers_materials as H
from canopy_ao.blender import materials


@pytest.fixture
def scene():
    return H.empty_scene()


def _source(mat):
    return [n for n in mat.node_tree.nodes if n.get("canopy_ao") == "source"]


def test_wire_twice_adds_nothing(scene):
    obj = H.add_plane()
    mat = H.add_material(obj)
    n0 = len(mat.node_tree.nodes)
    added = materials.wire_vertex_ao(obj, "CanopyAO")
    assert added == 4  # attribute, where baked, multiply, AOV output
    assert len(mat.node_tree.nodes) == n0 + 4
    links1 = len(mat.node_tree.links)
    assert materials.wire_vertex_ao(obj, "CanopyAO") == 0
    assert len(mat.node_tree.nodes) == n0 + 4
    assert len(mat.node_tree.links) == links1
    src = _source(mat)[0]
    assert src.bl_idname == "ShaderNodeVertexColor" and src.layer_name == "CanopyAO"
    # AO reaches Base Color through the multiply node
    base = mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"]
    assert base.is_linked and base.links[0].from_node.get("canopy_ao") == "mix"
    aov = next(n for n in mat.node_tree.nodes if n.get("canopy_ao") == "aov")
    assert aov.bl_idname == "ShaderNodeOutputAOV"
    assert getattr(aov, "aov_name", aov.name) == "BakedAO"


def test_unwire_restores_unlinked_base_color(scene):
    obj = H.add_plane()
    mat = H.add_material(obj, color=(0.1, 0.2, 0.3, 1.0))
    before = H.tree_snapshot(mat)
    materials.wire_vertex_ao(obj, "CanopyAO")
    assert materials.unwire(obj) == 4
    assert H.tree_snapshot(mat) == before
    base = mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"]
    assert not base.is_linked
    assert tuple(base.default_value) == pytest.approx((0.1, 0.2, 0.3, 1.0))
    assert materials.unwire(obj) == 0


def test_unwire_restores_original_link(scene):
    obj = H.add_plane()
    mat = H.add_material(obj)
    nt = mat.node_tree
    rgb = nt.nodes.new("ShaderNodeRGB")
    nt.links.new(rgb.outputs["Color"], nt.nodes["Principled BSDF"].inputs["Base Color"])
    before = H.tree_snapshot(mat)
    materials.wire_vertex_ao(obj, "CanopyAO")
    # the user's colour now feeds the multiply node, not Base Color directly
    assert nt.nodes["Principled BSDF"].inputs["Base Color"].links[0].from_node != rgb
    materials.unwire(obj)
    assert H.tree_snapshot(mat) == before
    assert nt.nodes["Principled BSDF"].inputs["Base Color"].links[0].from_node == rgb


def test_object_without_material_gets_ours_and_loses_it(scene):
    obj = H.add_plane()
    assert len(obj.material_slots) == 0
    n_mats = len(bpy.data.materials)
    assert materials.wire_vertex_ao(obj, "CanopyAO") == 4
    mat = obj.material_slots[0].material
    assert mat.get("canopy_ao")
    materials.unwire(obj)
    assert len(obj.material_slots) == 0
    assert len(bpy.data.materials) == n_mats


def test_two_materials_shared(scene):
    a = H.add_plane(name="A")
    b = H.add_plane(location=(3, 0, 0), name="B")
    m1 = H.add_material(a, "M1")
    m2 = H.add_material(a, "M2")
    b.data.materials.append(m1)
    assert materials.wire_vertex_ao(a, "CanopyAO") == 8
    assert materials.wire_vertex_ao(b, "CanopyAO") == 0  # shares M1, already wired
    materials.unwire(a)
    assert not any(n.get("canopy_ao") for m in (m1, m2) for n in m.node_tree.nodes)


def test_switch_vertex_to_texel_and_back(scene):
    obj = H.add_plane()
    mat = H.add_material(obj)
    before = H.tree_snapshot(mat)
    materials.wire_vertex_ao(obj, "CanopyAO")
    img = bpy.data.images.new("img", 4, 4, float_buffer=True)
    assert materials.wire_texel_ao(obj, img, "UVMap") == 2  # image + UV map (replaces attribute)
    src = _source(mat)
    assert len(src) == 1 and src[0].bl_idname == "ShaderNodeTexImage" and src[0].image == img
    uv = [n for n in mat.node_tree.nodes if n.get("canopy_ao") == "uv"]
    assert len(uv) == 1 and uv[0].uv_map == "UVMap"
    assert materials.wire_texel_ao(obj, img, "UVMap") == 0
    materials.wire_vertex_ao(obj, "CanopyAO")
    assert not [n for n in mat.node_tree.nodes if n.get("canopy_ao") == "uv"]
    materials.unwire(obj)
    assert H.tree_snapshot(mat) == before


def test_mix_node_type(scene):
    obj = H.add_plane()
    mat = H.add_material(obj)
    materials.wire_vertex_ao(obj, "CanopyAO")
    mix = next(n for n in mat.node_tree.nodes if n.get("canopy_ao") == "mix")
    expected = "ShaderNodeMix" if hasattr(bpy.types, "ShaderNodeMix") else "ShaderNodeMixRGB"
    assert mix.bl_idname == expected and mix.blend_type == "MULTIPLY"


@pytest.mark.skipif(not materials.NODES_OPTIONAL,
                    reason="Blender 5.x: every material uses nodes (use_nodes is deprecated)")
def test_material_without_nodes(scene):
    obj = H.add_plane()
    mat = bpy.data.materials.new("Plain")
    mat.use_nodes = False
    obj.data.materials.append(mat)
    materials.wire_vertex_ao(obj, "CanopyAO")
    assert mat.use_nodes
    materials.unwire(obj)
    assert not mat.use_nodes


def test_non_mesh_refused(scene):
    bpy.ops.object.empty_add()
    with pytest.raises(ValueError, match="not a mesh"):
        materials.wire_vertex_ao(bpy.context.object, "CanopyAO")


def test_aov_target_follows_name(scene):
    obj = H.add_plane()
    mat = H.add_material(obj)
    user = mat.node_tree.nodes.new("ShaderNodeRGB")
    user.name = "BakedAO"  # a user node with the pass's name does not get in the way
    materials.wire_vertex_ao(obj, "CanopyAO", aov_name="BakedAO")
    assert materials.wire_vertex_ao(obj, "CanopyAO", aov_name="TreeAO") == 0
    aov = next(n for n in mat.node_tree.nodes if n.get("canopy_ao") == "aov")
    assert materials._aov_target(aov) == "TreeAO"
    assert mat.node_tree.nodes.get("BakedAO") == user


def test_remove_wiring_operator_restores_the_material(scene):
    """The operator an artist presses: exactly what was added goes, for the named objects."""
    obj = H.add_plane()
    mat = H.add_material(obj, color=(0.4, 0.5, 0.6, 1.0))
    before = H.tree_snapshot(mat)
    materials.wire_vertex_ao(obj, "CanopyAO")
    assert H.tree_snapshot(mat) != before
    assert bpy.ops.canopy_ao.remove_wiring(objects=obj.name) == {'FINISHED'}
    assert H.tree_snapshot(mat) == before
    with pytest.raises(RuntimeError, match="no object named 'Nope'"):
        bpy.ops.canopy_ao.remove_wiring(objects="Nope")
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    with pytest.raises(RuntimeError, match="select the mesh objects"):
        bpy.ops.canopy_ao.remove_wiring()


def test_an_unbaked_object_sharing_the_material_keeps_its_colour(scene, tmp_path):
    """Per vertex, the wiring reads the AO attribute; a second object with the same material
    but no attribute (not baked) reads it as 0 in Cycles and rendered black. It keeps its
    colour (AO 1), and the baked one shows its AO, in the render and in the AOV."""
    import numpy as np
    from canopy_ao.blender import mesh_io
    baked, other = H.add_plane(location=(-1.1, 0, 0), name="Baked"), \
        H.add_plane(location=(1.1, 0, 0), name="Other")
    mat = bpy.data.materials.new("Glow")
    mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    out, glow = nt.nodes.new("ShaderNodeOutputMaterial"), nt.nodes.new("ShaderNodeEmission")
    glow.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    nt.links.new(glow.outputs[0], out.inputs["Surface"])
    baked.data.materials.append(mat)
    other.data.materials.append(mat)
    mesh_io.write_ao_attribute(baked, "CanopyAO", np.full(4, 0.5, np.float32))
    materials.wire_vertex_ao(baked, "CanopyAO")
    sc = bpy.context.scene
    bpy.ops.object.camera_add(location=(0, 0, 5))
    sc.camera = bpy.context.object
    sc.camera.data.type, sc.camera.data.ortho_scale = 'ORTHO', 5.0
    sc.render.engine = 'CYCLES'
    sc.cycles.samples, sc.cycles.use_denoising = 1, False
    sc.render.resolution_x, sc.render.resolution_y = 100, 50
    sc.view_settings.view_transform = 'Standard'
    sc.render.image_settings.file_format = 'OPEN_EXR'
    sc.render.filepath = str(tmp_path / "shared.exr")
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(sc.render.filepath)
    px = np.array(img.pixels[:]).reshape(50, 100, 4)
    assert px[25, 25, :3] == pytest.approx([0.5] * 3, abs=0.01)  # the baked one: its AO
    assert px[25, 75, :3] == pytest.approx([1.0] * 3, abs=0.01)  # the other: unshaded


def test_a_node_the_user_duplicated_from_ours_is_theirs(scene):
    """Shift+D copies a node's custom properties, our tag too: the user's copy of our attribute
    node (feeding Roughness here) survives wiring again and Remove Wiring."""
    obj = H.add_plane()
    mat = H.add_material(obj)
    nt = mat.node_tree
    materials.wire_vertex_ao(obj, "CanopyAO")
    src = _source(mat)[0]
    copy = nt.nodes.new("ShaderNodeVertexColor")
    for key in src.keys():
        copy[key] = src[key]
    copy.layer_name = "CanopyAO"
    nt.links.new(copy.outputs["Color"], nt.nodes["Principled BSDF"].inputs["Roughness"])
    assert materials.wire_vertex_ao(obj, "CanopyAO") == 0
    assert copy.name in nt.nodes
    assert materials.unwire(obj) == 4
    assert copy.name in nt.nodes and copy.outputs["Color"].is_linked


def test_every_shader_behind_a_mix_shader_gets_the_ao(scene):
    """A foliage material mixes Principled and Translucent (through a reroute here): the AO
    multiplies both colours, and Remove Wiring gives the material back as it was."""
    obj = H.add_plane()
    mat = H.add_material(obj)
    nt = mat.node_tree
    principled, out = nt.nodes["Principled BSDF"], nt.nodes["Material Output"]
    mix, trans = nt.nodes.new("ShaderNodeMixShader"), nt.nodes.new("ShaderNodeBsdfTranslucent")
    reroute = nt.nodes.new("NodeReroute")
    nt.links.new(principled.outputs[0], mix.inputs[1])
    nt.links.new(trans.outputs[0], mix.inputs[2])
    nt.links.new(mix.outputs[0], reroute.inputs[0])
    nt.links.new(reroute.outputs[0], out.inputs["Surface"])
    before = H.tree_snapshot(mat)
    assert materials.wire_vertex_ao(obj, "CanopyAO") == 5  # attribute, where baked, 2 × mix, AOV
    for sock in (principled.inputs["Base Color"], trans.inputs["Color"]):
        assert sock.is_linked and sock.links[0].from_node.get("canopy_ao") == "mix"
    assert materials.wire_vertex_ao(obj, "CanopyAO") == 0
    assert materials.unwire(obj) == 5
    assert H.tree_snapshot(mat) == before


def test_a_material_with_no_shader_colour_is_named_in_the_report(scene):
    """A surface shader with no colour input (a node group without one here) gets the AOV
    only: the bake's notes say so, naming the material, where it is silent otherwise."""
    from canopy_ao.blender import properties
    from canopy_ao.blender.job import run_bake
    obj = H.add_plane(name="Ground")
    obj.canopy_ao.role = 'GROUND'
    mat = H.add_material(obj, name="Grouped")
    nt = mat.node_tree
    group = bpy.data.node_groups.new("Look", "ShaderNodeTree")
    if hasattr(group, "interface"):  # 4.0+
        group.interface.new_socket("Shader", in_out='OUTPUT', socket_type="NodeSocketShader")
    else:
        group.outputs.new("NodeSocketShader", "Shader")
    node = nt.nodes.new("ShaderNodeGroup")
    node.node_tree = group
    nt.links.new(node.outputs[0], nt.nodes["Material Output"].inputs["Surface"])
    assert materials.without_colour(obj) == ["Grouped"]
    opts = dict(properties.scene_options(bpy.context.scene), method="sphere", tau=2.0,
                distance=0.0, show_proxies=False, wire_material=True)
    _job, rep = run_bake(bpy.context, ["Ground"], opts)
    assert any("'Grouped' has no surface shader colour" in n for n in rep["notes"]), rep["notes"]
    nt.links.new(nt.nodes["Principled BSDF"].outputs[0],
                 nt.nodes["Material Output"].inputs["Surface"])
    assert materials.without_colour(obj) == []  # a colour to multiply into


def test_shaders_behind_an_eevee_and_a_cycles_output_both_get_the_ao(scene):
    """A material with one Material Output per engine: Cycles renders its own output's shader,
    Eevee the other's; both multiply the AO, and unwire restores the material."""
    obj = H.add_plane()
    mat = H.add_material(obj)
    nt = mat.node_tree
    out = nt.nodes["Material Output"]
    out.target = 'EEVEE'
    cycles_out = nt.nodes.new("ShaderNodeOutputMaterial")
    cycles_out.target = 'CYCLES'
    diffuse = nt.nodes.new("ShaderNodeBsdfDiffuse")
    nt.links.new(diffuse.outputs[0], cycles_out.inputs["Surface"])
    before = H.tree_snapshot(mat)
    materials.wire_vertex_ao(obj, "CanopyAO")
    for sock in (nt.nodes["Principled BSDF"].inputs["Base Color"], diffuse.inputs["Color"]):
        assert sock.is_linked and sock.links[0].from_node.get("canopy_ao") == "mix"
    materials.unwire(obj)
    assert H.tree_snapshot(mat) == before
