"""Meshes with the shapes real assets have (Sapling Tree Gen's bent branch tubes, leaf cards,
boles), built in numpy for the tests."""
import numpy as np


def bent_tubes(rng, n=60, sides=8, rings=12, base=(0.0, 0.0), height=6.0):
    """n disconnected branch tubes (open ends), each bent through up to 120° as Sapling's
    branch curves are, radius tapering: the shape of a Sapling branch curve made a mesh."""
    verts, tris, off = [], [], 0
    ang = 2 * np.pi * np.arange(sides) / sides
    for _ in range(n):
        start = np.array([base[0], base[1], 0.0]) + rng.uniform([-.3, -.3, 1.0],
                                                                [.3, .3, height])
        length, bend = rng.uniform(1.0, 3.0), rng.uniform(1.2, 2.1)  # radians
        az = rng.uniform(0, 2 * np.pi)
        s = np.linspace(0, 1, rings)
        # an arc in the vertical plane of azimuth az
        rad = length / bend
        th = s * bend
        d = np.array([np.cos(az), np.sin(az), 0.0])
        centre = start[None, :] + rad * (np.sin(th)[:, None] * d[None, :]
                                         + (1 - np.cos(th))[:, None] * np.array([0, 0, 1.0]))
        tang = np.cos(th)[:, None] * d[None, :] + np.sin(th)[:, None] * np.array([0, 0, 1.0])
        side = np.cross(tang, np.array([-d[1], d[0], 0.0]))
        other = np.cross(tang, side)
        r = np.linspace(0.08, 0.02, rings) * length
        ring = (np.cos(ang)[None, :, None] * side[:, None, :]
                + np.sin(ang)[None, :, None] * other[:, None, :]) * r[:, None, None]
        verts.append((centre[:, None, :] + ring).reshape(-1, 3))
        i, j = np.meshgrid(np.arange(rings - 1), np.arange(sides), indexing="ij")
        a = i * sides + j
        b = i * sides + (j + 1) % sides
        tris.append(off + np.concatenate([np.stack([a, b, b + sides], -1).reshape(-1, 3),
                                          np.stack([a, b + sides, a + sides], -1).reshape(-1, 3)]))
        off += rings * sides
    return np.concatenate(verts).astype(np.float32), np.concatenate(tris).astype(np.int32)


def leaves(rng, n=800, centre=(0.0, 0.0, 5.0), radius=2.5, size=0.15, thick=0.0):
    """n flat quads in a ball (a crown); thick > 0 gives each a thickness (a closed box)."""
    c = np.asarray(centre) + rng.normal(0, radius / 2, (n, 3))
    quad = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float) * size
    rot = np.linalg.qr(rng.normal(size=(n, 3, 3)))[0]
    faces = [[0, 1, 2], [0, 2, 3]]
    if thick > 0:
        quad = np.concatenate([quad, quad + [0, 0, thick]])
        faces = [[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4],
                 [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]]
    v = c[:, None, :] + np.einsum("nij,kj->nki", rot, quad)
    t = (np.arange(n)[:, None, None] * len(quad) + np.array(faces)[None]).reshape(-1, 3)
    return v.reshape(-1, 3).astype(np.float32), t.astype(np.int32)


def join(*meshes):
    v, t, base = [], [], 0
    for p, tt in meshes:
        v.append(p)
        t.append(tt + base)
        base += len(p)
    return np.concatenate(v), np.concatenate(t)


def stem(base, height=3.0):
    """A tube from the ground up to the crown (a bole)."""
    import canopy_scenes as cs
    v, t, _uv = cs.tapered_cylinders([[base[0], base[1], 0.0]], [[base[0], base[1], height]],
                                     0.2, 0.12, sides=8)
    return v.astype(np.float32), t.astype(np.int32)


def cubes(centres, half):
    """Closed axis-aligned cubes (12 outward triangles each) around centres (N, 3)."""
    c = np.asarray(centres, np.float64).reshape(-1, 3)
    corner = np.array([[x, y, z] for z in (-1, 1) for y in (-1, 1) for x in (-1, 1)], float)
    faces = np.array([[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4],
                      [2, 6, 3], [3, 6, 7], [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5]])
    v = c[:, None, :] + half * corner[None]
    t = (np.arange(len(c))[:, None, None] * 8 + faces[None]).reshape(-1, 3)
    return v.reshape(-1, 3).astype(np.float32), t.astype(np.int32)


def ivy_on_wall(rng, thick=0.0, n_leaves=600, n_branches=12):
    """A 3 m × 2 m wall standing at y = 0 (a quad, or a slab of the given thickness), ivy leaves
    (small quads) scattered on and just in front of it, thin branch tubes climbing it, and a
    ground plane: the shapes of IvyGen's ivy on a wall."""
    if thick > 0:
        v, t = cubes([[0, 0, 0]], 1.0)
        wall = (v * np.float32([1.5, thick / 2, 1.0]) + np.float32([0, 0, 1.0]), t)
    else:
        wall = (np.float32([[-1.5, 0, 0], [1.5, 0, 0], [1.5, 0, 2], [-1.5, 0, 2]]),
                np.int32([[0, 1, 2], [0, 2, 3]]))
    # Leaves: small quads a few cm in front of the wall's face, turned at random.
    c = np.c_[rng.uniform(-1.4, 1.4, n_leaves), -thick / 2 - rng.uniform(0.01, 0.1, n_leaves),
              rng.uniform(0.05, 1.95, n_leaves)]
    quad = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float) * 0.06
    rot = np.linalg.qr(rng.normal(size=(n_leaves, 3, 3)))[0]
    lv = (c[:, None, :] + np.einsum("nij,kj->nki", rot, quad)).reshape(-1, 3).astype(np.float32)
    lt = (np.arange(n_leaves)[:, None, None] * 4 + np.array([[0, 1, 2], [0, 2, 3]])[None])
    leaves_ = (lv, lt.reshape(-1, 3).astype(np.int32))
    # Branches: thin open tubes climbing the wall's face, bent sideways.
    bv, bt, off = [], [], 0
    sides, rings = 6, 16
    ang = 2 * np.pi * np.arange(sides) / sides
    for _ in range(n_branches):
        x0, sway = rng.uniform(-1.3, 1.3), rng.uniform(-0.4, 0.4)
        s = np.linspace(0, 1, rings)
        centre = np.c_[x0 + sway * np.sin(np.pi * s), np.full(rings, -thick / 2 - 0.015),
                       1.9 * s]
        ring = np.stack([0.01 * np.cos(ang), 0.01 * np.sin(ang), np.zeros(sides)], 1)
        bv.append((centre[:, None, :] + ring[None]).reshape(-1, 3))
        i, j = np.meshgrid(np.arange(rings - 1), np.arange(sides), indexing="ij")
        a, b = i * sides + j, i * sides + (j + 1) % sides
        bt.append(off + np.concatenate([np.stack([a, b, b + sides], -1).reshape(-1, 3),
                                        np.stack([a, b + sides, a + sides], -1).reshape(-1, 3)]))
        off += rings * sides
    branches = (np.concatenate(bv).astype(np.float32), np.concatenate(bt).astype(np.int32))
    ground = (np.float32([[-4, -4, 0], [4, -4, 0], [4, 4, 0], [-4, 4, 0]]),
              np.int32([[0, 1, 2], [0, 2, 3]]))
    return {"Wall": wall, "IvyLeaves": leaves_, "IvyBranches": branches, "Ground": ground}
