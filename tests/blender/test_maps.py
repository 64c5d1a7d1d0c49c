"""Maps beyond grey AO: one channel of an existing color attribute or image (the others
bit-identical), and the canopy thickness per vertex and per texel, wired as a render pass."""
import os

import bpy
import numpy as np
import pytest

import helpers_materials as H
from canopy_ao import _core
from canopy_ao.blender import materials, properties
from canopy_ao.blender.job import run_bake
from canopy_ao.core.native import CanopyAOError


@pytest.fixture
def tree(tmp_path):
    """A UV-mapped ground plane (Ground) under a UV sphere of leaves (Leaves)."""
    H.empty_scene()
    ground = H.add_plane(size=6.0, subdivisions=11, name="Ground")
    bpy.ops.mesh.primitive_uv_sphere_add(segments=24, ring_count=12, radius=1.2,
                                         location=(0, 0, 1.6))
    return H.leaves_over_ground(ground, bpy.context.object, tmp_path)


def opts(**kw):
    base = dict(properties.scene_options(bpy.context.scene), method="ellipsoid", tau=2.0,
                distance=0.0, show_proxies=False)
    base.update(kw)
    return base


def _colors(attr, key="color"):
    buf = np.empty(len(attr.data) * 4, np.float32)
    attr.data.foreach_get(key, buf)
    return buf.reshape(-1, 4)


def _grey_ao(t, name):
    """The AO a grey bake writes (its red channel) on Ground, for comparison."""
    run_bake(bpy.context, ["Ground"], opts(attribute="Grey", image_dir=t["image_dir"]))
    return _colors(t["ground"].data.attributes["Grey"])[:, 0]


def test_channel_into_a_users_float_attribute_keeps_the_other_channels(tree):
    me = tree["ground"].data
    paint = me.color_attributes.new("Paint", 'FLOAT_COLOR', 'POINT')
    before = np.random.default_rng(0).random((len(me.vertices), 4)).astype(np.float32)
    paint.data.foreach_set("color", before.ravel())
    # Grey (no channel) into the user's attribute: refused, nothing changed.
    with pytest.raises(CanopyAOError, match="did not make"):
        run_bake(bpy.context, ["Ground"], opts(attribute="Paint"))
    assert np.array_equal(_colors(me.attributes["Paint"]), before)
    _job, rep = run_bake(bpy.context, ["Ground"], opts(attribute="Paint", channel="A"))
    after = _colors(me.attributes["Paint"])
    assert rep["channel"] == "A"
    assert np.array_equal(after[:, :3].view(np.uint32), before[:, :3].view(np.uint32))
    ao = _grey_ao(tree, "Grey")
    assert np.array_equal(after[:, 3], ao) and ao.min() < 0.9  # the crown shades the ground
    assert "Paint" not in tree["ground"].get("canopy_ao_attributes", "")  # still the user's


def test_channel_into_a_byte_corner_attribute_keeps_the_other_bytes(tree):
    me = tree["ground"].data
    attr = me.color_attributes.new("Col", 'BYTE_COLOR', 'CORNER')
    before = np.random.default_rng(1).integers(0, 256, (len(me.loops), 4)) / 255.0
    attr.data.foreach_set("color_srgb", before.astype(np.float32).ravel())
    before = _colors(attr, "color_srgb")
    run_bake(bpy.context, ["Ground"], opts(attribute="Col", channel="G"))
    after = _colors(me.attributes["Col"], "color_srgb")
    keep = [0, 2, 3]
    assert np.array_equal(after[:, keep], before[:, keep])
    loop_vert = np.empty(len(me.loops), np.int32)
    me.loops.foreach_get("vertex_index", loop_vert)
    ao = _grey_ao(tree, "Grey")
    assert np.abs(after[:, 1] - ao[loop_vert]).max() <= 0.5 / 255 + 1e-6


