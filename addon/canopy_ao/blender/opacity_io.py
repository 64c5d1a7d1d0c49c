"""Each occluder's opacity as Cycles renders it (docs/DESIGN.md, 'Opacity of leaf cards'): the
alpha expression of every material's Cycles surface read off its node tree, the images' pixels
and the UVs of the mesh's triangles, into a core opacity.ItemOpacity. What is read:
- the Principled BSDF's Alpha, a Transparent BSDF (alpha 0), a Mix Shader of such (any other
  BSDF is opaque);
- in an alpha: constants, an Image Texture's Alpha or Color (its luminance) read through a UV
  Map node, a Texture Coordinate's UV or the default UV map, and Math, Mix, Invert, ColorRamp
  and Reroute nodes between.
Anything else makes the material opaque with a note naming it."""

import numpy as np

from . import materials
from ..core import opacity

# BSDFs that stop Cycles' shadow (and AO) rays: glass and transmission included (no caustics).
OPAQUE_SHADERS = {"BSDF_DIFFUSE", "BSDF_GLOSSY", "BSDF_ANISOTROPIC", "BSDF_GLASS",
                  "BSDF_REFRACTION", "BSDF_TRANSLUCENT", "BSDF_VELVET", "BSDF_SHEEN",
                  "BSDF_TOON", "BSDF_HAIR", "BSDF_HAIR_PRINCIPLED", "SUBSURFACE_SCATTERING",
                  "EMISSION", "HOLDOUT", "BSDF_METALLIC", "BSDF_RAY_PORTAL", "EEVEE_SPECULAR"}
# Colour spaces whose pixels bpy hands over already linear (no transfer function to undo).
LINEAR_SPACES = {"Non-Color", "Linear", "Linear Rec.709", "Linear CIE-XYZ E", "Raw",
                 "Linear Rec.2020", "ACEScg", "Linear FilmLight E-Gamut"}


