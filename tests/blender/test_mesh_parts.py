"""Parts of one mesh (core/mesh_parts.py, blender/parts_io.py; issue #38 item 4): a Sapling tree
joined into one object bakes, rung by rung, as the same tree in two objects (bark, leaves),
whether its parts are told by material slots (leaves named so, or alpha-textured cards) or,
without materials, by the shape of its loose pieces; the report lists each part, its role and
why."""

import os
import sys

import bpy
import numpy as np
import pytest

from foliage_helpers import baked_ao, cli_bake
from conftest import REPO, _clear_scene, require_sapling

sys.path.insert(0, os.path.join(REPO, "examples"))
import foliage_scenes  # noqa: E402

RUNGS = ("sphere", "ellipsoid", "shells", "medium", "reeves_blau", "grid", "regression",
         "hybrid", "raytrace")


def _scene(joined, materials, cards=False):
    require_sapling()
    _clear_scene()
    col = bpy.data.collections.new("Tree")
    bpy.context.scene.collection.children.link(col)
    objs = foliage_scenes.sapling_card_tree(col, cards=cards, joined=joined,
                                            materials=materials)
    foliage_scenes.ground(col)
    for ob in bpy.context.scene.objects:
        ob.select_set(False)
    bpy.context.view_layer.update()
    return objs


@pytest.mark.parametrize("materials,cards", [(True, False), (True, True), (False, False)],
                         ids=["slots", "cards", "shape"])
def test_joined_tree_bakes_as_two_objects(tmp_path, capsys, materials, cards):
    """Every rung: the joined tree's AO (bark vertices first, as Object > Join keeps them)
    within 0.005 MAE of the two objects', and its report lists the parts: bark TRUNK, leaves
    CANOPY, each with its reason."""
    split = {}
    for method in RUNGS:
        objs = _scene(False, materials, cards)
        rep = cli_bake(tmp_path, capsys, "--all", "--method", method, "--samples", "32")
        assert rep["objects"][objs["trunk"].name]["role"] == "TRUNK"
        assert rep["objects"][objs["canopy"].name]["role"] == "CANOPY"
        split[method] = np.concatenate([baked_ao(objs["trunk"].name),
                                        baked_ao(objs["canopy"].name)])
    for method in RUNGS:
        _scene(True, materials, cards)
        rep = cli_bake(tmp_path, capsys, "--all", "--method", method, "--samples", "32")
        e = rep["objects"]["Tree"]
        assert [p["role"] for p in e["parts"]] == ["TRUNK", "CANOPY"], e
        assert all(p["why"] for p in e["parts"])
        assert "parts:" in e["role_source"]
        if cards:
            assert "Bark" in e["parts"][0]["why"] and "alpha" in e["parts"][1]["why"]
        elif materials:
            assert "Bark" in e["parts"][0]["why"] and "Leaves" in e["parts"][1]["why"]
        else:
            assert "closed pieces" in e["parts"][0]["why"]
        joined = baked_ao("Tree")
        assert joined.shape == split[method].shape
        mae = float(np.abs(joined - split[method]).mean())
        print(f"{method}: joined vs two objects MAE {mae:.5f}")
        assert mae <= 0.005, (method, mae)
    _clear_scene()



def test_joined_card_tree_per_texel(tmp_path, capsys):
    """Per texel, a texel takes its triangle's part: the joined card tree bakes into one image
    with its parts listed, values in [0, 1] and shaded (its cards overlap in UV space, every
    leaf on the whole square, so texels are not compared one by one with two objects')."""
    from canopy_ao.blender.job import run_bake
    from canopy_ao.blender import properties
    objs = _scene(True, True, True)
    opts = properties.scene_options(bpy.context.scene)
    opts.update(method="ellipsoid", mode="TEXEL", resolution=64, image_dir=str(tmp_path),
                overwrite=True)
    _job, rep = run_bake(bpy.context, [objs["tree"].name], opts)
    e = rep["objects"][objs["tree"].name]
    assert [p["role"] for p in e["parts"]] == ["TRUNK", "CANOPY"]
    img = bpy.data.images.load(e["texel"]["path"], check_existing=False)
    px = np.empty(len(img.pixels), np.float32)
    img.pixels.foreach_get(px)
    ao = px.reshape(64, 64, -1)[:, :, 0]
    assert np.all((ao >= 0) & (ao <= 1)) and ao.min() < 0.9
    _clear_scene()


def test_a_frame_range_bakes_a_joined_tree_whole(tmp_path, capsys):
    """A frame range (live frames alike) reads each object as one item: the joined tree bakes
    whole, with one role (a note says why), instead of failing on its parts' names ('Tree
    [trunk] is no longer in scene')."""
    _scene(True, True, True)
    rep = cli_bake(tmp_path, capsys, "--all", "--method", "ellipsoid", "--frames", "1", "2")
    assert "Tree" in rep["objects"], rep
    a = bpy.data.objects["Tree"].data.attributes[rep["cache"][0]]
    ao = np.empty(len(a.data), np.float32)
    a.data.foreach_get("value", ao)
    assert len(ao) == len(bpy.data.objects["Tree"].data.vertices)
    assert np.all((ao >= 0) & (ao <= 1))
    _clear_scene()
