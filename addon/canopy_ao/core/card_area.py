"""Leaf cards by their opaque part (docs/DESIGN.md, 'Opacity of leaf cards'; issue #38 item 2):
what weighs leaf area (the density grids, the crown fits) counts a card's triangle by the part
of it its material's alpha keeps, and where that part is. No bpy."""

from __future__ import annotations

import numpy as np

from .opacity import MaterialAlpha, srgb_decode

# A card's triangle is counted by the opaque part of it (docs/DESIGN.md, 'Opacity of leaf
# cards'): its alpha averaged over SUBDIVISIONS² points, the centroids of the triangles of its
# regular subdivision (an equal-area stratification), and where: the alpha-weighted centroid.
SUBDIVISIONS = 8
_CHUNK = 1 << 14  # triangles per batch (SUBDIVISIONS² points each)


def _subdivision_points(n=SUBDIVISIONS):
    """float64 (n², 2): barycentric (b1, b2) of the centroids of a triangle's n² sub-triangles
    (its regular subdivision: n(n+1)/2 upright, n(n−1)/2 inverted)."""
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    up = (i + j <= n - 1)
    down = (i + j <= n - 2)
    return np.concatenate([np.stack([i[up] + 1 / 3, j[up] + 1 / 3], 1),
                           np.stack([i[down] + 2 / 3, j[down] + 2 / 3], 1)]) / n


def texture_alpha(mat: MaterialAlpha, uv):
    """Alpha in [0, 1] of material ``mat`` at UVs float (N, 2), read as the tracer reads it:
    bilinear between texel centres (or the texel the UV falls in, when nearest) with wrap,
    then offset + scale × the value (sRGB-decoded first when srgb)."""
    uv = np.asarray(uv, np.float64).reshape(-1, 2)
    if mat.texture is None:
        return np.full(len(uv), float(mat.alpha))
    tex = mat.texture
    h, w = tex.shape
    if mat.nearest:
        t = tex[np.floor(uv[:, 1] * h).astype(np.int64) % h,
                np.floor(uv[:, 0] * w).astype(np.int64) % w].astype(np.float64)
    else:
        x, y = uv[:, 0] * w - 0.5, uv[:, 1] * h - 0.5
        x0, y0 = np.floor(x), np.floor(y)
        fx, fy = x - x0, y - y0
        i0, j0 = x0.astype(np.int64) % w, y0.astype(np.int64) % h
        i1, j1 = (i0 + 1) % w, (j0 + 1) % h
        t = ((1 - fy) * ((1 - fx) * tex[j0, i0] + fx * tex[j0, i1])
             + fy * ((1 - fx) * tex[j1, i0] + fx * tex[j1, i1]))
    if mat.srgb:
        t = srgb_decode(t)
    return np.clip(mat.offset + mat.scale * t, 0.0, 1.0)


def _clear_triangles(item):
    """(triangles int64 (M, 3), bool (M,) of those whose material is not opaque, slot (M,)),
    or None when the item has no such triangle."""
    op = getattr(item, "opacity", None)
    tris = np.asarray(item.triangles, np.int64).reshape(-1, 3)
    if op is None or not len(tris) or len(op.triangle_material) != len(tris) \
            or all(m.opaque for m in op.materials):
        return None
    slot = np.clip(np.asarray(op.triangle_material, np.int64), 0, len(op.materials) - 1)
    return tris, np.array([not m.opaque for m in op.materials])[slot], slot


def _sampled(item):
    """Per batch of the item's triangles whose material is not opaque: (their indices int64
    (m,), corners float64 (m, 3, 3), sample points float64 (m, S, 3), alpha there (m, S)), the
    samples the centroids of each triangle's regular subdivision; nothing when it has none."""
    got = _clear_triangles(item)
    if got is None:
        return
    tris, clear, slot = got
    op = item.opacity
    bary = _subdivision_points()
    w = np.column_stack([1.0 - bary.sum(1), bary])  # (S, 3) weights of the corners
    p = np.asarray(item.positions, np.float64)
    for k, mat in enumerate(op.materials):
        sel = np.flatnonzero(clear & (slot == k))
        for a in range(0, len(sel), _CHUNK):
            s = sel[a:a + _CHUNK]
            corners = p[tris[s]]
            uv = np.einsum("sc,mcd->msd", w, np.asarray(op.uvs[s], np.float64)) \
                if op.uvs is not None and mat.texture is not None else np.zeros((len(s), len(w), 2))
            alpha = texture_alpha(mat, uv.reshape(-1, 2)).reshape(len(s), -1)
            yield s, corners, np.einsum("sc,mcd->msd", w, corners), alpha


