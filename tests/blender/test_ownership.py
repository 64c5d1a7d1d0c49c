"""What a bake may replace: only attributes exactly as Canopy AO wrote them (a fingerprint of
the content, recorded on the mesh), and only image files Canopy AO wrote for that output (a
header record with the pixels' fingerprint); everything else is the user's and is refused
without Overwrite, before anything is written."""
import json
import os

import bpy
import numpy as np
import pytest

import helpers_materials as H
from canopy_ao import _core
from canopy_ao.blender import files_io, mesh_io, ownership
from canopy_ao.blender.job import run_bake
from canopy_ao.core.native import CanopyAOError
from test_maps import opts, tree  # noqa: F401 (tree: the fixture, a plane under leaves)

ATTR = "CanopyAO"


def _user_attribute(mesh, name=ATTR, value=0.25):
    """A colour attribute the user made (not grey: alpha 0.5)."""
    a = mesh.color_attributes.new(name, 'FLOAT_COLOR', 'POINT')
    c = np.full((len(mesh.vertices), 4), value, np.float32)
    c[:, 3] = 0.5
    a.data.foreach_set("color", c.ravel())
    return c


def _colors(mesh, name=ATTR):
    buf = np.empty(len(mesh.vertices) * 4, np.float32)
    mesh.attributes[name].data.foreach_get("color", buf)
    return buf.reshape(-1, 4)


def _refused(names, match="did not make|no longer what Canopy AO wrote|claimed only", **kw):
    with pytest.raises(CanopyAOError, match=match):
        run_bake(bpy.context, names, opts(**kw))


# === Attributes

def test_a_mesh_swapped_under_a_baked_object_keeps_its_users_attribute(tree):
    g = tree["ground"]
    run_bake(bpy.context, ["Ground"], opts())
    assert mesh_io.owned_attributes(g) == [ATTR]
    other = g.data.copy()
    other.attributes.remove(other.attributes[ATTR])
    other.pop(ownership.OWNED_PROP, None)
    user = _user_attribute(other)
    g.data = other  # the object's own record (pre-fingerprint add-ons kept one) must not count
    g["canopy_ao_attributes"] = json.dumps([ATTR])
    _refused(["Ground"])
    np.testing.assert_array_equal(_colors(other), user)
    run_bake(bpy.context, ["Ground"], opts(overwrite=True))
    assert not np.allclose(_colors(other)[:, 0], 0.25)


def test_a_copied_or_typed_record_does_not_vouch_for_another_attribute(tree):
    g, leaves = tree["ground"], tree["leaves"]
    run_bake(bpy.context, ["Ground"], opts())
    user = _user_attribute(leaves.data)
    for record in (lambda: g.data[ownership.OWNED_PROP],  # copied from a baked mesh
                   lambda: json.dumps({ATTR: "0" * 24}),  # typed by hand
                   lambda: json.dumps({ATTR: ownership.attribute_fingerprint(
                       g.data.attributes[ATTR])})):  # another mesh's true fingerprint
        leaves.data[ownership.OWNED_PROP] = record()
        _refused(["Leaves"])
        np.testing.assert_array_equal(_colors(leaves.data), user)
    # A pre-fingerprint record (a name list) typed onto a mesh with a user's colours.
    del leaves.data[ownership.OWNED_PROP]
    leaves.data[ownership.LEGACY_OWNED_PROP] = json.dumps([ATTR])
    leaves[ownership.LEGACY_OWNED_PROP] = json.dumps([ATTR])
    _refused(["Leaves"])
    np.testing.assert_array_equal(_colors(leaves.data), user)


def test_a_users_attribute_renamed_to_ours_is_refused(tree):
    g = tree["ground"]
    run_bake(bpy.context, ["Ground"], opts())
    g.data.attributes[ATTR].name = "OldAO"
    user = _user_attribute(g.data, "Mine")
    g.data.attributes["Mine"].name = ATTR
    _refused(["Ground"])
    np.testing.assert_array_equal(_colors(g.data), user)


