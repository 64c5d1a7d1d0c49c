"""Opacity of the occluders (docs/DESIGN.md, 'Opacity of leaf cards'): each material's alpha as a
constant or a texture, evaluated from a small expression the Blender side reads off the node
tree, and the ray tracer's arguments for it (native raytrace.h, 'Opacity').

An alpha expression is a nested tuple:
  ("const", a)                          a number
  ("image", key, channel)               channel "alpha" or "color" of image `key` (key: any
                                        hashable the reader also puts in ``images``)
  ("math", op, x, y)                    a Math node (MATH_OPS), clamped to [0, 1] where Blender's
                                        Clamp is on: ("clamp", e)
  ("mix", f, x, y)                      x + f (y − x): a Mix node's factor, a Mix Shader's
  ("invert", f, x)                      x + f (1 − 2x): Blender's Invert
  ("ramp", x, positions, alphas, mode)  a ColorRamp's Alpha (mode "LINEAR" or "CONSTANT")
Every image in one expression must be read through the same UV map (the reader checks).
An 8-bit sRGB image's colour is kept encoded (its key in ``encoded``): Cycles interpolates the
encoded values and decodes the result, so an alpha that is offset + scale × such a colour is
handed to the tracer in that form (MaterialAlpha.srgb), anything else decoded per texel.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


class NotUnderstood(ValueError):
    """An alpha this module cannot evaluate (the material bakes opaque, with a note)."""


MATH_OPS = {
    "ADD": np.add, "SUBTRACT": np.subtract, "MULTIPLY": np.multiply,
    "DIVIDE": lambda a, b: np.divide(a, b, out=np.zeros_like(np.asarray(a * b, np.float64)),
                                     where=np.asarray(b) != 0),
    "POWER": lambda a, b: np.power(np.maximum(a, 0.0), b),
    "MINIMUM": np.minimum, "MAXIMUM": np.maximum,
    "GREATER_THAN": lambda a, b: (np.asarray(a) > b).astype(np.float64),
    "LESS_THAN": lambda a, b: (np.asarray(a) < b).astype(np.float64),
}


@dataclass
class MaterialAlpha:
    """One material's alpha: a constant, or a float32 (H, W) texture (row 0 at v = 0) read
    through UV map ``uv_map`` ("" = the mesh's default)."""

    name: str
    alpha: float = 1.0
    texture: np.ndarray | None = None
    uv_map: str = ""
    # texture's alpha = offset + scale × (the interpolated texel, sRGB-decoded when srgb)
    srgb: bool = False
    scale: float = 1.0
    offset: float = 0.0
    nearest: bool = False  # the texel the UV falls in (Closest), not interpolated (Linear)

    @property
    def opaque(self):
        return self.texture is None and self.alpha >= 1.0


@dataclass
class ItemOpacity:
    """An item's triangles' opacity: materials[triangle_material[j]] is triangle j's (-1 =
    opaque), uvs float32 (M, 3, 2) its corners' UVs (or None: no textured material)."""

    materials: list
    triangle_material: np.ndarray
    uvs: np.ndarray | None = None
    notes: list = field(default_factory=list)


def srgb_decode(c):
    """sRGB-encoded values to linear (Cycles' color_srgb_to_linear)."""
    c = np.asarray(c, np.float64)
    return np.where(c < 0.04045, np.maximum(c, 0.0) / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def luminance(rgb):
    """Blender's colour-to-float conversion: the scene-linear luminance (Rec. 709)."""
    return np.asarray(rgb, np.float64) @ np.array([0.2126, 0.7152, 0.0722])


def evaluate(expr, images, encoded=frozenset()):
    """The alpha of expression ``expr``: a float, or a float64 (H, W) array when an image is in
    it. images: key -> float32 (H, W, 4) straight RGBA pixels, colour linear except for the
    keys in ``encoded`` (sRGB-encoded, decoded here texel by texel).
    Raises NotUnderstood for what it cannot evaluate (images of different sizes, unknown ops)."""
    kind = expr[0]
    if kind == "const":
        return float(expr[1])
    if kind == "image":
        px = images[expr[1]]
        if expr[2] == "alpha":
            return px[..., 3].astype(np.float64)
        rgb = px[..., :3]
        return luminance(srgb_decode(rgb) if expr[1] in encoded else rgb)
    args = [evaluate(e, images, encoded) for e in expr[1:] if isinstance(e, tuple)]
    shapes = {np.shape(a) for a in args if np.ndim(a)}
    if len(shapes) > 1:
        raise NotUnderstood("its alpha combines images of different sizes")
    if kind == "math":
        if expr[1] not in MATH_OPS:
            raise NotUnderstood(f"Math node '{expr[1]}' in its alpha")
        return MATH_OPS[expr[1]](args[0], args[1])
    if kind == "clamp":
        return np.clip(args[0], 0.0, 1.0)
    if kind == "mix":
        f, x, y = args
        return x + f * (y - x)
    if kind == "invert":
        f, x = args
        return x + f * (1.0 - 2.0 * x)
    if kind == "ramp":
        return _ramp(args[0], expr[2], expr[3], expr[4])
    raise NotUnderstood(f"'{kind}' in its alpha")


def _ramp(x, positions, alphas, mode):
    pos, val = np.asarray(positions, np.float64), np.asarray(alphas, np.float64)
    if mode == "CONSTANT":
        idx = np.clip(np.searchsorted(pos, x, side="right") - 1, 0, len(pos) - 1)
        return val[idx]
    if mode != "LINEAR":
        raise NotUnderstood(f"ColorRamp interpolation '{mode}' in its alpha")
    return np.interp(x, pos, val)


def _affine(expr, encoded):
    """(key, scale, offset) when ``expr`` is offset + scale × the colour of one encoded image
    (through constant mixes, inverts and clamps of the colour alone), else None."""
    kind = expr[0]
    if kind == "image":
        return (expr[1], 1.0, 0.0) if expr[2] == "color" and expr[1] in encoded else None
    if kind == "clamp" and expr[1][0] == "image":  # an 8-bit colour is in [0, 1] already
        return _affine(expr[1], encoded)
    if kind == "mix":
        f, x, y = expr[1:]
        if f[0] == "clamp":
            f = f[1]
        if x[0] == "const" and y[0] == "const":
            inner = _affine(f, encoded)
            if inner is not None:  # x + f (y − x)
                key, s, o = inner
                return key, s * (y[1] - x[1]), x[1] + o * (y[1] - x[1])
    if kind == "invert" and expr[1][0] == "const":
        inner = _affine(expr[2], encoded)
        if inner is not None:  # x + f (1 − 2x)
            f, (key, s, o) = expr[1][1], inner
            return key, s * (1 - 2 * f), o * (1 - 2 * f) + f
    return None


def material_alpha(name, expr, images, uv_map="", encoded=frozenset(), nearest=False):
    """The MaterialAlpha of material ``name`` whose alpha is ``expr`` (evaluate); nearest: its
    images are read at the texel the UV falls in (Blender's Closest)."""
    affine = _affine(expr, encoded)
    if affine is not None:
        key, scale, offset = affine
        tex = np.ascontiguousarray(luminance(images[key][..., :3]), dtype=np.float32)
        if float(np.min(offset + scale * srgb_decode(tex))) >= 1.0:
            return MaterialAlpha(name)
        return MaterialAlpha(name, texture=tex, uv_map=uv_map, srgb=True, scale=float(scale),
                             offset=float(offset), nearest=nearest)
    value = evaluate(expr, images, encoded)
    if np.ndim(value) == 0:
        return MaterialAlpha(name, alpha=float(np.clip(value, 0.0, 1.0)))
    tex = np.ascontiguousarray(np.clip(value, 0.0, 1.0), dtype=np.float32)
    if float(tex.min()) >= 1.0:
        return MaterialAlpha(name)  # an image that is opaque everywhere
    return MaterialAlpha(name, texture=tex, uv_map=uv_map, nearest=nearest)


def notes(items):
    """The notes of every item's opacity (materials read as opaque, and why), each once."""
    seen = []
    for it in items:
        op = getattr(it, "opacity", None)
        for line in (op.notes if op is not None else ()):
            if line not in seen:
                seen.append(line)
    return seen


def tracer_args(items):
    """The RayTracer's opacity arguments for the items' triangles concatenated in order
    (opacity_materials, opacity_uvs, opacity_alphas), or {} when every triangle is opaque (the
    tracer is then the plain one, bit for bit)."""
    if not any(getattr(it, "opacity", None) is not None
               and any(not m.opaque for m in it.opacity.materials) for it in items):
        return {}
    mats, uvs, alphas, slot = [], [], [], {}  # slot: id(MaterialAlpha) -> its index in alphas
    for it in items:
        m = len(it.triangles)
        op = getattr(it, "opacity", None)
        if op is None or all(a.opaque for a in op.materials):
            mats.append(np.full(m, -1, np.int32))
            uvs.append(np.zeros((m, 3, 2), np.float32))
            continue
        for a in op.materials:  # one copy of a material many items share (its texture)
            if not a.opaque and id(a) not in slot:
                slot[id(a)] = len(alphas)
                alphas.append(a.alpha if a.texture is None else
                              (a.texture, a.srgb, a.scale, a.offset, a.nearest))
        index = np.array([slot.get(id(a), -1) for a in op.materials], np.int32)
        # a face's material index past the last slot takes the last, as Blender renders it
        mats.append(index[np.clip(np.asarray(op.triangle_material, np.int64), 0,
                                  len(op.materials) - 1)])
        uvs.append(op.uvs if op.uvs is not None else np.zeros((m, 3, 2), np.float32))
    return {"opacity_materials": np.ascontiguousarray(np.concatenate(mats), dtype=np.int32),
            "opacity_uvs": np.ascontiguousarray(np.concatenate(uvs), dtype=np.float32),
            "opacity_alphas": alphas}


def tiled(parts):
    """The ItemOpacity of items' triangles copied as forest.realize copies them, or None when
    none of them has one. parts: [(item, mirrored bool (k,))] in realize's order: k copies of
    the item's triangles in turn, a mirrored copy wound the other way (its corners', so its
    UVs', order reversed)."""
    if all(getattr(it, "opacity", None) is None for it, _f in parts):
        return None
    mats, tms, uvs, notes = [], [], [], []
    for it, flip in parts:
        m, k, op = len(it.triangles), len(flip), getattr(it, "opacity", None)
        if op is None or len(op.triangle_material) != m or not op.materials:
            tm, uv = np.full(m, len(mats), np.int64), np.zeros((m, 3, 2), np.float32)
            mats.append(MaterialAlpha(it.name))  # opaque
        else:
            tm = np.clip(np.asarray(op.triangle_material, np.int64), 0,
                         len(op.materials) - 1) + len(mats)
            uv = op.uvs if op.uvs is not None else np.zeros((m, 3, 2), np.float32)
            mats.extend(op.materials)
        notes.extend(op.notes if op is not None else ())
        tms.append(np.tile(tm, k))
        u = np.broadcast_to(np.asarray(uv, np.float32), (k, m, 3, 2)).copy()
        u[np.asarray(flip, bool)] = u[np.asarray(flip, bool)][:, :, ::-1]
        uvs.append(u.reshape(-1, 3, 2))
    return ItemOpacity(mats, np.concatenate(tms).astype(np.int32), np.concatenate(uvs), notes)
