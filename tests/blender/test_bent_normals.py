"""Bent normals in Blender (blender/bent_io.py): a color attribute and an RGB EXR encoded
0.5 + 0.5 · n, in world or UV tangent space, and the refusals before anything is written."""
import os

import bpy
import numpy as np
import pytest

from canopy_ao import _core
from canopy_ao.blender import properties
from canopy_ao.blender.job import run_bake
from canopy_ao.core.native import CanopyAOError
from test_maps import tree  # noqa: F401 (the fixture: a UV-mapped ground under a leaf sphere)


def opts(**kw):
    base = dict(properties.scene_options(bpy.context.scene), method="ellipsoid", tau=2.0,
                distance=0.0, show_proxies=False, samples=256)
    base.update(kw)
    return base


def _decoded(obj, name):
    attr = obj.data.attributes[name]
    buf = np.empty(len(attr.data) * 4, np.float32)
    attr.data.foreach_get("color", buf)
    rgba = buf.reshape(-1, 4)
    assert np.all(rgba[:, 3] == 1.0)
    return 2.0 * rgba[:, :3] - 1.0


def test_world_and_tangent_attributes_lean_away_from_the_crown(tree):
    ground = tree["ground"]
    _job, rep = run_bake(bpy.context, ["Ground"], opts(bent_normals="WORLD"))
    world = _decoded(ground, "CanopyBentNormal")
    assert np.allclose(np.linalg.norm(world, axis=1), 1.0, atol=1e-5)
    assert rep["objects"]["Ground"]["bent_normals"]["space"] == "world"
    p = np.array([v.co for v in ground.data.vertices])[:, :2]
    r = np.linalg.norm(p, axis=1)
    # Under the crown's rim the open sky lies outward: the bent normal leans that way.
    rim = (r > 0.8) & (r < 2.0)
    assert np.mean(np.einsum("ij,ij->i", world[rim, :2], p[rim] / r[rim, None]) > 0.05) > 0.9
    tilt = np.degrees(np.arccos(np.clip(world[:, 2], -1, 1)))
    assert tilt[rim].mean() > tilt[r > 2.8].mean() + 5.0
    assert rep["objects"]["Ground"]["bent_normals"]["mean_tilt_degrees"] == pytest.approx(
        tilt.mean(), abs=1e-3)
    # The plane's UVs run along x and y with its normal up: tangent space is world space, and
    # a 90° turn about z (the UVs turn with it) turns the world vector but not the tangent one.
    run_bake(bpy.context, ["Ground"], opts(bent_normals="TANGENT", bent_normals_name="BentT"))
    tangent = _decoded(ground, "BentT")
    assert np.abs(tangent - world).max() < 1e-4
    ground.rotation_euler[2] = np.pi / 2
    bpy.context.view_layer.update()
    run_bake(bpy.context, ["Ground"], opts(bent_normals="TANGENT", bent_normals_name="BentT"))
    run_bake(bpy.context, ["Ground"], opts(bent_normals="WORLD"))
    turned = _decoded(ground, "CanopyBentNormal")
    assert np.abs(_decoded(ground, "BentT") - world).max() < 0.05  # the same scene, turned
    assert np.abs(turned[:, :2] - np.stack([-world[:, 1], world[:, 0]], 1)).max() < 0.05


def test_tangent_space_on_a_curved_uv_map_keeps_what_no_frame_changes(tree):
    """On the UV sphere (tangents turning with the surface, poles included), through bpy.ops:
    the tangent-space z is the world bent normal's cosine with the normal, and its length is
    the same, whatever the tangent frame."""
    leaves = tree["leaves"]
    run_bake(bpy.context, ["Leaves"], opts(bent_normals="WORLD", bent_normals_name="BentW"))
    r = bpy.ops.canopy_ao.bake(objects="Leaves", method="ellipsoid", tau=2.0,
                               use_world_distance=False, distance=0.0, samples=256,
                               show_proxies=False, bent_normals='TANGENT')
    assert r == {'FINISHED'}
    world, tangent = _decoded(leaves, "BentW"), _decoded(leaves, "CanopyBentNormal")
    n = np.array([v.normal for v in leaves.data.vertices])
    assert np.abs(tangent[:, 2] - np.einsum("ij,ij->i", world, n)).max() < 2e-3
    assert np.allclose(np.linalg.norm(tangent, axis=1), 1.0, atol=2e-3)
    assert np.abs(tangent[:, :2]).max() > 0.3  # the frames do turn: not all along z


