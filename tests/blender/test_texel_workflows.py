"""Texel bakes against what users' files hold: one material shared by several objects (each
object's AO is its own image, a material shows one), linked duplicates, and where images of a
.blend never saved go."""
import os
import shutil
import tempfile

import bpy
import pytest

import helpers_materials as H


@pytest.fixture
def scene():
    sc = H.empty_scene()
    yield sc
    H.empty_scene()


def _bake(image_dir, objects, **kw):
    args = dict(objects=objects, mode='TEXEL', resolution=8, method="sphere", tau=2.0,
                use_world_distance=False, distance=5.0, show_proxies=False,
                image_dir=str(image_dir))
    args.update(kw)
    return bpy.ops.canopy_ao.bake(**args)


def _sources(mat):
    return [n.image for n in mat.node_tree.nodes if n.get("canopy_ao") == "source"]


@pytest.mark.parametrize("other", ["target", "not baked", "linked duplicate"])
def test_wiring_into_a_material_another_object_shows_is_refused(scene, tmp_path, other):
    """A material shows one image: wired for A, then for B, it showed B's AO on A (or A's on
    an object not baked, through that object's own UVs). Refused before anything is written,
    naming the material and its other users; an Atlas (one image for every target) is how
    targets sharing a material are wired."""
    a = H.add_plane(name="A")
    mat = H.add_material(a, "Shared")
    if other == "linked duplicate":
        b = a.copy()  # shares the mesh, so the material too
        scene.collection.objects.link(b)
        b.name, b.location.x = "B", 5.0
    else:
        b = H.add_plane(location=(5.0, 0.0, 0.0), name="B")
        b.data.materials.append(mat)
    names = "A,B" if other == "target" else "A"
    with pytest.raises(RuntimeError, match="material 'Shared'.*also shown on B"):
        _bake(tmp_path, names, wire_material=True)
    assert not os.listdir(tmp_path) and _sources(mat) == []
    # Unwired, each object gets its own image and nothing is refused.
    assert _bake(tmp_path, "A", wire_material=False) == {'FINISHED'}
    if other == "target":  # one image for both: what a shared material can show
        assert _bake(tmp_path, "A,B", wire_material=True, atlas="Both") == {'FINISHED'}
        assert [i.name for i in _sources(mat)] == ["Both_CanopyAO"]


def test_a_target_without_material_whose_mesh_another_object_uses_is_refused(scene, tmp_path):
    """Wiring gives an object without a material one of ours on its mesh: a linked duplicate
    would show the target's AO through it."""
    a = H.add_plane(name="A")
    b = a.copy()
    scene.collection.objects.link(b)
    b.name = "B"
    with pytest.raises(RuntimeError, match="A: .*also shown on B"):
        _bake(tmp_path, "A", wire_material=True)
    assert len(a.material_slots) == 0 and not os.listdir(tmp_path)


def _read(path):
    with open(path, "rb") as f:
        return f.read()


def test_a_blend_never_saved_keeps_its_images_apart_from_another_ones(scene, tmp_path):
    """Both files never saved, their images went to one temporary folder with records that
    both said 'unsaved': the second file's bake replaced the image the first shows, also once
    the first was saved (its material still reads the temporary file)."""
    H.add_plane(name="Ground", size=4.0)
    assert _bake("", "Ground", wire_material=True) == {'FINISHED'}
    first = bpy.data.images["Ground_CanopyAO"].filepath
    kept = _read(first)
    assert os.path.dirname(first).startswith(os.path.join(tempfile.gettempdir(), "canopy_ao"))
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "a.blend"))
    H.empty_scene()  # another file, never saved: a ball over its ground
    H.add_plane(name="Ground", size=4.0)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.5, location=(0.0, 0.0, 0.6))
    assert _bake("", "Ground", wire_material=True) == {'FINISHED'}
    second = bpy.data.images["Ground_CanopyAO"].filepath
    try:
        assert second != first and _read(first) == kept
        assert _read(second) != kept  # the ball's shadow: not the first file's image
    finally:
        for path in (first, second):
            shutil.rmtree(os.path.dirname(path), ignore_errors=True)


@pytest.mark.parametrize("name", ["Tree, left", " Padded ", "Ast/Zweig ü", "木"])
def test_an_operator_bakes_an_object_whatever_its_name(scene, tmp_path, name):
    """objects= is a comma-separated list: an object whose name has a comma or spaces at its
    ends could not be named ('no object named Tree, left'); the whole text naming an object
    is that object. Slashes and other letters keep a file of their own."""
    H.add_plane(name=name)
    assert _bake(tmp_path, name) == {'FINISHED'}
    (image,) = [i for i in bpy.data.images if i.get("canopy_ao_object") == name]
    assert os.path.dirname(bpy.path.abspath(image.filepath)) == str(tmp_path)
    assert bpy.ops.canopy_ao.remove_wiring(objects=name) == {'FINISHED'}