def test_a_painted_attribute_is_the_users_until_overwritten(tree):
    g = tree["ground"]
    run_bake(bpy.context, ["Ground"], opts())
    c = _colors(g.data)
    c[5] = (1.0, 0.0, 0.0, 1.0)  # one vertex painted red
    g.data.attributes[ATTR].data.foreach_set("color", c.ravel())
    _refused(["Ground"], match="no longer what Canopy AO wrote")
    np.testing.assert_array_equal(_colors(g.data), c)
    run_bake(bpy.context, ["Ground"], opts(overwrite=True))
    assert mesh_io.owned_attributes(g) == [ATTR]
    run_bake(bpy.context, ["Ground"], opts(tau=3.0))  # ours again: no Overwrite needed


def test_a_modal_bake_checks_again_what_was_painted_while_it_ran(tree):
    """A modal bake yields to the UI between its steps, so an attribute painted after the bake
    read it is checked again at the commit (a blocking bake, where nothing runs in between,
    checks once)."""
    from canopy_ao.blender.job import BakeJob
    g = tree["ground"]
    run_bake(bpy.context, ["Ground"], opts())
    job = BakeJob(bpy.context, ["Ground"], opts(tau=3.0))  # modal: not blocking
    c = _colors(g.data)
    c[5] = (1.0, 0.0, 0.0, 1.0)  # painted while the bake runs
    g.data.attributes[ATTR].data.foreach_set("color", c.ravel())
    job.run()
    with pytest.raises(CanopyAOError, match="no longer what Canopy AO wrote"):
        job.commit(bpy.context)
    np.testing.assert_array_equal(_colors(g.data), c)



def test_a_record_from_before_fingerprints_never_vouches_for_an_attribute(tree):
    """A pre-fingerprint record (a name list on object and mesh) proves nothing: a user's grey
    colour attribute or float mask of that name is refused through bpy.ops and the command
    line's path, unchanged, with a message naming the object; Overwrite replaces it once and
    the fingerprint record takes the list's place."""
    g = tree["ground"]
    n = len(g.data.vertices)
    grey = np.repeat(np.linspace(0.2, 0.9, n, dtype=np.float32)[:, None], 4, axis=1)
    grey[:, 3] = 1.0  # R = G = B, A = 1: what the old add-on wrote, painted by the user
    g.data.color_attributes.new(ATTR, 'FLOAT_COLOR', 'POINT').data.foreach_set(
        "color", grey.ravel())
    mask = np.linspace(0.0, 1.0, n, dtype=np.float32)  # a weight-like mask in [0, 1]
    g.data.attributes.new("Mask", 'FLOAT', 'POINT').data.foreach_set("value", mask)
    for idb in (g, g.data):
        idb[ownership.LEGACY_OWNED_PROP] = json.dumps([ATTR, "Mask"])
    assert ownership.ownership(g.data, ATTR) == ownership.ownership(g.data, "Mask") == 'unproven'
    assert mesh_io.owned_attributes(g) == []
    with pytest.raises(RuntimeError, match="Ground: its attribute 'CanopyAO' is claimed only"):
        bpy.ops.canopy_ao.bake(objects="Ground", method="ellipsoid", tau=2.0)
    _refused(["Ground"], match="Ground: its attribute 'Mask' is claimed only by the record of "
                               "a Canopy AO without fingerprints", attribute="Mask")
    np.testing.assert_array_equal(_colors(g.data), grey)
    got = np.empty(n, np.float32)
    g.data.attributes["Mask"].data.foreach_get("value", got)
    np.testing.assert_array_equal(got, mask)
    run_bake(bpy.context, ["Ground"], opts(overwrite=True))
    assert json.loads(g.data[ownership.LEGACY_OWNED_PROP]) == ["Mask"]  # the other stays
    assert mesh_io.owned_attributes(g) == [ATTR]
    run_bake(bpy.context, ["Ground"], opts(tau=3.0))  # proven ours now: no Overwrite needed


