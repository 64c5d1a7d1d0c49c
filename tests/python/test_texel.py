"""canopy_ao._core per-texel API: rasterize_uv / TexelSet / splat_texels / dilate_margin /
write_image / read_image — round trips through the bindings and the error messages a user sees.
"""
import os
import sys

import numpy as np
import pytest

from canopy_ao import _core as core  # conftest.py puts addon/ on sys.path


def quad(u0=0.0, v0=0.0, u1=1.0, v1=1.0):
    """Two triangles covering [u0, u1] x [v0, v1]; positions = (2u+1, 3v-1, u+v)."""
    uv = np.array([[u0, v0], [u1, v0], [u1, v1], [u0, v0], [u1, v1], [u0, v1]], np.float32)
    pos = np.stack([2 * uv[:, 0] + 1, 3 * uv[:, 1] - 1, uv[:, 0] + uv[:, 1]], 1)
    nrm = np.tile(np.float32([0, 0, 1]), (6, 1))
    return uv, pos.astype(np.float32), nrm


def test_quad_covers_every_texel_once_bottom_row_first():
    uv, pos, nrm = quad()
    t = core.rasterize_uv(uv, pos, nrm, resolution=8)
    assert len(t) == 64 and t.resolution == (8, 8)
    np.testing.assert_array_equal(t.pixels, np.arange(64, dtype=np.int32))
    assert t.exact.dtype == np.bool_ and t.exact.all()
    assert t.overlapping_texels == 0 and t.degenerate == 0
    # Texel (i, j) centre is ((i + .5) / 8, (j + .5) / 8); row j = 0 is v = 0 (the bottom).
    i, j = t.pixels % 8, t.pixels // 8
    u, v = (i + 0.5) / 8, (j + 0.5) / 8
    np.testing.assert_allclose(t.positions, np.stack([2 * u + 1, 3 * v - 1, u + v], 1), atol=1e-5)
    np.testing.assert_allclose(t.normals, np.tile([0, 0, 1], (64, 1)), atol=1e-6)
    np.testing.assert_allclose(t.barycentrics.sum(1), 1, atol=1e-6)
    assert t.triangles.dtype == np.int32 and set(t.triangles) == {0, 1}


def test_grouped_corner_shape_and_face_normals():
    uv, pos, _ = quad(0.1, 0.2, 0.7, 0.9)
    flat = core.rasterize_uv(uv, pos, resolution=(np.int64(20), 10))
    grouped = core.rasterize_uv(uv.reshape(2, 3, 2), pos.reshape(2, 3, 3), None, (20, 10))
    np.testing.assert_array_equal(flat.pixels, grouped.pixels)
    assert flat.width == 20 and flat.height == 10
    # Face normal of (2u+1, 3v-1, u+v) is (-3, -2, 6) / 7.
    np.testing.assert_allclose(flat.normals, np.tile(np.float32([-3, -2, 6]) / 7, (len(flat), 1)),
                               atol=1e-5)


def test_arrays_are_read_only_views_that_outlive_the_set():
    uv, pos, nrm = quad()
    t = core.rasterize_uv(uv, pos, nrm, resolution=4)
    p = t.positions
    assert not p.flags.writeable and p.flags.c_contiguous and p.dtype == np.float32
    del t
    assert p.shape == (16, 3) and np.isfinite(p).all()


def test_thin_sliver_gives_conservative_texels():
    w = 32
    uv = np.float32([[2, 3.1], [20, 3.1], [20, 3.2]]) / w
    pos = np.zeros((3, 3), np.float32)
    assert len(core.rasterize_uv(uv, pos, resolution=w, conservative=False)) == 0
    t = core.rasterize_uv(uv, pos, resolution=w)
    assert len(t) == 18 and not t.exact.any()
    assert t.stats["conservative_texels"] == 18 and t.stats["exact_texels"] == 0


def test_overlap_and_degenerate_counts():
    uv, pos, nrm = quad(0.1, 0.1, 0.6, 0.6)
    uv2 = np.concatenate([uv, uv, np.float32([[0.2, 0.2], [0.4, 0.4], [0.6, 0.6]])])
    pos2 = np.concatenate([pos, pos, pos[:3]])
    t = core.rasterize_uv(uv2, pos2, resolution=16)
    assert t.overlapping_texels == t.stats["exact_texels"] > 0
    assert t.degenerate == 1 and t.stats["triangles"] == 5
    assert "overlapping" in repr(t)


