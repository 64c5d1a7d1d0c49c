"""The AOV written by wire_vertex_ao reaches the compositor with the baked values (docs/DESIGN.md,
'Facts measured in Blender').

Headless, Render Result / Viewer pixels cannot be read; a compositor File Output node writes the
pass to EXR and we load it back.
"""
import math

import bpy
import numpy as np
import pytest

import helpers_materials as H
from canopy_ao.blender import materials

AO_VALUE = 0.37


@pytest.fixture
def scene():
    return H.empty_scene()


def _compositor_tree(scene):
    """The scene's compositor node tree: Blender 5.x keeps it in a node group
    (scene.compositing_node_group), earlier versions in scene.node_tree (after use_nodes)."""
    if hasattr(scene, "compositing_node_group"):
        tree = bpy.data.node_groups.new("CanopyAOTestCompositor", "CompositorNodeTree")
        scene.compositing_node_group = tree
        return tree
    scene.use_nodes = True
    return scene.node_tree


def _render_aov(scene, aov_name, tmp_path):
    scene.render.engine = "CYCLES"
    scene.cycles.samples = 4
    scene.cycles.use_denoising = False
    scene.cycles.use_adaptive_sampling = False
    scene.cycles.device = "CPU"
    scene.render.resolution_x = 16
    scene.render.resolution_y = 16
    scene.render.resolution_percentage = 100
    scene.render.filter_size = 0.01  # no pixel filter blur across the object's edge
    if hasattr(scene.render, "compositor_device"):  # 4.2+: headless there is no GPU to use
        scene.render.compositor_device = "CPU"
    tree = _compositor_tree(scene)
    tree.nodes.clear()
    rl = tree.nodes.new("CompositorNodeRLayers")
    out = tree.nodes.new("CompositorNodeOutputFile")
    if hasattr(out.format, "media_type"):  # Blender 5.x: single-layer EXR is an IMAGE
        out.format.media_type = "IMAGE"
    out.format.file_format = "OPEN_EXR"
    out.format.color_depth = "32"
    if hasattr(out, "file_output_items"):  # Blender 5.x: directory, file name, items
        out.directory = str(tmp_path)
        out.file_name = "aov_"
        out.file_output_items.new("RGBA", "ao")
    else:  # up to 4.x: base path and file slots
        out.base_path = str(tmp_path)
        out.file_slots[0].path = "aov_"
    tree.links.new(rl.outputs[aov_name], out.inputs[0])
    bpy.ops.render.render(write_still=False)
    written = sorted(tmp_path.glob("aov_*.exr"))
    assert len(written) == 1, f"File Output wrote {written} in {tmp_path}"
    path = written[0]
    img = bpy.data.images.load(str(path))
    px = np.empty(16 * 16 * 4, dtype=np.float32)
    img.pixels.foreach_get(px)
    bpy.data.images.remove(img)
    return px.reshape(16, 16, 4)


def _camera_looking_down(scene, ortho_scale):
    cam_data = bpy.data.cameras.new("Cam")
    cam_data.type = "ORTHO"
    cam_data.ortho_scale = ortho_scale
    cam = bpy.data.objects.new("Cam", cam_data)
    cam.location = (0, 0, 5)  # default camera orientation looks down -Z
    scene.collection.objects.link(cam)
    scene.camera = cam


def test_aov_pass_reads_baked_value(scene, tmp_path):
    obj = H.add_plane(size=2.0)
    H.add_material(obj)
    H.set_point_color(obj, "CanopyAO", AO_VALUE)
    materials.wire_vertex_ao(obj, "CanopyAO", aov_name="BakedAO")
    materials.ensure_view_layer_aov(scene, "BakedAO")
    _camera_looking_down(scene, ortho_scale=4.0)  # plane covers the centre half of the frame
    px = _render_aov(scene, "BakedAO", tmp_path)
    centre = px[5:11, 5:11, 0]
    corners = np.array([px[0, 0, 0], px[0, -1, 0], px[-1, 0, 0], px[-1, -1, 0]])
    assert np.allclose(centre, AO_VALUE, atol=1e-3), centre
    assert np.allclose(corners, 0.0, atol=1e-3), corners


def test_ensure_view_layer_aov_idempotent(scene):
    a = materials.ensure_view_layer_aov(scene, "BakedAO")
    b = materials.ensure_view_layer_aov(scene, "BakedAO")
    assert len(scene.view_layers[0].aovs) == 1
    assert a[0].name == b[0].name == "BakedAO"
    assert a[0].type == "VALUE"
    assert materials.remove_view_layer_aov(scene, "BakedAO") == 1
    assert len(scene.view_layers[0].aovs) == 0


def test_aov_named_ao_refused(scene):
    obj = H.add_plane()
    with pytest.raises(ValueError, match="collides"):
        materials.ensure_view_layer_aov(scene, "AO")
    with pytest.raises(ValueError, match="BakedAO"):
        materials.wire_vertex_ao(obj, "CanopyAO", aov_name="AO")
    assert len(scene.view_layers[0].aovs) == 0
    assert len(obj.material_slots) == 0  # refused before anything changed