def test_a_duplicated_mesh_keeps_ownership_of_the_copy(tree):
    """Make Single User copies the mesh with its record: the copy holds exactly what Canopy AO
    wrote, so it stays ours; a frame cache attribute (FLOAT) is fingerprinted alike."""
    g = tree["ground"]
    run_bake(bpy.context, ["Ground"], opts())
    mesh_io.write_float_attribute(g, "CanopyAO_7", np.linspace(0, 1, len(g.data.vertices)))
    g.data = g.data.copy()
    assert sorted(mesh_io.owned_attributes(g)) == [ATTR, "CanopyAO_7"]
    assert mesh_io.remove_owned_attribute(g, "CanopyAO_7")
    assert mesh_io.owned_attributes(g) == [ATTR]


# === Image files

def _texel(tree, **kw):
    return opts(mode='TEXEL', resolution=16, image_dir=tree["image_dir"], **kw)


def _bytes(path):
    with open(path, "rb") as f:
        return f.read()


def test_names_a_file_name_cannot_tell_apart_write_their_own_files(tree):
    """'Tree.001', 'Tree 001', 'Tree/001' and 'Tree_001' clean to one file name, as do names
    differing only in non-ASCII letters: each object gets its own EXR, holding its own AO."""
    names = ["Tree.001", "Tree 001", "Tree/001", "Tree_001", "Baum_ä", "Baum_ö"]
    for i, name in enumerate(names):  # each further from the tree: each its own AO
        H.add_plane(size=1.0, location=(0.4 * i, 0.0, 0.0), name=name)
        bpy.context.object.canopy_ao.role = 'GROUND'
    assert all(n in bpy.data.objects for n in names)  # Blender kept every name as given
    job, rep = run_bake(bpy.context, names, _texel(tree))
    paths = [rep["objects"][n]["texel"]["path"] for n in names]
    assert len({p.casefold() for p in paths}) == len(names), paths
    assert os.path.basename(paths[3]) == "Tree_001_CanopyAO.exr"  # a clean name stays as is
    for t in job.targets:
        path = rep["objects"][t.item.name]["texel"]["path"]
        np.testing.assert_array_equal(_core.read_image(path)[:, :, 0], t.stats["image"])


def test_names_differing_only_in_case_are_refused_before_writing(tree):
    for name in ("Oak", "oak"):
        H.add_plane(size=1.0, name=name)
    n_images = len(bpy.data.images)
    with pytest.raises(CanopyAOError, match="'Oak'.*'oak'.*same file"):
        run_bake(bpy.context, ["Oak", "oak"], _texel(tree))
    assert os.listdir(tree["image_dir"]) == [] and len(bpy.data.images) == n_images


def test_a_file_canopy_ao_did_not_write_is_refused_without_overwrite(tree):
    d = tree["image_dir"]
    path = os.path.join(d, "Ground_CanopyAO.exr")
    _core.write_image(path, np.full((8, 8), 0.5, np.float32))  # the user's own EXR
    user = _bytes(path)
    n_images = len(bpy.data.images)
    with pytest.raises(CanopyAOError, match="Ground_CanopyAO.exr' already exists and Canopy "
                                            "AO did not write it"):
        run_bake(bpy.context, ["Ground", "Leaves"], _texel(tree))
    assert _bytes(path) == user and sorted(os.listdir(d)) == ["Ground_CanopyAO.exr"]
    assert len(bpy.data.images) == n_images
    # Not an image at all (a text file at the path): the same.
    with open(path, "w") as f:
        f.write("notes")
    with pytest.raises(CanopyAOError, match="did not write it"):
        run_bake(bpy.context, ["Ground"], _texel(tree))
    # With Overwrite it goes; the file is then ours, and a re-bake needs no Overwrite. A file
    # named like the bake's backup of the old one is not the bake's either: it stays.
    with open(path + ".canopy_ao-previous", "w") as f:
        f.write("mine")
    run_bake(bpy.context, ["Ground"], _texel(tree, overwrite=True))
    run_bake(bpy.context, ["Ground"], _texel(tree, tau=3.0))
    assert sorted(os.listdir(d)) == ["Ground_CanopyAO.exr",
                                     "Ground_CanopyAO.exr.canopy_ao-previous"]
    assert _bytes(path + ".canopy_ao-previous") == b"mine"