def opaque_parts(item):
    """(corners float64 (K, 3, 3), source int64 (K,)): each triangle of ``item`` whose material
    is not opaque and that has an opaque point, shrunk by √(its mean alpha) and moved to the
    alpha-weighted centroid of its area (so its area is its opaque area, centred where that
    is), and its index in the item's triangles; None when the item has no such triangle."""
    if _clear_triangles(item) is None:
        return None
    out, src = [np.zeros((0, 3, 3))], [np.zeros(0, np.int64)]
    for s, corners, pts, alpha in _sampled(item):
        f = alpha.mean(1)
        centre = np.einsum("ms,msd->md", alpha, pts) / np.maximum(alpha.sum(1), 1e-300)[:, None]
        g = corners.mean(1)
        ok = f > 0
        out.append(centre[ok, None, :]
                   + np.sqrt(f[ok])[:, None, None] * (corners[ok] - g[ok, None, :]))
        src.append(s[ok])
    return np.concatenate(out), np.concatenate(src)


def opaque_corners(item):
    """(points float64 (K, 3, 3), source int64 (K,)): for each triangle of ``item`` whose
    material is not opaque and that has an opaque point, the opaque point nearest each of its
    corners (among its subdivision's centroids, those of alpha ≥ ½, else of its highest alpha:
    on the card, where it is opaque), and its index in the item's triangles; None when the
    item has no such triangle."""
    if _clear_triangles(item) is None:
        return None
    out, src = [np.zeros((0, 3, 3))], [np.zeros(0, np.int64)]
    for s, corners, pts, alpha in _sampled(item):
        ok = alpha.max(1) > 0
        opaque = alpha >= np.minimum(0.5, alpha.max(1, keepdims=True))
        d = ((pts[:, None, :, :] - corners[:, :, None, :]) ** 2).sum(-1)  # (m, 3, S)
        d = np.where(opaque[:, None, :], d, np.inf)
        near = np.argmin(d, axis=2)  # (m, 3)
        out.append(np.take_along_axis(pts, near[:, :, None], axis=1)[ok])
        src.append(s[ok])
    return np.concatenate(out), np.concatenate(src)


def counted_triangles(item):
    """(positions float32 (V', 3), triangles int32 (M', 3)) of an item's triangles as leaf area
    counts them: an opaque triangle as it is, one whose material is not opaque as
    opaque_parts gives it, so its area is its opaque area and it sits where it is opaque (one
    with no opaque point dropped). An item without such triangles gives its own arrays back,
    untouched."""
    got = _clear_triangles(item)
    if got is None:
        return item.positions, item.triangles
    tris, clear, _slot = got
    shrunk, _src = opaque_parts(item)
    n = len(item.positions)
    verts = np.concatenate([np.asarray(item.positions, np.float64), shrunk.reshape(-1, 3)])
    keep = np.concatenate([tris[~clear], n + np.arange(3 * len(shrunk)).reshape(-1, 3)])
    return (np.ascontiguousarray(verts, np.float32), np.ascontiguousarray(keep, np.int32))


def counted_item(item):
    """A copy of ``item`` whose positions and triangles are counted_triangles' (the item
    itself when nothing changes), for what weighs leaf area: the density grid, the ray-free
    rung's grid."""
    p, t = counted_triangles(item)
    if p is item.positions:
        return item
    from .scene import SceneItem
    return SceneItem(item.name, item.role, item.tree, p, np.zeros_like(p), t,
                     tree_source=item.tree_source)


def counted_points(item):
    """float32 (N, 3): the points a crown's proxies are fitted to: the vertices of the
    item's triangles as counted (counted_triangles), its own positions when nothing changes."""
    p, t = counted_triangles(item)
    if p is item.positions:
        return p
    return np.ascontiguousarray(p[np.unique(t)])
