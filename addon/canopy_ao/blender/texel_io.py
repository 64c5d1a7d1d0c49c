"""Per-texel receivers and results in Blender, around the native UV raster
(docs/DESIGN.md, 'Data flow').

    evaluated mesh ──foreach_get──► per-corner UV / world position / world normal (float32)
    ──_core.rasterize_uv──► one point per covered texel, N × N with anti-aliasing (TexelReceivers)
    ──the bake's evaluation──► AO per texel (their mean) ──_core.splat_texels──► image + margin
    ──files_io.write_image (OpenImageIO, or core/image_files.py)──► image file ──► Blender image

Image conventions (texel_raster.h, Blender): texel (i, j) has its centre at
uv = ((i + 0.5) / W, (j + 0.5) / H); row 0 is the bottom (v = 0).
"""
from dataclasses import dataclass, field

import bpy
import numpy as np

from . import corner_io, materials, mesh_io, ownership, texel_points
from .files_io import Output, check_outputs, image_path, write_own_file
from ..core import texel_budget
# Kept under their old names for code that writes image files of its own through texel_io.
from ..core.native import CanopyAOError, _core

TAG = "canopy_ao"
OBJ_KEY = "canopy_ao_object"   # on our images: the object they belong to ...
MAP_KEY = "canopy_ao_map"      # ... and the map they hold (absent: "CanopyAO", the AO)
MAX_RESOLUTION = 16384
# === Mesh → texel receivers

def resolve_uv_map(obj, uv_map):
    """The UV map's name (the active one when uv_map is empty); CanopyAOError without it."""
    me = obj.data
    if len(me.uv_layers) == 0:
        raise CanopyAOError(f"Object '{obj.name}' has no UV map; add one (UV > Smart UV "
                            "Project) or bake per vertex")
    if not uv_map:
        layer = me.uv_layers.active or me.uv_layers[0]
        return layer.name
    if me.uv_layers.get(uv_map) is None:
        names = ", ".join(l.name for l in me.uv_layers)
        raise CanopyAOError(f"Object '{obj.name}' has no UV map named '{uv_map}' (it has: "
                            f"{names}); pick one of those or leave the UV map empty for the "
                            "active one")
    return uv_map


def gather_corner_triangles(obj, depsgraph, uv_map):
    """Triangulated corner data of obj's evaluated mesh, world space.

    Returns (uvs float32 (3M, 2), positions float32 (3M, 3), normals float32 (3M, 3) unit);
    corner k of triangle t is row 3t + k. Normals are corner (split) normals, so flat and
    smooth shading and custom normals are what the texels see. World space as for vertices
    (mesh_io's transform).
    """
    ob_eval = obj.evaluated_get(depsgraph)
    mesh = ob_eval.to_mesh()
    try:
        layer = mesh.uv_layers.get(uv_map)
        if layer is None:
            raise CanopyAOError(f"Object '{obj.name}': its modifiers drop UV map '{uv_map}'; "
                                "apply them or choose a UV map the evaluated mesh keeps")
        mesh.calc_loop_triangles()
        n_tri, n_loops, n_verts = len(mesh.loop_triangles), len(mesh.loops), len(mesh.vertices)
        corner = np.empty(n_tri * 3, dtype=np.int32)
        mesh.loop_triangles.foreach_get("loops", corner)
        loop_vert = np.empty(n_loops, dtype=np.int32)
        mesh.loops.foreach_get("vertex_index", loop_vert)
        co = np.empty(n_verts * 3, dtype=np.float32)
        mesh.vertices.foreach_get("co", co)
        uv = np.empty(n_loops * 2, dtype=np.float32)
        layer.data.foreach_get("uv", uv)
        nor = corner_io.corner_normals(mesh, n_loops)
    finally:
        ob_eval.to_mesh_clear()
    pos, nrm = mesh_io._to_world(co.reshape(n_verts, 3)[loop_vert[corner]], nor[corner],
                                 obj.matrix_world)
    return np.ascontiguousarray(uv.reshape(n_loops, 2)[corner]), pos, nrm


def rasterize(uvs, positions, normals, width, height):
    """(pixels int32 (T,), positions float32 (T, 3), normals float32 (T, 3), stats dict,
    triangles int32 (T,)): one receiver point per covered texel, ascending pixel index
    j * width + i, by the native rasteriser (conservative coverage: islands thinner than a
    texel keep texels); triangles: the loop triangle (corner row // 3) each texel lies on."""
    ts = _core.rasterize_uv(uvs, positions, normals, resolution=(width, height),
                            conservative=True)
    # The TexelSet's arrays are read-only views of its own buffers: copy what the bake keeps.
    stats = {k: int(v) for k, v in dict(ts.stats).items()}
    return (np.array(ts.pixels, dtype=np.int32),
            np.array(ts.positions, dtype=np.float32).reshape(-1, 3),
            np.array(ts.normals, dtype=np.float32).reshape(-1, 3), stats,
            np.array(ts.triangles, dtype=np.int32))


