"""Procedural vegetation scenes for Canopy AO tests and benchmarks.

Pure numpy, no ``bpy``: the same arrays feed the native core directly (bench/accuracy.py) and
Blender (examples/blender_scene.py, examples/make_scene.py), so both see identical geometry.
Every scene is deterministic: one ``np.random.default_rng(seed)`` stream per scene.

Units are metres, Z is up, the ground (where there is one) is the plane z = 0.

Roles (the object custom property ``canopy_ao_role`` in Blender):
    canopy  leaves (small single-sided quads, 4 vertices / 2 triangles each, every leaf its own
            disconnected piece, random orientation)
    trunk   trunk and branches (low-poly tapered cylinders, no caps)
    ground  a grid plane with UVs
    grass   grass blades (thin tapered two-segment strips)

Usage::

    from canopy_scenes import make_scene, SCENES
    scene = make_scene("round_tree", seed=0)
    V, T, part_of_vertex = scene.merged()
"""
from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass

import numpy as np

ROLES = ("canopy", "trunk", "ground", "grass")


# === Data ====================================================================================

@dataclass
class MeshPart:
    """One object of a scene: a triangle mesh with a role.

    vertices  float32 (V, 3), world space, metres
    triangles int32 (M, 3), indices in [0, V)
    uvs       float32 (V, 2), one UV per vertex (leaves: the unit square per leaf)
    """
    name: str
    role: str
    tree: str | None
    vertices: np.ndarray
    triangles: np.ndarray
    uvs: np.ndarray

    def __post_init__(self):
        if self.role not in ROLES:
            raise ValueError(f"role must be one of {ROLES}, got {self.role!r}")
        self.vertices = np.ascontiguousarray(self.vertices, dtype=np.float32).reshape(-1, 3)
        self.triangles = np.ascontiguousarray(self.triangles, dtype=np.int32).reshape(-1, 3)
        self.uvs = np.ascontiguousarray(self.uvs, dtype=np.float32).reshape(-1, 2)

    @property
    def n_vertices(self) -> int:
        return len(self.vertices)


class Scene(list):
    """A list of MeshPart with a name and the seed it was built from."""

    def __init__(self, name: str, parts=(), seed: int = 0, info: dict | None = None):
        super().__init__(parts)
        self.name = name
        self.seed = seed
        self.info = dict(info or {})

    # --- queries ---
    def parts_by_role(self, role: str) -> list[MeshPart]:
        return [p for p in self if p.role == role]

    @property
    def roles(self) -> set[str]:
        return {p.role for p in self}

    @property
    def n_vertices(self) -> int:
        return sum(p.n_vertices for p in self)

    @property
    def n_triangles(self) -> int:
        return sum(len(p.triangles) for p in self)

    def bbox(self) -> tuple[np.ndarray, np.ndarray]:
        lo = np.min([p.vertices.min(0) for p in self if p.n_vertices], axis=0)
        hi = np.max([p.vertices.max(0) for p in self if p.n_vertices], axis=0)
        return lo, hi

    def ao_distance(self) -> float:
        """An AO distance that covers the whole scene: its bounding-box diagonal."""
        lo, hi = self.bbox()
        return float(np.linalg.norm(hi - lo))

    def merged(self):
        """All parts in one mesh: (vertices (V,3) f32, triangles (M,3) i32, part index (V,) i32)."""
        offs = np.cumsum([0] + [p.n_vertices for p in self])
        V = np.concatenate([p.vertices for p in self]).astype(np.float32)
        T = np.concatenate([p.triangles + o for p, o in zip(self, offs[:-1])]).astype(np.int32)
        part = np.repeat(np.arange(len(self), dtype=np.int32), [p.n_vertices for p in self])
        return V, T, part

    def summary(self) -> str:
        rows = [f"scene {self.name} (seed {self.seed}): {self.n_vertices} vertices, "
                f"{self.n_triangles} triangles, AO distance {self.ao_distance():.2f} m"]
        for p in self:
            rows.append(f"  {p.name:24s} {p.role:7s} {str(p.tree):8s} "
                        f"{p.n_vertices:9d} v {len(p.triangles):9d} t")
        return "\n".join(rows)


# === Geometry helpers ========================================================================

