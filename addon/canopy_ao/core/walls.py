"""GROUND surfaces as solid occluders of the proxy rungs (docs/DESIGN.md, 'How each role is
lit'): a wall an ivy climbs, a rock face, the ground under a wall.

The GROUND items' triangles are grouped by the plane they lie in (their unit normal to within
PLANE_ANGLE, their offset to within PLANE_OFFSET of the surfaces' diagonal: scale-free), and
each plane's triangles are replaced by the convex hull of their corners in that plane, a
patch, where they cover at least COVERAGE of it (else they are facets of a curved surface
scattered over one plane, and left out). A receiver sees a patch as an opaque polygon: its
cosine-weighted form factor (Lambert's contour integral, exact for a polygon) after clipping
it to the receiver's hemisphere and to the AO distance (the patch's plane meets the sphere of
radius D in a disc; the disc is a DISC_SIDES-gon of its area). Patches are summed (solid
surfaces meeting at an edge, a wall on a ground, mostly cover different directions) and
clipped to 1: V = 1 − Σ F.

A receiver on a patch's plane (its own surface, or the ground under a wall's foot: within EPS
of the patch's size) is moved that hair off it to the patch's front (its triangles' side), so
a flat ground sees itself edge-on (F = 0) and the wall's foot sees the ground fill the lower
half of its hemisphere.

A bake makes every GROUND plane a patch, a flat ground alone too: it occludes what stands above
it (leaves facing down, a trunk's foot) as it does for rays. Live frames rebuild patches only
when a GROUND surface holds a wall (a solid plane steeper than 45°, STEEP; has_wall), then of
every plane; a ground alone's occlusion they hold from the first bake (core/live.held_ground:
its patch costs a frame tens of times a rung's own evaluation, DESIGN).
"""

from __future__ import annotations

import hashlib

import numpy as np

from . import native

PLANE_ANGLE = 0.02      # normals in one plane: unit normals within this (radians, ≈ 1.1°)
PLANE_OFFSET = 1e-3     # offsets within this share of the surfaces' bounding diagonal
MAX_PATCHES = 64        # the largest planes by area; the rest are left out (see DESIGN)
COVERAGE = 0.5          # a plane's triangles cover at least this share of their hull
DISC_SIDES = 8          # the AO distance's disc as a regular polygon of its area
EPS = 1e-5              # on a patch's plane: this share of the patch's diameter from it
CHUNK = 8192            # receivers per numpy block
# Live frames rebuild patches only where a GROUND surface has a wall: a solid plane steeper
# than 45° (Blender's Z up). A ground alone's they hold from the first bake: their evaluation
# costs ~0.13-0.25 µs per receiver and patch natively (numpy 0.8-5 µs), tens of times an
# analytic rung's own (docs/DESIGN.md), each frame.
STEEP = np.cos(np.pi / 4)


class Patch:
    """One plane's opaque convex polygon: corners (K, 3) float64, unit normal m (its
    triangles' area-weighted side), area, diameter."""

    def __init__(self, corners, normal, area):
        self.corners = corners
        self.normal = normal
        self.area = float(area)
        self.offset = float(normal @ corners.mean(0))
        self.diameter = float(np.linalg.norm(corners.max(0) - corners.min(0)))


_LAST = [None, []]  # the last build's (key, patches): live frames over a still ground


def has_wall(patches) -> bool:
    """Whether some patch is a wall: steeper than 45° (STEEP)."""
    return any(abs(pt.normal[2]) < STEEP for pt in patches)


def build(items) -> list:
    """The patches of every GROUND item with triangles (an empty list when there are none).
    The same GROUND geometry as the last call's (a live frame's) returns its patches."""
    ground = [it for it in items if it.role == "GROUND" and len(it.triangles)]
    if not ground:
        return []
    h = hashlib.blake2b(digest_size=16)
    for it in ground:
        for a in (it.positions, it.triangles):
            a = np.ascontiguousarray(a)
            h.update(str((a.dtype, a.shape)).encode())
            h.update(memoryview(a).cast("B"))
    key = h.digest()
    if _LAST[0] != key:
        _LAST[:] = [key, _build(ground)]
    return list(_LAST[1])