def test_an_image_folder_blender_could_not_load_from_is_refused_before_writing(scene,
                                                                               tmp_path):
    """A backslash is a folder name's letter on Linux but a separator to Blender, which then
    could not load the image written there: the bake failed with an internal error after
    writing the file. Refused by name before anything is written."""
    H.add_plane(name="Ground")
    folder = tmp_path / "a\\b"
    with pytest.raises(RuntimeError, match="backslash"):
        _bake(folder, "Ground")
    assert not folder.exists() and not [i for i in bpy.data.images if i.get("canopy_ao")]


@pytest.mark.parametrize("udim", [False, True])
def test_uvs_reaching_past_the_baked_square_are_named(scene, tmp_path, udim):
    """A UV map reaching past 0–1 (or past a UDIM tile) baked only what lies inside, without a
    word: the image's edge showed on the rest. The report names the triangles; a map inside
    says nothing."""
    from canopy_ao.blender.job import run_bake
    from canopy_ao.blender import properties
    obj = H.add_plane(name="Ground", subdivisions=1)  # 8 triangles, UVs over 0–1
    opts = dict(properties.scene_options(bpy.context.scene), mode='TEXEL', resolution=16,
                method="sphere", tau=2.0, distance=5.0, show_proxies=False, udim=udim,
                image_dir=str(tmp_path))
    _job, rep = run_bake(bpy.context, ["Ground"], opts)
    assert rep["objects"]["Ground"]["texel"]["warnings"] == []
    uv = obj.data.uv_layers.active.data
    for loop in uv:  # its right column of quads (4 triangles) reaches past u = 1
        loop.uv = (loop.uv[0] * 1.5, loop.uv[1])
    _job, rep = run_bake(bpy.context, ["Ground"], dict(opts, overwrite=True))
    (warning,) = rep["objects"]["Ground"]["texel"]["warnings"]
    square = "the UDIM tile of their centre" if udim else "the 0–1 square"
    assert f"4 triangles of UV map 'UVMap' reach outside {square}" in warning, warning


def test_linked_duplicates_bake_per_texel_into_images_of_their_own(scene, tmp_path):
    """Two objects sharing one mesh (Alt+D) were refused per texel as per vertex ('only one
    result could stay on it'), though per texel each result is an image of its own: baked,
    the one under the ball darker than its twin in the open (per vertex still refused)."""
    from canopy_ao.blender.job import run_bake
    from canopy_ao.blender import properties
    from canopy_ao.core.native import CanopyAOError, _core
    ground = H.add_plane(name="Ground", size=4.0)
    twin = ground.copy()
    scene.collection.objects.link(twin)
    twin.name, twin.location.x = "Twin", 10.0
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.5, location=(0.0, 0.0, 0.6))
    opts = dict(properties.scene_options(bpy.context.scene), mode='TEXEL', resolution=16,
                method="raytrace", samples=16, distance=5.0, show_proxies=False,
                image_dir=str(tmp_path))
    _job, rep = run_bake(bpy.context, ["Ground", "Twin"], opts)
    ao = {n: _core.read_image(rep["objects"][n]["texel"]["path"]) for n in ("Ground", "Twin")}
    assert ao["Ground"].min() < 0.5 and ao["Twin"].min() == 1.0
    with pytest.raises(CanopyAOError, match="share one mesh"):
        run_bake(bpy.context, ["Ground", "Twin"], dict(opts, mode='VERTEX'))


@pytest.mark.parametrize("mode, noun", [('VERTEX', "4 vertices"), ('TEXEL', "64 texels")])
def test_the_line_of_an_object_names_its_receivers(scene, tmp_path, mode, noun):
    """The panel's line for an object read '4 vertexs'."""
    from canopy_ao.blender import properties
    from canopy_ao.blender.job import BakeJob
    H.add_plane(name="Ground")
    opts = dict(properties.scene_options(bpy.context.scene), mode=mode, resolution=8,
                method="sphere", tau=2.0, distance=5.0, show_proxies=False,
                image_dir=str(tmp_path))
    job = BakeJob(bpy.context, ["Ground"], opts, blocking=True)
    job.prepare()
    line = job.step()
    assert f", {noun}, " in line, line