@dataclass
class TexelReceivers:
    """One object's covered texels as receivers, and what the raster said about them."""

    uv_map: str
    resolution: int
    margin: int
    pixels: np.ndarray
    positions: np.ndarray
    normals: np.ndarray
    stats: dict = field(default_factory=dict)  # raster counts, "warnings", "notes"
    triangles: np.ndarray | None = None  # int32 (T,): each texel's loop triangle
    tiles: list = field(default_factory=list)  # (UDIM number, first, end receiver) per tile
    uvs: np.ndarray | None = None  # float32 (3M, 2): the mesh's corner UVs, as gathered
    aa: int = 1  # anti-aliasing: aa × aa sub-samples per texel, texel-major (texel k's rows
    sub: tuple | None = None  # k·aa² ..): positions, normals, triangles; None when aa is 1


def split_tiles(uvs):
    """[(udim number, corner rows, (du, dv))] for corner UVs float32 (3M, 2): each triangle in
    the tile of its UV centroid, and the offset that moves that tile onto 0–1; plus the count
    of triangles outside UDIM's range 1001–1999 (u in [0, 10), v in [0, 100))."""
    tile = np.floor(uvs.reshape(-1, 3, 2).astype(np.float64).mean(axis=1))
    ok = np.all(np.isfinite(tile), axis=1)
    tile[~ok] = -1
    ok &= (tile[:, 0] >= 0) & (tile[:, 0] < 10) & (tile[:, 1] >= 0) & (tile[:, 1] < 100)
    number = np.where(ok, 1001 + tile[:, 0] + 10 * tile[:, 1], 0).astype(np.int64)
    out = []
    for n in np.unique(number[ok]):
        tris = np.flatnonzero(number == n)
        rows = (tris[:, None] * 3 + np.arange(3)).ravel()
        out.append((int(n), rows, ((n - 1001) % 10, (n - 1001) // 10)))
    return out, int(np.count_nonzero(~ok))


def spilling_triangles(uvs, udim):
    """How many triangles (corner UVs float32 (3M, 2)) have a corner outside the square they
    are baked into, a hair's tolerance aside: 0–1 (a non-finite UV counts), or with udim the
    UDIM tile of their centre (those in no tile are split_tiles' to count)."""
    t = uvs.reshape(-1, 3, 2).astype(np.float64)
    base = np.floor(t.mean(axis=1, keepdims=True)) if udim else np.zeros((1, 1, 2))
    with np.errstate(invalid="ignore"):
        inside = ((t >= base - 1e-6) & (t <= base + 1.0 + 1e-6)).all(axis=(1, 2))
        if udim:  # in no UDIM tile: not baked at all, counted by split_tiles
            b = base[:, 0]
            inside |= ~(np.isfinite(b).all(axis=1) & (b[:, 0] >= 0) & (b[:, 0] < 10)
                        & (b[:, 1] >= 0) & (b[:, 1] < 100))
    return int(np.count_nonzero(~inside))


def receivers(obj, depsgraph, uv_map=None, resolution=1024, margin=4, udim=False, aa=1):
    """The texels of obj's UV layout at resolution² as receivers (udim: of every UDIM tile its
    UVs use, tile by tile, split_tiles), with aa × aa sub-samples each when aa > 1
    (texel_points.subsamples). Raises CanopyAOError before reading anything when obj is not a mesh, has no
    (such) UV map, or the sizes are wrong, before rasterising when the bake would not fit in
    the available memory (texel_budget.check_memory), and after reading when no texel centre
    falls inside a face of the UV map."""
    if obj.type != "MESH":
        raise CanopyAOError(f"Object '{obj.name}' is not a mesh; only meshes can be baked per "
                            "texel")
    uv_map = resolve_uv_map(obj, uv_map)
    res = int(resolution)
    if not 1 <= res <= MAX_RESOLUTION:
        raise CanopyAOError(f"Resolution {resolution} is out of range; use 1 to "
                            f"{MAX_RESOLUTION} texels")
    if margin < 0:
        raise CanopyAOError(f"Margin must be >= 0 texels, not {margin}")
    aa = int(aa)
    if not 1 <= aa <= 8:
        raise CanopyAOError(f"Anti-aliasing must be 1 to 8 (sub-samples per texel side), not "
                            f"{aa}")
    uvs, pos, nrm = gather_corner_triangles(obj, depsgraph, uv_map)
    parts, outside = split_tiles(uvs) if udim else ([(1001, slice(None), (0, 0))], 0)
    if not parts:
        raise CanopyAOError(f"Object '{obj.name}': no triangle of UV map '{uv_map}' lies in a "
                            "UDIM tile (1001–1999: u in [0, 10), v >= 0); move its UVs there "
                            "or bake without UDIM Tiles")
    texel_budget.check_memory(obj.name, np.concatenate([uvs[r] for _n, r, _d in parts]), res,
                              aa, len(parts))
    got, tiles, stats = [], [], {}
    for number, rows, (du, dv) in parts:
        tile_uvs = np.ascontiguousarray(uvs[rows] - np.float32([du, dv]) if du or dv
                                        else uvs[rows])
        tile_pos, tile_nrm = np.ascontiguousarray(pos[rows]), np.ascontiguousarray(nrm[rows])
        px, tp, tn, st, tt = rasterize(tile_uvs, tile_pos, tile_nrm, res, res)
        reach = texel_points.reach(tile_uvs, tile_pos, tt, res) if aa > 1 else None
        tri_map = None
        if not isinstance(rows, slice):  # the tile's triangle k is the mesh's rows[3k] // 3
            tri_map = (rows[0::3] // 3).astype(np.int32)
            tt = tri_map[tt]
        sub = (texel_points.subsamples(tile_uvs, tile_pos, tile_nrm, res, aa, px, tp, tn, tt, tri_map,
                           reach) if aa > 1 else ())
        got.append((px, tp, tn, tt) + sub)
        start = tiles[-1][2] if tiles else 0
        tiles.append((number, start, start + len(px)))
        for k, v in st.items():
            stats[k] = stats.get(k, 0) + v
    pixels, tpos, tnrm, ttri, *sub = (np.concatenate([g[i] for g in got]) if len(got) > 1
                                      else got[0][i] for i in range(len(got[0])))
    stats.update(warnings=[], notes=[], uv_map=uv_map, resolution=res, texels=int(len(pixels)))
    if outside:
        stats["warnings"].append(f"Object '{obj.name}': {outside} triangles of UV map "
                                 f"'{uv_map}' lie outside the UDIM tiles 1001–1999 (u in "
                                 "[0, 10), v >= 0); they are not baked")
    spill = spilling_triangles(uvs, udim)
    if spill:
        stats["warnings"].append(f"Object '{obj.name}': {spill} triangles of UV map "
                                 f"'{uv_map}' reach outside the "
                                 f"{'UDIM tile of their centre' if udim else '0–1 square'}; "
                                 "what lies beyond is not baked (the image shows its edge "
                                 "there): pack the UVs inside"
                                 f"{'' if udim else ', or bake UDIM Tiles'}")
    if stats.get("overlapping_texels", 0) > 0:
        stats["warnings"].append(
            f"Object '{obj.name}': UV map '{uv_map}' overlaps ({stats['overlapping_texels']} "
            "texels lie in two or more faces); those texels show one face's AO. Unwrap without "
            "overlaps (UV > Smart UV Project) for a correct bake")
    if len(pixels) == 0:  # nothing to bake: refused, before anything is written
        raise CanopyAOError(f"Object '{obj.name}': no texel centre falls inside a face of its "
                            f"UV map '{uv_map}' at {res}×{res} (its UVs lie outside the "
                            f"{'UDIM tiles' if udim else '0–1 square'} or enclose no area); "
                            "unwrap it (UV > Smart UV Project), raise the resolution or bake "
                            "per vertex (nothing was changed)")
    return TexelReceivers(uv_map, res, int(margin), pixels, tpos, tnrm, stats, ttri, tiles, uvs,
                          aa, tuple(sub) if aa > 1 else None)


def splat(pixels, values, width, height, margin, background=1.0):
    """(image float32 (H, W), mask uint8 (H, W): 0 empty, 1 covered, 2 margin)."""
    img, mask = _core.splat_texels(np.ascontiguousarray(pixels, dtype=np.int32),
                                   np.ascontiguousarray(values, dtype=np.float32),
                                   (width, height), margin=int(margin),
                                   background=float(background), return_mask=True)
    return (np.asarray(img, dtype=np.float32).reshape(height, width),
            np.asarray(mask, dtype=np.uint8).reshape(height, width))


# === Blender image

def find_image(key, value, suffix="CanopyAO"):
    """Our image whose property key is value (OBJ_KEY: the object's name) holding map suffix."""
    for img in bpy.data.images:
        if img.get(TAG) and img.get(key) == value and img.get(MAP_KEY, "CanopyAO") == suffix:
            return img
    return None


def _retile(img, path, source, numbers=None):
    """Point img at path with source 'FILE' or 'TILED' (which finds name.<tile>.exr beside it
    and sets the <UDIM> token), keeping only the tiles in numbers: a tile no longer baked must
    not stay."""
    img.source = 'FILE'
    img.filepath = path
    img.source = source
    img.reload()
    if source == 'TILED' and numbers is not None:
        for tile in [t for t in img.tiles if t.number not in numbers]:
            img.tiles.remove(tile)


def load_image(obj, path, suffix="CanopyAO", key=OBJ_KEY, name=None, numbers=None,
               tiled=False):
    """(image, undo): our image of obj (or, key=tiles_io.ATLAS_KEY, of the atlas named obj),
    (re)loaded from path, tiled when asked (path: the first tile's file); undo() puts back
    what was."""
    value = obj if isinstance(obj, str) else obj.name
    img = find_image(key, value, suffix)
    if img is not None:
        old = (img.filepath, img.source, [t.number for t in img.tiles])

        def undo():
            _retile(img, *old)
    else:
        # Never touches a user image of the same name: load() makes a new datablock, and it
        # takes a free name (a taken one would be taken from the user's image).
        img = bpy.data.images.load(path, check_existing=False)
        img.name = ownership.free_name(bpy.data.images, name or f"{value}_{suffix}", img)
        img[TAG] = True
        img[key] = value
        img[MAP_KEY] = suffix

        def undo():
            bpy.data.images.remove(img)
    _retile(img, path, 'TILED' if tiled else 'FILE', numbers)
    img.colorspace_settings.name = "Non-Color"  # AO is data, not a colour to convert
    return img, undo


def bake_texel(context, obj, ao_fn, uv_map=None, resolution=1024, margin=4, image_dir=None,
               wire=True, aov_name="BakedAO", overwrite=False):
    """Bake AO per texel of obj's UV layout into an EXR and a Blender image, wired into obj's
    materials (wire_texel_ao) unless wire=False: the bake's texel path with any AO function.

    ao_fn(positions float32 (T, 3), normals float32 (T, 3)) -> float32 (T,) AO in [0, 1].
    Returns (image, stats); stats holds the raster counts, "path", "texels", "warnings"
    (e.g. overlapping UVs) and "notes". Raises CanopyAOError (a ValueError) before changing
    anything when obj is not a mesh, has no (such) UV map, or the resolution is out of range,
    or when the EXR would replace a file that is not its own (check_file) without overwrite.
    """
    if wire:
        materials.check_aov_name(aov_name)
    rx = receivers(obj, context.evaluated_depsgraph_get(), uv_map, resolution, margin)
    check_outputs([(image_path(obj, image_dir, [], make=False), Output(obj.name))], overwrite)
    ao = np.asarray(ao_fn(rx.positions, rx.normals), dtype=np.float32)
    if ao.shape != (len(rx.pixels),) or not np.all(np.isfinite(ao)):
        raise CanopyAOError(f"Object '{obj.name}': the AO model returned {ao.shape} values "
                            f"for {len(rx.pixels)} texels or non-finite AO")
    from .commit import Transaction
    txn = Transaction()
    try:
        image, stats = write_texels(obj, rx, np.clip(ao, 0.0, 1.0), image_dir, txn,
                                    overwrite=overwrite)
        if wire:
            stats["nodes_added"] = materials.wire_texel_ao(obj, image, rx.uv_map, aov_name)
    except BaseException:
        txn.rollback()
        raise
    txn.done()
    return image, stats


def write_texels(obj, rx, ao, image_dir, txn, suffix="CanopyAO", background=1.0,
                 overwrite=False, fmt="EXR"):
    """Splat AO (or another map: suffix names it) per texel into the image, write its file
    (format fmt, core/image_formats.py) and
    (re)load it as obj's image, each write recorded in txn (commit.Transaction; a replaced file
    is kept until txn.done()). Returns (image, stats)."""
    res = rx.resolution
    img_arr, mask = splat(rx.pixels, ao, res, res, rx.margin, background)
    stats = dict(rx.stats, margin_texels=int(np.count_nonzero(mask == 2)),
                 notes=list(rx.stats["notes"]))
    path = image_path(obj, image_dir, stats["notes"], suffix, fmt=fmt)
    write_own_file(path, img_arr, txn, Output(obj.name, suffix), overwrite, fmt)
    image, undo_image = load_image(obj, path, suffix)
    txn.add(undo_image)
    stats.update(path=path, writer="native", image=img_arr, mask=mask)
    return image, stats