def _build(ground) -> list:
    first = np.cumsum([0] + [len(it.positions) for it in ground])
    pos = np.concatenate([it.positions for it in ground]).astype(np.float64)
    tri = np.concatenate([it.triangles + f for it, f in zip(ground, first)])
    t = pos[tri]  # (T, 3, 3)
    cross = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    dbl = np.linalg.norm(cross, axis=1)
    ok = dbl > 1e-12 * max(float(dbl.max()), 1e-30)
    t, tri, cross, dbl = t[ok], tri[ok], cross[ok], dbl[ok]
    if not len(t):
        return []
    m = cross / dbl[:, None]
    lo, hi = t.reshape(-1, 3).min(0), t.reshape(-1, 3).max(0)
    diag = max(float(np.linalg.norm(hi - lo)), 1e-30)
    d = np.einsum("ij,ij->i", m, t.mean(1))
    step = PLANE_OFFSET * diag
    # one int64 per (normal, offset) cell: normals' cells within ±64, offsets' within ±2^20
    key = np.round(m / PLANE_ANGLE).astype(np.int64) + 64
    key = (key[:, 0] * 128 + key[:, 1]) * 128 + key[:, 2]
    key = key * (1 << 21) + np.round(d / step).astype(np.int64) + (1 << 20)
    _, group = np.unique(key, return_inverse=True)
    group = group.reshape(-1)
    area = np.bincount(group, dbl * 0.5)
    gm = np.column_stack([np.bincount(group, cross[:, k], len(area)) for k in range(3)])
    gm /= np.maximum(np.linalg.norm(gm, axis=1, keepdims=True), 1e-300)
    gd = np.bincount(group, d * dbl) / np.maximum(np.bincount(group, dbl), 1e-300)
    # one plane cut by the rounding into two keys is one patch again: the largest pieces
    # first, each joining the first plane within a step of it
    planes, members = [], []
    for g in np.argsort(-area)[:4 * MAX_PATCHES]:
        for j, (pm, pd) in enumerate(planes):
            if np.linalg.norm(gm[g] - pm) < PLANE_ANGLE and abs(gd[g] - pd) < step:
                members[j].append(g)
                break
        else:
            planes.append((gm[g], gd[g]))
            members.append([g])
    order = np.argsort([-area[g].sum() for g in map(np.array, members)])
    patches = []
    for j in order:
        if len(patches) == MAX_PATCHES:
            break
        sel = np.isin(group, members[j])
        normal = cross[sel].sum(0)
        normal /= max(np.linalg.norm(normal), 1e-30)
        hull = _hull_in_plane(pos[np.unique(tri[sel])], normal)
        if hull is None:
            continue
        covered = area[members[j]].sum()
        hull_area = 0.5 * abs(float(np.cross(hull, np.roll(hull, -1, axis=0)).sum(0) @ normal))
        # facets of a curved surface that happen to share a plane, far apart, are no solid
        # piece of it: their hull would be a sheet where there is none
        if covered >= COVERAGE * hull_area:
            patches.append(Patch(hull, normal, covered))
    return patches


def _hull_in_plane(points, normal):
    """The convex hull (K, 3), counter-clockwise about normal, of points projected on their
    mean plane; None when it has no area."""
    u = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    c = points.mean(0)
    q = np.column_stack([(points - c) @ u, (points - c) @ v])
    # Akl–Toussaint: points inside the octagon of the extreme points in 8 directions are not
    # on the hull (a subdivided ground keeps only its rim)
    a = np.arange(8) * np.pi / 4
    ext = q[np.argmax(q @ np.stack([np.cos(a), np.sin(a)]), axis=0)]
    ext = ext[np.sort(np.unique(ext, axis=0, return_index=True)[1])]
    if len(ext) >= 3:
        e = np.roll(ext, -1, axis=0) - ext
        side = e[:, 0] * (q[:, None, 1] - ext[:, 1]) - e[:, 1] * (q[:, None, 0] - ext[:, 0])
        q = q[~np.all(side > 1e-12 * max(float(np.abs(q).max()), 1e-300), axis=1)]
    q = np.unique(q, axis=0)
    if len(q) < 3:
        return None

    def half(pts):
        out = []
        for p in pts:
            while len(out) >= 2 and np.cross(out[-1] - out[-2], p - out[-2]) <= 0:
                out.pop()
            out.append(p)
        return out[:-1]
    h = np.array(half(q) + half(q[::-1]))  # Andrew's monotone chain
    if len(h) < 3:
        return None
    return c + h[:, :1] * u + h[:, 1:] * v


