"""Grass scattered as instances (a hair particle system rendering one blade object: how grass is
usually made in Blender) occludes the ground as the same field made real does, under every
rung (docs/DESIGN.md, 'How each role is lit'). Before, instances of a prototype without leaves
were dropped: the ground under a particle field read 1.0 under every rung, rays included.

Known answers: the realised field (the same blades, each at its instance's matrix, joined into
one mesh beside the ground) is the reference: the instanced bake must agree with it to noise
for the rays and closely for the analytic rungs (they see the same arrays); the blade prototype
gets one AO per vertex, its instances' mean, darker at the root than at the tip."""

import bpy
import numpy as np
import pytest

import tree_scene
from conftest import _clear_scene, add_mesh
from canopy_ao.blender import mesh_io, properties
from canopy_ao.blender.job import run_bake

ATTR = "CanopyAO"
HEIGHT = 0.3


def blade():
    """A blade modelled along +Y (a hair particle lays its instance's Y axis along the hair),
    4 quads, 0.02 m wide at the root, tapering, HEIGHT tall."""
    p, t = [], []
    for i in range(5):
        s = i / 4
        w = 0.01 * (1 - s) + 0.001
        p += [(-w, HEIGHT * s, 0.02 * s * s), (w, HEIGHT * s, 0.02 * s * s)]
    for i in range(4):
        a = 2 * i
        t += [(a, a + 1, a + 3), (a, a + 3, a + 2)]
    return np.float32(p), np.int32(t)


@pytest.fixture
def field():
    """Ground (4 × 4 m, 32 × 32 cells) with a hair particle system of 1500 instances of Blade
    (in collection BladeProto, excluded from the view layer: only its instances are seen)."""
    _clear_scene()
    scene = bpy.context.scene
    scene.canopy_ao.calibrate_tau = True
    gp, gt = tree_scene.plane(size=4.0, cuts=32)
    ground = add_mesh("Ground", gp, gt)
    coll = bpy.data.collections.new("BladeProto")
    scene.collection.children.link(coll)
    add_mesh("Blade", *blade(), collection=coll)
    bpy.context.view_layer.layer_collection.children["BladeProto"].exclude = True
    mod = ground.modifiers.new("Grass", 'PARTICLE_SYSTEM')
    ps = mod.particle_system.settings
    ps.type = 'HAIR'
    ps.count = 1500
    ps.use_advanced_hair = True
    ps.hair_length = 1.0
    ps.render_type = 'OBJECT'
    ps.instance_object = bpy.data.objects["Blade"]
    ps.particle_size = 1.0
    ps.size_random = 0.3
    ps.use_rotations = True
    ps.rotation_mode = 'NOR'  # the blade's Y axis along the ground's normal: upright
    ps.phase_factor_random = 2.0  # any turn about it
    mod.particle_system.seed = 7
    bpy.context.view_layer.update()
    yield ground
    _clear_scene()


def instances_made_real(name, points, triangles):
    """(vertex blocks, triangle blocks): the mesh (points, triangles) of prototype `name` moved
    by each of its instances' matrices, as a script making the instances real would."""
    dg = bpy.context.evaluated_depsgraph_get()
    verts, tris = [], []
    for inst in dg.object_instances:
        if inst.is_instance and inst.instance_object.original.name == name:
            m = np.array(inst.matrix_world, np.float64)
            tris.append(triangles + len(verts) * len(points))
            verts.append((points @ m[:3, :3].T + m[:3, 3]).astype(np.float32))
    return verts, tris


def realize_field():
    """The field made real, as a script would: every instance's blade, moved by its matrix,
    joined into one mesh 'RealGrass'; the particle system removed."""
    verts, tris = instances_made_real("Blade", *blade())
    assert len(verts) == 1500
    ground = bpy.data.objects["Ground"]
    ground.modifiers.remove(ground.modifiers["Grass"])
    add_mesh("RealGrass", np.concatenate(verts), np.concatenate(tris))
    bpy.context.view_layer.update()


def bake_ground(method, distance=0.5, **kw):
    opts = properties.scene_options(bpy.context.scene)
    opts.update(method=method, distance=distance, samples=64, tau=None if method == "auto" else 2.0,
                show_proxies=False, **kw)
    _job, rep = run_bake(bpy.context, ["Ground"], opts)
    return mesh_io.read_ao_attribute(bpy.data.objects["Ground"], ATTR), rep


