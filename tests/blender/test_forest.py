"""Instanced trees in Blender (docs/DESIGN.md, 'How each role is lit'): a tree collection instanced
over a plane by collection-instance empties and by a particle system. Known answers: the ground
under an instance is darker than open ground (by ≥ 0.05, as for a real tree in test_addon.py); the
prototype's meshes get the attribute once (one mesh, shared by every instance) when the bake is of
everything, and none when only the ground is baked; the report counts the instances."""

import bpy
import numpy as np
import pytest

import tree_scene
from conftest import _clear_scene, add_mesh
from canopy_ao.blender import mesh_io, properties
from canopy_ao.blender.job import run_bake

ATTR = "CanopyAO"
PLACES = [((-5.0, -5.0, 0.0), 0.0, 1.0), ((5.0, -4.0, 0.0), 0.8, 1.2), ((0.0, 5.0, 0.0), 2.0, 0.9)]


@pytest.fixture
def proto():
    """Collection 'TreeProto' (Trunk + Leaves of tree_scene, excluded from the view layer, so
    only its instances are in the scene) and a 24 × 24 m Ground."""
    _clear_scene()
    coll = bpy.data.collections.new("TreeProto")
    bpy.context.scene.collection.children.link(coll)
    parts = tree_scene.scene(False)
    for name in ("Trunk", "Leaves"):
        add_mesh(name, *parts[name], collection=coll)
    p, t = tree_scene.plane(size=24.0, cuts=48)
    add_mesh("Ground", p, t)
    bpy.context.view_layer.layer_collection.children["TreeProto"].exclude = True
    bpy.context.scene.canopy_ao.calibrate_tau = True
    yield coll
    _clear_scene()


def ground_xy():
    me = bpy.data.objects["Ground"].data
    co = np.empty(len(me.vertices) * 3, np.float32)
    me.vertices.foreach_get("co", co)
    return co.reshape(-1, 3)[:, :2]


def bake_all(names=(), **kw):
    """The bake of everything visible (no names, nothing selected), or of ``names``."""
    for ob in bpy.context.view_layer.objects:
        ob.select_set(False)
    opts = properties.scene_options(bpy.context.scene)
    opts.update(method="ellipsoid", tau=2.0, distance=0.0, show_proxies=False)
    opts.update(kw)
    return run_bake(bpy.context, list(names), opts)


def check(rep, places):
    g = mesh_io.read_ao_attribute(bpy.data.objects["Ground"], ATTR)
    xy = ground_xy()
    open_ground = np.ones(len(xy), bool)
    for (x, y, _z), _a, _s in places:
        d = np.linalg.norm(xy - [x, y], axis=1)
        open_ground &= d > 5.0
        assert g[d < 0.8].mean() < g[open_ground | (d > 5.0)].mean() - 0.05, (x, y)
    assert rep["instances"]["instances"] == len(places)
    assert set(rep["instances"]["prototypes"]) == {"Trunk", "Leaves"}
    for name in ("Trunk", "Leaves"):
        me = bpy.data.objects[name].data
        assert len([a for a in me.attributes if a.name == ATTR]) == 1
        a = mesh_io.read_ao_attribute(bpy.data.objects[name], ATTR)
        assert np.all((a >= 0) & (a <= 1)) and a.min() < 0.9, name
    assert any("forest: " in n for n in rep["notes"])


def place_instances(proto):
    """A collection-instance empty of ``proto`` at each of PLACES (TreeInstance0, ...)."""
    for i, (loc, angle, scale) in enumerate(PLACES):
        e = bpy.data.objects.new(f"TreeInstance{i}", None)
        e.instance_type = 'COLLECTION'
        e.instance_collection = proto
        e.location, e.rotation_euler[2], e.scale = loc, angle, (scale,) * 3
        bpy.context.scene.collection.objects.link(e)
    bpy.context.view_layer.update()


def test_collection_instances(proto):
    place_instances(proto)
    _job, rep = bake_all()
    check(rep, PLACES)
    # A re-bake replaces the prototype's attribute, it does not add one.
    _job, rep = bake_all()
    check(rep, PLACES)


def test_particle_instances(proto):
    ground = bpy.data.objects["Ground"]
    emitter = add_mesh("Emitter", np.float32([[-6, -6, 0], [6, -6, 0], [6, 6, 0], [-6, 6, 0]]),
                       np.int32([[0, 1, 2], [0, 2, 3]]))
    mod = emitter.modifiers.new("Trees", 'PARTICLE_SYSTEM')
    ps = mod.particle_system.settings
    ps.type = 'HAIR'
    ps.count = 4
    ps.use_advanced_hair = True
    ps.use_rotations = True
    ps.rotation_mode = 'NONE'  # keep the tree upright (hair would lay its x axis along the hair)
    ps.render_type = 'COLLECTION'
    ps.instance_collection = proto
    ps.use_whole_collection = True  # each particle a whole tree, not one of its objects
    ps.particle_size = 1.0
    ps.hair_length = 1.0
    emitter.show_instancer_for_render = False
    emitter.show_instancer_for_viewport = False
    bpy.context.view_layer.update()
    dg = bpy.context.evaluated_depsgraph_get()
    places = []
    for inst in dg.object_instances:
        if inst.is_instance and inst.instance_object.original.name == "Leaves":
            crown = np.array(inst.matrix_world) @ [0.0, 0.0, 2.6, 1.0]  # Leaves' centre
            assert crown[2] > 1.5, "the instanced tree should stand upright"
            places.append((tuple(crown[:3]), 0.0, 1.0))
    assert len(places) == 4
    emitter.canopy_ao.role = 'IGNORE'
    _job, rep = bake_all()
    assert ground.name in rep["objects"]
    check(rep, places)


