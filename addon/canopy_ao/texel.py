"""Per-texel AO: Blender glue around the native UV raster (DESIGN 6, issue 4).

    evaluated mesh ──foreach_get──► per-corner UV / world position / world normal (float32)
    ──_core.rasterize_uv──► one receiver point per covered texel ──ao_fn──► AO per texel
    ──_core.splat_texels──► image + dilated margin ──► EXR file ──► Blender image, wired

The native functions are used when this build of ``_core`` has them; otherwise a numpy
rasterizer (texel centres only, no conservative texels) stands in and the stats say so.

Image conventions (texel_raster.h, Blender): texel (i, j) has its centre at
uv = ((i + 0.5) / W, (j + 0.5) / H); row 0 is the bottom (v = 0).
"""
import os
import tempfile

import bpy
import numpy as np

from . import materials

__all__ = ["bake_texel", "bake_objects", "gather_corner_triangles", "rasterize",
           "splat", "image_name"]

TAG = "canopy_ao"
OBJ_KEY = "canopy_ao_object"   # on our images: the object they belong to


def image_name(obj):
    return f"{obj.name}_CanopyAO"


def _core():
    try:
        from . import _core as c
    except ImportError:
        return None
    return c


# === Mesh → per-corner arrays

def _resolve_uv_map(obj, uv_map):
    me = obj.data
    if len(me.uv_layers) == 0:
        raise ValueError(f"Object '{obj.name}' has no UV map; add one (UV > Smart UV Project) "
                         "or bake per vertex")
    if not uv_map:
        layer = me.uv_layers.active or me.uv_layers[0]
        return layer.name
    if me.uv_layers.get(uv_map) is None:
        names = ", ".join(l.name for l in me.uv_layers)
        raise ValueError(f"Object '{obj.name}' has no UV map named '{uv_map}' (it has: "
                         f"{names}); pick one of those or leave the UV map empty for the "
                         "active one")
    return uv_map


def _corner_normals(mesh, n_loops):
    out = np.empty(n_loops * 3, dtype=np.float32)
    if hasattr(mesh, "corner_normals"):  # 4.1+
        mesh.corner_normals.foreach_get("vector", out)
    else:  # 3.4 – 4.0: split normals honour smooth/flat shading and custom normals
        mesh.calc_normals_split()
        mesh.loops.foreach_get("normal", out)
    return out.reshape(n_loops, 3)


def gather_corner_triangles(obj, depsgraph, uv_map):
    """Triangulated corner data of obj's evaluated mesh, world space.

    Returns (uvs float32 (3M, 2), positions float32 (3M, 3), normals float32 (3M, 3) unit);
    corner k of triangle t is row 3t + k. Normals are corner (split) normals, so flat and
    smooth shading and custom normals are what the texels see.
    """
    ob_eval = obj.evaluated_get(depsgraph)
    mesh = ob_eval.to_mesh()
    try:
        layer = mesh.uv_layers.get(uv_map)
        if layer is None:
            raise ValueError(f"Object '{obj.name}': its modifiers drop UV map '{uv_map}'; "
                             "apply them or choose a UV map the evaluated mesh keeps")
        mesh.calc_loop_triangles()
        n_tri = len(mesh.loop_triangles)
        n_loops = len(mesh.loops)
        n_verts = len(mesh.vertices)
        corner = np.empty(n_tri * 3, dtype=np.int32)
        mesh.loop_triangles.foreach_get("loops", corner)
        loop_vert = np.empty(n_loops, dtype=np.int32)
        mesh.loops.foreach_get("vertex_index", loop_vert)
        co = np.empty(n_verts * 3, dtype=np.float32)
        mesh.vertices.foreach_get("co", co)
        co = co.reshape(n_verts, 3)
        uv = np.empty(n_loops * 2, dtype=np.float32)
        layer.data.foreach_get("uv", uv)
        uv = uv.reshape(n_loops, 2)
        nor = _corner_normals(mesh, n_loops)
    finally:
        ob_eval.to_mesh_clear()
    m = np.array(obj.matrix_world, dtype=np.float64)
    pos = co[loop_vert[corner]].astype(np.float64) @ m[:3, :3].T + m[:3, 3]
    try:
        nm = np.linalg.inv(m[:3, :3]).T  # normals transform by the inverse transpose
    except np.linalg.LinAlgError:
        nm = np.eye(3)
    nrm = nor[corner].astype(np.float64) @ nm.T
    ln = np.linalg.norm(nrm, axis=1, keepdims=True)
    nrm = np.where(ln > 1e-20, nrm / np.maximum(ln, 1e-20), 0.0)
    return (np.ascontiguousarray(uv[corner], dtype=np.float32),
            np.ascontiguousarray(pos, dtype=np.float32),
            np.ascontiguousarray(nrm, dtype=np.float32))