def test_texel_image_holds_the_encoded_bent_normals(tree):
    _job, rep = run_bake(bpy.context, ["Ground"], opts(
        mode='TEXEL', resolution=32, bent_normals="TANGENT", image_dir=tree["image_dir"]))
    tx = rep["objects"]["Ground"]["texel"]
    path = tx["bent_normals_path"]
    assert os.path.exists(path) and path != tx["path"]
    img = next(i for i in bpy.data.images if i.get("canopy_ao_map") == "CanopyBentNormal")
    assert img.colorspace_settings.name == "Non-Color"
    rgb = _core.read_image(path)[:, :, :3]  # row 0 = the bottom (v = 0)
    b = 2.0 * rgb.reshape(-1, 3) - 1.0
    assert np.allclose(np.linalg.norm(b, axis=1), 1.0, atol=1e-4)  # the plane covers every texel
    assert np.all(b[:, 2] > 0.2)
    # Texel (i, j) lies at x = 6 (u - 0.5), y = 6 (v - 0.5): under the rim it leans outward.
    j, i = np.mgrid[0:32, 0:32]
    xy = np.stack([6 * ((i + 0.5) / 32 - 0.5), 6 * ((j + 0.5) / 32 - 0.5)], -1).reshape(-1, 2)
    r = np.linalg.norm(xy, axis=1)
    rim = (r > 0.8) & (r < 2.0)
    assert np.mean(np.einsum("ij,ij->i", b[rim, :2], xy[rim] / r[rim, None]) > 0.05) > 0.9

    # The file is ours now: a re-bake replaces it; a file Canopy AO did not write is refused
    # before anything is written (the bent normals' image follows the AO's ownership rules).
    run_bake(bpy.context, ["Ground"], opts(
        mode='TEXEL', resolution=32, bent_normals="TANGENT", image_dir=tree["image_dir"]))
    _core.write_image(path, np.full((8, 8), 0.5, np.float32))  # the user's own EXR
    with open(path, "rb") as f:
        user = f.read()
    with pytest.raises(CanopyAOError, match="did not write it"):
        run_bake(bpy.context, ["Ground"], opts(
            mode='TEXEL', resolution=32, bent_normals="TANGENT", image_dir=tree["image_dir"]))
    with open(path, "rb") as f:
        assert f.read() == user


def test_refusals_before_anything_is_written(tree):
    ground = tree["ground"]
    with pytest.raises(CanopyAOError, match="UDIM"):
        run_bake(bpy.context, ["Ground"], opts(mode='TEXEL', udim=True, bent_normals="WORLD",
                                                image_dir=tree["image_dir"]))
    with pytest.raises(CanopyAOError, match="name of its own"):
        run_bake(bpy.context, ["Ground"], opts(bent_normals="WORLD",
                                                bent_normals_name="CanopyAO"))
    ground.data.uv_layers.remove(ground.data.uv_layers[0])
    with pytest.raises(CanopyAOError, match="no UV map"):
        run_bake(bpy.context, ["Ground"], opts(bent_normals="TANGENT"))
    assert "CanopyAO" not in ground.data.attributes
    assert "CanopyBentNormal" not in ground.data.attributes
    # World space needs no UVs.
    run_bake(bpy.context, ["Ground"], opts(bent_normals="WORLD"))
    assert "CanopyBentNormal" in ground.data.attributes


