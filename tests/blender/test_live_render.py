"""Live AO in an animation render (``blender -b … -a`` with the CLI's --live): every rendered
frame shows that frame's geometry and that frame's AO, pixel for pixel what a full bake of the
frame renders (issue #36, item 1)."""

import os
import subprocess

import bpy
import numpy as np
import pytest

from conftest import _clear_scene, add_oak_scene, add_wind_key
from canopy_ao.blender import live, mesh_io, properties
from canopy_ao.blender.job import run_bake

ROLES = {"Trunk": 'TRUNK', "Leaves": 'CANOPY', "Ground": 'GROUND', "Grass": 'GRASS'}
LIVE_ARGS = ["--method", "ellipsoid", "--tau", "1.7", "--no-proxies"]
# 8-bit PNGs of the same scene, seed and samples: equal up to one step of rounding.
PIXEL_TOL = 1.5 / 255


def held_at_first_frame(scene, opts):
    """{name: AO factor}: what a live bake at frame 1 with opts holds of a ground alone
    (core/live.held_ground), as a live session started there holds it."""
    from test_live import held_ground
    scene.frame_set(1)
    run_bake(bpy.context, [], dict(opts, live=True))
    live.stop(scene)
    return held_ground(scene)


def bake_as_a_live_frame(opts, held):
    """A full bake of this frame (not live) lit as a live frame is: patches only where a wall
    is (core/walls.py), the ground alone's occlusion ``held`` from the first frame."""
    from canopy_ao.core import walls
    build = walls.build
    walls.build = lambda items: (lambda pt: pt if walls.has_wall(pt) else [])(build(items))
    try:
        run_bake(bpy.context, [], opts)
    finally:
        walls.build = build
    for name, factor in held.items():
        ob = bpy.context.scene.objects[name]
        ao = mesh_io.read_ao_attribute(ob, opts["attribute"])
        mesh_io.write_ao_attribute(ob, opts["attribute"], ao * factor, overwrite=True)


def _deforming_tree(how, persistent=False):
    """The tree scene, its leaves deformed over frames 1-3 by a keyed shape key or a keyed
    Simple Deform (bend); leaves and ground show CanopyAO through an emission material; a
    32-pixel Cycles render at 1 sample with a transparent film (the alpha is the silhouette)."""
    _clear_scene()
    scene = bpy.context.scene
    add_oak_scene(ROLES)
    leaves = scene.objects["Leaves"]
    if how == "shape_key":
        add_wind_key(leaves, 0.6, 3)
    else:
        bend = leaves.modifiers.new("Bend", 'SIMPLE_DEFORM')
        bend.deform_method, bend.deform_axis = 'BEND', 'Y'
        for frame, angle in ((1, 0.0), (3, 1.2)):
            bend.angle = angle
            bend.keyframe_insert("angle", frame=frame)
    mat = bpy.data.materials.new("AOView")
    mat.use_nodes = True
    nodes = mat.node_tree.nodes
    nodes.clear()
    attr = nodes.new("ShaderNodeAttribute")
    attr.attribute_name = "CanopyAO"
    emit, out = nodes.new("ShaderNodeEmission"), nodes.new("ShaderNodeOutputMaterial")
    mat.node_tree.links.new(attr.outputs["Color"], emit.inputs["Color"])
    mat.node_tree.links.new(emit.outputs[0], out.inputs[0])
    for name in ("Leaves", "Ground"):
        scene.objects[name].data.materials.append(mat)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(cam)
    cam.location, cam.rotation_euler = (0.0, -12.0, 3.0), (1.45, 0.0, 0.0)
    scene.camera = cam
    scene.render.engine = 'CYCLES'
    scene.cycles.samples, scene.cycles.use_denoising = 1, False  # no OIDN in Debian
    scene.render.film_transparent = True
    scene.render.use_persistent_data = persistent
    scene.render.resolution_x = scene.render.resolution_y = 32
    scene.render.image_settings.file_format = 'PNG'
    scene.view_settings.view_transform = 'Standard'
    scene.frame_start, scene.frame_end = 1, 3
    scene.frame_set(1)
    return scene


def _pixels(path):
    img = bpy.data.images.load(path)
    try:
        return np.array(img.pixels[:], np.float32).reshape(img.size[1], img.size[0], -1)
    finally:
        bpy.data.images.remove(img)


@pytest.mark.parametrize("how, persistent, armed", [
    ("shape_key", False, False), ("simple_deform", False, False), ("shape_key", True, False),
    ("simple_deform", False, True)])
