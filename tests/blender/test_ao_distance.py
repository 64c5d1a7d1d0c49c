"""The AO distance means what Cycles means: the World's distance (10 without a World, as
Cycles' sync uses), its 0 (Cycles: no occlusion, AO 1.0 everywhere) refused by name rather than
read as unlimited, and the Cycles check bakes the distance the bake used, the add-on's own
unlimited (0) as a length no ray in the scene reaches past, at any scale."""
import bpy
import numpy as np
import pytest

import helpers_materials as H
from canopy_ao.blender import gather, mesh_io

ATTR = "CanopyAO"


@pytest.fixture
def disk_over_plane():
    """Ground (8 x 8 quads, side 2) under a disk of radius 1 at height 1, nothing selected."""
    H.empty_scene()
    ground = H.add_plane(size=2.0, subdivisions=7, name="Ground")
    bpy.ops.mesh.primitive_circle_add(vertices=32, radius=1.0, fill_type="NGON",
                                      location=(0, 0, 1.0))
    bpy.context.object.name = "Disk"
    for ob in bpy.data.objects:
        ob.select_set(False)
    return ground


def _world(distance):
    world = bpy.data.worlds.new("W")
    world.light_settings.distance = distance
    bpy.context.scene.world = world
    return world


def test_the_worlds_zero_is_refused_by_the_operator_and_the_cli(disk_over_plane, capsys):
    from canopy_ao import cli
    _world(0.0)
    with pytest.raises(RuntimeError, match="World 'W' has AO distance 0.*1.0 everywhere"):
        bpy.ops.canopy_ao.bake(objects="Ground", method="sphere", tau=2.0)
    with pytest.raises(SystemExit) as exc:
        cli.main(["--objects", "Ground", "--method", "sphere", "--tau", "2"])
    err = capsys.readouterr().err
    assert exc.value.code == 1 and "AO distance 0" in err and "--distance" in err, err
    assert ATTR not in disk_over_plane.data.attributes
    # A distance given is the add-on's own: 0 = unlimited, as documented.
    with pytest.raises(SystemExit) as exc:
        cli.main(["--objects", "Ground", "--method", "sphere", "--tau", "2", "--distance", "0"])
    assert exc.value.code == 0, capsys.readouterr().err
    assert ATTR in disk_over_plane.data.attributes


def test_without_a_world_the_distance_is_cycles_ten(disk_over_plane, capsys):
    """No World: Cycles' AO bake cuts rays at 10 (a disk at height 10.5 does not occlude,
    at 9.5 it does), and so does the bake, whose Cycles check agrees."""
    from canopy_ao import cli
    assert bpy.context.scene.world is None
    disk = bpy.data.objects["Disk"]
    disk.scale = (12.0, 12.0, 1.0)
    for height, shaded in ((10.5, False), (9.5, True)):
        disk.location.z = height
        with pytest.raises(SystemExit) as exc:
            cli.main(["--objects", "Ground", "--method", "raytrace", "--samples", "32",
                      "--check-cycles", "--cycles-samples", "32"])
        out = capsys.readouterr()
        assert exc.value.code == 0, out.err
        ao = mesh_io.read_ao_attribute(disk_over_plane, ATTR)
        assert (ao.mean() < 0.99) == shaded, (height, ao.mean())
        mae = float(out.out.split("vs Cycles MAE ")[1].split()[0])
        assert mae < 0.05, (height, mae, out.out)
    assert gather.world_ao_distance(bpy.context.scene) == 10.0


def test_the_cycles_check_of_an_unlimited_bake_is_unlimited_at_any_scale(disk_over_plane):
    """Ours unlimited (0) on a scene a million times larger: the check must not bake a fixed
    stand-in distance (a disk 1.5e6 up would not occlude at 1e6), but the scene's own reach."""
    from canopy_ao.blender.job import run_bake
    scale = 1.5e6
    for ob in bpy.data.objects:
        ob.scale = (scale,) * 3
        ob.location = tuple(c * scale for c in ob.location)
    _world(0.0)  # the check sets the World's distance itself and restores it
    _job, rep = run_bake(bpy.context, ["Ground"], dict(
        method="raytrace", samples=32, distance=0.0, check_cycles=True, cycles_samples=32,
        show_proxies=False, use_world_distance=False))
    e = rep["objects"]["Ground"]
    assert e["ao_mean"] < 0.9, e  # the disk occludes
    assert e["cycles"]["mae"] < 0.05, e["cycles"]
    assert bpy.context.scene.world.light_settings.distance == 0.0
    np.testing.assert_allclose(mesh_io.read_ao_attribute(disk_over_plane, ATTR).mean(),
                               e["ao_mean"], atol=1e-6)


def test_the_cycles_bake_refuses_a_distance_of_zero(disk_over_plane):
    """Cycles' 0 is no occlusion: its bake is never run with it (a caller's unlimited must
    become a length first)."""
    from canopy_ao.blender import cycles_check
    engine = bpy.context.scene.render.engine
    with pytest.raises(ValueError, match="Cycles would read 1.0 everywhere"):
        cycles_check.bake_cycles_vertex_ao(bpy.context, [disk_over_plane], 0.0, 4)
    assert bpy.context.scene.render.engine == engine and bpy.context.scene.world is None