# === Raster (native, or the numpy stand-in)

def _rasterize_numpy(uvs, positions, normals, width, height, max_candidates=1 << 22,
                     with_triangles=False):
    """Texel-centre coverage in numpy. Lowest triangle id wins a texel; texels whose centre is
    strictly inside two or more triangles count as overlapping. Returns as rasterize()."""
    m = len(uvs) // 3
    tri_uv = uvs.reshape(m, 3, 2).astype(np.float64) * (width, height)
    a, b, c = tri_uv[:, 0], tri_uv[:, 1], tri_uv[:, 2]
    e1, e2 = b - a, c - a
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    finite = np.all(np.isfinite(tri_uv.reshape(m, 6)), axis=1)
    ok = finite & (np.abs(det) > 1e-12)
    lo = np.where(ok[:, None], np.ceil(tri_uv.min(axis=1) - 0.5), 0).astype(np.int64)
    hi = np.where(ok[:, None], np.floor(tri_uv.max(axis=1) - 0.5), -1).astype(np.int64)
    lo = np.maximum(lo, 0)
    hi = np.minimum(hi, (width - 1, height - 1))
    w = np.maximum(hi[:, 0] - lo[:, 0] + 1, 0)
    h = np.maximum(hi[:, 1] - lo[:, 1] + 1, 0)
    counts = w * h
    counts[~ok] = 0
    owner = np.full(width * height, -1, dtype=np.int64)
    bary = np.zeros((width * height, 3), dtype=np.float64)
    hits = np.zeros(width * height, dtype=np.int32)
    safe_det = np.where(ok, det, 1.0)
    cum = np.cumsum(counts)
    start = 0
    while start < m:
        # triangles [start, stop) whose candidates fit the budget (at least one triangle)
        base = cum[start - 1] if start else 0
        stop = int(np.searchsorted(cum, base + max_candidates, side="right"))
        stop = max(stop, start + 1)
        t_idx = np.arange(start, stop)
        cnt = counts[start:stop]
        tot = int(cnt.sum())
        start = stop
        if tot == 0:
            continue
        t = np.repeat(t_idx, cnt)
        k = np.arange(tot) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        i = lo[t, 0] + k % w[t]
        j = lo[t, 1] + k // w[t]
        px = i + 0.5 - a[t, 0]
        py = j + 0.5 - a[t, 1]
        l1 = (px * e2[t, 1] - py * e2[t, 0]) / safe_det[t]
        l2 = (e1[t, 0] * py - e1[t, 1] * px) / safe_det[t]
        l0 = 1.0 - l1 - l2
        eps = 1e-9
        inside = (l0 >= -eps) & (l1 >= -eps) & (l2 >= -eps)
        strict = (l0 > 1e-4) & (l1 > 1e-4) & (l2 > 1e-4)
        pix = (j * width + i)
        np.add.at(hits, pix[strict], 1)
        sel = np.flatnonzero(inside)
        pix_in = pix[sel]
        # first occurrence per pixel = lowest triangle (candidates are in triangle order)
        uniq, first = np.unique(pix_in, return_index=True)
        free = owner[uniq] < 0
        uniq, first = uniq[free], first[free]
        s = sel[first]
        owner[uniq] = t[s]
        bary[uniq] = np.stack([l0[s], l1[s], l2[s]], axis=1)
    pixels = np.flatnonzero(owner >= 0).astype(np.int32)
    tri = owner[pixels]
    bc = bary[pixels]
    corners = tri[:, None] * 3 + np.arange(3)
    pos = np.einsum("tk,tkd->td", bc, positions[corners].astype(np.float64))
    nrm = np.einsum("tk,tkd->td", bc, normals[corners].astype(np.float64))
    ln = np.linalg.norm(nrm, axis=1, keepdims=True)
    # where the corner normals cancel, the face normal (texel_raster.h does the same)
    p3 = positions.reshape(m, 3, 3).astype(np.float64)[tri]
    face = np.cross(p3[:, 1] - p3[:, 0], p3[:, 2] - p3[:, 0])
    fl = np.linalg.norm(face, axis=1, keepdims=True)
    face = np.where(fl > 1e-30, face / np.maximum(fl, 1e-30), 0.0)
    nrm = np.where(ln > 1e-6, nrm / np.maximum(ln, 1e-30), face)
    stats = {"triangles": m, "degenerate": int(np.count_nonzero(finite & ~ok)),
             "invalid_uv": int(np.count_nonzero(~finite)), "exact_texels": int(len(pixels)),
             "conservative_texels": 0,
             "overlapping_texels": int(np.count_nonzero(hits >= 2)), "raster": "numpy"}
    out = (pixels, np.ascontiguousarray(pos, dtype=np.float32),
           np.ascontiguousarray(nrm, dtype=np.float32), stats)
    return out + (tri.astype(np.int32),) if with_triangles else out