def test_geometry_nodes_instances(proto):
    """Instance on Points of a Collection Info (the scatter object's own mesh is empty)."""
    scatter = add_mesh("Scatter", np.float32([[0, 0, 0]]), np.zeros((0, 3), np.int32))
    ng = bpy.data.node_groups.new("Forest", 'GeometryNodeTree')
    for in_out in ("INPUT", "OUTPUT"):
        if hasattr(ng, "interface"):  # Blender 4.0+: the group interface
            ng.interface.new_socket("Geometry", in_out=in_out, socket_type='NodeSocketGeometry')
        else:
            (ng.inputs if in_out == "INPUT" else ng.outputs).new('NodeSocketGeometry', "Geometry")
    out = ng.nodes.new('NodeGroupOutput')
    line = ng.nodes.new('GeometryNodeMeshLine')
    line.inputs["Count"].default_value = 3
    line.inputs["Start Location"].default_value = (-6.0, -3.0, 0.0)
    line.inputs["Offset"].default_value = (6.0, 3.0, 0.0)
    iop = ng.nodes.new('GeometryNodeInstanceOnPoints')
    info = ng.nodes.new('GeometryNodeCollectionInfo')
    info.inputs["Collection"].default_value = proto
    ng.links.new(line.outputs["Mesh"], iop.inputs["Points"])
    ng.links.new(info.outputs[0], iop.inputs["Instance"])
    ng.links.new(iop.outputs[0], out.inputs[0])
    scatter.modifiers.new("GN", 'NODES').node_group = ng
    bpy.context.view_layer.update()
    _job, rep = bake_all()
    check(rep, [((-6.0 + 6 * i, -3.0 + 3 * i, 0.0), 0.0, 1.0) for i in range(3)])


def test_raytrace_traces_the_instances(proto):
    """The exact rung through the add-on's job: the ground under collection instances gets the
    AO of rays against the same trees realised (un-instanced), to noise, and the report says
    the calibration rays saw them too (auto)."""
    from canopy_ao.core.native import _core
    place_instances(proto)
    opts = properties.scene_options(bpy.context.scene)
    opts.update(method="raytrace", samples=64, distance=0.0, show_proxies=False)
    _job, rep = run_bake(bpy.context, ["Ground"], opts)
    got = mesh_io.read_ao_attribute(bpy.data.objects["Ground"], ATTR)
    # The same triangles realised: each tree part under each empty's world matrix.
    gp, gt = tree_scene.plane(size=24.0, cuts=48)
    verts, tris, base = [gp], [gt], len(gp)
    parts = tree_scene.scene(False)
    for i in range(len(PLACES)):
        m = np.array(bpy.data.objects[f"TreeInstance{i}"].matrix_world, np.float64)
        for name in ("Trunk", "Leaves"):
            p, t = parts[name]
            verts.append((p @ m[:3, :3].T + m[:3, 3]).astype(np.float32))
            tris.append(t + base)
            base += len(p)
    rt = _core.RayTracer(np.ascontiguousarray(np.concatenate(verts), np.float32),
                         np.ascontiguousarray(np.concatenate(tris), np.int32))
    up = np.tile(np.float32([0, 0, 1]), (len(gp), 1))
    want = np.asarray(rt.ao(gp, up, samples=512, seed=5,
                            vertex_ids=np.arange(len(gp), dtype=np.int32)))
    shaded = want < 0.95
    assert shaded.sum() > 50
    assert np.abs(got - want)[shaded].mean() < 0.03
    assert abs(float(np.mean(got[shaded] - want[shaded]))) < 0.01
    opts.update(method="auto")
    _job, rep = run_bake(bpy.context, ["Ground"], opts)
    assert rep["calibration"]["instances_traced"] is True


@pytest.mark.parametrize("method", ["raytrace", "auto", "ellipsoid"])
def test_a_ground_bake_leaves_the_prototypes_untouched(proto, method):
    """Baking only the ground writes nothing into the prototypes' meshes (nobody asked for
    their AO: they are fitted, and occlude, but are not baked), and the ground gets the same
    AO, bit for bit, as when the prototypes are baked too: a fixed rung fits them as before;
    under auto they are fitted without calibrating on themselves (forest_fit.fit_only: ellipsoid
    shells at the default τ, what their own calibration gives here, where it picks rays), and
    the ground's rays are seeded per receiver."""
    place_instances(proto)
    kw = dict(method=method, samples=32, tau=None if method == "auto" else 2.0)
    _job, rep = bake_all(["Ground"], **kw)
    ground = mesh_io.read_ao_attribute(bpy.data.objects["Ground"], ATTR)
    for name in ("Trunk", "Leaves"):
        assert ATTR not in bpy.data.objects[name].data.attributes, name
    assert rep["instances"]["prototypes"] == {} and rep["instances"]["instances"] == 3
    assert any("instanced tree TreeProto: 3 instance(s)" in line
               for line in _job.lines), _job.lines
    _job, rep = bake_all(**kw)  # everything: the prototypes baked and written as well
    assert set(rep["instances"]["prototypes"]) == {"Trunk", "Leaves"}
    if method == "auto":  # calibrated on themselves: rays, which light with the ellipsoid
        assert rep["instances"]["prototypes"]["Leaves"]["method"] == "raytrace"
    for name in ("Trunk", "Leaves"):
        assert ATTR in bpy.data.objects[name].data.attributes, name
    want = mesh_io.read_ao_attribute(bpy.data.objects["Ground"], ATTR)
    assert want.min() < 0.9  # the trees shade it
    assert np.array_equal(ground, want), np.abs(ground - want).max()
