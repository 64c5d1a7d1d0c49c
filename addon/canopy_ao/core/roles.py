"""Guess what part a mesh plays in a vegetation scene from its geometry alone (no bpy).

Roles (docs/DESIGN.md, 'How each role is lit'):
- ``CANOPY``: leaves; its points fit the proxies, and it receives.
- ``TRUNK``: receives, and occludes the ground as a solid.
- ``GROUND``: a surface things stand on or climb: a flat ground, a slope, a wall or a rock face
  (a sheet or a plate in any orientation); receives, and is traced as an occluder by rays.
- ``GRASS``: many small disconnected blades standing on one plane; receives (its field's blade
  layer, grass_layer.py).
- ``IGNORE``: takes no part.

Everything here works on whole numpy arrays; there is no per-vertex Python loop.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .native import require

ROLES = ("CANOPY", "TRUNK", "GROUND", "GRASS", "IGNORE")

# A piece is "many small disconnected pieces" when the mesh has at least this many components.
MANY_COMPONENTS = 24
# Flat: the thinnest extent is below this fraction of the widest.
FLAT_RATIO = 0.05
# A surface (a wall, a rock face, a slope: few pieces, any orientation): the area-weighted
# normals share one direction — λmax of Σ a n nᵀ / Σ a (piece_shape's plate) at least this.
# A sheet or a thin slab is near 1 (a 3 × 2 × 0.5 box 0.71), a tube ≤ 0.5 however it bends or
# forks, a cube or a ball 1/3: scale-free, and blind to how the surface is turned.
SURFACE_PLATE = 0.7
# ... or it is an open sheet, bumps and all (a rough rock face, a terrain): its area-weighted
# mean normal (piece_shape's openness) at least this; a tube, open at its ends, is near 0.
SURFACE_OPEN = 0.5


def _group_min_max(values, labels, k):
    """Per-label min and max of values (N, D) for labels in [0, k) (each label present)."""
    order = np.argsort(labels, kind="stable")
    starts = np.searchsorted(labels[order], np.arange(k))
    v = values[order]
    return np.minimum.reduceat(v, starts, axis=0), np.maximum.reduceat(v, starts, axis=0)


def connected_components(n_vertices: int, triangles: np.ndarray) -> np.ndarray:
    """Label each vertex with its connected component.

    n_vertices: V. triangles: #F by 3 int array of vertex indices in [0, V) (any integer
    dtype and layout; rows of 3).
    Returns int64 (V,) labels in [0, #components), numbered in order of first vertex.
    Vertices used by no triangle are components of their own.

    Native union-find (mesh_components.h): near-linear in V + F, whatever the mesh's diameter
    (numpy's bulk pointer jumping took 0.25 s on a 250k-vertex Sapling branch mesh, a third of
    the role guess). Raises ValueError for an index outside [0, V).
    """
    tris = np.asarray(triangles).reshape(-1, 3)
    if len(tris) and (tris.min() < 0 or tris.max() >= n_vertices):
        raise ValueError(f"triangles hold vertex indices outside [0, {n_vertices})")
    return require().connected_components(int(n_vertices),
                                          np.ascontiguousarray(tris, dtype=np.int32))


@dataclass
class MeshStats:
    """Geometry facts a role guess rests on (world space)."""

    n_vertices: int
    n_components: int
    extent: np.ndarray  # (3,) bounding-box size, sorted largest first
    z_extent: float
    xy_extent: float
    component_size_ratio: float  # median component diagonal / object diagonal
    base_spread: float  # spread of component lowest z, relative to the object's diagonal
    component_aspect: float  # median component height / width (blades are tall and thin)
    component_flatness: float  # median λmin/λmid of each piece's covariance: 0 = flat card
    labels: np.ndarray = field(repr=False, default=None)
    tube_fraction: float = 0.0  # share of the surface area in closed (tube or solid) pieces


def mesh_stats(positions: np.ndarray, triangles: np.ndarray) -> MeshStats:
    """Compute :class:`MeshStats` for world-space positions (V by 3) and triangles (F by 3)."""
    p = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    n = len(p)
    if n == 0:
        z = np.zeros(3)
        return MeshStats(0, 0, z, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, np.zeros(0, np.int64))
    labels = connected_components(n, triangles)
    k = int(labels.max()) + 1
    lo, hi = p.min(axis=0), p.max(axis=0)
    ext = hi - lo
    diag = float(np.linalg.norm(ext)) or 1.0
    # Per-component bounding boxes, all at once.
    cmin, cmax = _group_min_max(p, labels, k)
    cext = cmax - cmin
    cdiag = np.linalg.norm(cext, axis=1)
    cwidth = np.maximum(np.hypot(cext[:, 0], cext[:, 1]), 1e-12)
    return MeshStats(
        n_vertices=n,
        n_components=k,
        extent=np.sort(ext)[::-1],
        z_extent=float(ext[2]),
        xy_extent=float(max(ext[0], ext[1])),
        component_size_ratio=float(np.median(cdiag) / diag),
        base_spread=float(np.std(cmin[:, 2]) / diag),
        component_aspect=float(np.median(cext[:, 2] / cwidth)),
        component_flatness=_flatness(p, labels, k),
        labels=labels,
        tube_fraction=_tube_fraction(p, triangles, labels, k),
    )


# A piece is closed (a tube or a solid) when its area-weighted mean normal is below this
# fraction of its area; a flat or cupped card (a leaf, a blade) is near 1.
CLOSED_OPENNESS = 0.3
# ... and its normals do not all share one direction: the largest eigenvalue of the
# area-weighted normal tensor is ~1 for a thin plate (a leaf given a thickness), ~0.5 for a
# tube (normals all round its axis), 1/3 for a ball.
CLOSED_PLATE = 0.8


def piece_shape(positions, triangles, labels, k):
    """Per connected piece: (area, openness, plate), float64 (k,) each.

    openness = |Σ a n| / Σ a over the piece's triangles (a: area, n: unit normal): the mean
    normal of a closed surface is exactly 0 (divergence theorem), of an open tube nearly 0 (only
    its two end openings are missing), of a flat card 1. It does not care how a branch bends,
    unlike the covariance of its points (a curved Sapling branch looks as flat as a leaf to
    that). plate = λmax of Σ a n nᵀ / Σ a tells a thin solid plate (≈ 1) from a tube (≈ 0.5).
    Pieces without triangles get area 0, openness 1, plate 1."""
    p = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    t = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    if len(t) == 0 or k == 0:
        return np.zeros(k), np.ones(k), np.ones(k)
    a, b, c = p[t[:, 0]], p[t[:, 1]], p[t[:, 2]]
    cr = 0.5 * np.cross(b - a, c - a)  # area × unit normal
    area = np.linalg.norm(cr, axis=1)
    lab = labels[t[:, 0]]
    A = np.bincount(lab, area, k)
    S = np.stack([np.bincount(lab, cr[:, i], k) for i in range(3)], 1)
    safe = np.maximum(A, 1e-300)
    openness = np.where(A > 0, np.linalg.norm(S, axis=1) / safe, 1.0)
    w = np.where(area > 0, 1.0 / np.maximum(area, 1e-300), 0.0)  # a n nᵀ = cr crᵀ / a
    T = np.empty((k, 3, 3))
    for i in range(3):
        for j in range(i, 3):
            T[:, i, j] = T[:, j, i] = np.bincount(lab, cr[:, i] * cr[:, j] * w, k) / safe
    plate = np.where(A > 0, np.linalg.eigvalsh(T)[:, 2], 1.0)
    return A, openness, plate


def _tube_fraction(p, triangles, labels, k):
    area, openness, plate = piece_shape(p, triangles, labels, k)
    total = area.sum()
    if not total > 0:
        return 0.0
    closed = (openness < CLOSED_OPENNESS) & (plate < CLOSED_PLATE)
    return float(area[closed].sum() / total)


def _flatness(p, labels, k, max_pieces=4000):
    """Median over pieces of λmin/λmid of the piece's point covariance: ~0 for flat cards
    (leaves, blades), ~1 for tubes (branches: their two short axes are alike). Pieces of fewer
    than 3 points do not count; beyond max_pieces a fixed sample of pieces estimates it."""
    if k > max_pieces:
        keep = np.zeros(k, bool)
        keep[np.random.default_rng(0).choice(k, max_pieces, replace=False)] = True
        sel = keep[labels]
        _, labels = np.unique(labels[sel], return_inverse=True)
        p, k = p[sel], max_pieces
    q = p - p.mean(axis=0)
    cnt = np.bincount(labels, minlength=k).astype(np.float64)
    mean = np.stack([np.bincount(labels, q[:, i], k) for i in range(3)], 1) / cnt[:, None]
    second = np.empty((k, 3, 3))
    for i in range(3):
        for j in range(i, 3):
            second[:, i, j] = second[:, j, i] = np.bincount(labels, q[:, i] * q[:, j], k) / cnt
    cov = second - mean[:, :, None] * mean[:, None, :]
    ok = cnt >= 3
    if not ok.any():
        return 1.0
    ev = np.linalg.eigvalsh(cov[ok])  # ascending
    ratio = np.clip(ev[:, 0], 0, None) / np.maximum(ev[:, 1], 1e-30)
    return float(np.median(ratio))


def guess_role(positions: np.ndarray, triangles: np.ndarray) -> tuple[str, str]:
    """Guess a role for a mesh. Returns (role, reason) where reason is a short human sentence.

    - flat and wide (z extent < 5 % of the xy extent, few pieces) → GROUND;
    - few pieces whose normals share one direction, or an open sheet (a wall, a rock face, a
      slope: a sheet or a slab in any orientation; SURFACE_PLATE, SURFACE_OPEN) → GROUND;
    - many small pieces whose lowest points lie near one plane, taller than wide, the whole
      object low and wide → GRASS;
    - many small pieces, most of their area in closed tubes (unwelded branches: Sapling's
      branch curves converted to a mesh, however they bend) → TRUNK;
    - many small flat pieces in a blob → CANOPY;
    - many tube-like pieces without faces (point covariance), or one or a few solid pieces →
      TRUNK.
    """
    s = mesh_stats(positions, triangles)
    if s.n_vertices == 0:
        return "IGNORE", "empty mesh"
    flat = s.z_extent < FLAT_RATIO * max(s.xy_extent, 1e-12)
    many = s.n_components >= MANY_COMPONENTS and s.component_size_ratio < 0.25
    if flat and not many:
        return "GROUND", f"flat (height {s.z_extent:.3g} vs width {s.xy_extent:.3g})"
    if many and s.tube_fraction > 0.5:
        return "TRUNK", (f"{s.n_components} pieces, {100 * s.tube_fraction:.0f} % of the area "
                         "in closed tubes (branches)")
    if many and len(triangles) == 0 and s.component_flatness > 0.6:
        return "TRUNK", f"{s.n_components} tube-like pieces (branches)"
    if many:
        low_and_wide = s.z_extent < 0.5 * s.xy_extent
        if low_and_wide and s.base_spread < 0.05 and s.component_aspect > 1.0:
            return "GRASS", f"{s.n_components} upright blades on one plane"
        return "CANOPY", f"{s.n_components} small pieces in a blob"
    if flat:
        return "GROUND", "flat"
    area, opened, plate = piece_shape(positions, triangles, np.zeros(s.n_vertices, np.int64), 1)
    if area[0] > 0 and (plate[0] >= SURFACE_PLATE or opened[0] >= SURFACE_OPEN):
        return "GROUND", (f"a surface in any orientation (a wall, a rock face, a slope: normals "
                          f"agree {plate[0]:.2f}, mean normal {opened[0]:.2f}), not a tube")
    return "TRUNK", f"{s.n_components} solid piece(s)"


def blade_heights(positions: np.ndarray, triangles: np.ndarray, up=(0.0, 0.0, 1.0)):
    """Ground level and blade height of a grass mesh, from its connected components.

    Returns (ground_height, blade_height): the median lowest point and the median height of the
    blades along ``up`` (Hegeman Eq. 9 needs both; found, not asked for: docs/DESIGN.md, 'The method
    ladder').
    """
    p = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    if len(p) == 0:
        return 0.0, 1.0
    u = np.asarray(up, dtype=np.float64)
    u = u / np.linalg.norm(u)
    h = p @ u
    labels = connected_components(len(p), triangles)
    k = int(labels.max()) + 1
    lo, hi = _group_min_max(h, labels, k)
    ground = float(np.median(lo))
    blade = float(np.median(hi - lo))
    if not blade > 0:
        blade = float(h.max() - h.min()) or 1.0
    return ground, blade
