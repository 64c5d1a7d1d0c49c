"""Leaf cards: the exact rung's rays pass a material's transparency as Cycles' AO bake does
(native raytrace.h, 'Opacity'; docs/DESIGN.md, 'Opacity of leaf cards'). A card over a ground,
both baked here at a few hundred samples: the margins are that noise (σ ≈ 0.02 per vertex, 0.005
on a mean of 49), far below what opaque rays got wrong (0.3–0.5 under a card of alpha 0.5)."""

import bpy
import numpy as np
import pytest

from conftest import _clear_scene, add_mesh
from canopy_ao.blender import cycles_check, materials, mesh_io, properties
from canopy_ao.blender.job import run_bake

SAMPLES = 512


@pytest.fixture
def clean():
    _clear_scene()
    yield
    _clear_scene()


def _scene(material):
    """A 7 × 7-vertex ground on [-1, 1]² and a 3 × 3 card at height 0.6 over it, UVs [0, 1]²
    (u along x), carrying ``material``."""
    g = np.linspace(-1.0, 1.0, 7)
    xy = np.array([(x, y) for y in g for x in g], np.float32)
    ground = np.column_stack([xy, np.zeros(len(xy), np.float32)])
    tris = []
    for r in range(6):
        for c in range(6):
            a = 7 * r + c
            tris += [[a, a + 1, a + 8], [a, a + 8, a + 7]]
    ob = add_mesh("Ground", ground, np.int32(tris))
    ob["canopy_ao_role"] = "GROUND"
    s, h = 1.5, 0.6
    card = add_mesh("Card", np.float32([[-s, -s, h], [s, -s, h], [s, s, h], [-s, s, h]]),
                    np.int32([[0, 1, 2], [0, 2, 3]]))
    card["canopy_ao_role"] = "CANOPY"
    uv = card.data.uv_layers.new(name="UVMap")
    corner_uv = {0: (0, 0), 1: (1, 0), 2: (1, 1), 3: (0, 1)}
    vals = np.float32([corner_uv[lp.vertex_index] for lp in card.data.loops]).ravel()
    attr = card.data.attributes.get("UVMap")
    if attr is not None and attr.data_type == "FLOAT2":  # Blender 3.5+: UV maps are attributes
        attr.data.foreach_set("vector", vals)
    else:
        uv.data.foreach_set("uv", vals)
    card.data.materials.append(material)
    return ob


