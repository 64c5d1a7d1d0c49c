"""Engine packings (ORM, HDRP mask) and the glTF path: a bake with For glTF, exported by
Blender's own glTF exporter, is valid to the Khronos glTF validator (node, gltf-validator from
scripts/install_deps.sh), and its occlusionTexture's R and its COLOR_0 hold the baked AO."""
import json
import os
import shutil
import struct
import subprocess

import bpy
import numpy as np
import pytest

import helpers_materials as H
from canopy_ao.blender import properties
from canopy_ao.blender.job import run_bake
from canopy_ao.core.native import CanopyAOError

HERE = os.path.dirname(os.path.abspath(__file__))
VALIDATOR = os.path.join(os.environ.get("CANOPY_AO_NPM", "/var/cache/canopy-ao/npm"),
                         "node_modules", "gltf-validator")
RES = 32
BYTE = 0.5 / 255 + 1e-6  # one 8-bit rounding (the exporter writes PNG)


@pytest.fixture
def tree(tmp_path):
    """A UV-mapped ground (Ground, a material of the user's) under a sphere of leaves."""
    H.empty_scene()
    ground = H.add_plane(size=6.0, subdivisions=5, name="Ground")
    H.add_material(ground)
    bpy.ops.mesh.primitive_uv_sphere_add(segments=16, ring_count=8, radius=1.2,
                                         location=(0, 0, 1.6))
    return H.leaves_over_ground(ground, bpy.context.object, tmp_path)


def opts(t, **kw):
    base = dict(properties.scene_options(bpy.context.scene), method="ellipsoid", tau=2.0,
                distance=0.0, show_proxies=False, image_dir=t["image_dir"], resolution=RES)
    base.update(kw)
    return base


def _pixels(image):
    buf = np.empty(image.size[0] * image.size[1] * image.channels, np.float32)
    image.pixels.foreach_get(buf)
    return buf.reshape(-1, image.channels)


def _orm(name, res=RES):
    """A user's ORM texture: roughness and metallic noise in G and B, alpha 1."""
    img = bpy.data.images.new(name, res, res, alpha=True, float_buffer=True)
    vals = np.random.default_rng(3).random((res * res, 4)).astype(np.float32)
    img.pixels.foreach_set(vals.ravel())
    return img, _pixels(img)


def _grey(t):
    """The Ground's grey texel AO (its image's R), baked as it is by default."""
    _job, rep = run_bake(bpy.context, ["Ground"], opts(t, mode='TEXEL'))
    return _pixels(bpy.data.images.load(rep["objects"]["Ground"]["texel"]["path"],
                                        check_existing=False))[:, 0]


def test_packing_presets_write_their_channel_only(tree):
    grey = _grey(tree)
    assert grey.min() < 0.9  # the crown shades the ground
    for packing, c in (("ORM", 0), ("HDRP_MASK", 1)):
        img, before = _orm("Packed" + packing)
        r = bpy.ops.canopy_ao.bake(objects="Ground", mode='TEXEL', packing=packing,
                                   pack_image=img.name, method="ellipsoid", tau=2.0,
                                   distance=0.0, show_proxies=False, resolution=RES,
                                   image_dir=tree["image_dir"])
        assert r == {'FINISHED'}
        after = _pixels(img)
        keep = [k for k in range(4) if k != c]
        assert np.array_equal(after[:, keep].view(np.uint32), before[:, keep].view(np.uint32))
        assert np.abs(after[:, c] - grey).max() <= 1e-6


def test_packing_refusals_name_the_image_and_change_nothing(tree):
    t = tree
    with pytest.raises(CanopyAOError, match="Packing ORM per texel.*no image named 'Nope'"):
        run_bake(bpy.context, ["Ground"], opts(t, mode='TEXEL', packing="ORM",
                                               pack_image="Nope"))
    wide, before = _orm("Wide", RES)
    wide.scale(RES * 2, RES)
    before = _pixels(wide)
    with pytest.raises(CanopyAOError, match=r"Packing HDRP_MASK of 'Ground': image 'Wide' is "
                                            r"64×32 .*square image of Resolution texels"):
        run_bake(bpy.context, ["Ground"], opts(t, mode='TEXEL', packing="HDRP_MASK",
                                               pack_image="Wide"))
    assert np.array_equal(_pixels(wide), before)
    with pytest.raises(CanopyAOError, match="Packing ORM puts the AO in channel R, but "
                                            "Channel is G"):
        run_bake(bpy.context, ["Ground"], opts(t, mode='TEXEL', packing="ORM", channel="G",
                                               pack_image="Wide"))
    gone = bpy.data.images.new("Gone", RES, RES)
    gone.source = 'FILE'
    gone.filepath = os.path.join(t["image_dir"], "moved_away.png")
    with pytest.raises(CanopyAOError, match="image 'Gone' has no pixels .*moved_away.png"):
        run_bake(bpy.context, ["Ground"], opts(t, mode='TEXEL', packing="ORM",
                                               pack_image="Gone"))
    assert not os.path.exists(t["image_dir"]) or not os.listdir(t["image_dir"])
    mat = t["ground"].active_material
    assert not [n for n in mat.node_tree.nodes if n.get("canopy_ao")]


