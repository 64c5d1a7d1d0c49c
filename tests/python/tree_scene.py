"""A small tree + ground scene as numpy arrays, shared by the plain and the Blender tests.

trunk: a closed cylinder, radius 0.15, z in [0, 2]; leaves: 0.15-unit quads scattered in a ball
of radius 1.2 centred at (0, 0, 2.6); ground: a 20 x 20 plane at z = 0 subdivided 24 x 24;
grass (optional): upright blades 0.3 high on z = 0 away from the tree.
"""

import numpy as np


# The role each of scene()'s objects plays in a bake.
ROLE = {"Trunk": "TRUNK", "Leaves": "CANOPY", "Ground": "GROUND", "Grass": "GRASS"}


def cylinder(radius=0.15, height=2.0, segments=12):
    a = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    ring = np.stack([radius * np.cos(a), radius * np.sin(a)], axis=1)
    bottom = np.column_stack([ring, np.zeros(segments)])
    top = np.column_stack([ring, np.full(segments, height)])
    pos = np.concatenate([bottom, top, [[0, 0, 0], [0, 0, height]]])
    i = np.arange(segments)
    j = (i + 1) % segments
    side = np.concatenate([np.stack([i, j, j + segments], 1),
                           np.stack([i, j + segments, i + segments], 1)])
    cb, ct = 2 * segments, 2 * segments + 1
    caps = np.concatenate([np.stack([np.full(segments, cb), j, i], 1),
                           np.stack([np.full(segments, ct), i + segments, j + segments], 1)])
    return pos.astype(np.float32), np.concatenate([side, caps]).astype(np.int32)


def leaves(count=1500, center=(0.0, 0.0, 2.6), radius=1.2, size=0.15, seed=1):
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(count, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    c = np.asarray(center) + d * radius * rng.random(count)[:, None] ** (1 / 3)
    u = rng.normal(size=(count, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(u, rng.normal(size=(count, 3)))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    h = size / 2
    quad = np.stack([c - h * u - h * v, c + h * u - h * v, c + h * u + h * v, c - h * u + h * v], 1)
    base = 4 * np.arange(count)[:, None]
    tris = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]])
    return quad.reshape(-1, 3).astype(np.float32), tris.astype(np.int32)


def plane(size=20.0, cuts=24, z=0.0):
    g = np.linspace(-size / 2, size / 2, cuts + 1)
    x, y = np.meshgrid(g, g, indexing="ij")
    pos = np.column_stack([x.ravel(), y.ravel(), np.full(x.size, z)])
    i, j = np.meshgrid(np.arange(cuts), np.arange(cuts), indexing="ij")
    v0 = (i * (cuts + 1) + j).ravel()
    v1, v2, v3 = v0 + cuts + 1, v0 + cuts + 2, v0 + 1
    tris = np.concatenate([np.stack([v0, v1, v2], 1), np.stack([v0, v2, v3], 1)])
    return pos.astype(np.float32), tris.astype(np.int32)


def grass(count=300, height=0.3, width=0.03, region=(4.0, 8.0), seed=2):
    rng = np.random.default_rng(seed)
    x = rng.uniform(region[0], region[1], count)
    y = rng.uniform(-2.0, 2.0, count)
    a = rng.uniform(0, np.pi, count)
    dx, dy = width * np.cos(a), width * np.sin(a)
    quad = np.stack([np.stack([x - dx, y - dy, np.zeros(count)], 1),
                     np.stack([x + dx, y + dy, np.zeros(count)], 1),
                     np.stack([x + dx, y + dy, np.full(count, height)], 1),
                     np.stack([x - dx, y - dy, np.full(count, height)], 1)], 1)
    base = 4 * np.arange(count)[:, None]
    tris = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]])
    return quad.reshape(-1, 3).astype(np.float32), tris.astype(np.int32)


def vertex_normals(pos, tris):
    """Area-weighted vertex normals (unit; +z for isolated vertices)."""
    p = pos.astype(np.float64)
    fn = np.cross(p[tris[:, 1]] - p[tris[:, 0]], p[tris[:, 2]] - p[tris[:, 0]])
    n = np.zeros_like(p)
    for k in range(3):
        np.add.at(n, tris[:, k], fn)
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    n = np.where(ln > 0, n / np.maximum(ln, 1e-30), [0.0, 0.0, 1.0])
    return n.astype(np.float32)


def scene(with_grass=False):
    """{name: (positions, triangles)}"""
    out = {"Trunk": cylinder(), "Leaves": leaves(), "Ground": plane()}
    if with_grass:
        out["Grass"] = grass()
    return out


def scene_items(core, scale=1.0):
    """scene() without grass as the add-on's core.SceneItems (``core``: canopy_ao.core, passed
    in so this module imports no add-on), roles by ROLE, tree "T" but the ground's, every
    coordinate times ``scale``."""
    items = []
    for name, (p, t) in scene(False).items():
        q = np.asarray(p, np.float32) * scale
        items.append(core.SceneItem(name, ROLE[name], "" if name == "Ground" else "T", q,
                                    vertex_normals(q, t), t))
    return items
