"""examples/foliage_scenes.py (issue #38 item 6): every scene builds with Blender's own tools
(Sapling, IvyGen, Geometry Nodes, particles), as its command line documents."""

import os
import subprocess
import sys

import bpy
import pytest

from conftest import REPO, _clear_scene, require_sapling

sys.path.insert(0, os.path.join(REPO, "examples"))
import foliage_scenes  # noqa: E402

EXPECT = {"card_tree": {"Tree_branches", "Tree_leaves", "Ground"},
          "card_tree_joined": {"Tree", "Ground"},
          "card_birch": {"Tree_branches", "Tree_leaves", "Ground"},
          "opaque_tree": {"Tree_branches", "Tree_leaves", "Ground"},
          "sapling_joined": {"Tree", "Ground"},
          "ivy_wall": {"Wall", "Ground", "IvyLeaf"},
          "gn_cards": {"Trunk", "Crown", "LeafCard", "Ground"},
          "particle_cards": {"Trunk", "Crown", "LeafCard", "Ground"}}


@pytest.mark.parametrize("scene", foliage_scenes.SCENES + foliage_scenes.PICTURES)
def test_scene_builds(scene):
    require_sapling()
    if scene == "ivy_wall":
        from conftest import require_ivygen
        require_ivygen()
    objs = foliage_scenes.build(scene)
    names = {o.name for o in bpy.context.scene.objects}
    assert EXPECT[scene] <= names, names
    if scene.startswith("card_"):  # the leaves' material keeps its alpha texture
        mats = {m.name for o in objs.values() for m in o.data.materials if m}
        assert "Leaf card" in mats and "Bark" in mats, mats
    _clear_scene()


def test_documented_command(tmp_path):
    require_sapling()
    blend = tmp_path / "card_tree_joined.blend"
    r = subprocess.run([bpy.app.binary_path, "-b", "--factory-startup", "--python-exit-code",
                        "1", "--python", os.path.join(REPO, "examples", "foliage_scenes.py"),
                        "--", "--scene", "card_tree_joined", "--blend", str(blend)],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, (r.stdout + r.stderr)[-2000:]
    assert blend.exists() and "foliage_scenes: card_tree_joined" in r.stdout