def test_splat_and_margin():
    uv, pos, nrm = quad(0.25, 0.25, 0.5, 0.5)
    t = core.rasterize_uv(uv, pos, nrm, resolution=16)
    values = np.linspace(0.1, 0.9, len(t), dtype=np.float32)
    img, mask = t.splat(values, margin=2, background=1.0, return_mask=True)
    assert img.shape == (16, 16) and img.dtype == np.float32 and mask.dtype == np.uint8
    np.testing.assert_array_equal(img.ravel()[t.pixels], values)  # covered texels untouched
    assert (mask.ravel()[t.pixels] == 1).all()
    # Island is texels 4..7; margin 2 fills 2..9, the rest stays background.
    assert (mask[2:10, 2:10] != 0).all() and (mask[2:10, 2:10] == 2).sum() == 64 - 16
    assert (img[mask == 0] == 1.0).all() and (mask == 0).sum() == 256 - 64
    assert np.isfinite(img).all()
    rgb = core.splat_texels(t.pixels, np.repeat(values[:, None], 3, 1), (16, 16), margin=0)
    assert rgb.shape == (16, 16, 3)
    again = np.full((16, 16), 1.0, np.float32)
    m2 = np.zeros((16, 16), np.uint8)
    again.ravel()[t.pixels] = values
    m2.ravel()[t.pixels] = 1
    core.dilate_margin(again, m2, 2)
    np.testing.assert_array_equal(again, img)
    np.testing.assert_array_equal(m2, mask)


def test_image_round_trips(tmp_path):
    rng = np.random.default_rng(1)
    grey = rng.uniform(-1, 4, (13, 21)).astype(np.float32)
    core.write_image(tmp_path / "g.exr", grey)  # os.PathLike accepted
    back = core.read_image(str(tmp_path / "g.exr"))
    assert back.shape == (13, 21, 1) and back.dtype == np.float32
    np.testing.assert_array_equal(back[..., 0], grey)
    # Files store the top row first; read_image(bottom_up=False) shows the file's order.
    np.testing.assert_array_equal(core.read_image(tmp_path / "g.exr", bottom_up=False)[..., 0],
                                  grey[::-1])
    rgb = rng.uniform(0, 1, (9, 7, 3)).astype(np.float32)
    core.write_image(tmp_path / "c.png", rgb)
    back = core.read_image(tmp_path / "c.png")
    assert back.shape == (9, 7, 3)
    assert np.abs(back - rgb).max() <= 1 / 65535
    core.write_image(tmp_path / "h.exr", rgb, dtype="half")
    np.testing.assert_allclose(core.read_image(tmp_path / "h.exr"), rgb, atol=1e-3)


@pytest.mark.parametrize("name", ["h.exr", "h.png"])
def test_header_attributes_round_trip(tmp_path, name):
    path = tmp_path / name
    attrs = {"canopy_ao": '{"owner": "Tree.001", "map": "CanopyAO"}', "note_2": "Baum ä"}
    core.write_image(path, np.full((4, 5), 0.5, np.float32), attributes=attrs)
    got = core.read_image_attributes(path)
    assert {k: got.get(k) for k in attrs} == attrs
    core.write_image(path, np.full((4, 5), 0.5, np.float32))  # none: none left over
    assert "canopy_ao" not in core.read_image_attributes(path)


@pytest.mark.parametrize("attrs, match", [
    ({"a:b": "x"}, "letters, digits and '_'"), ({"": "x"}, "letters, digits"),
    ({"é": "x"}, "letters, digits"), ({"k": 3}, "str to str"), ({1: "x"}, "str to str"),
    ({"k": "a\0b"}, "NUL"), ({"k": ""}, "empty"), (["k"], "dict of str"),
])
def test_bad_header_attributes_are_value_errors(tmp_path, attrs, match):
    with pytest.raises(ValueError, match=match):
        core.write_image(tmp_path / "a.exr", np.zeros((2, 2), np.float32), attributes=attrs)
    assert not (tmp_path / "a.exr").exists()


def test_reading_the_header_of_a_missing_or_non_image_file_names_it(tmp_path):
    with pytest.raises(core.CanopyAOError, match="nope.exr"):
        core.read_image_attributes(tmp_path / "nope.exr")
    (tmp_path / "t.exr").write_text("not an image")
    with pytest.raises(core.CanopyAOError, match="t.exr"):
        core.read_image_attributes(tmp_path / "t.exr")


