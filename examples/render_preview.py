"""Render a baked scene headless to PNG, showing the baked AO (or the lit, AO-multiplied look).

    blender -b scene.blend --python examples/render_preview.py -- --out preview.png
        [--attribute CanopyAO] [--look ao|shaded] [--size 800 600] [--samples 16]

`ao` (default) overrides every material with an emission shader reading the colour attribute,
so the picture is the AO itself (white = open sky). `shaded` renders the scene's own materials
(with the AO wired into them by `--wire-material`) under a sun and sky. Cycles, CPU: works
without a display. Exits non-zero with a message on failure.
"""
import argparse
import math
import os
import sys

import bpy
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from mathutils import Vector


def scene_bounds(objects):
    lo = Vector((math.inf,) * 3)
    hi = Vector((-math.inf,) * 3)
    for ob in objects:
        for corner in ob.bound_box:
            w = ob.matrix_world @ Vector(corner)
            lo = Vector(map(min, lo, w))
            hi = Vector(map(max, hi, w))
    return lo, hi


def frame_camera(scene, objects, width, height):
    lo, hi = scene_bounds(objects)
    centre = (lo + hi) / 2
    radius = max((hi - lo).length / 2, 1e-6)
    cam_data = bpy.data.cameras.new("CanopyAO_PreviewCam")
    cam_data.lens = 50
    cam = bpy.data.objects.new("CanopyAO_PreviewCam", cam_data)
    scene.collection.objects.link(cam)
    fov = 2 * math.atan(cam_data.sensor_width / (2 * cam_data.lens))
    fov = min(fov, fov * height / width) if width >= height else fov
    dist = radius / math.sin(fov / 2) * 1.05
    direction = Vector((1.0, -1.4, 0.55)).normalized()
    cam.location = centre + direction * dist
    cam.rotation_euler = (-direction).to_track_quat("-Z", "Y").to_euler()
    cam_data.clip_end = dist * 4
    scene.camera = cam


def ao_override(attribute):
    mat = bpy.data.materials.new("CanopyAO_PreviewAO")
    mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    attr = nt.nodes.new("ShaderNodeVertexColor")
    attr.layer_name = attribute
    emit = nt.nodes.new("ShaderNodeEmission")
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    nt.links.new(attr.outputs["Color"], emit.inputs["Color"])
    nt.links.new(emit.outputs["Emission"], out.inputs["Surface"])
    return mat


def main(argv):
    ap = argparse.ArgumentParser(prog="render_preview.py")
    ap.add_argument("--out", required=True)
    ap.add_argument("--attribute", default="CanopyAO")
    ap.add_argument("--look", choices=("ao", "shaded"), default="ao")
    ap.add_argument("--size", type=int, nargs=2, default=(800, 600))
    ap.add_argument("--samples", type=int, default=16)
    a = ap.parse_args(argv)

    scene = bpy.context.scene
    meshes = [o for o in scene.objects if o.type == "MESH" and not o.hide_render]
    if not meshes:
        raise RuntimeError("the scene has no visible mesh objects to render")
    baked = [o for o in meshes if a.attribute in o.data.color_attributes]
    if a.look == "ao" and not baked:
        raise RuntimeError(f"no object has a colour attribute named '{a.attribute}': bake first")

    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = a.samples
    scene.cycles.use_denoising = False  # Debian's build has no OpenImageDenoise
    scene.render.resolution_x, scene.render.resolution_y = a.size
    scene.render.resolution_percentage = 100
    scene.render.image_settings.file_format = "PNG"
    scene.render.filepath = os.path.abspath(a.out)
    scene.view_settings.view_transform = "Standard"
    # Frame the vegetation, not a ground plane that may be many times larger.
    role = lambda o: o.get("canopy_ao_role") or getattr(getattr(o, "canopy_ao", None), "role", "")
    subjects = [o for o in meshes if str(role(o)).lower() != "ground"] or meshes
    frame_camera(scene, subjects, *a.size)

    if scene.world is None:
        scene.world = bpy.data.worlds.new("CanopyAO_PreviewWorld")
    scene.world.use_nodes = True
    bg = scene.world.node_tree.nodes.get("Background")
    if a.look == "ao":
        # The AO itself: emission only, no lighting, black background.
        scene.view_layers[0].material_override = ao_override(a.attribute)
        scene.cycles.max_bounces = 0
        if bg:
            bg.inputs["Color"].default_value = (0.02, 0.02, 0.025, 1)
    else:
        if bg:
            bg.inputs["Color"].default_value = (0.6, 0.7, 0.9, 1)
            bg.inputs["Strength"].default_value = 1.0
        sun = bpy.data.objects.new("CanopyAO_PreviewSun", bpy.data.lights.new("Sun", "SUN"))
        sun.data.energy = 3.0
        sun.rotation_euler = (math.radians(40), 0, math.radians(30))
        scene.collection.objects.link(sun)
    # No machine paths in the picture: Blender stamps the .blend's path into the PNG's text.
    scene.render.use_stamp_filename = False
    bpy.ops.render.render(write_still=True)
    print(f"render_preview: wrote {a.out} ({a.look}, {len(baked)} baked objects)")
    return 0


if __name__ == "__main__":
    from blender_script import run
    run(main, "render_preview")