def test_channel_into_a_float_and_a_byte_image_keeps_the_other_channels(tree):
    ground = tree["ground"]
    res = 32
    _job, rep = run_bake(bpy.context, ["Ground"], opts(mode='TEXEL', resolution=res,
                                                       image_dir=tree["image_dir"]))
    grey = rep["objects"]["Ground"]["texel"]["path"]
    ao = bpy.data.images.load(grey, check_existing=False)
    ref = np.empty(res * res * 4, np.float32)
    ao.pixels.foreach_get(ref)
    ref = ref.reshape(-1, 4)[:, 0]
    for is_float, channel in ((True, "B"), (False, "R")):
        img = bpy.data.images.new(f"Packed{is_float}", res, res, alpha=True,
                                  float_buffer=is_float)
        rng = np.random.default_rng(2)
        vals = rng.random(res * res * 4).astype(np.float32)
        if not is_float:
            vals = np.round(vals * 255) / 255
        img.pixels.foreach_set(vals)
        before = np.empty_like(vals)
        img.pixels.foreach_get(before)
        run_bake(bpy.context, ["Ground"], opts(mode='TEXEL', resolution=res, channel=channel,
                                               pack_image=img.name,
                                               image_dir=tree["image_dir"]))
        after = np.empty_like(vals)
        img.pixels.foreach_get(after)
        c = "RGBA".index(channel)
        keep = [k for k in range(4) if k != c]
        b4, af = before.reshape(-1, 4), after.reshape(-1, 4)
        assert np.array_equal(af[:, keep].view(np.uint32), b4[:, keep].view(np.uint32))
        assert np.abs(af[:, c] - ref).max() <= (1e-6 if is_float else 0.5 / 255 + 1e-6)
    assert ground.name  # the object itself is untouched by packing