class _Reader:
    """Builds one material's alpha expression (core/opacity.py), collecting its images."""

    def __init__(self):
        self.images = {}  # image name -> float32 (H, W, 4) RGBA, colour linear unless encoded
        self.encoded = set()  # images whose colour is sRGB-encoded (8-bit sRGB: core/opacity.py)
        self.uv_maps = set()
        self.interpolations = set()  # of the Image Texture nodes read

    def shader(self, socket):
        """The alpha of the shader reaching input ``socket``."""
        if not socket.is_linked:
            return ("const", 1.0)
        node, _out = self._source(socket)
        kind = node.type
        if kind == "BSDF_PRINCIPLED":
            return self.value(node.inputs["Alpha"])
        if kind == "BSDF_TRANSPARENT":
            return ("const", 0.0)
        if kind == "MIX_SHADER":
            return ("mix", ("clamp", self.value(node.inputs[0])), self.shader(node.inputs[1]),
                    self.shader(node.inputs[2]))
        if kind in OPAQUE_SHADERS:
            return ("const", 1.0)
        raise opacity.NotUnderstood(f"its surface is a '{node.name}' node")

    def value(self, socket):
        """The float reaching input ``socket`` (a colour as its luminance)."""
        if not socket.is_linked:
            v = socket.default_value
            if hasattr(v, "__len__"):
                return ("const", float(opacity.luminance(list(v)[:3])))
            return ("const", float(v))
        node, out = self._source(socket)
        kind = node.type
        if kind == "TEX_IMAGE":
            return self._image(node, out)
        if kind == "VALUE":
            return ("const", float(node.outputs[0].default_value))
        if kind == "MATH":
            e = ("math", node.operation, self.value(node.inputs[0]), self.value(node.inputs[1]))
            return ("clamp", e) if node.use_clamp else e
        if kind == "MIX_RGB" and node.blend_type == "MIX":
            e = ("mix", ("clamp", self.value(node.inputs[0])), self.value(node.inputs[1]),
                 self.value(node.inputs[2]))
            return ("clamp", e) if node.use_clamp else e
        if kind == "MIX" and node.blend_type == "MIX" and node.data_type in ("FLOAT", "RGBA"):
            a, b = (2, 3) if node.data_type == "FLOAT" else (6, 7)  # Blender 3.4+ input order
            f = self.value(node.inputs[0])
            e = ("mix", ("clamp", f) if node.clamp_factor else f, self.value(node.inputs[a]),
                 self.value(node.inputs[b]))
            return ("clamp", e) if getattr(node, "clamp_result", False) else e
        if kind == "INVERT":
            return ("invert", self.value(node.inputs[0]), self.value(node.inputs[1]))
        if kind == "VALTORGB":
            ramp = node.color_ramp
            pos = [e.position for e in ramp.elements]
            if out.name == "Alpha":
                vals = [e.color[3] for e in ramp.elements]
            else:
                vals = [float(opacity.luminance(list(e.color)[:3])) for e in ramp.elements]
            return ("ramp", self.value(node.inputs[0]), pos, vals, ramp.interpolation)
        raise opacity.NotUnderstood(f"its alpha comes from a '{node.name}' node")

    @staticmethod
    def _source(socket):
        """The (node, output socket) feeding ``socket``, through reroutes."""
        link = socket.links[0]
        if getattr(link, "is_muted", False) or not link.is_valid:
            raise opacity.NotUnderstood("its alpha has a muted or invalid link")
        node = link.from_node
        if node.mute:
            raise opacity.NotUnderstood(f"its alpha passes the muted node '{node.name}'")
        if node.type == "REROUTE":
            if not node.inputs[0].is_linked:
                raise opacity.NotUnderstood(f"its alpha ends at the reroute '{node.name}'")
            return _Reader._source(node.inputs[0])
        return node, link.from_socket

    def _image(self, node, out):
        img = node.image
        if img is None or node.projection != "FLAT":
            raise opacity.NotUnderstood(f"its Image Texture '{node.name}' has no image or is "
                                        "not flat-projected")
        vec = node.inputs["Vector"]
        uv = ""
        if vec.is_linked:
            src, sock = self._source(vec)
            if src.type == "UVMAP":
                uv = src.uv_map
            elif not (src.type == "TEX_COORD" and sock.name == "UV"):
                raise opacity.NotUnderstood(f"its Image Texture '{node.name}' is not read "
                                            "through a UV map")
        self.uv_maps.add(uv)
        self.interpolations.add(node.interpolation)
        if len(self.uv_maps) > 1:
            raise opacity.NotUnderstood("its alpha reads images through several UV maps")
        if out.name == "Alpha" and img.alpha_mode == "NONE":
            return ("const", 1.0)
        space = img.colorspace_settings.name
        if out.name != "Alpha" and space not in LINEAR_SPACES | {"sRGB"} and not img.is_float:
            # 8-bit sRGB stays encoded (core/opacity.py); other spaces must be linear
            raise opacity.NotUnderstood(f"its image '{img.name}' is in colour space '{space}'")
        if img.name not in self.images:
            self.images[img.name] = _pixels(img)
            if space == "sRGB" and not img.is_float:
                self.encoded.add(img.name)
        return ("image", img.name, "alpha" if out.name == "Alpha" else "color")


def _pixels(img):
    """float32 (H, W, 4) RGBA of ``img`` as bpy holds them."""
    w, h = int(img.size[0]), int(img.size[1])
    channels = int(img.channels)
    if w < 1 or h < 1 or len(img.pixels) != w * h * channels:
        raise opacity.NotUnderstood(f"its image '{img.name}' has no pixels (missing file?)")
    buf = np.empty(w * h * channels, np.float32)
    img.pixels.foreach_get(buf)
    px = np.ones((h, w, 4), np.float32)
    px[..., :min(channels, 4)] = buf.reshape(h, w, channels)[..., :4]
    if channels < 3:
        px[..., 1:3] = px[..., :1]
    return px


def material_alpha(mat):
    """(opacity.MaterialAlpha, note or None) of material ``mat`` (None: an empty slot)."""
    if mat is None or not materials.uses_nodes(mat) or mat.node_tree is None:
        return opacity.MaterialAlpha(mat.name if mat else ""), None
    out = mat.node_tree.get_output_node("CYCLES")
    if out is None:
        return opacity.MaterialAlpha(mat.name), None
    reader = _Reader()
    try:
        expr = reader.shader(out.inputs["Surface"])
        return opacity.material_alpha(mat.name, expr, reader.images,
                                      next(iter(reader.uv_maps), ""), reader.encoded,
                                      nearest=reader.interpolations == {"Closest"}), None
    except opacity.NotUnderstood as exc:
        why = str(exc)
    except (AttributeError, KeyError, IndexError, TypeError, ValueError) as exc:
        # a node this Blender spells otherwise: never a failed bake, an opaque material
        why = f"its nodes could not be read ({type(exc).__name__}: {exc})"
    return opacity.MaterialAlpha(mat.name), (f"material '{mat.name}': {why}; its surfaces are "
                                              "treated as opaque")