def _principled(name):
    mat = bpy.data.materials.new(name)
    materials.enable_nodes(mat)
    bsdf = next(n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    return mat, bsdf


def _bake_both(distance=10.0):
    """(ours, Cycles, report) on the ground's vertices."""
    opts = properties.scene_options(bpy.context.scene)
    opts.update(method="raytrace", samples=SAMPLES, distance=distance, use_world_distance=False)
    _job, rep = run_bake(bpy.context, ["Ground"], opts)
    ours = mesh_io.read_ao_attribute(bpy.data.objects["Ground"], "CanopyAO")
    cyc = cycles_check.bake_cycles_vertex_ao(bpy.context, [bpy.data.objects["Ground"]],
                                             distance, SAMPLES)["Ground"]
    return ours, cyc, rep


@pytest.mark.parametrize("alpha", [0.0, 0.5, 1.0])
def test_a_uniform_card_of_alpha_a_shades_the_ground_as_in_cycles(clean, alpha):
    mat, bsdf = _principled(f"Card{alpha}")
    bsdf.inputs["Alpha"].default_value = alpha
    _scene(mat)
    ours, cyc, _rep = _bake_both()
    if alpha == 0.0:
        assert np.all(cyc > 0.99) and np.all(ours == 1.0)  # nothing stops a ray
    assert abs(float(ours.mean()) - float(cyc.mean())) < 0.02
    assert float(np.abs(ours - cyc).max()) < 0.1


@pytest.mark.parametrize("via", ["direct", "math", "ramp", "closest"])
def test_a_textured_card_half_opaque_shades_the_ground_as_in_cycles(clean, via):
    """The card's image is clear for u < ½ (x < 0) and opaque beyond, read through the card's
    UV map (directly, through a Math node's Greater Than 0.5, a constant ColorRamp at 0.5, or
    directly from an image set to Closest interpolation):
    the ground is open on one side and dark on the other, as in Cycles."""
    img = bpy.data.images.new("HalfCard", 16, 16, alpha=True)
    px = np.ones((16, 16, 4), np.float32)
    px[:, :8, 3] = 0.0
    img.pixels.foreach_set(px.ravel())
    mat, bsdf = _principled("TexturedCard")
    tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
    tex.image = img
    nt = mat.node_tree
    if via == "closest":
        tex.interpolation = "Closest"
    if via in ("direct", "closest"):
        nt.links.new(tex.outputs["Alpha"], bsdf.inputs["Alpha"])
    elif via == "math":
        node = nt.nodes.new("ShaderNodeMath")
        node.operation, node.inputs[1].default_value = "GREATER_THAN", 0.5
        nt.links.new(tex.outputs["Alpha"], node.inputs[0])
        nt.links.new(node.outputs[0], bsdf.inputs["Alpha"])
    else:
        node = nt.nodes.new("ShaderNodeValToRGB")
        node.color_ramp.interpolation = "CONSTANT"
        node.color_ramp.elements[1].position = 0.5
        nt.links.new(tex.outputs["Alpha"], node.inputs[0])
        nt.links.new(node.outputs["Color"], bsdf.inputs["Alpha"])
    ground = _scene(mat)
    ours, cyc, _rep = _bake_both()
    x = np.array([v.co.x for v in ground.data.vertices])
    assert cyc[x < -0.5].mean() > 0.8 and cyc[x > 0.5].mean() < 0.4  # Cycles sees the halves
    assert abs(float(ours.mean()) - float(cyc.mean())) < 0.02
    assert float(np.abs(ours - cyc).max()) < 0.1


def test_a_material_not_understood_is_opaque_with_a_note_naming_it(clean):
    """An alpha from a Noise Texture is not read: the card bakes as an opaque one, and the
    report's notes name the material."""
    mat, bsdf = _principled("NoisyCard")
    noise = mat.node_tree.nodes.new("ShaderNodeTexNoise")
    mat.node_tree.links.new(noise.outputs["Fac"], bsdf.inputs["Alpha"])
    _scene(mat)
    opts = properties.scene_options(bpy.context.scene)
    opts.update(method="raytrace", samples=64, distance=10.0, use_world_distance=False)
    _job, rep = run_bake(bpy.context, ["Ground"], opts)
    noisy = mesh_io.read_ao_attribute(bpy.data.objects["Ground"], "CanopyAO").copy()
    assert any("NoisyCard" in n and "opaque" in n for n in rep["notes"]), rep["notes"]
    mat.node_tree.links.remove(bsdf.inputs["Alpha"].links[0])
    bsdf.inputs["Alpha"].default_value = 1.0
    run_bake(bpy.context, ["Ground"], opts)
    opaque = mesh_io.read_ao_attribute(bpy.data.objects["Ground"], "CanopyAO")
    assert np.array_equal(noisy, opaque)


def test_a_mix_with_a_transparent_bsdf_by_an_images_color_shades_as_in_cycles(clean):
    """The other common card: Mix Shader (Transparent BSDF, Principled) whose factor is an
    image's Color read through a UV Map node; here a black-and-white mask, white for v ≥ ½."""
    img = bpy.data.images.new("Mask", 8, 8)
    px = np.ones((8, 8, 4), np.float32)
    px[:4, :, :3] = 0.0
    img.pixels.foreach_set(px.ravel())
    mat = bpy.data.materials.new("MaskCard")
    materials.enable_nodes(mat)
    nt = mat.node_tree
    bsdf = next(n for n in nt.nodes if n.type == "BSDF_PRINCIPLED")
    out = next(n for n in nt.nodes if n.type == "OUTPUT_MATERIAL")
    mix, clear = nt.nodes.new("ShaderNodeMixShader"), nt.nodes.new("ShaderNodeBsdfTransparent")
    tex, uvmap = nt.nodes.new("ShaderNodeTexImage"), nt.nodes.new("ShaderNodeUVMap")
    tex.image, uvmap.uv_map = img, "UVMap"
    nt.links.new(uvmap.outputs["UV"], tex.inputs["Vector"])
    nt.links.new(tex.outputs["Color"], mix.inputs[0])
    nt.links.new(clear.outputs[0], mix.inputs[1])
    nt.links.new(bsdf.outputs[0], mix.inputs[2])
    nt.links.new(mix.outputs[0], out.inputs["Surface"])
    ground = _scene(mat)
    ours, cyc, _rep = _bake_both()
    y = np.array([v.co.y for v in ground.data.vertices])
    assert cyc[y < -0.5].mean() > 0.8 and cyc[y > 0.5].mean() < 0.4
    assert abs(float(ours.mean()) - float(cyc.mean())) < 0.02
    assert float(np.abs(ours - cyc).max()) < 0.1


def test_the_command_line_reports_the_material_it_could_not_read(clean, tmp_path):
    """The CLI as documented, on a saved scene: the bake succeeds and its JSON report's notes
    name the material read as opaque."""
    import json
    import os
    import subprocess
    mat, bsdf = _principled("NoisyCard")
    noise = mat.node_tree.nodes.new("ShaderNodeTexNoise")
    mat.node_tree.links.new(noise.outputs["Fac"], bsdf.inputs["Alpha"])
    _scene(mat)
    blend, report = str(tmp_path / "cards.blend"), str(tmp_path / "report.json")
    bpy.ops.wm.save_as_mainfile(filepath=blend, copy=True)
    r = subprocess.run([bpy.app.binary_path, "-b", blend, "--factory-startup", "--addons",
                        "canopy_ao", "--python-exit-code", "1", "--python-expr",
                        "import canopy_ao.cli as c; c.main()", "--", "--objects", "Ground",
                        "--method", "raytrace", "--samples", "16", "--report", report],
                       env=dict(os.environ), capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, (r.stdout + r.stderr)[-2000:]
    with open(report, encoding="utf-8") as f:
        notes = json.load(f)["notes"]
    assert any("NoisyCard" in n and "opaque" in n for n in notes), notes


def test_texels_of_the_ground_under_a_half_transparent_card_agree_with_cycles(clean, tmp_path):
    """Per texel (the receivers start on their triangles, not at vertices): a 16 × 16 texel bake
    of the ground under a card of alpha 0.5, against Cycles' texel bake of the same layout."""
    mat, bsdf = _principled("HalfCard")
    bsdf.inputs["Alpha"].default_value = 0.5
    ground = _scene(mat)
    uv = ground.data.uv_layers.new(name="UVMap")
    co = np.array([ground.data.vertices[lp.vertex_index].co[:2] for lp in ground.data.loops])
    vals = np.float32((co + 1.0) / 2.0).ravel()
    attr = ground.data.attributes.get("UVMap")
    if attr is not None and attr.data_type == "FLOAT2":
        attr.data.foreach_set("vector", vals)
    else:
        uv.data.foreach_set("uv", vals)
    opts = properties.scene_options(bpy.context.scene)
    opts.update(method="raytrace", samples=SAMPLES, distance=10.0, use_world_distance=False,
                mode="TEXEL", resolution=16, image_dir=str(tmp_path))
    _job, rep = run_bake(bpy.context, ["Ground"], opts)
    img = bpy.data.images.load(rep["objects"]["Ground"]["texel"]["path"], check_existing=False)
    px = np.empty(len(img.pixels), np.float32)
    img.pixels.foreach_get(px)
    ours = px.reshape(16, 16, -1)[:, :, 0]
    cyc, mask = cycles_check.bake_cycles_texel_ao(bpy.context, ground, "UVMap", 16, 10.0,
                                                  SAMPLES, return_mask=True)
    assert mask.sum() == 256
    assert abs(float(ours[mask].mean()) - float(cyc[mask].mean())) < 0.02
    assert float(np.abs(ours - cyc)[mask].max()) < 0.12