def test_a_file_of_ours_that_was_edited_or_belongs_to_another_output_is_refused(tree):
    d = tree["image_dir"]
    _job, rep = run_bake(bpy.context, ["Ground"], _texel(tree))
    path = rep["objects"]["Ground"]["texel"]["path"]
    record = json.loads(_core.read_image_attributes(path)[files_io.FILE_RECORD])
    assert record["owner"] == "Ground" and record["map"] == "CanopyAO"
    img = _core.read_image(path)[:, :, 0].copy()
    img[3, 4] = 0.0  # painted over in an image editor that kept the header
    _core.write_image(path, img, attributes={files_io.FILE_RECORD: json.dumps(record)})
    with pytest.raises(CanopyAOError, match="did not write it \\(or changed since"):
        run_bake(bpy.context, ["Ground"], _texel(tree))
    # A true record, of another object (what a case-insensitive file system would give).
    files_io.write_file(path, img, files_io.Output("Leaves"))
    with pytest.raises(CanopyAOError, match="holds Canopy AO's 'CanopyAO' of 'Leaves', not "
                                            "'CanopyAO' of 'Ground'"):
        run_bake(bpy.context, ["Ground"], _texel(tree))
    # An atlas of the object's name is another output: its file is not the object's.
    files_io.write_file(path, img, files_io.Output("Ground", atlas=True))
    with pytest.raises(CanopyAOError, match="of atlas 'Ground', not 'CanopyAO' of 'Ground'"):
        run_bake(bpy.context, ["Ground"], _texel(tree))
    assert sorted(os.listdir(d)) == ["Ground_CanopyAO.exr"]


def test_udim_tiles_and_atlases_keep_files_that_are_not_theirs(tree):
    d = tree["image_dir"]
    tile = os.path.join(d, "Ground_CanopyAO.1001.exr")
    _core.write_image(tile, np.zeros((4, 4), np.float32))
    with pytest.raises(CanopyAOError, match="Ground_CanopyAO.1001.exr' already exists"):
        run_bake(bpy.context, ["Ground"], _texel(tree, udim=True))
    atlas = os.path.join(d, "Shared_CanopyAO.exr")
    _core.write_image(atlas, np.zeros((4, 4), np.float32))
    with pytest.raises(CanopyAOError, match="Shared_CanopyAO.exr' already exists"):
        run_bake(bpy.context, ["Ground", "Leaves"], _texel(tree, atlas="Shared"))
    os.remove(tile)
    # A user's file named like a tile this bake does not write stays (only our stale tiles go).
    stale = os.path.join(d, "Ground_CanopyAO.1005.exr")
    _core.write_image(stale, np.zeros((4, 4), np.float32))
    user = _bytes(stale)
    run_bake(bpy.context, ["Ground"], _texel(tree, udim=True))
    assert _bytes(stale) == user
    assert os.path.exists(tile)


def test_two_objects_packing_into_one_image_are_refused(tree):
    """Each would replace the other's channel of the one Pack Image: one result would be lost
    while both were reported baked."""
    img = bpy.data.images.new("Mask", 16, 16, alpha=True)
    before = np.empty(16 * 16 * 4, np.float32)
    img.pixels.foreach_get(before)
    with pytest.raises(CanopyAOError, match="Ground, Leaves would each pack into channel G "
                                            "of image 'Mask'"):
        run_bake(bpy.context, ["Ground", "Leaves"], _texel(tree, channel="G",
                                                           pack_image="Mask"))
    after = np.empty_like(before)
    img.pixels.foreach_get(after)
    np.testing.assert_array_equal(after, before)


def test_the_command_line_refuses_a_users_file_and_overwrites_when_asked(tree, capsys):
    from canopy_ao import cli
    d = tree["image_dir"]
    path = os.path.join(d, "Ground_CanopyAO.exr")
    _core.write_image(path, np.full((8, 8), 0.5, np.float32))
    args = ["--objects", "Ground", "--method", "ellipsoid", "--tau", "2", "--mode", "texel",
            "--resolution", "16", "--image-dir", d, "--no-proxies"]
    with pytest.raises(SystemExit) as exc:
        cli.main(args)
    assert exc.value.code == 1 and path in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        cli.main(args + ["--overwrite"])
    assert exc.value.code == 0
    assert files_io.file_record(path)["owner"] == "Ground"
