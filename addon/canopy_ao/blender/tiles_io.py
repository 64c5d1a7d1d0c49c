"""Texel bakes beyond one object's 0–1 tile (docs/DESIGN.md, 'Maps'): every UDIM tile a mesh's
UVs use (one EXR per tile, one tiled Blender image with the ``<UDIM>`` token), and several
objects sharing one UV atlas baked into one image, with the texels two objects claim reported.

The native rasteriser covers the 0–1 square; a tile's triangles are shifted into it (tile
1001 + u + 10 v holds the triangles whose UV centroid lies in [u, u+1) × [v, v+1)), so each
tile is rasterised and dilated on its own and its margin never bleeds into a neighbour.
"""

import os
from types import SimpleNamespace

import numpy as np

from . import cycles_check, files_io, texel_io
from ..core import metrics
from ..core.native import CanopyAOError

ATLAS_KEY = "canopy_ao_atlas"  # on an atlas image: the atlas's name


def write_tiled(owner, parts, image_dir, txn, suffix="CanopyAO", tiled=False, atlas=False,
                background=1.0, overwrite=False, fmt="EXR"):
    """Splat every part's values per tile, write one file per tile (format fmt) and load them
    as one image.

    owner: the object (or, atlas=True, the atlas's name) the image belongs to; parts:
    [(TexelReceivers, values float32 (T,))] of the objects writing it (values in receiver
    order, rx.tiles saying which rows are which tile). A texel two parts claim keeps the later
    part's value. Returns (image, stats): "tiles" {number: (image (H, W), mask)}, "paths",
    "claimed" {number: claims per texel}, "shared_texels" (texels claimed twice or more)."""
    rx0 = parts[0][0]
    res, margin = rx0.resolution, rx0.margin
    notes = []
    name = owner if atlas else owner.name

    def out(tile):
        return files_io.Output(name, suffix, tile, atlas)
    path0 = files_io.image_path(SimpleNamespace(name=name), image_dir, notes, suffix, fmt=fmt)
    numbers = sorted({n for rx, _v in parts for n, _a, _b in rx.tiles})
    if tiled:  # our tiles of an earlier bake that this one does not write go too (ours only)
        (d, stem), ext = os.path.split(os.path.splitext(path0)[0]), os.path.splitext(path0)[1]
        for f in os.listdir(d):
            rest = f[len(stem) + 1:-len(ext)] if f.startswith(stem + ".") else ""
            if (f.endswith(ext) and rest.isdigit() and int(rest) not in numbers
                    and files_io.check_file(os.path.join(d, f), out(int(rest))) is None):
                files_io.remove_file(os.path.join(d, f), txn)
    stats = {"tiles": {}, "paths": [], "claimed": {}, "notes": notes}
    # The image's undo is recorded before the files' so that a rollback runs it after theirs,
    # when the old tile files are back for it to find.
    undo_image = []
    txn.add(lambda: undo_image and undo_image[0]())
    for n in numbers:
        pix = [rx.pixels[a:b] for rx, _v in parts for m, a, b in rx.tiles if m == n]
        val = [np.asarray(v)[a:b] for rx, v in parts for m, a, b in rx.tiles if m == n]
        claims = np.bincount(np.concatenate(pix), minlength=res * res).reshape(res, res)
        img, mask = texel_io.splat(np.concatenate(pix), np.concatenate(val), res, res, margin,
                                   background)
        path = files_io.tile_path(path0, n) if tiled else path0
        files_io.write_own_file(path, img, txn, out(n if tiled else None), overwrite, fmt)
        stats["tiles"][n], stats["claimed"][n] = (img, mask), claims
        stats["paths"].append(path)
    stats["shared_texels"] = int(sum(np.count_nonzero(c > 1) for c in stats["claimed"].values()))
    image, undo = texel_io.load_image(owner, stats["paths"][0], suffix,
                                      ATLAS_KEY if atlas else texel_io.OBJ_KEY,
                                      numbers=numbers, tiled=tiled)
    undo_image.append(undo)
    return image, stats