# === glTF export, validated


def _export(path, **kw):
    """bpy.ops.export_scene.gltf of the scene, vertex colours as the add-on documents: the
    render color attribute as COLOR_0 (4.2+: Use Vertex Color Active; 3.x: Colors)."""
    props = bpy.ops.export_scene.gltf.get_rna_type().properties.keys()
    if "export_vertex_color" in props:
        kw["export_vertex_color"] = 'ACTIVE'
    if "export_all_vertex_colors" in props:  # 5.x: on, its COLOR_0 is another attribute
        kw["export_all_vertex_colors"] = False
    else:
        kw["export_colors"] = True
    r = bpy.ops.export_scene.gltf(filepath=path, export_format='GLB', export_yup=False,
                                  export_apply=False, **kw)
    assert r == {'FINISHED'}


def _validate(path):
    """The Khronos validator's report on path; fails naming the fix when it is not installed,
    skips only where node itself is missing."""
    node = shutil.which("node") or shutil.which("nodejs")
    if node is None:
        pytest.skip("node is not installed here, so the Khronos glTF validator cannot run "
                    "(scripts/install_deps.sh installs nodejs)")
    assert os.path.isfile(os.path.join(VALIDATOR, "package.json")), \
        f"gltf-validator is not in {VALIDATOR}: run scripts/install_deps.sh"
    out = subprocess.run([node, os.path.join(HERE, "gltf_validate.js"), VALIDATOR, path],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout)
    errors = [m for m in report["issues"]["messages"] if m["severity"] == 0]
    assert report["issues"]["numErrors"] == 0, errors
    return report


def _glb(path):
    """(json, binary chunk) of a .glb."""
    with open(path, "rb") as f:
        data = f.read()
    magic, _version, _length = struct.unpack_from("<III", data, 0)
    assert magic == 0x46546C67
    n, _kind = struct.unpack_from("<II", data, 12)
    doc = json.loads(data[20:20 + n])
    m, _kind = struct.unpack_from("<II", data, 20 + n)
    return doc, data[28 + n:28 + n + m]


def _view(doc, blob, view):
    v = doc["bufferViews"][view]
    return blob[v.get("byteOffset", 0):v.get("byteOffset", 0) + v["byteLength"]]


def _accessor(doc, blob, index):
    """An accessor's values as float32 (count, components), normalized integers scaled to
    0-1, and half the step between two of its values (0 for floats)."""
    a = doc["accessors"][index]
    comps = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[a["type"]]
    dtype = {5126: np.float32, 5123: np.uint16, 5121: np.uint8}[a["componentType"]]
    raw = _view(doc, blob, a["bufferView"])[a.get("byteOffset", 0):]
    vals = np.frombuffer(raw, dtype, a["count"] * comps).reshape(-1, comps).astype(np.float32)
    if a.get("normalized"):
        vals /= np.iinfo(dtype).max
        return vals, 0.5 / np.iinfo(dtype).max
    return vals, 0.0


def _mesh_primitive(doc, name):
    node = next(n for n in doc["nodes"] if n.get("name") == name)
    return doc["meshes"][node["mesh"]]["primitives"]


