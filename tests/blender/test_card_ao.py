"""A card's own AO (core/card_ao.py; issue #38 item 3), against Cycles' texel bake of the card:
a 1 × 1 alpha-textured card standing on a ground. Cycles' vertex bake reads 0 at its clear
corners; ours carries the AO of the card's opaque part to its vertices (their mean within 0.02
of Cycles' mean over the opaque texels, wherever on the card the leaf is), and our texel bake
agrees with Cycles' on the opaque texels."""

import os
import sys

import bpy
import numpy as np
import pytest

from conftest import REPO, _clear_scene, add_grid_ground, add_mesh
from canopy_ao.blender import cycles_check, mesh_io, properties
from canopy_ao.blender.job import run_bake

sys.path.insert(0, os.path.join(REPO, "examples"))
import foliage_scenes  # noqa: E402

SAMPLES, RES = 256, 32


def _scene(centre, length):
    """A 4 × 4 ground (9 × 9 vertices) and the card in the xz plane, x in [-0.5, 0.5], z in
    [0, 1], UVs (x + 0.5, z), its leaf a lens (foliage_scenes.leaf_card_image)."""
    _clear_scene()
    add_grid_ground(4.0, 8)
    p = np.array([[-0.5, 0, 0], [0.5, 0, 0], [0.5, 0, 1], [-0.5, 0, 1]], np.float32)
    card = add_mesh("Card", p, np.int32([[0, 1, 2], [0, 2, 3]]))
    card["canopy_ao_role"] = "CANOPY"
    me = card.data
    uv = me.uv_layers.new(name="UVMap")
    co = np.array([me.vertices[lp.vertex_index].co for lp in me.loops])
    uv.data.foreach_set("uv", np.float32(np.column_stack([co[:, 0] + 0.5, co[:, 2]])).ravel())
    img, _frac = foliage_scenes.leaf_card_image("Leaf", RES, centre=centre, length=length)
    me.materials.append(foliage_scenes.card_material("LeafCard", img))
    c = (np.arange(RES) + 0.5) / RES * 2.0 - 1.0
    u, v = np.meshgrid(c, c)
    return card, (u / foliage_scenes.LEAF_WIDTH) ** 2 + ((v - centre) / length) ** 2 < 1.0


@pytest.mark.parametrize("centre,length", [(0.0, 1.0), (0.5, 0.5)], ids=["whole", "top"])
def test_card_vertices_carry_their_opaque_part(tmp_path, centre, length):
    card, leaf = _scene(centre, length)
    opts = properties.scene_options(bpy.context.scene)
    opts.update(method="raytrace", samples=SAMPLES, distance=10.0, use_world_distance=False)
    run_bake(bpy.context, ["Card"], opts)
    ours_v = mesh_io.read_ao_attribute(card, "CanopyAO")
    cyc_v = cycles_check.bake_cycles_vertex_ao(bpy.context, [card], 10.0, SAMPLES)["Card"]
    opts.update(mode="TEXEL", resolution=RES, image_dir=str(tmp_path))
    _job, rep = run_bake(bpy.context, ["Card"], opts)
    img = bpy.data.images.load(rep["objects"]["Card"]["texel"]["path"], check_existing=False)
    px = np.empty(len(img.pixels), np.float32)
    img.pixels.foreach_get(px)
    ours_t = px.reshape(RES, RES, -1)[:, :, 0]
    cyc_t, mask = cycles_check.bake_cycles_texel_ao(bpy.context, card, "UVMap", RES, 10.0,
                                                    SAMPLES, return_mask=True)
    opaque = leaf & mask
    print(f"vertices ours {np.round(ours_v, 3)}, Cycles {np.round(cyc_v, 3)}; opaque texels "
          f"Cycles {cyc_t[opaque].mean():.3f}, ours {ours_t[opaque].mean():.3f}")
    assert float(np.abs(cyc_v).max()) < 0.05  # Cycles: black cards
    assert float(cyc_t[mask & ~leaf].mean()) < 0.01  # ... and black clear texels
    # Ours: the opaque part's AO, carried to the vertices
    assert abs(float(ours_v.mean()) - float(cyc_t[opaque].mean())) < 0.02
    assert float(np.abs(ours_t - cyc_t)[opaque].mean()) < 0.02
    _clear_scene()