def test_command_line_bakes_and_refuses_bent_normals(tree, capsys, tmp_path):
    """--bent-normals through the CLI: tangent space written with its report entry; without a
    UV map, exit code 1 with the reason, nothing written."""
    import json
    from canopy_ao import cli
    report = tmp_path / "r.json"
    with pytest.raises(SystemExit) as exc:
        cli.main(["--objects", "Ground", "--method", "sphere", "--tau", "2", "--no-proxies",
                  "--bent-normals", "tangent", "--samples", "32", "--report", str(report)])
    assert exc.value.code == 0, capsys.readouterr().err
    rep = json.loads(report.read_text())
    assert rep["objects"]["Ground"]["bent_normals"]["space"] == "tangent"
    assert "CanopyBentNormal" in tree["ground"].data.attributes
    leaves = tree["leaves"]
    leaves.data.uv_layers.remove(leaves.data.uv_layers[0])
    with pytest.raises(SystemExit) as exc:
        cli.main(["--objects", "Leaves", "--method", "sphere", "--tau", "2", "--no-proxies",
                  "--bent-normals", "tangent"])
    assert exc.value.code == 1 and "no UV map" in capsys.readouterr().err
    assert "CanopyBentNormal" not in leaves.data.attributes
    assert "CanopyAO" not in leaves.data.attributes


def _bent_rays(monkeypatch, **kw):
    """The rays the bent normals' traces cast in a texel bake of the ground, per texel, and the
    bake's report (lighting.trace spied on: a call casts samples / point_group per point)."""
    from canopy_ao.core import lighting
    calls, trace = [], lighting.trace

    def spy(plan, p, n, *args, **extra):
        if extra.get("bent_normals"):
            samples = extra.get("samples", args[0] if args else None)
            calls.append(len(p) * samples // extra.get("point_group", 1))
        return trace(plan, p, n, *args, **extra)
    monkeypatch.setattr(lighting, "trace", spy)
    _job, rep = run_bake(bpy.context, ["Ground"], opts(mode='TEXEL', resolution=16, **kw))
    texels = rep["objects"]["Ground"]["texel"]["texels"]
    return sum(calls) / texels, rep


@pytest.mark.parametrize("aa", [1, 2, 3])
def test_texel_bent_normals_deal_a_texels_samples_over_its_sub_samples(tree, monkeypatch, aa):
    """A texel's bent normal costs its Samples rays (rounded up to a multiple of the N × N
    sub-samples, as its AO's), not N² × Samples: counted, not timed (it cast 4 and 9 times
    the rays at 2 × 2 and 3 × 3)."""
    from canopy_ao.core.texel_budget import texel_rays
    per_texel, _rep = _bent_rays(monkeypatch, texel_aa=aa, bent_normals="WORLD",
                                 image_dir=tree["image_dir"])
    assert per_texel == texel_rays(256, aa * aa)  # 256, 256, 261


def test_texel_ao_with_bent_normals_is_the_ao_without_them(tree):
    """Under the exact rung one trace gives a texel's AO and bent normal: with its rays dealt
    over the sub-samples as the AO alone deals them, the AO is the same to the bit (it was
    another estimate, from every sub-sample's full Samples)."""
    got = {}
    for bent in ("OFF", "WORLD"):
        _job, rep = run_bake(bpy.context, ["Ground"], opts(
            mode='TEXEL', resolution=16, texel_aa=2, method="raytrace", samples=16,
            bent_normals=bent, image_dir=tree["image_dir"]))
        got[bent] = _core.read_image(rep["objects"]["Ground"]["texel"]["path"]).copy()
    assert got["OFF"].min() < 0.9  # the crown shades part of the ground
    np.testing.assert_array_equal(got["OFF"], got["WORLD"])


def test_a_texels_bent_normal_weighs_its_sub_samples_by_their_open_rays():
    """A sub-sample whose rays were all blocked stands in its normal (raytrace.h): it adds no
    direction to its texel's; weights that are all zero fall back to the plain mean."""
    from canopy_ao.blender.texel_target import texel_bent
    up, lean = np.array([0.0, 0.0, 1.0]), np.array([0.6, 0.0, 0.8])
    bent = np.float32([up, lean, lean, up, up, up, up, up])  # two texels of 4 sub-samples
    out = texel_bent(bent, np.float32([0.0, 0.5, 0.25, 0.0, 0, 0, 0, 0]), 4)
    np.testing.assert_allclose(out, [lean, up], atol=1e-6)
    np.testing.assert_allclose(texel_bent(bent, None, 4)[0], (up + lean) / np.linalg.norm(
        up + lean), atol=1e-6)