@pytest.mark.parametrize("packing", ["NONE", "HDRP_MASK"])
def test_texel_bake_exports_as_a_valid_occlusion_texture(tree, tmp_path, packing):
    """The grey AO image, and the AO packed into G of a mask map, both reach the exported
    occlusionTexture's R (the exporter takes the channel our Separate Color node names)."""
    t = tree
    mat = t["ground"].active_material
    img = _orm("Mask")[0] if packing != "NONE" else None
    r = bpy.ops.canopy_ao.bake(objects="Ground", mode='TEXEL', gltf=True, method="ellipsoid",
                               tau=2.0, distance=0.0, show_proxies=False, resolution=RES,
                               image_dir=t["image_dir"], packing=packing,
                               pack_image=img.name if img else "")
    assert r == {'FINISHED'}
    baked = (_pixels(img)[:, 1] if img else
             _pixels(bpy.data.images["Ground_CanopyAO"])[:, 0])
    assert baked.min() < 0.9
    # The user's base colour is as it was: the occlusion wiring feeds only the glTF group.
    assert not mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"].is_linked
    path = str(tmp_path / "ground.glb")
    _export(path, use_selection=False)
    _validate(path)
    doc, blob = _glb(path)
    gmat = next(m for m in doc["materials"] if m["name"] == mat.name)
    occ = gmat["occlusionTexture"]
    png = _view(doc, blob, doc["images"][doc["textures"][occ["index"]]["source"]]["bufferView"])
    out = tmp_path / "occlusion.png"
    out.write_bytes(png)
    img = bpy.data.images.load(str(out))
    img.colorspace_settings.name = "Non-Color"  # the PNG's bytes as they are
    assert tuple(img.size) == (RES, RES)
    assert np.abs(_pixels(img)[:, 0] - baked).max() <= BYTE


def test_a_users_gltf_group_is_reused_and_its_occlusion_not_replaced(tree, tmp_path):
    t = tree
    mat = t["ground"].active_material
    nt = mat.node_tree
    group = bpy.data.node_groups.new("glTF Settings", "ShaderNodeTree")
    if hasattr(group, "interface"):
        group.interface.new_socket("Occlusion", in_out="INPUT", socket_type="NodeSocketFloat")
    else:
        group.inputs.new("NodeSocketFloat", "Occlusion")
    node = nt.nodes.new("ShaderNodeGroup")
    node.node_tree = group
    value = nt.nodes.new("ShaderNodeValue")
    nt.links.new(value.outputs[0], node.inputs["Occlusion"])
    before = H.tree_snapshot(mat)
    with pytest.raises(CanopyAOError, match="already feeds its Occlusion from 'Value'"):
        run_bake(bpy.context, ["Ground"], opts(t, mode='TEXEL', gltf=True))
    assert H.tree_snapshot(mat) == before
    nt.nodes.remove(value)
    run_bake(bpy.context, ["Ground"], opts(t, mode='TEXEL', gltf=True))
    groups = [n for n in nt.nodes if n.bl_idname == "ShaderNodeGroup"]
    assert groups == [node] and node.inputs["Occlusion"].is_linked
    assert "glTF Material Output" not in bpy.data.node_groups  # no second group made
    bpy.ops.canopy_ao.remove_wiring(objects="Ground")  # the wiring comes off again, the user's group stays
    assert [n for n in nt.nodes if n.bl_idname == "ShaderNodeGroup"] == [node]
    assert not node.inputs["Occlusion"].is_linked


def test_vertex_bake_in_a_channel_exports_as_color_0(tree, tmp_path):
    t = tree
    me = t["ground"].data
    paint = me.color_attributes.new("Paint", 'FLOAT_COLOR', 'POINT')
    base = np.random.default_rng(4).random((len(me.vertices), 4)).astype(np.float32)
    paint.data.foreach_set("color", base.ravel())
    me.color_attributes.new("Other", 'BYTE_COLOR', 'CORNER')
    me.color_attributes.render_color_index = me.color_attributes.find("Other")
    r = bpy.ops.canopy_ao.bake(objects="Ground", attribute="Paint", packing="ORM", gltf=True,
                               method="ellipsoid", tau=2.0, distance=0.0, show_proxies=False)
    assert r == {'FINISHED'}
    assert me.color_attributes[me.color_attributes.render_color_index].name == "Paint"
    colors = np.empty(len(me.vertices) * 4, np.float32)
    me.color_attributes["Paint"].data.foreach_get("color", colors)
    colors = colors.reshape(-1, 4)
    assert np.array_equal(colors[:, 1:], base[:, 1:]) and colors[:, 0].min() < 0.9
    path = str(tmp_path / "ground.glb")
    _export(path, use_selection=False)
    _validate(path)
    doc, blob = _glb(path)
    prims = _mesh_primitive(doc, "Ground")
    pos = np.concatenate([_accessor(doc, blob, p["attributes"]["POSITION"])[0] for p in prims])
    cols = [_accessor(doc, blob, p["attributes"]["COLOR_0"]) for p in prims]
    col = np.concatenate([c for c, _half in cols])
    half = max(h for _c, h in cols)  # 8- or 16-bit where an exporter writes integers
    verts = np.empty(len(me.vertices) * 3, np.float32)
    me.vertices.foreach_get("co", verts)
    verts = verts.reshape(-1, 3)
    nearest = np.argmin(((pos[:, None, :] - verts[None]) ** 2).sum(-1), axis=1)
    assert np.abs(pos - verts[nearest]).max() < 1e-5
    # COLOR_0 is the attribute's channels (RGB or RGBA): the AO in R beside the user's own.
    assert np.abs(col - colors[nearest, :col.shape[1]]).max() <= half + 1e-6