def visibility(patches, p, n, distance=np.inf, near=0.0) -> np.ndarray:
    """float32 (N,): 1 − Σ over patches of the form factor each covers of the receivers'
    hemisphere between `near` and `distance`, clipped to [0, 1]; all ones without patches.
    The native module's patch_visibility computes it (the same numbers in float64, 6–41×
    faster: bench/walls_speed.py); visibility_numpy, the reference, where the module is not
    loaded."""
    if not patches or len(p) == 0 or native._core is None:
        return visibility_numpy(patches, p, n, distance, near)
    corners = np.ascontiguousarray(np.concatenate([pt.corners for pt in patches]), np.float64)
    counts = np.array([len(pt.corners) for pt in patches], np.int32)
    planes = np.array([[*pt.normal, pt.offset, pt.diameter] for pt in patches], np.float64)
    return native._core.patch_visibility(
        corners, counts, planes, np.ascontiguousarray(p, np.float64),
        np.ascontiguousarray(n, np.float64), float(distance), float(near))


def visibility_numpy(patches, p, n, distance=np.inf, near=0.0) -> np.ndarray:
    """visibility in numpy (CHUNK receivers at a time), the native function's reference."""
    N = len(p)
    out = np.ones(N, np.float32)
    if not patches or N == 0:
        return out
    p = np.asarray(p, np.float64)
    n = np.asarray(n, np.float64)
    for a in range(0, N, CHUNK):
        pp, nn = p[a:a + CHUNK], n[a:a + CHUNK]
        occ = np.zeros(len(pp))
        for patch in patches:
            occ += _form_factor(patch, pp, nn, distance)
            if near > 0:
                occ -= _form_factor(patch, pp, nn, near)
        out[a:a + CHUNK] = np.clip(1.0 - occ, 0.0, 1.0)
    return out


def _form_factor(patch, p, n, distance):
    """(N,) the cosine-weighted share of each receiver's hemisphere the patch covers within
    `distance` of it: 0 where the patch is wholly below its horizon or out of reach."""
    out = np.zeros(len(p))
    above = np.einsum("kj,nj->nk", patch.corners, n) - np.einsum("nj,nj->n", p, n)[:, None]
    live = np.any(above > EPS * patch.diameter, axis=1) & (
        np.abs(p @ patch.normal - patch.offset) < distance)
    if np.any(live):
        out[live] = _form_factor_of(patch, p[live], n[live], distance)
    return out


