"""texel_io.py: per-texel receivers and results (UV gather, native raster, image file, wiring)."""
import os

import bpy
import numpy as np
import pytest

import helpers_materials as H
from canopy_ao.blender import texel_io as texel


@pytest.fixture
def scene():
    return H.empty_scene()


def _ramp(positions, normals):
    """AO = 0.5 + 0.25 x: on the default plane (x in [-1, 1], u = (x + 1) / 2) a known image."""
    return (0.5 + 0.25 * positions[:, 0]).astype(np.float32)


def _pixels(img):
    w, h = img.size
    px = np.empty(w * h * 4, dtype=np.float32)
    img.pixels.foreach_get(px)
    return px.reshape(h, w, 4)


def _set_uvs(obj, fn):
    uv = obj.data.uv_layers.active.data
    buf = np.empty(len(uv) * 2, dtype=np.float32)
    uv.foreach_get("uv", buf)
    uv.foreach_set("uv", fn(buf.reshape(-1, 2)).astype(np.float32).ravel())
    obj.data.update()  # foreach_set does not tag the depsgraph


def test_no_uv_map_refused(scene, tmp_path):
    bpy.ops.mesh.primitive_plane_add(calc_uvs=False)
    obj = bpy.context.object
    n_img, n_mat = len(bpy.data.images), len(bpy.data.materials)
    with pytest.raises(ValueError) as info:
        texel.bake_texel(bpy.context, obj, _ramp, resolution=16, image_dir=str(tmp_path))
    assert str(info.value) == (f"Object '{obj.name}' has no UV map; add one "
                               "(UV > Smart UV Project) or bake per vertex")
    assert (len(bpy.data.images), len(bpy.data.materials)) == (n_img, n_mat)
    assert len(obj.material_slots) == 0 and not os.listdir(tmp_path)


def test_unknown_uv_map_named(scene, tmp_path):
    obj = H.add_plane()
    with pytest.raises(ValueError, match="no UV map named 'Nope'.*UVMap"):
        texel.bake_texel(bpy.context, obj, _ramp, uv_map="Nope", resolution=16,
                         image_dir=str(tmp_path))


def test_uv_plane_gets_image_wired(scene, tmp_path):
    obj = H.add_plane()
    H.add_material(obj)
    image, stats = texel.bake_texel(bpy.context, obj, _ramp, resolution=16, margin=2,
                                    image_dir=str(tmp_path))
    assert os.path.exists(stats["path"]) and stats["path"].endswith(".exr")
    assert image.get("canopy_ao") and image.name == "Plane_CanopyAO"
    assert image.size[0] == 16 and image.size[1] == 16
    assert stats["texels"] == 256 and stats["overlapping_texels"] == 0
    assert not stats["warnings"]
    # texel column i has its centre at u = (i + 0.5) / 16, x = 2u - 1
    px = _pixels(image)
    u = (np.arange(16) + 0.5) / 16
    expected = 0.5 + 0.25 * (2 * u - 1)
    assert np.allclose(px[:, :, 0], expected[None, :], atol=1e-4)
    # wired: Image Texture reading our image through the UV Map node
    nt = obj.material_slots[0].material.node_tree
    src = [n for n in nt.nodes if n.get("canopy_ao") == "source"]
    uv = [n for n in nt.nodes if n.get("canopy_ao") == "uv"]
    assert len(src) == 1 and src[0].bl_idname == "ShaderNodeTexImage" and src[0].image == image
    assert len(uv) == 1 and uv[0].uv_map == "UVMap"
    assert stats["nodes_added"] == 4


def test_rebake_reuses_image_and_nodes(scene, tmp_path):
    obj = H.add_plane()
    image, _ = texel.bake_texel(bpy.context, obj, _ramp, resolution=16, image_dir=str(tmp_path))
    n_img = len(bpy.data.images)
    image2, stats = texel.bake_texel(bpy.context, obj, lambda p, n: np.full(len(p), 0.25),
                                     resolution=16, image_dir=str(tmp_path))
    assert image2 == image and len(bpy.data.images) == n_img
    assert stats["nodes_added"] == 0
    assert np.allclose(_pixels(image2)[:, :, 0], 0.25)


def test_user_image_never_overwritten(scene, tmp_path):
    obj = H.add_plane()
    user = bpy.data.images.new("Plane_CanopyAO", 4, 4, float_buffer=True)
    user.pixels.foreach_set(np.full(64, 0.9, dtype=np.float32))
    image, _ = texel.bake_texel(bpy.context, obj, _ramp, resolution=16, image_dir=str(tmp_path))
    assert image != user and image.get("canopy_ao") and not user.get("canopy_ao")
    assert user.size[0] == 4 and np.allclose(_pixels(user), 0.9)
    # Nor renamed: Blender 3.4 gives a name set on one image to it and renames the image that
    # had it (the user's became Plane_CanopyAO.001, and whatever found it by name lost it).
    assert user.name == "Plane_CanopyAO" and image.name != user.name