def own_mask(rx, number, res):
    """bool (H, W): the texels of tile ``number`` that rx's object covers."""
    m = np.zeros(res * res, bool)
    for n, a, b in rx.tiles:
        if n == number:
            m[rx.pixels[a:b]] = True
    return m.reshape(res, res)


def write_atlas(targets, txn, opts):
    """Every texel target into one image named opts["atlas"] (and the thickness into another),
    each object wired to it; a note names the objects whose texels overlap."""
    name, tiled = opts["atlas"], opts["udim"]
    image, st = write_tiled(name, [(t.rx, t.ao) for t in targets], opts["image_dir"] or None,
                            txn, tiled=tiled, atlas=True, overwrite=opts["overwrite"],
                            fmt=opts["image_format"])
    timage = None
    if targets[0].thickness is not None:
        timage, _ts = write_tiled(name, [(t.rx, t.thickness) for t in targets],
                                  opts["image_dir"] or None, txn, suffix=opts["thickness_name"],
                                  tiled=tiled, atlas=True, background=0.0,
                                  overwrite=opts["overwrite"], fmt=opts["image_format"])
    overlaps = []
    for i, t in enumerate(targets):
        shared = 0
        for n, (img, _mask) in st["tiles"].items():
            mine = own_mask(t.rx, n, t.rx.resolution)
            shared += int(np.count_nonzero(mine & (st["claimed"][n] > 1)))
        t.stats = dict(t.rx.stats, atlas=name, path=st["paths"][0], paths=st["paths"],
                       shared_texels=shared, tiles=sorted(st["tiles"]), notes=st["notes"],
                       image_tiles=st["tiles"], claimed_tiles=st["claimed"])
        if shared:
            overlaps.append(f"{t.obj.name} ({shared})")
        t.wire(txn, opts, image, timage)
    if overlaps:
        targets[0].stats.setdefault("warnings", []).append(
            f"atlas '{name}': {st['shared_texels']} texels are claimed by two or more objects "
            f"(texels per object: {', '.join(overlaps)}); each shows the last object's value")
    return st


def check_tiles(context, t, distance, samples):
    """Cycles' AO bake compared texel by texel on every tile the target wrote: the mesh's UVs
    are shifted so each tile in turn lies on 0–1 (and put back), and only the object's own
    covered texels count (not the margin, not another object's in an atlas)."""
    me = t.obj.data
    layer = me.uv_layers[t.rx.uv_map]
    uv = np.empty(len(layer.data) * 2, np.float32)
    layer.data.foreach_get("uv", uv)
    ours, ref, per_tile = [], [], {}
    try:
        for n, (img, _mask) in t.stats["image_tiles"].items():
            shift = np.array([(n - 1001) % 10, (n - 1001) // 10], np.float32)
            layer.data.foreach_set("uv", (uv.reshape(-1, 2) - shift).ravel())
            me.update()
            r, m = cycles_check.bake_cycles_texel_ao(context, t.obj, t.rx.uv_map, len(img),
                                                     distance, samples, return_mask=True)
            m &= own_mask(t.rx, n, len(img))
            if "claimed_tiles" in t.stats:  # an atlas: texels another object also claims
                m &= t.stats["claimed_tiles"][n] == 1  # may show that object's value
            if np.any(m):
                ours.append(img[m])
                ref.append(r[m])
                per_tile[n] = float(np.abs(img[m] - r[m]).mean())
    finally:
        layer.data.foreach_set("uv", uv)
        me.update()
    if not ours:
        raise CanopyAOError(f"{t.obj.name}: Cycles covered none of its texels")
    out = {k: float(v) for k, v in metrics.compare(np.concatenate(ours),
                                                   np.concatenate(ref)).items()}
    out["mae_per_tile"] = per_tile
    return out