def rasterize(uvs, positions, normals, width, height, with_triangles=False):
    """(pixels int32 (T,), positions float32 (T, 3), normals float32 (T, 3), stats dict):
    one receiver point per covered texel, ascending pixel index j * width + i.
    with_triangles=True appends int32 (T,): the triangle (corner row // 3) each texel lies on.
    Native: conservative coverage (islands thinner than a texel keep texels); the numpy
    stand-in covers texel centres only."""
    core = _core()
    fn = getattr(core, "rasterize_uv", None) if core is not None else None
    if fn is None:
        return _rasterize_numpy(uvs, positions, normals, width, height,
                                with_triangles=with_triangles)
    ts = fn(uvs, positions, normals, resolution=(width, height), conservative=True)
    # The TexelSet's arrays are read-only views of its own buffers: copy what ao_fn receives
    # so nothing outlives or writes into it.
    pixels = np.array(ts.pixels, dtype=np.int32)
    pos = np.array(ts.positions, dtype=np.float32).reshape(-1, 3)
    nrm = np.array(ts.normals, dtype=np.float32).reshape(-1, 3)
    stats = {k: int(v) for k, v in dict(ts.stats).items()}
    stats["raster"] = "native"
    if with_triangles:
        return pixels, pos, nrm, stats, np.array(ts.triangles, dtype=np.int32)
    return pixels, pos, nrm, stats


def _dilate_numpy(img, mask, margin):
    """Ring by ring: an empty texel with filled 8-neighbours takes their mean (texel_raster.h)."""
    h, w = img.shape
    for _ in range(int(margin)):
        filled = mask > 0
        if filled.all():
            break
        v = np.pad(np.where(filled, img, 0.0), 1)
        f = np.pad(filled.astype(np.float32), 1)
        s = np.zeros((h, w), dtype=np.float64)
        n = np.zeros((h, w), dtype=np.float64)
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                if dx or dy:
                    s += v[1 + dy:1 + dy + h, 1 + dx:1 + dx + w]
                    n += f[1 + dy:1 + dy + h, 1 + dx:1 + dx + w]
        grow = ~filled & (n > 0)
        img[grow] = (s[grow] / n[grow]).astype(np.float32)
        mask[grow] = 2
    return img, mask