@pytest.mark.parametrize("packed", [False, True], ids=["generated", "packed"])
def test_an_image_without_a_file_keeps_its_packed_channel_through_a_save(tree, packed,
                                                                          monkeypatch):
    """A .blend keeps a generated image's recipe and a packed one's packed bytes, not the
    pixels: the bake packs the new pixels, so a save and reload show the AO, not the old
    pixels; a failed bake leaves the packed bytes as they were."""
    from canopy_ao.blender import job as job_mod
    res = 32
    img = bpy.data.images.new("ORM", res, res, alpha=True)
    img.use_fake_user = True
    vals = np.tile(np.array([0.2, 0.6, 0.4, 1.0], np.float32), res * res)
    img.pixels.foreach_set(vals)
    if packed:
        img.pack()
        old = bytes(img.packed_file.data)

        def broken(self, rep):
            raise RuntimeError("boom")
        with monkeypatch.context() as m:
            m.setattr(job_mod.BakeJob, "_result_texts", broken)
            with pytest.raises(RuntimeError, match="boom"):
                run_bake(bpy.context, ["Ground"], opts(mode='TEXEL', resolution=res,
                                                       channel="R", pack_image="ORM"))
        assert bytes(img.packed_file.data) == old
    run_bake(bpy.context, ["Ground"], opts(mode='TEXEL', resolution=res, channel="R",
                                           pack_image="ORM"))
    baked = np.empty(res * res * 4, np.float32)
    img.pixels.foreach_get(baked)
    assert baked[0::4].min() < 0.9  # the crown shades the ground
    path = os.path.join(tree["image_dir"], "packed.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    got = np.empty(res * res * 4, np.float32)
    bpy.data.images["ORM"].pixels.foreach_get(got)
    assert np.abs(got - baked).max() < 1e-6  # AO in R, the other channels as they were
    assert np.abs(got[1::4] - 0.6).max() < 0.5 / 255 + 1e-6


def test_refusals_before_anything_is_written(tree):
    for name in ("", "CanopyAO", "BakedAO"):  # no name, the AO's attribute, the AO's AOV
        with pytest.raises(CanopyAOError, match="a name of its own"):
            run_bake(bpy.context, ["Ground"], opts(thickness=True, thickness_name=name))
    with pytest.raises(CanopyAOError, match="no image named"):
        run_bake(bpy.context, ["Ground"], opts(mode='TEXEL', channel="R", pack_image="Nope"))
    uv = _uvs(tree["ground"])
    _set_uvs(tree["ground"], uv - 3.0)  # every triangle left of tile 1001
    with pytest.raises(CanopyAOError, match="no triangle of UV map 'UVMap' lies in a UDIM"):
        run_bake(bpy.context, ["Ground"], opts(mode='TEXEL', udim=True))
    _set_uvs(tree["ground"], uv)
    bpy.data.images.new("Small", 8, 8)
    with pytest.raises(CanopyAOError, match="Resolution to 8"):
        run_bake(bpy.context, ["Ground"], opts(mode='TEXEL', resolution=16, channel="R",
                                               pack_image="Small",
                                               image_dir=tree["image_dir"]))


def test_thickness_per_vertex_wired_as_a_pass(tree_scene_objects):
    obs = tree_scene_objects
    _job, rep = run_bake(bpy.context, ["Leaves", "Trunk", "Ground"],
                         opts(thickness=True, wire_material=True))
    leaves = _colors(obs["Leaves"].data.attributes["CanopyThickness"])[:, 0]
    ground = _colors(obs["Ground"].data.attributes["CanopyThickness"])[:, 0]
    # Leaves fill a ball: 0 at its rim, deep inside near its centre (1 - |x - C| / R).
    p = np.array([v.co for v in obs["Leaves"].data.vertices])
    r = np.linalg.norm(p - p.mean(axis=0), axis=1)
    assert 0.0 <= leaves.min() < 0.05 and leaves.max() > 0.7
    assert leaves[r < np.quantile(r, 0.2)].mean() > leaves[r > np.quantile(r, 0.8)].mean() + 0.4
    assert np.all(ground == 0.0)  # the ground lies below the crown
    assert rep["objects"]["Leaves"]["thickness_mean"] == pytest.approx(leaves.mean(), abs=1e-6)
    for ob in (obs["Leaves"], obs["Ground"]):
        nt = ob.material_slots[0].material.node_tree
        aov = [n for n in nt.nodes if n.get("canopy_ao") == "thickness_aov"]
        src = [n for n in nt.nodes if n.get("canopy_ao") == "thickness_source"]
        assert len(aov) == 1 and len(src) == 1 and src[0].layer_name == "CanopyThickness"
        assert materials._aov_target(aov[0]) == "CanopyThickness"
    materials.unwire(obs["Leaves"])
    assert len(obs["Leaves"].material_slots) == 0  # our material, nodes and all, is gone


def test_thickness_per_texel_writes_its_own_image(tree):
    _job, rep = run_bake(bpy.context, ["Leaves"], opts(
        mode='TEXEL', resolution=32, thickness=True, image_dir=tree["image_dir"],
        wire_material=True))
    path = rep["objects"]["Leaves"]["texel"]["thickness_path"]
    assert os.path.exists(path) and path != rep["objects"]["Leaves"]["texel"]["path"]
    img = next(i for i in bpy.data.images if i.get("canopy_ao_map") == "CanopyThickness")
    px = np.empty(32 * 32 * 4, np.float32)
    img.pixels.foreach_get(px)
    assert 0.0 <= px.min() and px.max() <= 1.0
    nt = tree["leaves"].material_slots[0].material.node_tree
    (src,) = [n for n in nt.nodes if n.get("canopy_ao") == "thickness_source"]
    (uv,) = [n for n in nt.nodes if n.get("canopy_ao") == "uv"]
    assert src.image == img and src.inputs["Vector"].links[0].from_node == uv
    (ao,) = [n for n in nt.nodes if n.get("canopy_ao") == "source"]
    assert ao.image != img  # the AO keeps its own image


def _uvs(obj):
    layer = obj.data.uv_layers.active.data
    buf = np.empty(len(layer) * 2, np.float32)
    layer.foreach_get("uv", buf)
    return buf.reshape(-1, 2)


def _set_uvs(obj, uv):
    obj.data.uv_layers.active.data.foreach_set("uv", np.ascontiguousarray(uv, np.float32).ravel())
    obj.data.update()


def _face_shift(obj, uv, where):
    """Per-corner UV offsets moving each face by where(face's mean u, mean v)."""
    shift = np.zeros((len(uv), 2), np.float32)
    for p in obj.data.polygons:
        rows = list(p.loop_indices)
        shift[rows] = where(*uv[rows].mean(axis=0))
    return shift


def _read_tile(path):
    return _core.read_image(path)[:, :, 0]


def test_udim_bake_writes_each_used_tile_with_its_margin(tree):
    """Faces moved to tiles 1002 and 1011 (same place in their tile) bake the same texels as
    before the move, each tile in its own file with a margin, loaded as one tiled image."""
    ground, res = tree["ground"], 32
    _job, rep = run_bake(bpy.context, ["Ground"], opts(mode='TEXEL', resolution=res,
                                                       image_dir=tree["image_dir"]))
    whole = _read_tile(rep["objects"]["Ground"]["texel"]["path"])
    uv = _uvs(ground)
    _set_uvs(ground, uv + _face_shift(ground, uv, lambda u, v: (1, 0) if u > 0.5 else
                                      (0, 1) if v > 0.5 else (0, 0)))  # → 1002, 1011
    _job, rep = run_bake(bpy.context, ["Ground"], opts(mode='TEXEL', resolution=res, udim=True,
                                                       image_dir=tree["image_dir"]))
    tex = rep["objects"]["Ground"]["texel"]
    assert tex["tiles"] == [1001, 1002, 1011]
    assert [os.path.basename(p) for p in tex["paths"]] == [
        f"Ground_CanopyAO.{n}.exr" for n in (1001, 1002, 1011)]
    image = next(i for i in bpy.data.images if i.get("canopy_ao_object") == "Ground")
    assert image.source == 'TILED' and "<UDIM>" in image.filepath
    assert sorted(t.number for t in image.tiles) == [1001, 1002, 1011]
    covered = np.zeros((res, res), bool)
    for n, path in zip(tex["tiles"], tex["paths"]):
        mask = _job.targets[0].stats["image_tiles"][n][1]
        tile = _read_tile(path)
        own = mask == 1
        assert np.any(mask == 2), n  # a margin round each tile's islands
        assert np.abs(tile[own] - whole[own]).max() < 1e-6, n
        assert not np.any(covered & own), n  # each texel of the layout in one tile only
        covered |= own
    # A later bake with fewer tiles leaves no stale tile for Blender to find.
    _set_uvs(ground, uv)
    _job, rep = run_bake(bpy.context, ["Ground"], opts(mode='TEXEL', resolution=res, udim=True,
                                                       image_dir=tree["image_dir"]))
    assert rep["objects"]["Ground"]["texel"]["tiles"] == [1001]
    assert not os.path.exists(os.path.join(tree["image_dir"], "Ground_CanopyAO.1002.exr"))
    assert [t.number for t in image.tiles] == [1001]
    # Without UDIM the same image of the object is a plain one again.
    run_bake(bpy.context, ["Ground"], opts(mode='TEXEL', resolution=res,
                                           image_dir=tree["image_dir"]))
    assert image.source == 'FILE' and "<UDIM>" not in image.filepath
    assert [i for i in bpy.data.images if i.get("canopy_ao_object") == "Ground"] == [image]


def test_two_objects_into_one_atlas_each_write_their_own_texels(tree):
    ground, res = tree["ground"], 32
    other = H.add_plane(size=2.0, subdivisions=3, location=(2.0, 2.0, 0.0), name="Patch")
    other.canopy_ao.role = 'GROUND'
    _set_uvs(ground, _uvs(ground) * (0.5, 1.0))              # left half of the atlas
    _set_uvs(other, _uvs(other) * (0.5, 1.0) + (0.5, 0.0))   # right half
    alone = {}
    for ob in (ground, other):
        _j, rep = run_bake(bpy.context, [ob.name], opts(mode='TEXEL', resolution=res,
                                                        image_dir=tree["image_dir"]))
        alone[ob.name] = (_read_tile(rep["objects"][ob.name]["texel"]["path"]),
                          _j.targets[0].stats["mask"] == 1)
    job, rep = run_bake(bpy.context, ["Ground", "Patch"], opts(
        mode='TEXEL', resolution=res, atlas="Shared", image_dir=tree["image_dir"],
        wire_material=True))
    assert rep["atlas"]["shared_texels"] == 0
    (path,) = rep["atlas"]["paths"]
    assert os.path.basename(path) == "Shared_CanopyAO.exr"
    atlas = _read_tile(path)
    for name, (img, own) in alone.items():
        assert own.sum() > 50 and np.abs(atlas[own] - img[own]).max() < 1e-6, name
    image = next(i for i in bpy.data.images if i.get("canopy_ao_atlas") == "Shared")
    for ob in (ground, other):
        nt = ob.material_slots[0].material.node_tree
        assert [n.image for n in nt.nodes if n.get("canopy_ao") == "source"] == [image]
    # Overlapping layouts: the texels both claim are counted and the note names both.
    _set_uvs(other, _uvs(other) - (0.5, 0.0))
    _job, rep = run_bake(bpy.context, ["Ground", "Patch"], opts(
        mode='TEXEL', resolution=res, atlas="Shared", image_dir=tree["image_dir"]))
    assert rep["atlas"]["shared_texels"] > 50
    note = next(n for n in rep["notes"] if "claimed by two" in n)
    assert "Ground (" in note and "Patch (" in note


def test_cycles_checks_every_tile_and_each_atlas_object_on_its_own_texels(tree):
    """The check per tile (UVs shifted onto 0–1 and back) finds what the one-tile check finds
    on the same texels, and a packed channel is checked as the grey AO is."""
    ground, res = tree["ground"], 32
    o = dict(mode='TEXEL', resolution=res, image_dir=tree["image_dir"], check_cycles=True,
             cycles_samples=16)
    _j, rep = run_bake(bpy.context, ["Ground"], opts(**o))
    one = rep["objects"]["Ground"]["cycles"]
    uv = _uvs(ground)
    moved = uv + _face_shift(ground, uv, lambda u, v: (1, 0) if u > 0.5 else (0, 0))
    _set_uvs(ground, moved)
    _j, rep = run_bake(bpy.context, ["Ground"], opts(udim=True, **o))
    tiles = rep["objects"]["Ground"]["cycles"]
    assert np.array_equal(_uvs(ground), moved)  # put back after the check
    assert sorted(tiles["mae_per_tile"]) == [1001, 1002]
    assert abs(tiles["n"] - one["n"]) <= 0.1 * one["n"]
    assert abs(tiles["mae"] - one["mae"]) < 0.03, (tiles["mae"], one["mae"])
    _set_uvs(ground, uv)
    _j, rep = run_bake(bpy.context, ["Ground"], opts(atlas="Solo", **o))
    solo = rep["objects"]["Ground"]["cycles"]
    assert abs(solo["mae"] - one["mae"]) < 0.03 and abs(solo["n"] - one["n"]) <= 0.1 * one["n"]
    _j, rep = run_bake(bpy.context, ["Ground"], opts(check_cycles=True, cycles_samples=16,
                                                     attribute="Packed", channel="B"))
    assert rep["objects"]["Ground"]["cycles"]["mae"] < 0.2


def test_channel_into_a_saved_png_is_saved_and_the_other_bytes_stay(tree):
    res = 16
    img = bpy.data.images.new("Mask", res, res, alpha=True)
    vals = np.random.default_rng(3).integers(0, 256, res * res * 4) / 255.0
    img.pixels.foreach_set(vals.astype(np.float32))
    path = os.path.join(tree["image_dir"], "mask.png")
    img.filepath_raw = path
    img.file_format = 'PNG'
    img.save()
    img.source = 'FILE'
    img.reload()
    before = _core.read_image(path)
    run_bake(bpy.context, ["Ground"], opts(mode='TEXEL', resolution=res, channel="G",
                                           pack_image="Mask", image_dir=tree["image_dir"]))
    after = _core.read_image(path)
    assert before.shape == after.shape == (res, res, 4)
    keep = [0, 2, 3]
    assert np.array_equal(np.round(after[..., keep] * 255), np.round(before[..., keep] * 255))
    assert not np.array_equal(after[..., 1], before[..., 1])
    assert not [f for f in os.listdir(tree["image_dir"]) if "previous" in f]  # no backup left