def test_cli_packing_as_the_readme_spells_it(tree, capsys):
    """--packing hdrp-mask --pack-image NAME on the command line: AO in G only; a channel
    that contradicts the preset exits 1 with both named, the image untouched."""
    from canopy_ao import cli
    img, before = _orm("Mask")
    base = ["--objects", "Ground", "--mode", "texel", "--resolution", str(RES), "--method",
            "ellipsoid", "--tau", "2", "--distance", "0", "--no-proxies",
            "--image-dir", tree["image_dir"], "--pack-image", "Mask"]
    with pytest.raises(SystemExit) as exc:
        cli.main(base + ["--packing", "orm", "--channel", "b"])
    assert exc.value.code == 1
    assert "Packing ORM puts the AO in channel R, but Channel is B" in capsys.readouterr().err
    assert np.array_equal(_pixels(img), before)
    with pytest.raises(SystemExit) as exc:
        cli.main(base + ["--packing", "hdrp-mask"])
    assert exc.value.code == 0, capsys.readouterr().err
    after = _pixels(img)
    assert np.array_equal(after[:, [0, 2, 3]], before[:, [0, 2, 3]])
    assert not np.array_equal(after[:, 1], before[:, 1])


def test_a_failed_bake_leaves_no_gltf_wiring(tree, monkeypatch):
    """A failure after the occlusion wiring rolls it back: the material as it was, no glTF
    node group left, and per vertex the render color attribute as it was."""
    from canopy_ao.blender import gltf_io
    t = tree
    mat = t["ground"].active_material
    before = H.tree_snapshot(mat)
    real = gltf_io.wire_occlusion

    def wire_then_fail(*args):
        real(*args)
        raise RuntimeError("disk full")
    monkeypatch.setattr(gltf_io, "wire_occlusion", wire_then_fail)
    with pytest.raises(RuntimeError, match="disk full"):
        run_bake(bpy.context, ["Ground"], opts(t, mode='TEXEL', gltf=True))
    assert H.tree_snapshot(mat) == before
    assert not [g for g in bpy.data.node_groups if g.name.startswith("glTF")]
    me = t["ground"].data
    me.color_attributes.new("Other", 'BYTE_COLOR', 'CORNER')
    me.color_attributes.new("Paint", 'FLOAT_COLOR', 'POINT')  # kept by the rollback
    me.color_attributes.render_color_index = me.color_attributes.find("Other")
    real_set = gltf_io.set_color_export

    def set_then_fail(*args):
        real_set(*args)
        raise RuntimeError("disk full")
    monkeypatch.setattr(gltf_io, "set_color_export", set_then_fail)
    with pytest.raises(RuntimeError, match="disk full"):
        run_bake(bpy.context, ["Ground"], opts(t, gltf=True, attribute="Paint", channel="R"))
    assert me.color_attributes[me.color_attributes.render_color_index].name == "Other"


@pytest.mark.parametrize("flag", [["--gltf"], ["--packing", "orm"]])
def test_frame_range_bake_refuses_gltf_and_packing(tree, capsys, flag):
    from canopy_ao import cli
    with pytest.raises(SystemExit) as exc:
        cli.main(["--objects", "Ground", "--method", "ellipsoid", "--tau", "2", "--no-proxies",
                  "--frames", "1", "2"] + flag)
    assert exc.value.code == 1
    assert "For glTF and Packing are for single bakes" in capsys.readouterr().err
    assert not [a for a in tree["ground"].data.attributes if a.name.startswith("CanopyAO")]