METHODS = ["raytrace", "sphere", "grid", "regression", "auto"]


def test_instanced_grass_occludes_the_ground_as_the_same_field_made_real(field):
    got = {}
    for m in METHODS:
        got[m], rep = bake_ground(m)
        fields = rep["instances"]["realized"]
        assert len(fields) == 1 and next(iter(fields.values()))["instances"] == 1500, fields
        assert any("instanced grass" in n and "1500 instance(s) of Blade" in n
                   for n in rep["notes"]), rep["notes"]
    realize_field()
    for m in METHODS:
        want, rep = bake_ground(m)
        assert not rep["instances"]["realized"]
        # The field shades its ground (its mean reads 0.85 on Blender 3.4).
        assert want.mean() < 0.9, (m, want.mean())
        # The same arrays, to float rounding: the same bake (0.0 on Blender 3.4; before, the
        # instanced field read 1.0 everywhere, 0.15 off).
        err = np.abs(got[m] - want).mean()
        assert err < 0.002, (m, err)


def test_a_field_too_big_to_realise_stays_instances_traced_by_rays(field, monkeypatch):
    """Over forest.MAX_REALIZED_VERTICES (3 M; here lowered below the field's 15,000) the
    instances stay instances: the exact rung still traces them, and the note says that the
    other rungs do not see them (a field that size would not fit in memory made real)."""
    from canopy_ao.core import forest
    monkeypatch.setattr(forest, "MAX_REALIZED_VERTICES", 10_000)
    rays, rep = bake_ground("raytrace")
    assert not rep["instances"]["realized"]
    assert any("15,000 vertices in all, over the 10,000" in n and "stay instances" in n
               for n in rep["notes"]), rep["notes"]
    assert rays.mean() < 0.9, rays.mean()  # traced: the field still shades its ground
    sphere, _rep = bake_ground("sphere")
    assert sphere.min() == 1.0  # as the note says: the analytic rungs do not see it


def test_the_blade_gets_its_instances_mean(field):
    _ao, rep = bake_ground("raytrace")
    a = mesh_io.read_ao_attribute(bpy.data.objects["Blade"], ATTR)
    assert a.shape == (10,)
    root, tip = a[:2].mean(), a[-2:].mean()
    # In a dense field the root is well shaded and the tip nearly open.
    assert root < 0.5 < tip, (root, tip)
    assert rep["instances"]["prototypes"]["Blade"]["vertices"] == 10


def test_a_visible_blade_target_takes_the_field_not_its_lone_value(field):
    """The prototype also in the scene (beside the field, a target of the bake): its AO is the
    field's, not that of the one blade standing alone."""
    bpy.context.view_layer.layer_collection.children["BladeProto"].exclude = False
    bpy.data.objects["Blade"].location = (10.0, 0.0, 0.0)
    bpy.context.view_layer.update()
    opts = properties.scene_options(bpy.context.scene)
    opts.update(method="raytrace", distance=0.5, samples=64, show_proxies=False)
    run_bake(bpy.context, ["Ground", "Blade"], opts)
    a = mesh_io.read_ao_attribute(bpy.data.objects["Blade"], ATTR)
    assert a[:2].mean() < 0.5, a  # alone on no ground it would read ~1.0 at the root


