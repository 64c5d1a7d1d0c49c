"""Forests: instanced trees as occluders of the ground (issue 6, item 6; DESIGN 3.4). No bpy.

A forest is a few unique tree prototypes, each with its fitted shells in the prototype's own
space, and many instances, each a 4×4 world matrix (rotation, translation, any scale, even
non-uniform or mirrored). The prototype's self-AO is baked once and shared by its instances
(they share the mesh data); the ground sees every instance's shells as occluders, evaluated by
the core's :class:`OccluderField`, which cuts each occluder off where its effect drops below ε
(Shanmugam–Arikan Eq. 5) and indexes them in a uniform grid, so a receiver's cost is bounded by
the number of shells within reach of it, not by the tree count (bench/forest.py measures it).

Transforming a shell is exact: the image of the ellipsoid {c + Q diag(r) u : |u| ≤ 1} under
x ↦ A x + t is {A c + t + B u : |u| ≤ 1} with B = A Q diag(r); with the SVD B = U S Vᵀ (V only
rotates the unit ball) it is the ellipsoid with centre A c + t, axes U and radii S. So
non-uniform scale and shear need no refit and no approximation.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .native import _core, require

DEFAULT_EPSILON = 1e-3  # the core's default cut-off (occluders.h)


def shell_arrays(shells):
    """Ellipsoids as arrays: centres (K, 3), axes (K, 3, 3) (columns = unit axes), radii (K, 3),
    all float64."""
    shells = list(shells)
    if not shells:
        z = np.zeros((0, 3))
        return z, np.zeros((0, 3, 3)), z.copy()
    c = np.array([np.asarray(e.center, np.float64) for e in shells])
    q = np.array([np.asarray(e.axes, np.float64) for e in shells])
    r = np.array([np.asarray(e.radii, np.float64) for e in shells])
    return c, q, r


def transform_shell_arrays(centers, axes, radii, matrices):
    """Every shell under every matrix, exactly (module docstring).

    centers (K, 3), axes (K, 3, 3), radii (K, 3): the prototype's shells; matrices (N, 4, 4)
    affine world matrices (the last row is ignored). Returns centres (N·K, 3), axes (N·K, 3, 3)
    (orthonormal, right-handed), radii (N·K, 3) ordered instance-major (instance i's shells are
    rows i·K … i·K + K − 1). A singular matrix (a zero scale) gives a zero radius: drop those
    with :func:`valid_rows`.
    """
    m = np.asarray(matrices, np.float64).reshape(-1, 4, 4)
    a, t = m[:, :3, :3], m[:, :3, 3]
    centers = np.asarray(centers, np.float64).reshape(-1, 3)
    axes = np.asarray(axes, np.float64).reshape(-1, 3, 3)
    radii = np.asarray(radii, np.float64).reshape(-1, 3)
    n, k = len(m), len(centers)
    wc = np.einsum("nij,kj->nki", a, centers) + t[:, None, :]
    b = np.einsum("nij,kjl->nkil", a, axes * radii[:, None, :])  # A Q diag(r)
    u, s, _vt = np.linalg.svd(b.reshape(-1, 3, 3))
    # A mirrored instance gives a left-handed U; flipping one axis leaves the shape unchanged.
    flip = np.linalg.det(u) < 0
    u[flip, :, 2] *= -1.0
    return wc.reshape(n * k, 3), u, s


def valid_rows(radii, tiny=1e-9):
    """Rows whose radii are all finite and > tiny (a zero-scaled instance has none)."""
    radii = np.asarray(radii)
    return np.all(np.isfinite(radii), axis=1) & np.all(radii > tiny, axis=1)


def make_ellipsoids(centers, axes, radii):
    """_core.Ellipsoid objects from arrays (rows with a degenerate radius are skipped)."""
    keep = valid_rows(radii)
    c = np.asarray(centers, np.float32)[keep]
    q = np.asarray(axes, np.float32)[keep]
    r = np.asarray(radii, np.float32)[keep]
    return [_core.Ellipsoid(c[i], q[i], r[i]) for i in range(len(c))]


def instance_shells(shells, matrices):
    """World-space _core.Ellipsoid list: each of ``shells`` (the prototype's, in its own space)
    under each of ``matrices`` (N, 4, 4). Instance-major order."""
    c, q, r = shell_arrays(shells)
    if not len(c):
        return []
    return make_ellipsoids(*transform_shell_arrays(c, q, r, matrices))


def unique_matrices(matrices, decimals=5):
    """Matrices (N, 4, 4) with exact repeats (to ``decimals``) removed, first-seen order kept.
    A tree made of several objects yields the same instance matrix once per object."""
    m = np.asarray(matrices, np.float64).reshape(-1, 4, 4)
    if not len(m):
        return m
    _u, first = np.unique(np.round(m.reshape(len(m), 16), decimals), axis=0, return_index=True)
    return m[np.sort(first)]


@dataclass
class Prototype:
    """One unique tree: its shells (leaf crown, semi-transparent with optical depth tau) and
    solid trunk ellipsoids, in the prototype's space, and its instances' matrices (N, 4, 4)."""

    name: str
    shells: list
    tau: float
    matrices: np.ndarray
    solids: list = field(default_factory=list)

    @property
    def count(self) -> int:
        return int(len(np.asarray(self.matrices).reshape(-1, 16)))


class Forest:
    """Every instance of every prototype as occluders, built once (one OccluderField per
    prototype for its crowns, each with its own τ, and one for every solid trunk), evaluated
    for any number of receivers. V = Π (1 − occ), so the fields multiply."""

    def __init__(self, prototypes, epsilon=DEFAULT_EPSILON):
        require()
        if not (0.0 <= epsilon < 1.0):
            raise ValueError(f"epsilon must be in [0, 1), got {epsilon}")
        self.epsilon = float(epsilon)
        self.prototypes = list(prototypes)
        self.fields = []
        solids = []
        self.shell_count = 0
        for p in self.prototypes:
            world = instance_shells(p.shells, p.matrices)
            self.shell_count += len(world)
            if world:
                self.fields.append(_core.OccluderField(world, float(p.tau), epsilon=self.epsilon))
            solids += instance_shells(p.solids, p.matrices)
        self.solid_count = len(solids)
        if solids:
            self.fields.append(_core.OccluderField(solids, 1.0, epsilon=self.epsilon, solid=True))

    @property
    def instances(self) -> int:
        return sum(p.count for p in self.prototypes)

    @property
    def max_candidates(self) -> int:
        """Largest number of occluders one receiver can test (summed over the fields)."""
        return sum(int(f.max_candidates) for f in self.fields)

    def ao(self, positions, normals):
        """Visibility float32 (N,) of receivers (float32 (N, 3) each) under every instance."""
        p = np.ascontiguousarray(positions, dtype=np.float32).reshape(-1, 3)
        n = np.ascontiguousarray(normals, dtype=np.float32).reshape(-1, 3)
        out = np.ones(len(p), np.float32)
        if not len(p):
            return out
        for f in self.fields:
            out *= np.asarray(f.ao(p, n), np.float32)
        return out


def prototype_from_plan(plan, tree, matrices, name=None):
    """The Prototype of ``tree`` as an engine Plan fitted it (its chosen shells, τ and solid
    trunks, in the space the prototype was baked in), placed by ``matrices`` (N, 4, 4) that
    map that space to each instance's."""
    return Prototype(name or tree, list(plan.proxies.get(tree, [])), float(plan.tau),
                     np.asarray(matrices, np.float64).reshape(-1, 4, 4),
                     list(plan.trunks.get(tree, [])))