def _form_factor_of(patch, p, n, distance):
    m = patch.normal
    eps = EPS * patch.diameter
    x = p.copy()
    h = x @ m - patch.offset
    flat = np.abs(h) < eps
    x[flat] += (eps - h[flat])[:, None] * m
    h[flat] = eps
    poly = patch.corners[None] - x[:, None]  # (N, K, 3), relative to each receiver
    mask = np.ones(poly.shape[:2], bool)
    # the receiver's hemisphere: n · v ≥ 0
    poly, mask = _clip(poly, mask, n, np.zeros(len(x)))
    if np.isfinite(distance):
        r2 = distance * distance - h * h
        reach = r2 > 0
        far = np.linalg.norm(poly, axis=2).max(1, where=mask, initial=0.0) > distance
        todo = reach & far
        if np.any(todo):
            # the disc of radius sqrt(D² − h²) around the receiver's foot on the plane, as a
            # DISC_SIDES-gon of its area: a half-space per side, its outward normal w in-plane
            r = np.sqrt(np.maximum(r2, 0.0)) * np.sqrt(
                2 * np.pi / (DISC_SIDES * np.sin(2 * np.pi / DISC_SIDES)))
            u = np.cross(m, [1.0, 0.0, 0.0] if abs(m[0]) < 0.9 else [0.0, 1.0, 0.0])
            u /= np.linalg.norm(u)
            v = np.cross(m, u)
            sub_p, sub_m = poly[todo], mask[todo]
            foot = -h[todo, None] * m  # the foot relative to the receiver
            for k in range(DISC_SIDES):
                ang = 2 * np.pi * (k + 0.5) / DISC_SIDES
                w = np.cos(ang) * u + np.sin(ang) * v
                # keep w · (v − foot) ≤ r·cos(π/K)  ⇔  (−w) · v ≥ −(r·cos + w·foot)
                lim = r[todo] * np.cos(np.pi / DISC_SIDES) + foot @ w
                sub_p, sub_m = _clip(sub_p, sub_m, np.broadcast_to(-w, foot.shape), -lim)
            full = np.zeros((len(x), max(poly.shape[1], sub_p.shape[1]), 3))
            fm = np.zeros(full.shape[:2], bool)
            full[:, :poly.shape[1]] = poly
            fm[:, :mask.shape[1]] = mask
            full[todo] = 0.0
            fm[todo] = False
            full[todo, :sub_p.shape[1]] = sub_p
            fm[todo, :sub_m.shape[1]] = sub_m
            poly, mask = full, fm
        poly = poly.copy()
        mask = mask & reach[:, None]
    return _lambert(poly, mask, n)


def _clip(poly, mask, w, c):
    """Each receiver's convex polygon (valid corners first, in order) clipped to w · v ≥ c
    (Sutherland–Hodgman). Returns the polygons compacted, valid corners first."""
    N, K = mask.shape
    count = mask.sum(1)
    idx = np.arange(K)
    nxt = np.where(idx[None] + 1 < count[:, None], idx[None] + 1, 0)
    b = np.take_along_axis(poly, nxt[:, :, None], axis=1)
    sa = np.einsum("nkj,nj->nk", poly, w) - c[:, None]
    sb = np.take_along_axis(sa, nxt, axis=1)
    ina, inb = (sa >= 0) & mask, (sb >= 0) & mask
    cut = mask & (ina != inb)
    tt = np.where(cut, sa / np.where(cut, sa - sb, 1.0), 0.0)
    cross = poly + tt[:, :, None] * (b - poly)
    slots = np.stack([poly, cross], axis=2).reshape(N, 2 * K, 3)
    keep = np.stack([ina, cut], axis=2).reshape(N, 2 * K)
    width = max(int(keep.sum(1).max(initial=0)), 1)  # never more than K + 1 (convex)
    order = np.argsort(~keep, axis=1, kind="stable")[:, :width]
    rows = np.arange(N)[:, None]
    return slots[rows, order], keep[rows, order]


def _lambert(poly, mask, n):
    """(N,) the form factor of each receiver's polygon (corners relative to it, valid first):
    |Σ θ_i n · (v_i × v_i+1)/|v_i × v_i+1|| / 2π over its edges."""
    count = mask.sum(1)
    K = mask.shape[1]
    idx = np.arange(K)
    nxt = np.where(idx[None] + 1 < count[:, None], idx[None] + 1, 0)
    a = poly / np.maximum(np.linalg.norm(poly, axis=2, keepdims=True), 1e-300)
    b = np.take_along_axis(a, nxt[:, :, None], axis=1)
    c = np.cross(a, b)
    s = np.linalg.norm(c, axis=2)
    theta = np.arctan2(s, np.einsum("nkj,nkj->nk", a, b))
    term = np.where(mask & (s > 1e-12), theta * np.einsum("nkj,nj->nk", c, n) /
                    np.maximum(s, 1e-300), 0.0)
    f = np.abs(term.sum(1)) / (2 * np.pi)
    return np.where(count >= 3, np.minimum(f, 1.0), 0.0)