def splat(pixels, values, width, height, margin, background=1.0):
    """(image float32 (H, W), mask uint8 (H, W): 0 empty, 1 covered, 2 margin)."""
    core = _core()
    fn = getattr(core, "splat_texels", None) if core is not None else None
    values = np.ascontiguousarray(values, dtype=np.float32)
    if fn is not None:
        img, mask = fn(np.ascontiguousarray(pixels, dtype=np.int32), values, (width, height),
                       margin=int(margin), background=float(background), return_mask=True)
        return (np.asarray(img, dtype=np.float32).reshape(height, width),
                np.asarray(mask, dtype=np.uint8).reshape(height, width))
    img = np.full(width * height, background, dtype=np.float32)
    mask = np.zeros(width * height, dtype=np.uint8)
    img[pixels] = values
    mask[pixels] = 1
    img, mask = _dilate_numpy(img.reshape(height, width), mask.reshape(height, width), margin)
    return img, mask


# === Image file and Blender image

def _image_path(obj, image_dir, notes):
    fname = bpy.path.clean_name(image_name(obj)) + ".exr"
    if image_dir:
        if image_dir.startswith("//") and not bpy.data.filepath:
            d = os.path.join(tempfile.gettempdir(), "canopy_ao")
            notes.append(f"'{image_dir}' is relative to the .blend, which is not saved yet; "
                         f"the image went to {d}")
        else:
            d = bpy.path.abspath(image_dir)
    elif bpy.data.filepath:
        d = os.path.dirname(bpy.data.filepath)
    else:
        d = os.path.join(tempfile.gettempdir(), "canopy_ao")
        notes.append(f"the .blend is not saved yet; the image went to {d}")
    try:
        os.makedirs(d, exist_ok=True)
    except OSError as exc:
        raise RuntimeError(f"Cannot create the image folder '{d}': {exc}; choose another "
                           "Image Folder") from exc
    return os.path.join(d, fname)


def _find_our_image(obj):
    for img in bpy.data.images:
        if img.get(TAG) and img.get(OBJ_KEY) == obj.name:
            return img
    return None


def _write_exr(path, ao):
    """Write a grey float image; the native writer when available, else Blender's."""
    h, w = ao.shape
    core = _core()
    fn = getattr(core, "write_image", None) if core is not None else None
    if fn is not None:
        # grey (H, W), row 0 = bottom: the writer flips rows so the file shows v = 1 on top
        fn(path, np.ascontiguousarray(ao, dtype=np.float32), dtype="float", bottom_up=True)
        return "native"
    tmp = bpy.data.images.new("_CanopyAO_write", w, h, alpha=True, float_buffer=True)
    try:
        # Non-Color before the pixels go in: a "Linear" float image was written sRGB-encoded
        # (0.25 came back as 0.537) in 3.4.
        tmp.colorspace_settings.name = "Non-Color"
        rgba = np.ones((h, w, 4), dtype=np.float32)
        rgba[:, :, :3] = ao[:, :, None]
        tmp.pixels.foreach_set(rgba.ravel())
        tmp.filepath_raw = path
        tmp.file_format = "OPEN_EXR"
        tmp.save()
    except RuntimeError as exc:
        raise RuntimeError(f"Could not write '{path}': {exc}") from exc
    finally:
        bpy.data.images.remove(tmp)
    return "blender"


def _load_image(obj, path):
    img = _find_our_image(obj)
    if img is not None:
        img.filepath = path
        img.reload()
    else:
        # Never touches a user image of the same name: load() makes a new datablock and Blender
        # gives it a free name.
        img = bpy.data.images.load(path, check_existing=False)
        img.name = image_name(obj)
        img[TAG] = True
        img[OBJ_KEY] = obj.name
    img.colorspace_settings.name = "Non-Color"  # AO is data, not a colour to convert
    return img


# === Entry points

