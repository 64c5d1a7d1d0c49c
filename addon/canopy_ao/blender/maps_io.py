"""Maps beyond a grey AO attribute (docs/DESIGN.md, 'Maps'): a value into one channel of an
existing color attribute or image, leaving the other channels bit-identical, and the canopy
thickness wired into materials as a render pass.

Ownership is mesh_io's: an attribute Canopy AO did not make is written only when the user asks,
and then only into the chosen channel; naming the channel is that ask.
"""

import numpy as np

from . import materials, mesh_io
from .mesh_io import MeshIOError

CHANNELS = "RGBA"
# Color attributes whose channels can be written without touching the others: FLOAT_COLOR
# through "color" (raw floats), BYTE_COLOR through "color_srgb" (the stored bytes / 255, no
# colour conversion, so an unchanged byte reads and writes back as itself).
_KEY = {'FLOAT_COLOR': "color", 'BYTE_COLOR': "color_srgb"}


def channel_index(channel):
    """0..3 for 'R', 'G', 'B', 'A'; None for 'RGBA' (grey AO in R, G, B and alpha 1)."""
    return None if channel in ("", "RGBA") else CHANNELS.index(channel)


def check_channel_attribute(obj, name):
    """None if ``name`` on obj can take one channel (or does not exist yet, and will be made),
    else the reason it cannot."""
    if not name:
        return "the attribute name is empty"
    attr = obj.data.attributes.get(name)
    if attr is None:
        return None
    if attr.data_type not in _KEY or attr.domain not in ('POINT', 'CORNER'):
        return (f"{obj.name}: attribute '{name}' is {attr.data_type} on {attr.domain}; a "
                "channel can be written into a color attribute (Color or Byte Color) on "
                "vertices or face corners only")
    return None


def write_attribute_channel(obj, name, values, channel):
    """Write values (float (V,), one per vertex) into channel 'R', 'G', 'B' or 'A' of obj's
    color attribute ``name``; every other channel keeps its bits. A CORNER attribute gets each
    corner its vertex's value. A missing attribute is made (FLOAT_COLOR on vertices, other
    channels 1) and recorded as Canopy AO's; one Canopy AO made keeps its record."""
    why = check_channel_attribute(obj, name)
    if why:
        raise MeshIOError(why)
    mesh = obj.data
    n = len(mesh.vertices)
    values = np.asarray(values, np.float32).reshape(-1)
    if len(values) != n:
        raise MeshIOError(f"{obj.name}: {len(values)} values for {n} vertices")
    attr = mesh.attributes.get(name)
    made = attr is None
    ours = made or mesh_io.ownership(mesh, name) == 'ours'
    if made:
        attr = mesh.color_attributes.new(name=name, type='FLOAT_COLOR', domain='POINT')
        attr.data.foreach_set("color", np.ones(n * 4, np.float32))
    key = _KEY[attr.data_type]
    buf = np.empty(len(attr.data) * 4, np.float32)
    attr.data.foreach_get(key, buf)
    if attr.domain == 'CORNER':
        loop_vert = np.empty(len(mesh.loops), np.int32)
        mesh.loops.foreach_get("vertex_index", loop_vert)
        values = values[loop_vert]
    buf[channel_index(channel)::4] = np.clip(values, 0.0, 1.0) if key == "color_srgb" else values
    attr.data.foreach_set(key, buf)
    mesh.update_tag()
    if ours:  # the record follows the new content (an attribute of the user's stays theirs)
        mesh_io.mark_owned(obj, name, buf if key == "color" else None)
    return attr


def check_pack_image(image, resolution, channel):
    """Why ``channel`` of Blender image ``image`` cannot take a bake at ``resolution`` texels
    (None when it can): no pixels, not that square size, or no such channel."""
    w, h = image.size
    if w == 0 or h == 0:
        return (f"image '{image.name}' has no pixels (its file "
                f"'{image.filepath or '(none)'}' could not be read); reload or replace it")
    if (w, h) != (resolution, resolution):
        return (f"image '{image.name}' is {w}×{h} and the bake {resolution}×{resolution}; "
                + (f"set Resolution to {w} to pack into it" if w == h else
                   "the AO packs into a square image of Resolution texels"))
    if channel_index(channel) >= image.channels:
        return f"image '{image.name}' has {image.channels} channels, no {channel}"
    return None


