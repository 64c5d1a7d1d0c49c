"""Blender test fixtures: the add-on enabled once, a small tree + ground scene per test.

Run inside Blender (see run_pytest.py). If BLENDER_USER_SCRIPTS does not provide the add-on,
the repository's addon/ folder is put on sys.path so `canopy_ao` still imports.
"""

import os
import sys
import tempfile

import bpy
import numpy as np
import pytest

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
ADDON_PARENT = os.path.join(REPO, "addon")
sys.path.insert(0, os.path.join(REPO, "tests", "python"))

import tree_scene  # noqa: E402  (pure numpy scene arrays, shared with the plain tests)


def _ensure_importable():
    import importlib.util
    if importlib.util.find_spec("canopy_ao") is None:
        sys.path.insert(0, ADDON_PARENT)


@pytest.fixture(scope="session", autouse=True)
def addon():
    import addon_utils
    _ensure_importable()
    mod = addon_utils.enable("canopy_ao", default_set=True, handle_error=None)
    assert mod is not None, "the canopy_ao add-on did not enable"
    assert hasattr(bpy.types.Scene, "canopy_ao")
    yield mod


@pytest.fixture(scope="session")
def user_scripts():
    """A BLENDER_USER_SCRIPTS folder with the add-on, for Blender subprocesses."""
    env = os.environ.get("BLENDER_USER_SCRIPTS")
    if env and os.path.isdir(os.path.join(env, "addons", "canopy_ao")):
        return env
    d = tempfile.mkdtemp(prefix="canopy_ao_scripts_")
    os.makedirs(os.path.join(d, "addons"))
    os.symlink(os.path.join(ADDON_PARENT, "canopy_ao"), os.path.join(d, "addons", "canopy_ao"))
    return d


def _clear_scene():
    scene = bpy.context.scene
    for ob in list(bpy.data.objects):
        bpy.data.objects.remove(ob, do_unlink=True)
    for me in list(bpy.data.meshes):
        bpy.data.meshes.remove(me)
    for coll in list(bpy.data.collections):
        bpy.data.collections.remove(coll)
    return scene


def add_oak_scene(roles):
    """tests/python/tree_scene's tree (trunk, leaves, ground, grass) as objects with their roles
    (name -> role) set, trunk and leaves in the tree 'Oak'."""
    import tree_scene
    for name, (p, t) in tree_scene.scene(True).items():
        ob = add_mesh(name, p, t)
        ob.canopy_ao.role = roles[name]
        ob.canopy_ao.tree = "Oak" if name in ("Trunk", "Leaves") else ""


def add_wind_key(ob, amplitude, last_frame):
    """A keyed shape key 'Wind' that bends ob along x by amplitude × (z − 1.4)², 0 at frame 1
    and 1 at last_frame: the swaying crown of the live tests."""
    ob.shape_key_add(name="Basis")
    wind = ob.shape_key_add(name="Wind")
    co = np.empty(len(ob.data.vertices) * 3, np.float32)
    wind.data.foreach_get("co", co)
    co = co.reshape(-1, 3)
    co[:, 0] += amplitude * (co[:, 2] - 1.4) ** 2
    wind.data.foreach_set("co", co.ravel())
    for frame, value in ((1, 0.0), (last_frame, 1.0)):
        wind.value = value
        wind.keyframe_insert("value", frame=frame)
    return wind


def add_mesh(name, positions, triangles, collection=None):
    me = bpy.data.meshes.new(name)
    me.vertices.add(len(positions))
    me.vertices.foreach_set("co", np.ascontiguousarray(positions, np.float32).ravel())
    tris = np.ascontiguousarray(triangles, np.int32)
    me.loops.add(tris.size)
    me.loops.foreach_set("vertex_index", tris.ravel())
    me.polygons.add(len(tris))
    me.polygons.foreach_set("loop_start", np.arange(0, tris.size, 3, dtype=np.int32))
    me.polygons.foreach_set("loop_total", np.full(len(tris), 3, dtype=np.int32))
    me.update(calc_edges=True)
    me.validate()
    ob = bpy.data.objects.new(name, me)
    (collection or bpy.context.scene.collection).objects.link(ob)
    return ob


def add_grid_ground(size, cuts, name="Ground"):
    """A flat square ground of side ``size`` at z = 0, (cuts + 1)² vertices, role GROUND."""
    g = np.linspace(-size / 2, size / 2, cuts + 1)
    xy = np.array([(x, y) for y in g for x in g], np.float32)
    k = cuts + 1
    tris = [[k * r + c, k * r + c + 1, k * r + c + k + 1] for r in range(cuts) for c in range(cuts)]
    tris += [[k * r + c, k * r + c + k + 1, k * r + c + k] for r in range(cuts)
             for c in range(cuts)]
    ground = add_mesh(name, np.column_stack([xy, np.zeros(len(xy), np.float32)]),
                      np.int32(tris))
    ground["canopy_ao_role"] = "GROUND"
    return ground


@pytest.fixture
def tree_scene_objects():
    """Trunk (cylinder), Leaves (1500 quads in a ball of radius 1.2 at z = 2.6), Ground
    (20 x 20 plane at z = 0), Grass (300 blades at x in [4, 8]); nothing selected."""
    _clear_scene()
    obs = {name: add_mesh(name, p, t) for name, (p, t) in tree_scene.scene(True).items()}
    for ob in bpy.context.scene.objects:
        ob.select_set(False)
    bpy.context.view_layer.update()
    bpy.context.scene.canopy_ao.calibrate_tau = True
    yield obs
    _clear_scene()


def require_bundled(module, operator, name):
    """Enable one of Blender's bundled curve generators, or skip: they are bundled up to 4.1
    (from 4.2 on extensions, not in Debian's package). operator: its bpy.ops.curve name."""
    import addon_utils
    addon_utils.enable(module, default_set=False)
    try:  # bpy.ops.curve.<op> always exists as a wrapper; its RNA only when registered
        getattr(bpy.ops.curve, operator).get_rna_type()
    except KeyError:
        pytest.skip(f"{name} is not bundled with Blender {bpy.app.version_string} "
                    "(an extension from 4.2 on)")


def require_sapling():
    require_bundled("add_curve_sapling", "tree_add", "Sapling Tree Gen")


def require_ivygen():
    require_bundled("add_curve_ivygen", "ivy_gen", "IvyGen")