def bake_texel(context, obj, ao_fn, uv_map=None, resolution=1024, margin=4, image_dir=None,
               wire=True, aov_name="BakedAO", own_triangles=False):
    """Bake AO per texel of obj's UV layout into an EXR and a Blender image, wired into obj's
    materials (wire_texel_ao) unless wire=False.

    ao_fn(positions float32 (T, 3), normals float32 (T, 3)) -> float32 (T,) AO in [0, 1];
    with own_triangles=True it gets a third argument, int32 (T,): each texel's triangle in the
    evaluated mesh's loop-triangle order (so a ray can skip only what it starts on).
    Returns (image, stats); stats holds the raster counts, "path", "texels", "warnings"
    (e.g. overlapping UVs) and "notes". Raises ValueError before changing anything when obj is
    not a mesh, has no (such) UV map, or the resolution is out of range.
    """
    if obj.type != "MESH":
        raise ValueError(f"Object '{obj.name}' is not a mesh; only meshes can be baked per texel")
    uv_map = _resolve_uv_map(obj, uv_map)
    res = int(resolution)
    if not 1 <= res <= 16384:
        raise ValueError(f"Resolution {resolution} is out of range; use 1 to 16384 texels")
    if margin < 0:
        raise ValueError(f"Margin must be >= 0 texels, not {margin}")
    if wire:
        materials.check_aov_name(aov_name)
    depsgraph = context.evaluated_depsgraph_get()
    uvs, pos, nrm = gather_corner_triangles(obj, depsgraph, uv_map)
    pixels, tpos, tnrm, stats, ttri = rasterize(uvs, pos, nrm, res, res, with_triangles=True)
    stats = dict(stats)
    stats["warnings"] = []
    stats["notes"] = []
    stats["uv_map"] = uv_map
    stats["resolution"] = res
    if stats.get("overlapping_texels", 0) > 0:
        stats["warnings"].append(
            f"Object '{obj.name}': UV map '{uv_map}' overlaps ({stats['overlapping_texels']} "
            "texels lie in two or more faces); those texels show one face's AO. Unwrap without "
            "overlaps (UV > Smart UV Project) for a correct bake")
    if len(pixels) == 0:
        stats["warnings"].append(f"Object '{obj.name}': no texel centre falls inside its UV "
                                 f"map '{uv_map}' at {res}×{res}; raise the resolution or "
                                 "check the UVs lie in the 0–1 square")
        ao = np.zeros(0, dtype=np.float32)
    else:
        ao = np.asarray(ao_fn(tpos, tnrm, ttri) if own_triangles else ao_fn(tpos, tnrm),
                        dtype=np.float32)
        if ao.shape != (len(pixels),) or not np.all(np.isfinite(ao)):
            raise RuntimeError(f"Object '{obj.name}': the AO model returned "
                               f"{ao.shape} values for {len(pixels)} texels or non-finite AO")
        ao = np.clip(ao, 0.0, 1.0)
    img_arr, mask = splat(pixels, ao, res, res, int(margin))
    stats["texels"] = int(len(pixels))
    stats["margin_texels"] = int(np.count_nonzero(mask == 2))
    path = _image_path(obj, image_dir, stats["notes"])
    stats["writer"] = _write_exr(path, img_arr)
    stats["path"] = path
    image = _load_image(obj, path)
    if wire:
        stats["nodes_added"] = materials.wire_texel_ao(obj, image, uv_map, aov_name)
    return image, stats


def bake_objects(context, plan, targets, opts):
    """The bake operator's per-texel step: one image per target item (engine SceneItems),
    AO from the plan's model. Returns {object name: stats}."""
    from . import engine

    # Refuse before the first image is written: every target needs the UV map.
    for it in targets:
        obj = context.scene.objects[it.name]
        if obj.type != "MESH":
            raise ValueError(f"Object '{obj.name}' is not a mesh; only meshes can be baked "
                             "per texel")
        _resolve_uv_map(obj, opts.get("uv_map") or None)
    out = {}
    for it in targets:
        obj = context.scene.objects[it.name]

        def ao_fn(p, n, tri, it=it):
            # The texel's own triangle, when the texel mesh is the item's (same loop triangles).
            own = None
            if len(tri) and int(tri.max()) < len(it.triangles):
                own = {"triangle_ids": tri}
            return engine._evaluate_points(plan, it.role, it.tree, it.name, p, n,
                                           plan.method, plan.tau, own=own)

        _image, stats = bake_texel(
            context, obj, ao_fn, uv_map=opts.get("uv_map") or None,
            resolution=opts.get("resolution", 1024), margin=opts.get("margin", 4),
            image_dir=opts.get("image_dir") or None,
            wire=bool(opts.get("wire_material", True)),
            aov_name=opts.get("aov_name", "BakedAO"), own_triangles=True)
        out[obj.name] = stats
    return out
