"""Objects as an unusual user leaves them, baked as Cycles bakes them: a 1 m ground quad stood
up facing a 20 m wall 0.3 m away, under transforms that mirror it, flatten it (a scale of 0)
or come from a parent; and curves, text, surfaces and metaballs, which Cycles renders as the
mesh Blender makes of them, as occluders over or around the ground. Each compared with Cycles' own AO bake (16 samples,
distance 5; the wall leaves 0.00 or 1.00, so the comparison carries no noise)."""

import math

import bpy
import numpy as np
import pytest
from mathutils import Vector

from conftest import _clear_scene
from canopy_ao.blender import cycles_check, mesh_io

SAMPLES, DISTANCE = 16, 5.0
TOL = 0.05


def _quad(name, size, coll=None):
    s = size / 2
    me = bpy.data.meshes.new(name)
    me.from_pydata([(-s, -s, 0), (s, -s, 0), (s, s, 0), (-s, s, 0)], [], [(0, 1, 2, 3)])
    ob = bpy.data.objects.new(name, me)
    (coll or bpy.context.scene.collection).objects.link(ob)
    return ob


@pytest.fixture
def scene():
    _clear_scene()
    sc = bpy.context.scene
    if sc.world is None:
        sc.world = bpy.data.worlds.new("World")
    sc.world.light_settings.distance = DISTANCE
    yield sc
    _clear_scene()


def _bake_and_cycles(target):
    bpy.context.view_layer.update()
    result = bpy.ops.canopy_ao.bake(objects=target.name, method="raytrace", samples=SAMPLES,
                                    distance=DISTANCE, show_proxies=False)
    assert result == {'FINISHED'}
    ours = mesh_io.read_ao_attribute(target, "CanopyAO")
    cycles = cycles_check.bake_cycles_vertex_ao(bpy.context, [target], DISTANCE,
                                                SAMPLES)[target.name]
    return ours, cycles


def _parented_mirror(ob):
    parent = bpy.data.objects.new("Parent", None)
    bpy.context.scene.collection.objects.link(parent)
    parent.scale = (1.0, -1.0, 1.0)
    ob.parent = parent


# (name, what is done to the stood-up ground, Cycles' AO as measured: 0 facing the wall)
TRANSFORMS = [
    ("stood up", lambda ob: None, 0),
    ("mirrored in x", lambda ob: setattr(ob, "scale", (-1.0, 1.0, 1.0)), 0),
    ("mirrored in z (turned away)", lambda ob: setattr(ob, "scale", (1.0, 1.0, -1.0)), 1),
    ("non-uniform, mirrored in x", lambda ob: setattr(ob, "scale", (-2.0, 0.5, 3.0)), 0),
    ("flattened: scale 0 in z", lambda ob: setattr(ob, "scale", (1.0, 1.0, 0.0)), 0),
    ("under a parent mirrored in y", _parented_mirror, 1),
]


@pytest.mark.parametrize("change, cycles_ao", [t[1:] for t in TRANSFORMS],
                         ids=[t[0] for t in TRANSFORMS])
def test_a_transformed_ground_is_lit_as_cycles_lights_it(scene, change, cycles_ao):
    """The normals follow the transform as Cycles' do: mirrors by the inverse transpose, a
    scale of 0 as Cycles inverts it (the normal along the flattened axis, in world space;
    before: the object's normal unrotated, 0.4 against Cycles' 0.0)."""
    ground = _quad("Ground", 1.0)
    ground.canopy_ao.role = 'GROUND'
    ground.rotation_euler = (math.pi / 2, 0.0, 0.0)  # its +z normal now faces -y
    wall = _quad("Wall", 20.0)
    wall.canopy_ao.role = 'TRUNK'
    wall.rotation_euler, wall.location = (math.pi / 2, 0.0, 0.0), (0.0, -0.3, 0.0)
    change(ground)
    ours, cycles = _bake_and_cycles(ground)
    assert abs(cycles.mean() - cycles_ao) < TOL  # what Cycles does, as measured
    np.testing.assert_allclose(ours, cycles, atol=TOL)


def _text():
    bpy.ops.object.text_add(location=(0.0, 0.0, 0.3))
    ob = bpy.context.object
    ob.data.body, ob.data.size = "I", 60.0
    bpy.context.view_layer.update()  # centre the glyph (a bar) over the ground
    box = np.array([ob.matrix_world @ Vector(c) for c in ob.bound_box])
    ob.location.x -= float(box[:, 0].mean())
    ob.location.y -= float(box[:, 1].mean())
    return ob