def test_an_animation_render_with_live_ao_shows_each_frames_geometry_and_ao(
        how, persistent, armed, tmp_path, user_scripts):
    """Through the CLI's --live, or (armed) a file saved with live AO on rendered with no
    add-on arguments (a farm task re-arming from the file's record)."""
    scene = _deforming_tree(how, persistent)
    path = str(tmp_path / "anim.blend")
    env = dict(os.environ, BLENDER_USER_SCRIPTS=user_scripts)
    if armed:
        run_bake(bpy.context, [], dict(properties.scene_options(scene), method="ellipsoid",
                                       tau=1.7, show_proxies=False, live=True))
        bpy.ops.wm.save_as_mainfile(filepath=path, copy=True)
        live.stop(scene)
        cmd = ["blender", "-b", "--factory-startup", "--addons", "canopy_ao", path,
               "-o", str(tmp_path / "live_"), "-a"]
    else:
        bpy.ops.wm.save_as_mainfile(filepath=path, copy=True)
        cmd = ["blender", "-b", "--factory-startup", path, "--python-exit-code", "1",
               "--python-expr", "import canopy_ao.cli; canopy_ao.cli.main()",
               "-o", str(tmp_path / "live_"), "-a", "--", "--live"] + LIVE_ARGS
    out = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "canopy_ao: error" not in out.stderr, out.stderr
    assert "canopy_ao: warning" not in out.stderr, out.stderr  # nothing a frame could keep
    # The reference: each frame baked in full (same rung and τ, not live, but with a live
    # frame's GROUND rule, core/live.held_ground) and rendered here.
    opts = dict(properties.scene_options(scene), method="ellipsoid", tau=1.7,
                show_proxies=False, live=False)
    first = _pixels(str(tmp_path / "live_0001.png"))
    held = held_at_first_frame(scene, opts)
    try:
        for frame in (1, 2, 3):
            scene.frame_set(frame)
            bake_as_a_live_frame(opts, held)
            scene.render.filepath = str(tmp_path / f"full_{frame}.png")
            bpy.ops.render.render(write_still=True)
            want = _pixels(str(tmp_path / f"full_{frame}.png"))
            got = _pixels(str(tmp_path / f"live_{frame:04d}.png"))
            np.testing.assert_allclose(got[..., 3], want[..., 3], atol=PIXEL_TOL,
                                       err_msg=f"{how}: silhouette at frame {frame}")
            np.testing.assert_allclose(got[..., :3], want[..., :3], atol=PIXEL_TOL,
                                       err_msg=f"{how}: AO at frame {frame}")
        # The test means something: the leaves moved on screen between frames 1 and 3.
        assert np.abs(got[..., 3] - first[..., 3]).max() > 0.5
    finally:
        live.stop(bpy.context.scene)
        _clear_scene()


def test_renders_started_in_a_window_follow_the_frame(user_scripts):
    """In a real window (Xvfb): Ctrl+F12 with Lock Interface on and F12 with it off render each
    frame as a full bake of it renders (ui_live_render.py). Skipped without xvfb-run."""
    from ui_harness import run_in_window
    run_in_window(os.path.join(os.path.dirname(__file__), "ui_live_render.py"), user_scripts)


def test_a_render_leaves_the_files_meshes_alone_also_for_a_target_it_does_not_render(
        tmp_path):
    """A live target disabled in renders is not in the render's depsgraph (evaluated_get gives
    the original): the render writes nothing into it, and live AO goes on without an error."""
    scene = _deforming_tree("shape_key")
    try:
        opts = dict(properties.scene_options(scene), method="ellipsoid", tau=1.7,
                    show_proxies=False, live=True)
        run_bake(bpy.context, ["Trunk", "Leaves", "Ground", "Grass"], opts)
        grass = scene.objects["Grass"]
        before = mesh_io.read_ao_attribute(grass, "CanopyAO")
        grass.hide_render = True
        seen = []

        def after_live(sc, depsgraph=None):  # runs after live AO's handler (added later)
            if depsgraph is not None and depsgraph.mode == 'RENDER':
                seen.append(np.abs(mesh_io.read_ao_attribute(grass, "CanopyAO")
                                   - before).max())
        bpy.app.handlers.frame_change_post.append(after_live)
        try:
            scene.frame_current = 3  # the render's frame change only
            scene.render.filepath = str(tmp_path / "still.png")
            bpy.ops.render.render(write_still=True)
        finally:
            bpy.app.handlers.frame_change_post.remove(after_live)
        assert seen == [0.0]
        assert scene.canopy_ao.live, scene.canopy_ao.last_report
    finally:
        live.stop(bpy.context.scene)
        _clear_scene()


def test_a_keyed_target_whose_geometry_the_keys_do_not_change_is_named(tmp_path, capsys):
    """A target with only its transform keyed is written into the render's copy (a tag would
    reset its keyed transform), which an engine that redraws only updated meshes (Cycles with
    Persistent Data here) may keep: the render names it once."""
    scene = _deforming_tree("shape_key", persistent=True)
    try:
        run_bake(bpy.context, [], dict(properties.scene_options(scene), method="ellipsoid",
                                       tau=1.7, show_proxies=False, live=True))
        ground = scene.objects["Ground"]
        for frame, z in ((1, 0.0), (3, 0.01)):
            ground.location.z = z
            ground.keyframe_insert("location", index=2, frame=frame)
        capsys.readouterr()
        scene.frame_current = 2
        scene.render.filepath = str(tmp_path / "still.png")
        bpy.ops.render.render(write_still=True)
        err = capsys.readouterr().err
        assert "canopy_ao: warning: Ground: keyed" in err, err
        assert "Leaves" not in err  # its shape key re-evaluates it every frame
    finally:
        live.stop(bpy.context.scene)
        _clear_scene()
