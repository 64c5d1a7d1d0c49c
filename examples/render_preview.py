"""Render a baked scene headless to PNG, showing the baked AO (or the lit, AO-multiplied look).

    blender -b scene.blend --python examples/render_preview.py -- --out preview.png
        [--attribute CanopyAO] [--look ao|shaded] [--size 800 600] [--samples 16]
        [--frame OBJECT ...] [--view X Y Z] [--margin 1.05] [--background R G B] [--raw] [--grey]

`ao` (default) makes every material an emission shader reading the colour attribute, so the
picture is the AO itself (white = open sky); a material's alpha is kept (a Principled BSDF's
Alpha, a Mix Shader with a Transparent BSDF), so leaf cards are cut out as Cycles renders them.
`--raw`: a pixel is the AO value (Raw view; by default Standard, sRGB-encoded); `--grey`: one
grey channel, a third of the file. `shaded` renders the scene's own materials (with the AO
wired into them by `--wire-material`) under a sun and sky. The camera frames `--frame`'s
objects (default: every mesh but the ground) from direction `--view`. Cycles, CPU: works
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


def frame_camera(scene, objects, width, height, view=(1.0, -1.4, 0.55), margin=1.05):
    lo, hi = scene_bounds(objects)
    centre = (lo + hi) / 2
    radius = max((hi - lo).length / 2, 1e-6)
    cam_data = bpy.data.cameras.new("CanopyAO_PreviewCam")
    cam_data.lens = 50
    cam = bpy.data.objects.new("CanopyAO_PreviewCam", cam_data)
    scene.collection.objects.link(cam)
    fov = 2 * math.atan(cam_data.sensor_width / (2 * cam_data.lens))
    fov = min(fov, fov * height / width) if width >= height else fov
    dist = radius / math.sin(fov / 2) * margin
    direction = Vector(view).normalized()
    cam.location = centre + direction * dist
    cam.rotation_euler = (-direction).to_track_quat("-Z", "Y").to_euler()
    cam_data.clip_end = dist * 4
    scene.camera = cam


def ao_emission(nt, attribute):
    """An Emission node in node tree ``nt`` whose colour is the colour attribute."""
    attr = nt.nodes.new("ShaderNodeVertexColor")
    attr.layer_name = attribute
    emit = nt.nodes.new("ShaderNodeEmission")
    nt.links.new(attr.outputs["Color"], emit.inputs["Color"])
    return emit


def ao_cutout(mat, attribute):
    """Make ``mat`` show the AO as its emission where it is opaque and stay transparent where
    its alpha cuts it (leaf cards), as Cycles renders it: each shader reaching the Cycles
    output becomes the AO's emission, a Principled BSDF's mixed with a Transparent BSDF by its
    Alpha; Mix Shaders and Transparent BSDFs stay."""
    nt = mat.node_tree
    out = nt.get_output_node("CYCLES")
    if out is None:
        out = nt.nodes.new("ShaderNodeOutputMaterial")
    emit = ao_emission(nt, attribute)

    def shade(socket):
        node = socket.links[0].from_node if socket.is_linked else None
        if node is not None and node.type == "MIX_SHADER":
            for sub in node.inputs[1:3]:
                shade(sub)
            return
        if node is not None and node.type == "BSDF_TRANSPARENT":
            return
        target = emit.outputs[0]
        alpha = node.inputs.get("Alpha") if node is not None and node.type == "BSDF_PRINCIPLED" \
            else None
        if alpha is not None and (alpha.is_linked or alpha.default_value < 1.0):
            mix = nt.nodes.new("ShaderNodeMixShader")
            if alpha.is_linked:
                nt.links.new(alpha.links[0].from_socket, mix.inputs[0])
            else:
                mix.inputs[0].default_value = alpha.default_value
            nt.links.new(nt.nodes.new("ShaderNodeBsdfTransparent").outputs[0], mix.inputs[1])
            nt.links.new(emit.outputs[0], mix.inputs[2])
            target = mix.outputs[0]
        nt.links.new(target, socket)

    shade(out.inputs["Surface"])


def ao_override(attribute):
    """A material that is the colour attribute's emission alone."""
    mat = bpy.data.materials.new("CanopyAO_PreviewAO")
    mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    nt.links.new(ao_emission(nt, attribute).outputs["Emission"], out.inputs["Surface"])
    return mat


