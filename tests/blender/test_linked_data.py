"""Another .blend file's data stays that file's (blender/ownership.py, 'linked'): Blender saves
no edit of a linked mesh or material, so a bake never reports a write there as done. A linked,
instanced tree collection occludes but is not written, and the note says so, naming the mesh and
library; wiring into a linked material is refused before anything is written."""
import os
import re
import subprocess

import bpy
import numpy as np
import pytest

import tree_scene
from conftest import _clear_scene, add_mesh
from test_forest import PLACES, place_instances

ATTR = "CanopyAO"


def _library(tmp_path):
    """lib.blend: collection TreeProto (Trunk, Leaves) and material LibMat."""
    _clear_scene()
    coll = bpy.data.collections.new("TreeProto")
    parts = tree_scene.scene(False)
    for name in ("Trunk", "Leaves"):
        add_mesh(name, *parts[name], collection=coll)
    mat = bpy.data.materials.new("LibMat")
    mat.use_nodes = True
    path = str(tmp_path / "lib.blend")
    bpy.data.libraries.write(path, {coll, mat})
    bpy.data.collections.remove(coll)
    bpy.data.materials.remove(mat)
    _clear_scene()
    return path


def _ground():
    p, t = tree_scene.plane(size=24.0, cuts=24)
    return add_mesh("Ground", p, t)


def test_a_linked_instanced_tree_occludes_and_is_not_written(tmp_path, user_scripts):
    lib = _library(tmp_path)
    _ground()
    with bpy.data.libraries.load(lib, link=True) as (_src, dst):
        dst.collections = ["TreeProto"]
    place_instances(dst.collections[0])
    blend = str(tmp_path / "scene.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend, copy=True)
    _clear_scene()
    r = subprocess.run(
        [bpy.app.binary_path, "-b", "--factory-startup", blend, "--python-exit-code", "1",
         "--python-expr", "import canopy_ao.cli; canopy_ao.cli.main()", "--",
         "--all",  # everything: the prototypes' own AO asked for
         "--method", "ellipsoid", "--tau", "2", "--save"],
        env=dict(os.environ, BLENDER_USER_SCRIPTS=user_scripts), capture_output=True,
        text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    # Said, with the mesh and the library; not listed as baked.
    for name in ("Trunk", "Leaves"):  # the path as the file stores it (relative on save)
        assert re.search(rf"^canopy_ao: note: instanced {name}: its mesh '{name}' is linked "
                         r"from the library '(//)?[^']*lib\.blend', so its AO was not written",
                         r.stdout, re.M), r.stdout
    assert "Ground: role" in r.stdout and "Leaves: role" not in r.stdout
    # The saved file holds the ground's AO, darker under each tree than in the open (by more
    # than 0.05, as test_forest.py asks of local instances): the linked trees occlude.
    with bpy.data.libraries.load(blend) as (_src, dst):
        dst.meshes = ["Ground"]
    ground = dst.meshes[0]
    try:
        ao = np.empty(len(ground.vertices) * 4, np.float32)
        ground.attributes[ATTR].data.foreach_get("color", ao)
        co = np.empty(len(ground.vertices) * 3, np.float32)
        ground.vertices.foreach_get("co", co)
        xy, ao = co.reshape(-1, 3)[:, :2], ao.reshape(-1, 4)[:, 0]
        d = np.min([np.linalg.norm(xy - loc[:2], axis=1) for loc, _a, _s in PLACES], axis=0)
        assert ao[d < 1.0].mean() < ao[d > 5.0].mean() - 0.05
    finally:
        bpy.data.meshes.remove(ground)
    for lib_data in list(bpy.data.libraries):
        bpy.data.libraries.remove(lib_data)


def test_wiring_into_a_linked_material_is_refused_before_anything_is_written(tmp_path):
    lib = _library(tmp_path)
    ground = _ground()
    with bpy.data.libraries.load(lib, link=True) as (_src, dst):
        dst.materials = ["LibMat"]
    ground.data.materials.append(dst.materials[0])
    try:
        with pytest.raises(RuntimeError, match=(
                "Ground: its material 'LibMat' is linked from the library '.*lib.blend', so "
                "wiring the AO into it would be lost on save")):
            bpy.ops.canopy_ao.bake(objects="Ground", method="ellipsoid", tau=2.0,
                                   wire_material=True)
        assert ATTR not in ground.data.attributes
        assert not any(n.get("canopy_ao") for n in dst.materials[0].node_tree.nodes)
        # Without the wiring the bake goes on: the material is not written to.
        assert bpy.ops.canopy_ao.bake(objects="Ground", method="ellipsoid", tau=2.0) \
            == {'FINISHED'}
        assert ATTR in ground.data.attributes
    finally:
        _clear_scene()
        for lib_data in list(bpy.data.libraries):
            bpy.data.libraries.remove(lib_data)


def test_packing_into_a_linked_image_is_refused_before_anything_is_written(tmp_path):
    """A channel packed into another file's image would be lost on save (or saved into the
    library's own image file): refused, naming the image and library."""
    import helpers_materials as H
    _clear_scene()
    img = bpy.data.images.new("LibImg", 16, 16, alpha=True)
    img.pack()
    path = str(tmp_path / "images.blend")
    bpy.data.libraries.write(path, {img})
    bpy.data.images.remove(img)
    ground = H.add_plane(size=6.0, subdivisions=3, name="Ground")
    with bpy.data.libraries.load(path, link=True) as (_src, dst):
        dst.images = ["LibImg"]
    linked = dst.images[0]
    before = np.empty(16 * 16 * 4, np.float32)
    linked.pixels.foreach_get(before)
    try:
        with pytest.raises(RuntimeError, match="Ground: Pack Image 'LibImg' is linked from the "
                                               "library '.*images.blend'"):
            bpy.ops.canopy_ao.bake(objects="Ground", method="ellipsoid", tau=2.0, mode='TEXEL',
                                   resolution=16, channel='R', pack_image="LibImg",
                                   image_dir=str(tmp_path / "out"))
        after = np.empty_like(before)
        linked.pixels.foreach_get(after)
        np.testing.assert_array_equal(after, before)
        assert not (tmp_path / "out").exists()
    finally:
        _clear_scene()
        for lib_data in list(bpy.data.libraries):
            bpy.data.libraries.remove(lib_data)