def pack_image_channel(image, img, channel, txn):
    """Write img (float32 (H, W), row 0 = bottom) into channel 'R', 'G', 'B' or 'A' of a
    Blender image of the same size; the other channels keep their values (a byte image's
    unchanged bytes write back as themselves). Recorded in txn: undo puts the old pixels back
    (and the image's file, when it is saved to one, or its packed bytes)."""
    from .atomic_io import keep_file, replace_file
    w, h = image.size
    c = channel_index(channel)
    why = check_pack_image(image, img.shape[0], channel)  # img: the bake's square
    if why:
        raise MeshIOError(why)
    buf = np.empty(w * h * image.channels, np.float32)
    image.pixels.foreach_get(buf)
    old = buf.copy()
    # The .blend saves a packed image's packed bytes and a generated one's recipe, not its
    # pixels: such an image is packed with the new pixels (Blender packs a changed image's),
    # else a save and reload bring back the old ones (a generated image becomes a packed one).
    repack = image.source == 'GENERATED' or (image.source == 'FILE'
                                             and image.packed_file is not None)
    old_packed = bytes(image.packed_file.data) if image.packed_file is not None else None

    def undo():
        image.pixels.foreach_set(old)
        image.update()
        if old_packed is not None:
            image.pack(data=old_packed, data_len=len(old_packed))
        elif repack:  # a generated image stays packed, with its old pixels
            image.pack()
    txn.add(undo)
    buf[c::image.channels] = (np.clip(img, 0.0, 1.0) if not image.is_float else img).ravel()
    image.pixels.foreach_set(buf)
    image.update()
    if image.source == 'FILE' and image.filepath and image.packed_file is None:
        import bpy
        path, raw = bpy.path.abspath(image.filepath), image.filepath_raw
        txn.add(keep_file(path))

        def save(tmp):  # Blender saves beside, the rename replaces the file atomically
            image.filepath_raw = tmp
            try:
                image.save()
            finally:
                image.filepath_raw = raw
        replace_file(path, save)
    elif repack:
        image.pack()
    return image


def wire_thickness(obj, kind, source, aov_name, uv_map=None):
    """Read the thickness (attribute name for kind 'vertex', image for 'texel') in each of
    obj's materials into a shader AOV named aov_name. Idempotent; materials.unwire removes the
    nodes (they carry materials.TAG). Returns the nodes added."""
    materials.check_aov_name(aov_name)
    added = 0
    for mat in materials._object_materials(obj):
        nt = mat.node_tree
        src = next(iter(materials._ours(nt, "thickness_source")), None)
        if src is not None and src.get("kind") != kind:
            nt.nodes.remove(src)
            src = None
        if src is None:
            src = materials._new(nt, "ShaderNodeVertexColor" if kind == "vertex" else
                                 "ShaderNodeTexImage", "thickness_source", "Canopy Thickness",
                                 (-900, -700))
            src["kind"] = kind
            added += 1
        if kind == "vertex":
            src.layer_name = source
        else:
            src.image = source
            src.extension = "EXTEND"
            uv = next(iter(materials._ours(nt, "uv")), None)
            if uv is None:
                uv = materials._new(nt, "ShaderNodeUVMap", "uv", "Canopy AO UV", (-1100, -700))
                added += 1
            uv.uv_map = uv_map or ""
            materials._link_once(nt, uv.outputs["UV"], src.inputs["Vector"])
        aov = next(iter(materials._ours(nt, "thickness_aov")), None)
        if aov is None:
            aov = materials._new(nt, "ShaderNodeOutputAOV", "thickness_aov",
                                 "Canopy thickness pass", (0, -700))
            added += 1
        materials._set_aov_target(aov, aov_name)
        materials._link_once(nt, src.outputs["Color"], aov.inputs["Color"])
        materials._link_once(nt, src.outputs["Color"], aov.inputs["Value"])
    return added