def test_overlapping_uvs_warn_with_object_name(scene, tmp_path):
    obj = H.add_plane(subdivisions=1, name="Leafy")  # 4 quads
    # every quad (4 consecutive corners) onto the whole 0..1 square: 4-fold overlap
    def each_quad_full(uv):
        q = uv.reshape(-1, 4, 2)
        return ((q - q.min(axis=1, keepdims=True)) * 2).reshape(-1, 2)

    _set_uvs(obj, each_quad_full)
    _image, stats = texel.bake_texel(bpy.context, obj, _ramp, resolution=16,
                                     image_dir=str(tmp_path))
    assert stats["overlapping_texels"] > 0
    assert any("Leafy" in w and "overlap" in w for w in stats["warnings"])


def test_margin_dilates_outside_the_island(scene, tmp_path):
    obj = H.add_plane()
    _set_uvs(obj, lambda uv: uv * 0.5)  # island in the lower-left quarter
    image, stats = texel.bake_texel(bpy.context, obj, lambda p, n: np.full(len(p), 0.3),
                                    resolution=16, margin=2, image_dir=str(tmp_path),
                                    wire=False)
    px = _pixels(image)[:, :, 0]
    assert stats["texels"] == 64
    assert np.allclose(px[:10, :10], 0.3)       # island (8x8) + 2-texel margin
    assert np.allclose(px[11:, 11:], 1.0)       # background: open sky
    assert stats["margin_texels"] == 10 * 10 - 64


def test_raster_counts_shared_edges_once():
    # two triangles of a unit quad, UV = the whole tile: every texel once, no overlap
    uvs = np.array([[0, 0], [1, 0], [1, 1], [0, 0], [1, 1], [0, 1]], dtype=np.float32)
    pos = np.concatenate([uvs, np.zeros((6, 1), np.float32)], axis=1)
    nrm = np.tile(np.array([[0, 0, 1]], np.float32), (6, 1))
    pixels, tpos, tnrm, stats, _tri = texel.rasterize(uvs, pos, nrm, 8, 8)
    assert np.array_equal(pixels, np.arange(64))
    assert stats["overlapping_texels"] == 0
    assert np.allclose(tpos[:, 0], ((pixels % 8) + 0.5) / 8)
    assert np.allclose(tpos[:, 1], ((pixels // 8) + 0.5) / 8)
    assert np.allclose(tnrm, [0, 0, 1])


def test_texel_bake_checks_against_cycles(scene, tmp_path):
    """A plane under a disk: our texels from the exact disk formula vs Cycles' texel bake."""
    from canopy_ao.blender import cycles_check

    obj = H.add_plane(size=2.0)
    bpy.ops.mesh.primitive_circle_add(vertices=64, radius=2.0, fill_type="NGON",
                                      location=(0, 0, 1.0))

    def disk_ao(p, n):
        # cosine-weighted open fraction under a disk of radius 2 at height 1, on its axis;
        # off-axis texels differ, so only coarse agreement is asked for below
        return np.full(len(p), 1.0 - 4.0 / 5.0, dtype=np.float32)

    image, stats = texel.bake_texel(bpy.context, obj, disk_ao, resolution=16, margin=1,
                                    image_dir=str(tmp_path), wire=False)
    ours = _pixels(image)[:, :, 0]
    m = cycles_check.check_texel(bpy.context, obj, ours, stats["uv_map"], 100.0, 32)
    assert m["n"] == 256
    assert all(np.isfinite(v) for v in m.values())
    assert m["mae"] < 0.12 and -1.0 <= m["corr"] <= 1.0


def test_texels_of_a_moved_sphere_lie_on_it_in_world_space(scene):
    """The texel receivers come from the evaluated mesh in world space (the transform the
    vertex path uses): every texel of a UV sphere moved and scaled lies on that sphere, with
    its outward unit normal."""
    bpy.ops.mesh.primitive_uv_sphere_add(segments=32, ring_count=16, radius=1.0,
                                         location=(3.0, -1.0, 2.0))
    obj = bpy.context.object
    obj.scale = (2.0, 2.0, 2.0)
    bpy.context.view_layer.update()
    rx = texel.receivers(obj, bpy.context.evaluated_depsgraph_get(), "UVMap", 64)
    assert len(rx.pixels) > 1000 and rx.stats["texels"] == len(rx.pixels)
    r = np.linalg.norm(rx.positions - np.float32([3.0, -1.0, 2.0]), axis=1)
    assert np.all(np.abs(r - 2.0) < 0.05)  # polygonal sphere: inside the true one by < 2 %
    assert np.allclose(np.linalg.norm(rx.normals, axis=1), 1.0, atol=1e-4)
    outward = (rx.positions - np.float32([3.0, -1.0, 2.0])) / r[:, None]
    assert np.einsum("ij,ij->i", outward, rx.normals).min() > 0.9