def show_ao(objects, attribute):
    """Every object shows the colour attribute as emission: its node materials through
    ao_cutout (their alpha kept), other slots and objects without a material through one
    plain AO material."""
    plain = ao_override(attribute)
    done = set()
    for ob in objects:
        if not ob.material_slots:
            ob.data.materials.append(plain)
        for slot in ob.material_slots:
            mat = slot.material
            if mat is None or not mat.use_nodes or mat.node_tree is None:
                slot.material = plain
            elif mat.name_full not in done and mat is not plain:
                ao_cutout(mat, attribute)
                done.add(mat.name_full)


def main(argv):
    ap = argparse.ArgumentParser(prog="render_preview.py")
    ap.add_argument("--out", required=True)
    ap.add_argument("--attribute", default="CanopyAO")
    ap.add_argument("--look", choices=("ao", "shaded"), default="ao")
    ap.add_argument("--size", type=int, nargs=2, default=(800, 600))
    ap.add_argument("--samples", type=int, default=16)
    ap.add_argument("--frame", nargs="+", metavar="OBJECT",
                    help="frame these objects (default: every mesh but the ground)")
    ap.add_argument("--view", type=float, nargs=3, default=(1.0, -1.4, 0.55),
                    help="the direction from the framed objects to the camera")
    ap.add_argument("--margin", type=float, default=1.05,
                    help="camera distance over the one that just fits their bounding sphere")
    ap.add_argument("--background", type=float, nargs=3, default=(0.02, 0.02, 0.025),
                    metavar=("R", "G", "B"), help="the ao look's background colour (linear)")
    ap.add_argument("--grey", action="store_true",
                    help="write one grey channel (AO and thickness are grey): a smaller file")
    ap.add_argument("--raw", action="store_true",
                    help="pixels are the AO values (Raw view), not sRGB-encoded (Standard)")
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
    # Opaque film: no alpha channel to store; the smallest file zlib makes (pictures for docs).
    scene.render.image_settings.color_mode = "BW" if a.grey else "RGB"
    scene.render.image_settings.compression = 100
    scene.render.filepath = os.path.abspath(a.out)
    scene.view_settings.view_transform = "Raw" if a.raw else "Standard"
    # Frame the vegetation, not a ground plane that may be many times larger.
    role = lambda o: o.get("canopy_ao_role") or getattr(getattr(o, "canopy_ao", None), "role", "")
    subjects = [o for o in meshes if str(role(o)).lower() != "ground"] or meshes
    if a.frame:
        missing = [n for n in a.frame if n not in scene.objects]
        if missing:
            raise RuntimeError(f"--frame: no object named {', '.join(missing)}")
        subjects = [scene.objects[n] for n in a.frame]
    frame_camera(scene, subjects, *a.size, view=a.view, margin=a.margin)

    if scene.world is None:
        scene.world = bpy.data.worlds.new("CanopyAO_PreviewWorld")
    scene.world.use_nodes = True
    bg = scene.world.node_tree.nodes.get("Background")
    if a.look == "ao":
        # The AO itself: emission only, no lighting, a plain background.
        show_ao(meshes, a.attribute)
        scene.cycles.max_bounces = 0
        if bg:
            bg.inputs["Color"].default_value = (*a.background, 1)
    else:
        if bg:
            bg.inputs["Color"].default_value = (0.6, 0.7, 0.9, 1)
            bg.inputs["Strength"].default_value = 1.0
        sun = bpy.data.objects.new("CanopyAO_PreviewSun", bpy.data.lights.new("Sun", "SUN"))
        sun.data.energy = 3.0
        sun.rotation_euler = (math.radians(40), 0, math.radians(30))
        scene.collection.objects.link(sun)
    # No machine paths, dates or timings in the picture's PNG text (Blender stamps them): the
    # same scene gives the same bytes.
    scene.render.use_stamp_filename = False
    scene.render.use_stamp_date = scene.render.use_stamp_time = False
    scene.render.use_stamp_render_time = False
    bpy.ops.render.render(write_still=True)
    print(f"render_preview: wrote {a.out} ({a.look}, {len(baked)} baked objects)")
    return 0


if __name__ == "__main__":
    from blender_script import run
    run(main, "render_preview")