@pytest.mark.parametrize("kwargs, match", [
    (dict(uvs=np.zeros((6, 2))), "float32"),
    (dict(uvs=np.zeros((5, 2), np.float32)), r"uvs must have shape \(3\*M, 2\)"),
    (dict(positions=np.zeros((3, 3), np.float32)), "same triangles"),
    (dict(resolution=0), "resolution"),
    (dict(resolution=(16, 20000)), "resolution"),
    (dict(resolution=(1, 2, 3)), "resolution"),
    (dict(resolution=(8.0, 8)), "resolution"),
    (dict(resolution="8"), "resolution"),
    (dict(normals=np.zeros((6, 2), np.float32)), "normals"),
])
def test_rasterize_bad_input(kwargs, match):
    uv, pos, _ = quad()
    args = dict(uvs=uv, positions=pos, resolution=8)
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        core.rasterize_uv(**args)


def test_rasterize_non_finite_position():
    uv, pos, _ = quad()
    pos[4, 1] = np.nan
    with pytest.raises(ValueError, match="positions has a non-finite value"):
        core.rasterize_uv(uv, pos, resolution=8)


def test_splat_bad_input():
    with pytest.raises(ValueError, match="outside"):
        core.splat_texels(np.int32([64]), np.float32([0.5]), 8)
    with pytest.raises(ValueError, match="values must have shape"):
        core.splat_texels(np.int32([1, 2]), np.float32([0.5]), 8)
    with pytest.raises(ValueError, match="int32"):
        core.splat_texels(np.int64([1]), np.float32([0.5]), 8)
    with pytest.raises(ValueError, match="non-finite"):
        core.splat_texels(np.int32([1]), np.float32([np.nan]), 8)
    with pytest.raises(ValueError, match="margin"):
        core.splat_texels(np.int32([1]), np.float32([0.5]), 8, margin=-1)


def test_write_errors_name_the_path(tmp_path):
    img = np.zeros((4, 4), np.float32)
    bad = tmp_path / "no_such_folder" / "ao.exr"
    with pytest.raises(core.CanopyAOError, match="no_such_folder") as err:
        core.write_image(bad, img)
    assert isinstance(err.value, RuntimeError) and str(bad) in str(err.value)
    with pytest.raises(core.CanopyAOError, match="missing.exr"):
        core.read_image(tmp_path / "missing.exr")
    with pytest.raises(ValueError, match="PNG"):
        core.write_image(tmp_path / "a.png", img, dtype="float")
    with pytest.raises(ValueError, match="dtype must be"):
        core.write_image(tmp_path / "a.exr", img, dtype="double")
    with pytest.raises(ValueError, match="pixels must have shape"):
        core.write_image(tmp_path / "a.exr", np.zeros((4, 4, 5), np.float32))
    assert not (tmp_path / "a.png").exists()


@pytest.mark.skipif(not hasattr(core, "ao_canopy_sphere"), reason="models not in this build")
def test_bake_a_ground_texture_end_to_end(tmp_path):
    """Ground quad under a canopy sphere: texels are ordinary receivers for an AO model, and the
    EXR written from the splatted image reads back to the same AO at every covered texel."""
    uv, _, _ = quad()
    pos = np.column_stack([10 * uv - 5, np.zeros(6)]).astype(np.float32)  # 10 x 10 ground, z = 0
    nrm = np.tile(np.float32([0, 0, 1]), (6, 1))
    t = core.rasterize_uv(uv, pos, nrm, resolution=(64, 32))
    ao = core.ao_canopy_sphere(t.positions, t.normals, core.Sphere((0, 0, 2), 1.5), 2.0)
    assert ao.shape == (len(t),) and (ao >= 0).all() and (ao <= 1).all()
    image = t.splat(ao, margin=4)
    # Darkest under the sphere (image centre), open sky at the corners.
    assert image[16, 32] < image[0, 0] and image[0, 0] > 0.9
    core.write_image(tmp_path / "ground_ao.exr", image)
    back = core.read_image(tmp_path / "ground_ao.exr")[..., 0]
    np.testing.assert_array_equal(back.ravel()[t.pixels], ao)


def test_empty_mesh_gives_an_empty_set_and_a_background_image():
    t = core.rasterize_uv(np.zeros((0, 2), np.float32), np.zeros((0, 3), np.float32),
                          resolution=4)
    assert len(t) == 0 and t.positions.shape == (0, 3) and t.pixels.dtype == np.int32
    img = t.splat(np.zeros(0, np.float32), margin=3, background=0.5)
    np.testing.assert_array_equal(img, np.full((4, 4), 0.5, np.float32))