def _curve():
    cu = bpy.data.curves.new("Sheet", 'CURVE')
    cu.dimensions, cu.fill_mode = '2D', 'BOTH'
    sp = cu.splines.new('POLY')
    sp.points.add(3)
    for p, (x, y) in zip(sp.points, [(-10, -10), (10, -10), (10, 10), (-10, 10)]):
        p.co = (x, y, 0.0, 1.0)
    sp.use_cyclic_u = True
    ob = bpy.data.objects.new("Sheet", cu)
    ob.location.z = 0.3
    bpy.context.scene.collection.objects.link(ob)
    return ob


def _surface():
    """A NURBS sphere around the ground: every ray from it stops on its inside."""
    bpy.ops.surface.primitive_nurbs_surface_sphere_add(radius=3.0, location=(0, 0, 0))
    return bpy.context.object


def _metaball():
    """A metaball around the ground, likewise."""
    mb = bpy.data.metaballs.new("Ball")
    mb.elements.new(type='BALL').radius = 4.0
    ob = bpy.data.objects.new("Ball", mb)
    bpy.context.scene.collection.objects.link(ob)
    return ob


def _instanced_curve():
    """The curve sheet in a collection instanced by an empty, its own collection excluded
    from the view layer."""
    coll = bpy.data.collections.new("Sheets")
    bpy.context.scene.collection.children.link(coll)
    sheet = _curve()
    bpy.context.scene.collection.objects.unlink(sheet)
    coll.objects.link(sheet)
    bpy.context.view_layer.layer_collection.children["Sheets"].exclude = True
    empty = bpy.data.objects.new("SheetInstance", None)
    empty.instance_type, empty.instance_collection = 'COLLECTION', coll
    bpy.context.scene.collection.objects.link(empty)
    return empty


@pytest.mark.parametrize("make", [_text, _curve, _surface, _metaball, _instanced_curve],
                         ids=["text", "curve", "surface", "metaball", "instanced curve"])
def test_curves_text_surfaces_and_metaballs_occlude_as_cycles_renders_them(scene, make):
    """Cycles renders them as the mesh Blender makes of them, and its AO rays stop on them
    (0.00: a sheet over the ground, or a closed one around it); so do ours (before: they were
    left out, the ground read 1.00)."""
    ground = _quad("Ground", 1.0)
    ground.canopy_ao.role = 'GROUND'
    make()
    for ob in scene.objects:
        ob.select_set(False)
    ours, cycles = _bake_and_cycles(ground)
    assert cycles.mean() < TOL  # it occludes in Cycles
    np.testing.assert_allclose(ours, cycles, atol=TOL)


def test_a_loose_vertex_is_left_out_of_the_cycles_check(scene):
    """Cycles bakes face corners, so a loose vertex keeps 0 in its bake, whatever lights it:
    the check compares the vertices faces use (a stray vertex read as an error of up to 1)."""
    from canopy_ao.blender.job import run_bake
    from canopy_ao.blender import properties
    ground = _quad("Ground", 1.0)
    ground.canopy_ao.role = 'GROUND'
    ground.data.vertices.add(1)
    ground.data.vertices[4].co = (3.0, 3.0, 3.0)  # open sky: ours 1.0, Cycles' bake 0.0
    ground.data.update()
    opts = dict(properties.scene_options(scene), method="raytrace", samples=SAMPLES,
                distance=DISTANCE, show_proxies=False, check_cycles=True)
    _job, rep = run_bake(bpy.context, ["Ground"], opts)
    check = rep["objects"]["Ground"]["cycles"]
    assert check["n"] == 4 and check["mae"] < TOL, check


def test_custom_split_normals_of_a_target_are_named_in_the_notes(scene):
    """Cycles' bake turns each corner's hemisphere around its custom split normal; this bake's
    rays do too, per vertex and per texel (the two tests below), but its proxies, grid and
    medium take the vertex normals: the report names the object instead of saying nothing."""
    from canopy_ao.blender.job import run_bake
    from canopy_ao.blender import properties
    ground = _quad("Ground", 1.0)
    ground.canopy_ao.role = 'GROUND'
    opts = dict(properties.scene_options(scene), method="raytrace", samples=SAMPLES,
                distance=DISTANCE, show_proxies=False)
    _job, rep = run_bake(bpy.context, ["Ground"], opts)
    assert not any("custom split normals" in n for n in rep["notes"]), rep["notes"]
    me = ground.data
    if hasattr(me, "use_auto_smooth"):  # before 4.1, custom normals need Auto Smooth
        me.use_auto_smooth = True
    me.normals_split_custom_set([(0.0, 0.7071, 0.7071)] * len(me.loops))
    _job, rep = run_bake(bpy.context, ["Ground"], dict(opts, overwrite=True))
    assert any(n.startswith("Ground: custom split normals") and "not its proxies"
               in n for n in rep["notes"]), rep["notes"]


