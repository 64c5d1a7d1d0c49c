"""A texel's anti-aliasing points: the aa × aa points over its footprint at which a texel
bake evaluates AO and averages (docs/DESIGN.md, 'Texel anti-aliasing and memory')."""

import numpy as np

from ..core.native import _core


def reach(uvs, pos, tris, res):
    """float64 (T,): how far (world) a sub-sample may lie from its texel's point: two texels'
    width on the texel's own triangle (√(3D area / UV area) / res): a neighbour across an edge
    stays within it, another island across a UV seam (near in UV, apart in 3D) does not."""
    u, p = uvs.reshape(-1, 3, 2).astype(np.float64), pos.reshape(-1, 3, 3).astype(np.float64)
    e, f = u[:, 1] - u[:, 0], u[:, 2] - u[:, 0]
    uv_area = np.abs(e[:, 0] * f[:, 1] - e[:, 1] * f[:, 0])
    area = np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = np.where(uv_area > 0, np.sqrt(area / uv_area), np.inf)
    return 2.0 * scale[tris] / res


# A texel's footprint's width, in texels: Cycles jitters its bake samples over the central half
# of each texel (Blender's bake_differentials halves the UV derivative, "A = 0.5f / A"), so
# ours averages that box (bench/texel_aa.py: edge texels 0.030 → 0.017 against a whole texel).
FOOTPRINT = 0.5


def subsamples(uvs, pos, nrm, res, aa, pixels, positions, normals, triangles, tri_map, reach):
    """The aa × aa sub-sample points of each texel in pixels (ascending), texel-major: pass
    (a, b) rasterises the UVs shifted by minus FOOTPRINT × ((a + ½)/aa − ½, (b + ½)/aa − ½)
    texels, so its texel centres are the sub-sample points of the unshifted image (the centres
    of an aa × aa grid over the footprint's box); a sub-sample lies on whichever triangle
    covers it there (across an edge: the neighbour), or, off the island, on the nearest one
    (conservative coverage). One that a pass does not reach, or that lies farther than reach
    (reach(): across a UV seam on another surface) from its texel's point, keeps the
    texel's own point. tri_map: the pass's triangle ids to the mesh's (or None)."""
    cols = ([], [], [])  # per sub-sample: positions, normals, triangles of every texel
    off = ((np.arange(aa) + 0.5) / aa - 0.5) * (FOOTPRINT / res)
    for b in range(aa):
        for a in range(aa):
            ts = _core.rasterize_uv(np.ascontiguousarray(uvs - np.float32([off[a], off[b]])),
                                    pos, nrm, resolution=(res, res), conservative=True)
            px = np.asarray(ts.pixels)  # views of ts's buffers, read before ts goes
            if not len(px):  # nothing covered: every sub-sample is its texel's own point
                return tuple(np.repeat(x, aa * aa, 0) for x in (positions, normals, triangles))
            at = np.minimum(np.searchsorted(px, pixels), len(px) - 1)
            tp, tt = np.asarray(ts.positions).reshape(-1, 3)[at], np.asarray(ts.triangles)[at]
            d = tp - positions
            hit = (px[at] == pixels) & (np.einsum("ij,ij->i", d, d) <= reach * reach)
            cols[0].append(np.where(hit[:, None], tp, positions))
            cols[1].append(np.where(hit[:, None], np.asarray(ts.normals).reshape(-1, 3)[at],
                                    normals))
            cols[2].append(np.where(hit, tri_map[tt] if tri_map is not None else tt,
                                    triangles).astype(np.int32))
    return tuple(np.stack(c, axis=1).reshape((-1, 3) if c[0].ndim == 2 else -1)
                 for c in cols)
