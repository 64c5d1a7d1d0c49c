"""Real assets in Blender: a Sapling Tree Gen trunk is guessed a trunk, and trees loose in one
collection are told apart by where they stand (core/trees.py), as the report says."""

import bpy
import numpy as np
import pytest

from conftest import _clear_scene, add_mesh, require_sapling


def _sapling_tree(offset_x):
    """A quaking aspen from Blender's bundled Sapling Tree Gen (leaves on), its branch curve
    converted to a mesh beside the leaves, unparented into the scene collection (as a user
    gathering trees into one collection would have them)."""
    require_sapling()
    before = set(bpy.data.objects)
    bpy.ops.curve.tree_add(do_update=True, bevel=True, showLeaves=True, seed=int(offset_x))
    new = [o for o in bpy.data.objects if o not in before]
    curve = next(o for o in new if o.type == 'CURVE')
    bpy.ops.object.select_all(action='DESELECT')
    curve.select_set(True)
    bpy.context.view_layer.objects.active = curve
    bpy.ops.object.convert(target='MESH')
    out = []
    for o in [o for o in bpy.data.objects if o not in before]:
        if o.type != 'MESH':
            continue
        mw = o.matrix_world.copy()
        o.parent = None
        o.matrix_world = mw
        o.location.x += offset_x
        out.append(o)
    bpy.context.view_layer.update()
    return out


@pytest.fixture
def two_sapling_trees():
    _clear_scene()
    obs = _sapling_tree(0.0) + _sapling_tree(40.0)
    g = 60.0
    add_mesh("Ground", np.float32([[-g, -g, 0], [g, -g, 0], [g, g, 0], [-g, g, 0]]),
             np.int32([[0, 1, 2], [0, 2, 3]]))
    for ob in bpy.context.scene.objects:
        ob.select_set(False)
    bpy.context.view_layer.update()
    yield obs
    _clear_scene()


def test_sapling_trunks_and_two_trees_in_one_collection(two_sapling_trees):
    """Before: every Sapling trunk was guessed CANOPY, and the two trees loose in the scene
    collection were fitted as one."""
    from canopy_ao.blender import properties
    from canopy_ao.blender.job import run_bake
    opts = properties.scene_options(bpy.context.scene)
    opts.update(method="ellipsoid", tau=1.5, distance=0.0)
    _job, rep = run_bake(bpy.context, [], opts)
    objs = rep["objects"]
    wood = [o.name for o in two_sapling_trees if len(o.data.polygons) and
            objs[o.name]["role"] == "TRUNK"]
    leaves = [n for n, e in objs.items() if e["role"] == "CANOPY"]
    assert len(wood) == 2 and len(leaves) == 2, {n: e["role_source"] for n, e in objs.items()}
    assert all("closed tubes" in objs[n]["role_source"] for n in wood)
    trees = {objs[n]["tree"] for n in wood + leaves}
    assert len(trees) == 2 and len(rep["proxies"]) == 2
    for n in wood + leaves:
        assert objs[n]["tree_source"] == "collection" and objs[n]["tree_why"]
    # each trunk shares its tree with the leaves standing over it
    for w in wood:
        x = bpy.data.objects[w].location.x
        mate = min(leaves, key=lambda n: abs(bpy.data.objects[n].location.x - x))
        assert objs[w]["tree"] == objs[mate]["tree"]