def _rock_on_ground(shading):
    """An icosphere rock (20 faces) on a 20 × 20 grid ground: its faces smooth, flat, or smooth
    with custom split normals pointing away from a point 2 m below (a foliage trick)."""
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=20, y_subdivisions=20, size=4)
    bpy.context.object.name = "Ground"
    bpy.context.object.canopy_ao.role = 'GROUND'
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=1, radius=0.8, location=(0, 0, 0.6))
    rock = bpy.context.object
    rock.name = "Rock"
    rock.canopy_ao.role = 'TRUNK'
    me = rock.data
    for p in me.polygons:
        p.use_smooth = shading != "flat"
    if shading == "custom":
        if hasattr(me, "use_auto_smooth"):  # before 4.1, custom normals need Auto Smooth
            me.use_auto_smooth = True
        co = np.array([me.vertices[lp.vertex_index].co for lp in me.loops]) - (0.0, 0.0, -2.0)
        me.normals_split_custom_set([tuple(d) for d in co / np.linalg.norm(co, axis=1)[:, None]])
    return rock


@pytest.mark.parametrize("shading", ["flat", "custom", "smooth"])
def test_a_rocks_corners_turn_around_their_own_normals_as_cycles_bakes_them(scene, shading):
    """Cycles bakes each face corner around that corner's own normal (the face's on a flat
    face; the custom one where set). The rays per vertex do too: the rock's MAE against Cycles
    is 0.0065 flat and 0.0047 with custom normals, where taking the vertex normals read 0.045
    and 0.196 (smooth: 0.0099). This test prints them (run_pytest.py ... -k corners_turn -s)."""
    from canopy_ao.blender.job import run_bake
    from canopy_ao.blender import properties
    _rock_on_ground(shading)
    opts = dict(properties.scene_options(scene), method="raytrace", samples=64,
                distance=DISTANCE, show_proxies=False, check_cycles=True)
    _job, rep = run_bake(bpy.context, ["Rock", "Ground"], opts)
    rock = rep["objects"]["Rock"]["cycles"]
    print(f"{shading} rock: MAE {rock['mae']:.4f} against Cycles over {rock['n']:.0f} vertices")
    assert rock["n"] == 12 and rock["mae"] < 0.02, rock
    assert rep["objects"]["Ground"]["cycles"]["mae"] < 0.02, rep["objects"]["Ground"]["cycles"]


def test_custom_normals_per_texel_lift_their_rays_as_cycles_does(scene, tmp_path):
    """A ground's custom normals tilted 45° under a disk, per texel: Cycles lifts a grazing
    ray's start onto the smooth surface its corner normals describe (shadow terminator offset),
    and so do the rays, from the same corner normals. MAE against Cycles 0.0157, plain normals
    0.0180, where the lift from the vertex normals read 0.145 (this test prints it; -s)."""
    import helpers_materials as H
    from canopy_ao.blender.job import run_bake
    from canopy_ao.blender import properties
    ground = H.add_plane(name="Ground")
    bpy.ops.mesh.primitive_circle_add(vertices=24, radius=0.6, fill_type="NGON",
                                      location=(0.3, 0, 0.4))
    H.leaves_over_ground(ground, bpy.context.object, tmp_path)
    me = ground.data
    if hasattr(me, "use_auto_smooth"):  # before 4.1, custom normals need Auto Smooth
        me.use_auto_smooth = True
    me.normals_split_custom_set([(0.0, 0.7071, 0.7071)] * len(me.loops))
    opts = dict(properties.scene_options(scene), mode='TEXEL', method="raytrace", distance=0.0,
                show_proxies=False, image_dir=str(tmp_path), samples=64, resolution=32,
                check_cycles=True, cycles_samples=64)
    _job, rep = run_bake(bpy.context, ["Ground"], opts)
    check = rep["objects"]["Ground"]["cycles"]
    print(f"tilted custom normals per texel: MAE {check['mae']:.4f} against Cycles")
    assert check["n"] == 32 * 32 and check["mae"] < 0.03, check