def _uv_corners(mesh, name):
    """float32 (L, 2): UV map ``name``'s value at every face corner ("" = the default map,
    the one that renders), or None when the mesh has no such map."""
    layers = mesh.uv_layers
    if not name:
        name = next((l.name for l in layers if l.active_render), layers[0].name if layers else "")
        if not name:  # Cycles reads a missing default map as (0, 0) (item_opacity)
            return np.zeros((len(mesh.loops), 2), np.float32)
    layer = layers.get(name)
    uv = np.empty(2 * len(mesh.loops), np.float32)
    attr = mesh.attributes.get(name)
    if attr is not None and attr.data_type == "FLOAT2" and attr.domain == "CORNER":
        # Blender 3.5+: UV maps are attributes; before, geometry nodes that realise
        # instances keep a UV map as such an attribute, which Cycles finds by name
        attr.data.foreach_get("vector", uv)
    elif layer is not None:
        layer.data.foreach_get("uv", uv)
    else:
        return None
    return uv.reshape(-1, 2)


def item_opacity(obj, depsgraph, triangle_count, cache=None):
    """The opacity.ItemOpacity of ``obj`` (its evaluated mesh's loop triangles, of which there
    must be ``triangle_count``: the item's), or None when every material is opaque without a
    note. cache: a dict kept over one bake's objects, so a material many objects share is read
    (its images' pixels) once and handed to the tracer once."""
    cache = {} if cache is None else cache
    mats, notes = [], []
    # The evaluated object's slots: geometry nodes that realise instances bring the instances'
    # materials, which the original object's slots do not list.
    for slot in obj.evaluated_get(depsgraph).material_slots:
        key = slot.material.name_full if slot.material is not None else None
        if key not in cache:  # a material's note goes with the first object using it
            cache[key] = material_alpha(slot.material)
            if cache[key][1]:
                notes.append(f"{obj.name}: {cache[key][1]}")
        mats.append(cache[key][0])
    if all(m.opaque for m in mats):
        return opacity.ItemOpacity(mats, np.zeros(0, np.int32), notes=notes) if notes else None
    ob_eval = obj.evaluated_get(depsgraph)
    mesh = ob_eval.to_mesh()
    try:
        mesh.calc_loop_triangles()
        tris = mesh.loop_triangles
        if len(tris) != triangle_count:  # cannot happen for one depsgraph; never guess
            notes.append(f"{obj.name}: its triangles changed while reading its materials; "
                         "treated as opaque")
            return opacity.ItemOpacity([], np.zeros(0, np.int32), notes=notes)
        tm = np.empty(len(tris), np.int32)
        tris.foreach_get("material_index", tm)
        loops = np.empty(3 * len(tris), np.int32)
        tris.foreach_get("loops", loops)
        loops = loops.reshape(-1, 3)
        uvs = np.zeros((len(tris), 3, 2), np.float32)
        for k, m in enumerate(mats):
            if m.texture is None:
                continue
            corner = _uv_corners(mesh, m.uv_map)
            if not m.uv_map and not len(mesh.uv_layers):  # measured in Cycles 3.4
                notes.append(f"{obj.name}: material '{m.name}' reads the default UV map, "
                             "which the mesh lacks (geometry nodes that realise instances "
                             "keep it as an attribute in Blender 3.4), so Cycles reads its "
                             "image at UV (0, 0) on every face, and so does the bake; name "
                             "the map in a UV Map node to read it")
            if corner is None:
                notes.append(f"{obj.name}: material '{m.name}' reads UV map "
                             f"'{m.uv_map or '(default)'}', which the mesh lacks; treated "
                             "as opaque")
                mats[k] = opacity.MaterialAlpha(m.name)
                continue
            sel = tm == k
            uvs[sel] = corner[loops[sel]]
    finally:
        ob_eval.to_mesh_clear()
    return opacity.ItemOpacity(mats, tm, uvs, notes)
