"""A failed bake leaves nothing behind: an object with nothing to bake (no vertices, no texel
inside its UV square, positions that are not numbers) is refused by name before the first
write, through the operator and the command line, and no attribute, image or file of the
bake's other objects is left behind."""
import os

import bpy
import numpy as np
import pytest

import helpers_materials as H

ATTR = "CanopyAO"


def _no_vertices(obj):
    obj.data = bpy.data.meshes.new("Nothing")


def _uvs_outside(obj):
    uv = obj.data.uv_layers.active.data
    co = np.empty(len(uv) * 2, np.float32)
    uv.foreach_get("uv", co)
    uv.foreach_set("uv", co + 5.0)  # every face in the tile at (5, 5)
    obj.data.update()


def _uvs_collapsed(obj):
    uv = obj.data.uv_layers.active.data
    uv.foreach_set("uv", np.full(len(uv) * 2, 0.5, np.float32))  # no area at all
    obj.data.update()


def _no_faces(obj):
    me = bpy.data.meshes.new("Points")
    me.from_pydata([(0, 0, 1), (1, 0, 1), (0, 1, 1)], [], [])
    me.uv_layers.new(name="UVMap")
    obj.data = me


def _nan_vertex(obj):
    obj.data.vertices[0].co = (float("nan"), 0.0, 1.0)


def _infinite_scale(obj):
    obj.scale = (float("inf"), 1.0, 1.0)


# (how the second object is broken, mode, what the message says)
CASES = [
    (_no_vertices, "VERTEX", "has no vertices"),
    (_no_vertices, "TEXEL", "has no UV map"),
    (_uvs_outside, "TEXEL", "no texel centre falls inside a face"),
    (_uvs_collapsed, "TEXEL", "no texel centre falls inside a face"),
    (_no_faces, "TEXEL", "no texel centre falls inside a face"),
    (_nan_vertex, "VERTEX", "no finite world position"),
    (_nan_vertex, "TEXEL", "no finite world position"),
    (_infinite_scale, "VERTEX", "no finite world position"),
]
IDS = [f"{c[0].__name__.strip('_')}-{c[1].lower()}" for c in CASES]


@pytest.fixture
def two_objects(tmp_path):
    """Ground (UV-mapped, baked first) and Bad (a CANOPY cube above it, broken by the case),
    and an empty image folder."""
    H.empty_scene()
    ground = H.add_plane(size=4.0, subdivisions=3, name="Ground")
    bpy.ops.mesh.primitive_cube_add(size=0.5, location=(0, 0, 1))
    bad = bpy.context.object
    bad.name = "Bad"
    bad.canopy_ao.role = 'CANOPY'
    for ob in bpy.data.objects:
        ob.select_set(False)
    images = tmp_path / "images"
    images.mkdir()
    return ground, bad, str(images)


def _nothing_left(ground, bad, images, images_before):
    for ob in (ground, bad):
        assert ATTR not in ob.data.attributes, ob.name
    assert sorted(i.name for i in bpy.data.images) == images_before
    assert os.listdir(images) == []


@pytest.mark.parametrize("breaks,mode,message", CASES, ids=IDS)
def test_the_operator_refuses_by_name_and_writes_nothing(two_objects, breaks, mode,
                                                         message):
    ground, bad, images = two_objects
    breaks(bad)
    before = sorted(i.name for i in bpy.data.images)
    with pytest.raises(RuntimeError) as exc:
        bpy.ops.canopy_ao.bake(objects="Ground,Bad", method="sphere", tau=2.0, distance=0.0,
                               mode=mode, resolution=32, image_dir=images)
    text = str(exc.value)
    assert message in text and "'Bad'" in text and "internal error" not in text, text
    _nothing_left(ground, bad, images, before)


@pytest.mark.parametrize("breaks,mode,message", CASES, ids=IDS)
def test_the_cli_refuses_by_name_exits_1_and_writes_nothing(two_objects, capsys, breaks,
                                                            mode, message):
    from canopy_ao import cli
    ground, bad, images = two_objects
    breaks(bad)
    before = sorted(i.name for i in bpy.data.images)
    with pytest.raises(SystemExit) as exc:
        cli.main(["--objects", "Ground", "Bad", "--method", "sphere", "--tau", "2",
                  "--distance", "0", "--mode", mode.lower(), "--resolution", "32",
                  "--image-dir", images])
    err = capsys.readouterr().err
    assert exc.value.code == 1 and message in err and "'Bad'" in err, err
    assert "Traceback" not in err, err
    _nothing_left(ground, bad, images, before)


def test_a_failure_after_the_writes_undoes_them(two_objects, monkeypatch):
    """The panel lines are made inside the commit: a failure there undoes every write."""
    from canopy_ao.blender import job as job_mod
    ground, bad, images = two_objects

    def broken(self, rep):
        raise RuntimeError("boom: the panel line")
    monkeypatch.setattr(job_mod.BakeJob, "_result_texts", broken)
    for mode in ("VERTEX", "TEXEL"):
        before = sorted(i.name for i in bpy.data.images)
        with pytest.raises(RuntimeError, match="boom"):
            job_mod.run_bake(bpy.context, ["Ground", "Bad"], dict(
                method="sphere", tau=2.0, distance=0.0, mode=mode, resolution=32,
                image_dir=images, show_proxies=False))
        _nothing_left(ground, bad, images, before)


def test_a_failed_bake_takes_its_aov_off_only_the_view_layers_that_lacked_it(two_objects,
                                                                             monkeypatch):
    """Add AOV puts the pass on every view layer; one that already had it (the user's) keeps
    it when the bake fails, and the others lose it again."""
    from canopy_ao.blender import job as job_mod
    ground, bad, images = two_objects
    scene = bpy.context.scene
    first = scene.view_layers[0]
    second = scene.view_layers.new("Second")
    first.aovs.add().name = "BakedAO"

    def broken(self, rep):
        raise RuntimeError("boom: the panel line")
    monkeypatch.setattr(job_mod.BakeJob, "_result_texts", broken)
    with pytest.raises(RuntimeError, match="boom"):
        job_mod.run_bake(bpy.context, ["Ground"], dict(
            method="sphere", tau=2.0, distance=0.0, mode="VERTEX", add_aov=True,
            aov_name="BakedAO", show_proxies=False))
    assert [a.name for a in first.aovs] == ["BakedAO"]
    assert [a.name for a in second.aovs] == []
    assert ATTR not in ground.data.attributes