def test_meshes_left_out_of_renders_do_not_occlude(field):
    """Cycles' rays see only what it renders: a mesh disabled in renders, or an emitter whose
    own mesh is not shown in renders (Show Emitter off, as for a crown volume scattering
    leaves), occludes nothing in our bake either (before, any visible mesh did)."""
    ground = field
    ground.modifiers.remove(ground.modifiers["Grass"])
    p = np.float32([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (0.3, 0.6)])
    t = np.int32([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                  [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    box = add_mesh("Box", p, t)
    under = np.linalg.norm(field_xy(ground), axis=1) < 0.5
    shaded, _rep = bake_ground("raytrace")
    assert shaded[under].mean() < 0.6
    box.hide_render = True
    open_, _rep = bake_ground("raytrace")
    assert open_.min() == 1.0
    box.hide_render = False
    mod = box.modifiers.new("Leaves", 'PARTICLE_SYSTEM')
    mod.particle_system.settings.count = 1
    mod.particle_system.settings.render_type = 'OBJECT'
    mod.particle_system.settings.instance_object = bpy.data.objects["Blade"]
    box.show_instancer_for_render = False
    bpy.context.view_layer.update()
    emitter, _rep = bake_ground("raytrace")
    assert emitter[under].mean() > 0.95, emitter[under].mean()  # one blade is left


def field_xy(obj):
    me = obj.data
    co = np.empty(len(me.vertices) * 3, np.float32)
    me.vertices.foreach_get("co", co)
    return co.reshape(-1, 3)[:, :2]


def leaf():
    """A leaf quad, 0.12 m, modelled along +Y (a hair particle's axis)."""
    return (np.float32([[-0.04, 0, 0], [0.04, 0, 0], [0.04, 0.12, 0], [-0.04, 0.12, 0]]),
            np.int32([[0, 1, 2], [0, 2, 3]]))


def test_leaves_scattered_by_a_crown_volume_are_its_trees_canopy():
    """A stylised tree: a trunk, and a crown volume (an icosphere, Show Emitter off) scattering
    800 leaf instances through its volume. The leaves are that tree's canopy under every rung,
    as the same leaves made real: the ground under the crown reads what it reads then. Before,
    a lone leaf was guessed GROUND and its instances dropped: the ground under the crown saw
    the trunk alone."""
    _clear_scene()
    scene = bpy.context.scene
    scene.canopy_ao.calibrate_tau = True
    gp, gt = tree_scene.plane(size=8.0, cuts=32)
    add_mesh("Ground", gp, gt)
    parts = tree_scene.scene(False)
    add_mesh("Trunk", *parts["Trunk"])
    coll = bpy.data.collections.new("LeafProto")
    scene.collection.children.link(coll)
    add_mesh("Leaf", *leaf(), collection=coll)
    bpy.context.view_layer.layer_collection.children["LeafProto"].exclude = True
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=2, radius=1.3, location=(0, 0, 2.6))
    crown = bpy.context.active_object
    crown.name = "Crown"
    mod = crown.modifiers.new("Leaves", 'PARTICLE_SYSTEM')
    ps = mod.particle_system.settings
    ps.type = 'HAIR'
    ps.count = 800
    ps.emit_from = 'VOLUME'
    ps.use_advanced_hair = True
    ps.hair_length = 1.0
    ps.render_type = 'OBJECT'
    ps.instance_object = bpy.data.objects["Leaf"]
    ps.particle_size = 1.0
    ps.use_rotations = True
    ps.rotation_mode = 'NOR'
    ps.phase_factor_random = 2.0
    mod.particle_system.seed = 3
    crown.show_instancer_for_render = False
    bpy.context.view_layer.update()
    verts, tris = instances_made_real("Leaf", *leaf())
    assert len(verts) == 800
    try:
        got, reps = {}, {}
        for m in ("raytrace", "sphere", "shells", "regression"):
            got[m], reps[m] = bake_ground(m, distance=6.0)
            [real] = reps[m]["instances"]["realized"].values()
            assert real["role"] == "CANOPY" and real["instances"] == 800, real
        # Nobody asked for the leaf's own AO (neither it nor its crown a target): untouched.
        assert ATTR not in bpy.data.objects["Leaf"].data.attributes
        for ob in bpy.context.view_layer.objects:
            ob.select_set(False)
        opts = properties.scene_options(bpy.context.scene)
        opts.update(method="raytrace", distance=6.0, samples=64, tau=2.0, show_proxies=False)
        run_bake(bpy.context, [], opts)  # everything: the leaf gets its instances' mean
        a = mesh_io.read_ao_attribute(bpy.data.objects["Leaf"], ATTR)
        assert a.shape == (4,) and 0.05 < a.mean() < 0.95, a
        bpy.data.objects.remove(crown, do_unlink=True)
        add_mesh("RealLeaves", np.concatenate(verts), np.concatenate(tris))
        bpy.context.view_layer.update()
        under = np.linalg.norm(gp[:, :2], axis=1) < 1.0
        for m in got:
            want, rep = bake_ground(m, distance=6.0)
            assert not rep["instances"]["realized"]
            assert want[under].mean() < 0.85, (m, want[under].mean())
            err = np.abs(got[m] - want).mean()
            assert err < 0.002, (m, err)
    finally:
        _clear_scene()
