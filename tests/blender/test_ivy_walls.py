"""A wall an ivy climbs is a surface (GROUND): it receives and occludes like the ground and is
not made a tree of its own (core/roles.py; issue #38 item 5). Through the CLI, on a synthetic
wall with ivy-like leaves and branches, and on real ivy grown by Blender's bundled IvyGen."""

import json

import bpy
import numpy as np
import pytest

from conftest import _clear_scene, add_mesh, require_ivygen
from real_shapes import ivy_on_wall


def _bake(tmp_path, capsys, *args):
    from canopy_ao import cli
    report = tmp_path / "r.json"
    with pytest.raises(SystemExit) as exc:
        cli.main(["--all", "--overwrite", "--report", str(report), *args])
    assert exc.value.code == 0, capsys.readouterr().err
    return json.loads(report.read_text())


def _ao(name, attr):
    a = bpy.data.objects[name].data.attributes[attr]
    v = np.empty(len(a.data) * 4, np.float32)
    a.data.foreach_get("color", v)
    return v[0::4]


@pytest.fixture
def wall_scene():
    _clear_scene()
    obs = {n: add_mesh(n, p, t) for n, (p, t) in ivy_on_wall(np.random.default_rng(7)).items()}
    for ob in bpy.context.scene.objects:
        ob.select_set(False)
    bpy.context.view_layer.update()
    yield obs
    _clear_scene()


@pytest.mark.parametrize("method", ["raytrace", "auto"])
def test_wall_under_ivy_bakes_as_a_surface(wall_scene, tmp_path, capsys, method):
    """The wall is guessed GROUND and belongs to no tree; the ivy's leaves (CANOPY) and
    branches (TRUNK) are one tree, the only one fitted; the wall's AO is in [0, 1] and below 1
    where the ivy and the ground occlude it. It used to be a TRUNK and a tree of its own."""
    rep = _bake(tmp_path, capsys, "--method", method, "--samples", "32")
    objs = rep["objects"]
    got = {n: objs[n]["role"] for n in wall_scene}
    assert got == {"Wall": "GROUND", "IvyLeaves": "CANOPY", "IvyBranches": "TRUNK",
                   "Ground": "GROUND"}, {n: objs[n]["role_source"] for n in objs}
    assert "surface" in objs["Wall"]["role_source"]
    assert objs["IvyLeaves"]["tree"] == objs["IvyBranches"]["tree"]
    # The wall is lit as the ground is: no tree of its own, no proxy fitted to it.
    assert objs["Wall"]["tree"] == objs["Ground"]["tree"] and not objs["Wall"]["tree_why"]
    assert rep["proxies"] and all(k.startswith("IvyLeaves") for k in rep["proxies"])
    attr = bpy.context.scene.canopy_ao.attribute
    wall = _ao("Wall", attr)
    assert np.all((wall >= 0) & (wall <= 1))
    assert wall.mean() < 0.95  # the ivy and the ground occlude it


@pytest.fixture(params=[0.0, 0.2], ids=["quad", "slab"])
def real_ivy(request):
    """Ivy grown by IvyGen from the foot of a 3 m × 2 m wall (a quad, or a 20 cm slab) standing
    on an 8 m ground: IvyGen's leaf mesh (IvyLeaf) and its bevelled branch curve (IVY_Curve)."""
    require_ivygen()
    _clear_scene()
    thick = request.param
    if thick:
        bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0, 0, 1))
        bpy.context.active_object.scale = (3, thick, 2)
    else:
        bpy.ops.mesh.primitive_plane_add(size=1.0, location=(0, 0, 1), rotation=(1.5708, 0, 0))
        bpy.context.active_object.scale = (3, 2, 1)
    wall = bpy.context.active_object
    wall.name = "Wall"
    bpy.ops.object.transform_apply(location=True, rotation=True, scale=True)
    bpy.ops.mesh.primitive_plane_add(size=8.0)
    bpy.context.active_object.name = "Ground"
    bpy.ops.object.select_all(action='DESELECT')
    wall.select_set(True)
    bpy.context.view_layer.objects.active = wall
    bpy.context.scene.cursor.location = (0.0, -thick / 2 - 0.01, 0.02)
    props = bpy.context.window_manager.ivy_gen_props
    props.maxIvyLength, props.randomSeed = 3.0, 3
    assert bpy.ops.curve.ivy_gen(updateIvy=True) == {'FINISHED'}
    bpy.context.scene.cursor.location = (0.0, 0.0, 0.0)
    for ob in bpy.context.scene.objects:
        ob.select_set(False)
    bpy.context.view_layer.update()
    yield {ob.name: ob for ob in bpy.context.scene.objects}
    _clear_scene()


@pytest.mark.parametrize("method", ["raytrace", "auto"])
def test_ivygen_ivy_on_a_wall(real_ivy, tmp_path, capsys, method):
    """Real ivy from IvyGen: the wall is GROUND (it used to be '1 solid piece', a TRUNK and a
    tree of its own), the leaves CANOPY in the branch curve's tree, the only tree fitted; the
    wall is in no tree; its AO is in [0, 1]."""
    assert {"Wall", "Ground", "IvyLeaf", "IVY_Curve"} <= set(real_ivy), sorted(real_ivy)
    rep = _bake(tmp_path, capsys, "--method", method, "--samples", "32")
    objs = rep["objects"]
    why = {n: objs[n]["role_source"] for n in objs}
    assert objs["Wall"]["role"] == "GROUND" and "surface" in objs["Wall"]["role_source"], why
    assert objs["Ground"]["role"] == "GROUND", why
    assert objs["IvyLeaf"]["role"] == "CANOPY", why
    if "IVY_Curve" in objs:  # the branch curve, where curves are baked
        assert objs["IVY_Curve"]["role"] == "TRUNK", why
    # IvyGen parents the leaves to the branch curve: one tree, named by it, the only one fitted
    assert objs["IvyLeaf"]["tree"] == "IVY_Curve" and list(rep["proxies"]) == ["IVY_Curve"]
    assert objs["Wall"]["tree"] == objs["Ground"]["tree"] and not objs["Wall"]["tree_why"]
    attr = bpy.context.scene.canopy_ao.attribute
    wall = _ao("Wall", attr)
    assert np.all((wall >= 0) & (wall <= 1)) and wall.mean() < 1.0

