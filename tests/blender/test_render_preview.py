"""examples/render_preview.py's AO look (the README's leaf-card picture, examples/card_picture.sh):
a card's alpha cuts it out of the picture as Cycles renders it, so what shows through the clear
part is what lies behind, and the opaque part shows the baked AO itself (Raw, one grey
channel: a pixel is the AO value)."""
import os
import subprocess
import sys

import bpy
import numpy as np
import pytest

from conftest import REPO, _clear_scene

sys.path.insert(0, os.path.join(REPO, "examples"))
import foliage_scenes  # noqa: E402

CARD_AO = 0.3
BACKGROUND = 0.6


def half_clear_card(surface):
    """A 1 × 1 card standing in the XZ plane (facing −y), its left half opaque and its right
    half clear by a 2 × 2 image's alpha, every vertex's CanopyAO = CARD_AO. surface: "principled"
    (the Principled BSDF's Alpha, as foliage_scenes' cards) or "mix" (a Mix Shader of a
    Transparent and a Diffuse BSDF by the image's alpha)."""
    me = bpy.data.meshes.new("Card")
    me.from_pydata([[-0.5, 0, 0], [0.5, 0, 0], [0.5, 0, 1], [-0.5, 0, 1]], [], [[0, 1, 2, 3]])
    uv = me.uv_layers.new(name="UVMap")
    uv.data.foreach_set("uv", np.float32([[0, 0], [1, 0], [1, 1], [0, 1]]).ravel())
    img = bpy.data.images.new("HalfClear", 2, 2, alpha=True)
    img.pixels.foreach_set(np.float32([[1, 1, 1, 1], [1, 1, 1, 0]] * 2).ravel())
    img.pack()
    mat = foliage_scenes.card_material("Half clear", img)
    if surface == "mix":
        nt = mat.node_tree
        tex = next(n for n in nt.nodes if n.type == "TEX_IMAGE")
        mix = nt.nodes.new("ShaderNodeMixShader")
        nt.links.new(tex.outputs["Alpha"], mix.inputs[0])
        nt.links.new(nt.nodes.new("ShaderNodeBsdfTransparent").outputs[0], mix.inputs[1])
        nt.links.new(nt.nodes.new("ShaderNodeBsdfDiffuse").outputs[0], mix.inputs[2])
        nt.links.new(mix.outputs[0], nt.get_output_node("CYCLES").inputs["Surface"])
    me.materials.append(mat)
    attr = me.color_attributes.new("CanopyAO", "FLOAT_COLOR", "POINT")
    attr.data.foreach_set("color", np.float32([CARD_AO, CARD_AO, CARD_AO, 1.0] * 4))
    ob = bpy.data.objects.new("Card", me)
    bpy.context.scene.collection.objects.link(ob)
    return ob


def grey(path):
    img = bpy.data.images.load(path, check_existing=False)
    try:
        w, h = img.size
        px = np.empty(w * h * 4, np.float32)
        img.pixels.foreach_get(px)
        return px.reshape(h, w, 4)[..., 0]  # row 0 at the bottom, as Blender stores pixels
    finally:
        bpy.data.images.remove(img)


@pytest.mark.parametrize("surface", ["principled", "mix"])
def test_the_ao_look_cuts_cards_out_by_their_alpha(tmp_path, surface):
    _clear_scene()
    half_clear_card(surface)
    blend = str(tmp_path / "card.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend, copy=True)
    _clear_scene()
    out = str(tmp_path / "card.png")
    r = subprocess.run([bpy.app.binary_path, "-b", blend, "--python-exit-code", "1", "--python",
                        os.path.join(REPO, "examples", "render_preview.py"), "--",
                        "--out", out, "--size", "64", "48", "--samples", "4", "--frame", "Card",
                        "--view", "0", "-1", "0", "--raw", "--grey",
                        "--background", *[str(BACKGROUND)] * 3],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, (r.stdout + r.stderr)[-2000:]
    px = grey(out)
    assert px.shape == (48, 64)
    # Framed from straight in front, the card fills columns ~16-48 of the middle row: its
    # left half 16-32, its right half 32-48.
    row = px[px.shape[0] // 2]
    assert np.all(np.abs(row[18:30] - CARD_AO) < 0.02), row  # the opaque half: the AO
    assert np.all(np.abs(row[34:46] - BACKGROUND) < 0.02), row  # the clear half: behind it
    assert abs(px[2, 2] - BACKGROUND) < 0.02  # the background itself


def test_the_readme_card_picture_is_small_and_not_blank():
    """examples/images/card_birch_ao.png, made by examples/card_picture.sh: 900 × 600 under
    400 KB, and a tree in it (many grey tones between the background's and the ground's)."""
    path = os.path.join(REPO, "examples", "images", "card_birch_ao.png")
    assert os.path.getsize(path) < 400_000
    px = grey(path)
    assert px.shape == (600, 900)
    assert abs(px[-1, -1] - 0.2) < 0.02  # the background
    assert px.std() > 0.1
    assert len(np.unique(np.round(px * 255))) > 100