def geometry_hash(scene) -> str:
    """A key for caches of per-vertex results: the parts' names, vertex and triangle bytes."""
    h = hashlib.sha1()
    for p in scene:
        h.update(p.name.encode())
        h.update(np.ascontiguousarray(p.vertices).tobytes())
        h.update(np.ascontiguousarray(p.triangles).tobytes())
    return h.hexdigest()


def vertex_normals(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Per-vertex unit normals, corner-angle weighted like Blender's smooth vertex normals.

    Vertices no triangle uses (or whose triangles are all degenerate) get (0, 0, 1).
    Returns float32 (V, 3).
    """
    v = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64)
    out = np.zeros((len(v), 3))
    if len(t):
        p = v[t]                                   # (M, 3 corners, 3)
        fn = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        ln = np.linalg.norm(fn, axis=1, keepdims=True)
        fn = np.divide(fn, ln, out=np.zeros_like(fn), where=ln > 0)
        for c in range(3):
            e1 = p[:, (c + 1) % 3] - p[:, c]
            e2 = p[:, (c + 2) % 3] - p[:, c]
            d = np.einsum("ij,ij->i", e1, e2)
            n1 = np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1)
            ang = np.arccos(np.clip(np.divide(d, n1, out=np.zeros_like(d), where=n1 > 0), -1, 1))
            w = fn * ang[:, None]
            for k in range(3):
                out[:, k] += np.bincount(t[:, c], weights=w[:, k], minlength=len(v))
    ln = np.linalg.norm(out, axis=1, keepdims=True)
    good = ln[:, 0] > 1e-20
    out[good] /= ln[good]
    out[~good] = (0.0, 0.0, 1.0)
    return out.astype(np.float32)


def _unit(rng, n):
    x = rng.normal(size=(n, 3))
    return x / np.linalg.norm(x, axis=1, keepdims=True)


def _frames(normals, rng):
    """Two unit tangents per normal with a random spin."""
    a = _unit(rng, len(normals))
    t = np.cross(normals, a)
    bad = np.linalg.norm(t, axis=1) < 1e-6
    t[bad] = np.cross(normals[bad], [1.0, 0.0, 0.0])
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    b = np.cross(normals, t)
    return t, b


def leaf_quads(anchors, normals, rng, length=0.12, width=0.07, jitter=0.25):
    """Leaves: one quad per anchor, base edge centred on the anchor, facing ``normals``.

    Returns (vertices (4L,3), triangles (2L,3), uvs (4L,2)).
    """
    anchors = np.asarray(anchors, dtype=np.float64)
    n = len(anchors)
    t, b = _frames(np.asarray(normals, dtype=np.float64), rng)
    s = 1.0 + jitter * rng.uniform(-1, 1, size=(n, 1))
    hw, ln = 0.5 * width * s, length * s
    v = np.stack([anchors - hw * t, anchors + hw * t,
                  anchors + hw * t + ln * b, anchors - hw * t + ln * b], axis=1)
    base = 4 * np.arange(n)[:, None]
    tris = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]], axis=1).reshape(-1, 3)
    uv = np.tile(np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=np.float32), (n, 1))
    return v.reshape(-1, 3), tris, uv


def tapered_cylinders(p0, p1, r0, r1, sides=6):
    """Open tapered cylinders, one per segment p0[i]→p1[i] (no caps, one ring each end).

    Returns (vertices (2·sides·S,3), triangles (2·sides·S,3), uvs).
    """
    p0 = np.asarray(p0, dtype=np.float64).reshape(-1, 3)
    p1 = np.asarray(p1, dtype=np.float64).reshape(-1, 3)
    S = len(p0)
    r0 = np.broadcast_to(np.asarray(r0, dtype=np.float64), (S,))
    r1 = np.broadcast_to(np.asarray(r1, dtype=np.float64), (S,))
    ax = p1 - p0
    ax /= np.maximum(np.linalg.norm(ax, axis=1, keepdims=True), 1e-12)
    ref = np.where(np.abs(ax[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    u = np.cross(ax, ref)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    w = np.cross(ax, u)
    ang = 2 * np.pi * np.arange(sides) / sides
    ring = np.cos(ang)[None, :, None] * u[:, None, :] + np.sin(ang)[None, :, None] * w[:, None, :]
    v0 = p0[:, None, :] + r0[:, None, None] * ring
    v1 = p1[:, None, :] + r1[:, None, None] * ring
    verts = np.concatenate([v0, v1], axis=1).reshape(-1, 3)      # per segment: ring0, ring1
    i = np.arange(sides)
    j = (i + 1) % sides
    local = np.concatenate([np.stack([i, j, sides + j], 1), np.stack([i, sides + j, sides + i], 1)])
    tris = (local[None, :, :] + (2 * sides * np.arange(S))[:, None, None]).reshape(-1, 3)
    uv1 = np.stack([i / sides, np.zeros(sides)], 1)
    uv = np.tile(np.concatenate([uv1, uv1 + [0, 1]]), (S, 1))
    return verts, tris, uv


def polyline_cylinders(points, r_start, r_end, sides=6):
    """Segments along a polyline with the radius tapering linearly along it."""
    pts = np.asarray(points, dtype=np.float64)
    k = len(pts) - 1
    r = np.linspace(r_start, r_end, k + 1)
    return pts[:-1], pts[1:], r[:-1], r[1:]


def ground_grid(size=12.0, n=64, center=(0.0, 0.0), z=0.0):
    """A square n×n-vertex grid plane of side ``size`` centred at ``center``, z = ``z``."""
    xs = np.linspace(-size / 2, size / 2, n)
    X, Y = np.meshgrid(xs + center[0], xs + center[1], indexing="xy")
    v = np.stack([X.ravel(), Y.ravel(), np.full(n * n, z)], 1)
    i = np.arange(n - 1)
    a = (i[None, :] + n * i[:, None]).ravel()
    tris = np.concatenate([np.stack([a, a + 1, a + n + 1], 1), np.stack([a, a + n + 1, a + n], 1)])
    u = np.linspace(0, 1, n)
    U, W = np.meshgrid(u, u, indexing="xy")
    return v, tris, np.stack([U.ravel(), W.ravel()], 1)


def _concat(pieces):
    vs, ts, uvs, off = [], [], [], 0
    for v, t, uv in pieces:
        vs.append(v); ts.append(np.asarray(t) + off); uvs.append(uv); off += len(v)
    if not vs:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int32), np.zeros((0, 2))
    return np.concatenate(vs), np.concatenate(ts), np.concatenate(uvs)


# === Tree builder ============================================================================

def _in_crown(rng, n, lobes, outer_bias):
    """n points inside a union of ellipsoid lobes [(centre, radii), ...], denser near the skin.

    The radial coordinate is u^(1/(3+outer_bias)): outer_bias = 0 is uniform in volume, larger
    values push foliage to the outside as in real crowns (light-seeking leaves).
    """
    vol = np.array([np.prod(r) for _, r in lobes])
    which = rng.choice(len(lobes), size=n, p=vol / vol.sum())
    d = _unit(rng, n)
    rad = rng.uniform(size=n) ** (1.0 / (3.0 + outer_bias))
    c = np.array([lobes[i][0] for i in range(len(lobes))])[which]
    r = np.array([lobes[i][1] for i in range(len(lobes))])[which]
    return c + d * rad[:, None] * r


def _nearest_on_segments(q, a, b):
    """For each query point, the closest point on any of the segments a[j]→b[j] (chunked)."""
    out = np.empty_like(q)
    ab = b - a
    L2 = np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-12)
    for s in range(0, len(q), 2048):
        qq = q[s:s + 2048]
        t = np.clip(np.einsum("qjk,jk->qj", qq[:, None, :] - a[None], ab) / L2, 0, 1)
        p = a[None] + t[..., None] * ab[None]
        d = np.einsum("qjk,qjk->qj", p - qq[:, None, :], p - qq[:, None, :])
        out[s:s + 2048] = p[np.arange(len(qq)), d.argmin(1)]
    return out


def _broadleaf(rng, name, lobes, trunk_top, leaves, base=(0.0, 0.0), trunk_radius=0.18,
               n_primary=10, leaves_per_twig=40, leaf_size=(0.12, 0.07), outer_bias=2.0,
               droop=0.0, twig_spread=0.35):
    """A broadleaf tree: trunk → primary branches → twigs → leaf clusters around twig tips.

    lobes      [(centre, radii)] ellipsoids (relative to base) whose union is the crown
    droop      > 0 hangs leaf clusters below their twig tip (weeping habit), in metres
    """
    bx, by = base
    off = np.array([bx, by, 0.0])
    lobes = [(np.asarray(c, float) + off, np.asarray(r, float)) for c, r in lobes]
    top = off + [0, 0, trunk_top]
    segs = []
    # trunk, slightly leaning, up to the crown base, then a leader into the crown
    crown_top = max(c[2] + r[2] for c, r in lobes)
    lean = rng.normal(0, 0.05, 3) * [1, 1, 0]
    trunk_pts = np.array([off, off + [0, 0, trunk_top * 0.5] + lean * 0.5, top + lean,
                          off + [0, 0, 0.5 * (trunk_top + crown_top)] + lean])
    segs.append(polyline_cylinders(trunk_pts, trunk_radius, trunk_radius * 0.35))
    # primary branches from the upper trunk towards points near the crown skin
    n_twigs = max(1, leaves // leaves_per_twig)
    ends = _in_crown(rng, n_primary, lobes, outer_bias=8.0)
    starts = top + lean + np.outer(rng.uniform(-0.3, 0.6, n_primary) * (crown_top - trunk_top) * 0.5,
                                   [0, 0, 1])
    mids = 0.5 * (starts + ends) + rng.normal(0, 0.15, (n_primary, 3))
    pa = np.concatenate([starts, mids]); pb = np.concatenate([mids, ends])
    r_pa = np.concatenate([np.full(n_primary, trunk_radius * 0.45), np.full(n_primary, trunk_radius * 0.3)])
    r_pb = np.concatenate([np.full(n_primary, trunk_radius * 0.3), np.full(n_primary, trunk_radius * 0.12)])
    segs.append((pa, pb, r_pa, r_pb))
    # twigs: from the nearest point on a primary branch to a twig tip in the crown
    tips = _in_crown(rng, n_twigs, lobes, outer_bias)
    # only the branch-backed twigs get wood (cap the count so the trunk mesh stays low-poly)
    roots = _nearest_on_segments(tips, pa, pb)
    n_wood = min(n_twigs, 600)
    segs.append((roots[:n_wood], tips[:n_wood], np.full(n_wood, 0.025), np.full(n_wood, 0.008)))
    # leaves: clusters around twig tips
    which = rng.integers(0, n_twigs, leaves)
    anchors = tips[which] + rng.normal(0, twig_spread, (leaves, 3)) * [1, 1, 0.8]
    if droop > 0:
        anchors[:, 2] -= droop * rng.uniform(0, 1, leaves) ** 0.7
    anchors[:, 2] = np.maximum(anchors[:, 2], 0.05)
    lv, lt, luv = leaf_quads(anchors, _unit(rng, leaves), rng, *leaf_size)
    p0 = np.concatenate([s[0] for s in segs]); p1 = np.concatenate([s[1] for s in segs])
    r0 = np.concatenate([np.broadcast_to(s[2], (len(s[0]),)) for s in segs])
    r1 = np.concatenate([np.broadcast_to(s[3], (len(s[0]),)) for s in segs])
    tv, tt, tuv = tapered_cylinders(p0, p1, r0, r1, sides=6)
    return [MeshPart(f"{name}_trunk", "trunk", name, tv, tt, tuv),
            MeshPart(f"{name}_leaves", "canopy", name, lv, lt, luv)]


def _conifer_parts(rng, name, leaves, base=(0.0, 0.0), height=9.0, crown_base=1.5, radius=2.2,
                   whorls=14):
    """A conifer: straight trunk, whorls of down-sloping branches, needles along them."""
    off = np.array([base[0], base[1], 0.0])
    trunk = polyline_cylinders(np.array([off, off + [0, 0, height * 0.5], off + [0, 0, height]]),
                               0.2, 0.03)
    segs = [trunk]
    zs = np.linspace(crown_base, height * 0.95, whorls)
    starts, ends = [], []
    for z in zs:
        k = int(rng.integers(5, 8))
        frac = (height - z) / (height - crown_base)
        L = radius * frac * rng.uniform(0.8, 1.1, k) + 0.15
        phi = rng.uniform(0, 2 * np.pi) + 2 * np.pi * np.arange(k) / k + rng.normal(0, 0.15, k)
        d = np.stack([np.cos(phi), np.sin(phi), np.full(k, -0.25)], 1)
        s = off + [0, 0, z]
        starts.append(np.repeat(s[None], k, 0)); ends.append(s + d * L[:, None])
    starts = np.concatenate(starts); ends = np.concatenate(ends)
    blen = np.linalg.norm(ends - starts, axis=1)
    segs.append((starts, ends, np.full(len(starts), 0.05), np.full(len(starts), 0.01)))
    # needles: anchors along branches (length-weighted), scattered a little around them
    which = rng.choice(len(starts), leaves, p=blen / blen.sum())
    t = rng.uniform(0.15, 1.0, leaves) ** 0.8
    anchors = starts[which] + t[:, None] * (ends[which] - starts[which])
    anchors += rng.normal(0, 0.12, (leaves, 3)) * [1, 1, 0.6]
    lv, lt, luv = leaf_quads(anchors, _unit(rng, leaves), rng, length=0.10, width=0.025)
    p0 = np.concatenate([s[0] for s in segs]); p1 = np.concatenate([s[1] for s in segs])
    r0 = np.concatenate([np.broadcast_to(s[2], (len(s[0]),)) for s in segs])
    r1 = np.concatenate([np.broadcast_to(s[3], (len(s[0]),)) for s in segs])
    tv, tt, tuv = tapered_cylinders(p0, p1, r0, r1, sides=6)
    return [MeshPart(f"{name}_trunk", "trunk", name, tv, tt, tuv),
            MeshPart(f"{name}_leaves", "canopy", name, lv, lt, luv)]


def _ground(size, n, center=(0.0, 0.0)):
    v, t, uv = ground_grid(size, n, center)
    return MeshPart("ground", "ground", None, v, t, uv)


# === Scenes ==================================================================================

def round_tree(seed=0, leaves=20000, ground=True, leaf_size=(0.12, 0.07)):
    """A round broadleaf tree (oak/maple-like): spherical crown r ≈ 3 m on a 2.5 m trunk.

    leaf_size: (length, width) in metres; 20000 leaves of the default size give a leaf area
    index of about 6 over the crown's footprint."""
    rng = np.random.default_rng(seed)
    parts = _broadleaf(rng, "round", [((0, 0, 5.5), (3.0, 3.0, 2.8))], trunk_top=2.8, leaves=leaves,
                       leaf_size=tuple(leaf_size))
    if ground:
        parts.append(_ground(14.0, 64))
    return Scene("round_tree", parts, seed, {"leaves": leaves})


def columnar_tree(seed=0, leaves=20000, ground=True):
    """A columnar tree (Lombardy-poplar-like): tall narrow ellipsoidal crown."""
    rng = np.random.default_rng(seed)
    parts = _broadleaf(rng, "columnar", [((0, 0, 6.5), (1.3, 1.3, 5.0))], trunk_top=1.8,
                       leaves=leaves, n_primary=14, twig_spread=0.2, trunk_radius=0.15)
    if ground:
        parts.append(_ground(10.0, 64))
    return Scene("columnar_tree", parts, seed, {"leaves": leaves})


def weeping_tree(seed=0, leaves=30000, ground=True):
    """An irregular multi-lobed tree with weeping (hanging) foliage, willow/birch-like."""
    rng = np.random.default_rng(seed)
    lobes = [((0.0, 0.0, 5.2), (2.2, 2.0, 1.8)),
             ((1.9, 0.6, 4.4), (1.6, 1.4, 1.5)),
             ((-1.6, 1.2, 4.0), (1.4, 1.5, 1.4)),
             ((0.4, -1.9, 3.7), (1.3, 1.2, 1.3)),
             ((-0.6, -0.3, 6.6), (1.1, 1.1, 1.0))]
    parts = _broadleaf(rng, "weeping", lobes, trunk_top=2.4, leaves=leaves, n_primary=14,
                       droop=1.8, leaf_size=(0.10, 0.03), outer_bias=3.0)
    if ground:
        parts.append(_ground(14.0, 64))
    return Scene("weeping_tree", parts, seed, {"leaves": leaves})


def conifer(seed=0, leaves=40000, ground=True):
    """A conifer (spruce-like): conical crown of branch whorls, needles as thin quads."""
    rng = np.random.default_rng(seed)
    parts = _conifer_parts(rng, "conifer", leaves)
    if ground:
        parts.append(_ground(10.0, 64))
    return Scene("conifer", parts, seed, {"leaves": leaves})


def grass_field(seed=0, blades=20000, size=6.0, blade_height=0.3):
    """A grass field: blades (two-segment tapered strips, slightly bent) on a ground plane."""
    rng = np.random.default_rng(seed)
    n = blades
    xy = rng.uniform(-size / 2, size / 2, (n, 2))
    h = blade_height * rng.uniform(0.6, 1.0, n)
    phi = rng.uniform(0, 2 * np.pi, n)
    side = np.stack([np.cos(phi), np.sin(phi), np.zeros(n)], 1)       # blade width direction
    lean = np.stack([-np.sin(phi), np.cos(phi), np.zeros(n)], 1) * rng.uniform(0.0, 0.35, (n, 1))
    w = 0.012 * rng.uniform(0.7, 1.3, (n, 1))
    root = np.stack([xy[:, 0], xy[:, 1], np.zeros(n)], 1)
    up = np.array([0.0, 0.0, 1.0])
    mid = root + h[:, None] * (0.5 * up + 0.25 * lean)
    tip = root + h[:, None] * (up + lean)
    v = np.stack([root - w * side, root + w * side, mid - 0.7 * w * side, mid + 0.7 * w * side,
                  tip - 0.1 * w * side, tip + 0.1 * w * side], 1).reshape(-1, 3)
    loc = np.array([[0, 1, 3], [0, 3, 2], [2, 3, 5], [2, 5, 4]])
    t = (loc[None] + 6 * np.arange(n)[:, None, None]).reshape(-1, 3)
    uv = np.tile(np.array([[0, 0], [1, 0], [0, .5], [1, .5], [0, 1], [1, 1]], np.float32), (n, 1))
    parts = [MeshPart("grass", "grass", None, v, t, uv), _ground(size * 1.2, 64)]
    return Scene("grass_field", parts, seed, {"blades": blades, "blade_height": blade_height})


def grove(seed=0, n_trees=5, leaves=12000, size=30.0):
    """Several trees of mixed kinds (round, columnar, conifer, weeping) on a shared ground."""
    rng = np.random.default_rng(seed)
    parts, placed = [], []
    kinds = ["round", "conifer", "columnar", "weeping"]
    for i in range(n_trees):
        for _ in range(200):                       # keep trunks ≥ 5 m apart
            p = rng.uniform(-size / 2 + 4, size / 2 - 4, 2)
            if all(np.hypot(*(p - q)) > 5.0 for q in placed):
                break
        placed.append(p)
        kind, name = kinds[i % len(kinds)], f"tree{i}"
        s = rng.uniform(0.75, 1.15)               # size variation
        if kind == "conifer":
            parts += _conifer_parts(rng, name, leaves, base=p, height=9 * s, radius=2.2 * s)
        elif kind == "round":
            parts += _broadleaf(rng, name, [((0, 0, 5.5 * s), (3 * s, 3 * s, 2.8 * s))],
                                trunk_top=2.8 * s, leaves=leaves, base=p)
        elif kind == "columnar":
            parts += _broadleaf(rng, name, [((0, 0, 6.5 * s), (1.3 * s, 1.3 * s, 5 * s))],
                                trunk_top=1.8 * s, leaves=leaves, base=p, twig_spread=0.2)
        else:
            lobes = [((0, 0, 5.0 * s), (2.0 * s, 1.8 * s, 1.7 * s)),
                     ((1.6 * s, 0.5 * s, 4.2 * s), (1.4 * s, 1.3 * s, 1.3 * s)),
                     ((-1.4 * s, 1.0 * s, 3.9 * s), (1.3 * s, 1.3 * s, 1.3 * s))]
            parts += _broadleaf(rng, name, lobes, trunk_top=2.3 * s, leaves=leaves, base=p,
                                droop=1.5, leaf_size=(0.10, 0.03))
    parts.append(_ground(size, 96))
    return Scene("grove", parts, seed, {"n_trees": n_trees, "leaves": leaves})


def _ideal(rng, n_tris, radii, edge):
    """n_tris small random triangles, centres uniform in the ellipsoid ``radii``."""
    d = _unit(rng, n_tris)
    c = d * rng.uniform(size=(n_tris, 1)) ** (1 / 3) * np.asarray(radii, float)
    v = c[:, None, :] + edge * 0.6 * _unit(rng, 3 * n_tris).reshape(n_tris, 3, 3)
    t = np.arange(3 * n_tris).reshape(-1, 3)
    uv = np.tile(np.array([[0, 0], [1, 0], [0, 1]], np.float32), (n_tris, 1))
    return v.reshape(-1, 3), t, uv


def ideal_sphere(seed=0, n_tris=5000, radius=1.0, edge=0.06):
    """The paper's idealised case: a sphere uniformly filled with small random triangles.

    No ground, no trunk: the canopy model's assumptions hold exactly (up to sampling noise).
    """
    rng = np.random.default_rng(seed)
    v, t, uv = _ideal(rng, n_tris, (radius,) * 3, edge * radius)
    return Scene("ideal_sphere", [MeshPart("sphere_leaves", "canopy", "ideal", v, t, uv)], seed,
                 {"n_tris": n_tris, "radius": radius})


def ideal_ellipsoid(seed=0, n_tris=5000, radii=(1.6, 1.0, 0.6), edge=0.06):
    """As ideal_sphere, in an ellipsoid with semi-axes ``radii`` rotated 30° about Z."""
    rng = np.random.default_rng(seed)
    v, t, uv = _ideal(rng, n_tris, radii, edge)
    a = np.radians(30)
    R = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    v = v @ R.T
    return Scene("ideal_ellipsoid", [MeshPart("ellipsoid_leaves", "canopy", "ideal", v, t, uv)],
                 seed, {"n_tris": n_tris, "radii": list(radii)})


def area_preserving_leaf_size(leaves, base=20000, size=(0.12, 0.07)):
    """Leaf size that keeps the round tree's total leaf area (so its density and AO) at any count."""
    f = math.sqrt(base / max(leaves, 1))
    return (size[0] * f, size[1] * f)


def large_tree(seed=0, leaves=260000):
    """The round tree with ≥ 1M vertices (260k leaf quads): smaller leaves, same total leaf
    area as round_tree's 20000, so the crown is as dense (a real tree's fine foliage)."""
    s = round_tree(seed, leaves=leaves, leaf_size=area_preserving_leaf_size(leaves))
    s.name = "large_tree"
    return s


SCENES = {
    "round_tree": round_tree,
    "columnar_tree": columnar_tree,
    "weeping_tree": weeping_tree,
    "conifer": conifer,
    "grass_field": grass_field,
    "grove": grove,
    "ideal_sphere": ideal_sphere,
    "ideal_ellipsoid": ideal_ellipsoid,
    "large_tree": large_tree,
}

# Smaller sizes for quick runs on a shared 2-core box (same shapes, fewer leaves).
QUICK = {
    "round_tree": dict(leaves=5000),
    "columnar_tree": dict(leaves=5000),
    "weeping_tree": dict(leaves=6000),
    "conifer": dict(leaves=8000),
    "grass_field": dict(blades=5000),
    "grove": dict(n_trees=4, leaves=3000),
    "ideal_sphere": dict(n_tris=2000),
    "ideal_ellipsoid": dict(n_tris=2000),
    "large_tree": dict(leaves=60000),
}


def make_scene(name: str, seed: int = 0, quick: bool = False, **kwargs) -> Scene:
    """Build a scene by name; ``quick`` uses the smaller QUICK sizes unless overridden."""
    if name not in SCENES:
        raise ValueError(f"unknown scene {name!r}; choose from {', '.join(SCENES)}")
    args = dict(QUICK[name]) if quick else {}
    args.update(kwargs)
    return SCENES[name](seed=seed, **args)


if __name__ == "__main__":
    import sys
    import time
    for nm in (sys.argv[1:] or SCENES):
        t0 = time.perf_counter()
        sc = make_scene(nm)
        print(sc.summary(), f"\n  built in {time.perf_counter() - t0:.2f} s")
