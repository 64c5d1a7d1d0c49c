"""Forests: instanced trees as occluders of the ground (docs/DESIGN.md, 'The method ladder').
No bpy.

A forest is a few unique tree prototypes, each with its fitted shells in the prototype's own
space, and many instances, each a 4×4 world matrix (rotation, translation, any scale, even
non-uniform or mirrored). The prototype's self-AO is baked once and shared by its instances
(they share the mesh data); the ground sees every instance's shells as occluders, evaluated by
the core's ``ForestOccluders`` (forest.h, occluders.h), which cuts each occluder off where its
effect drops below ε (Shanmugam–Arikan Eq. 5) and indexes them in a uniform grid, so a
receiver's cost is bounded by the number of shells within reach of it, not by the tree count
(bench/forest.py measures it).

Transforming a shell is exact: the image of the ellipsoid {c + Q diag(r) u : |u| ≤ 1} under
x ↦ A x + t is {A c + t + B u : |u| ≤ 1} with B = A Q diag(r); with the SVD B = U S Vᵀ (V only
rotates the unit ball) it is the ellipsoid with centre A c + t, axes U and radii S. So
non-uniform scale and shear need no refit and no approximation.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .meshes import scene_triangles
from .native import CanopyAOError, _core, require
from .scene import ray_length, tau_of

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
    # The prototype's triangles in its own space, (vertices float32 (V, 3), triangles int32
    # (M, 3)), or None: what the exact rung's ray tracer instances (lighting.build_tracer), so
    # rays and calibration see the trees the shells stand for.
    mesh: tuple | None = None

    @property
    def count(self) -> int:
        return int(len(np.asarray(self.matrices).reshape(-1, 16)))


class Forest:
    """Every instance of every prototype as occluders, built once: the native
    ``_core.ForestOccluders`` (forest.h: one occluder field per prototype's world-space
    crowns, each with its own τ, and one for every solid trunk; V = Π (1 − occ), so the fields
    multiply). The scene plan multiplies it into every receiver it lights (lighting.lights
    attaches it); the other rungs call :meth:`ao`."""

    def __init__(self, prototypes, epsilon=DEFAULT_EPSILON, distance=0.0):
        require()
        if not (0.0 <= epsilon < 1.0):
            raise ValueError(f"epsilon must be in [0, 1), got {epsilon}")
        if not (distance >= 0.0):
            raise ValueError(f"distance must be >= 0 (0 = unlimited), got {distance}")
        self.epsilon = float(epsilon)
        self.distance = float(distance)  # the AO distance (0 = unlimited)
        self.prototypes = list(prototypes)
        self.tau_scale = 1.0  # every prototype's τ times this (forest_tau: fitted on receivers)
        self._crowns, self._solids = [], []  # world-space shells, kept for scaled()
        for p in self.prototypes:
            self._crowns.append(instance_shells(p.shells, p.matrices))
            self._solids += instance_shells(p.solids, p.matrices)
        self._build()

    def _build(self):
        crowns = [(c, float(p.tau) * self.tau_scale)
                  for c, p in zip(self._crowns, self.prototypes)]
        # No instance beyond the AO distance along a ray occludes.
        self.native = _core.ForestOccluders(crowns, self._solids, epsilon=self.epsilon,
                                            distance=ray_length(self.distance))

    def scaled(self, scale: float) -> "Forest":
        """The same instances with every prototype's τ times ``scale`` (the shells are not
        transformed again: only the occluder index is rebuilt, its cut-off depends on τ)."""
        out = object.__new__(Forest)
        out.__dict__.update(self.__dict__)
        out.tau_scale = self.tau_scale * float(scale)
        out._build()
        return out

    @property
    def instances(self) -> int:
        return sum(p.count for p in self.prototypes)

    @property
    def shell_count(self) -> int:
        return int(self.native.shells)

    @property
    def solid_count(self) -> int:
        return int(self.native.solids)

    @property
    def max_candidates(self) -> int:
        """Largest number of occluders one receiver can test (summed over the fields)."""
        return int(self.native.max_candidates)

    def ao(self, positions, normals):
        """Visibility float32 (N,) of receivers (float32 (N, 3) each) under every instance."""
        p = np.ascontiguousarray(positions, dtype=np.float32).reshape(-1, 3)
        n = np.ascontiguousarray(normals, dtype=np.float32).reshape(-1, 3)
        return self.native.ao(p, n)


def prototype_mesh(items):
    """(vertices float32 (V, 3), triangles int32 (M, 3)): every non-ignored item's triangles
    in one mesh (meshes.scene_triangles), or None when there are none."""
    try:
        return scene_triangles(items)
    except CanopyAOError:  # no triangles
        return None


def prototype_from_plan(plan, tree, matrices, name=None, items=None):
    """The Prototype of ``tree`` as an engine Plan fitted it (its chosen shells, τ and solid
    trunks, in the space the prototype was baked in), placed by ``matrices`` (N, 4, 4) that
    map that space to each instance's. ``items``: the prototype's SceneItems (in that space),
    whose triangles the exact rung traces at every instance (None: shells only)."""
    return Prototype(name or tree, list(plan.proxies.get(tree, [])),
                     tau_of(plan.taus(), tree),
                     np.asarray(matrices, np.float64).reshape(-1, 4, 4),
                     list(plan.trunks.get(tree, [])),
                     prototype_mesh(items) if items is not None else None)


# Realising instances costs memory in proportion to their vertices (positions, normals,
# triangles: ~40 bytes a vertex); above this many a prototype stays instanced (traced by the
# exact rung, not a grass layer: instances.Prototypes says so in a note).
MAX_REALIZED_VERTICES = 3_000_000


@dataclass
class Realized:
    """Every instance of a prototype's objects as one world-space SceneItem (``item``), and
    where each object's copies lie in it: ``spans`` [(object name, first vertex, instances,
    vertices per instance)], so a per-vertex result maps back to the shared mesh
    (:meth:`sample_vertices`)."""

    item: object  # scene.SceneItem
    spans: list

    @property
    def instances(self) -> int:
        """Instances of the prototype (its objects' copies: the most any object has)."""
        return max(k for _n, _a, k, _v in self.spans)

    @property
    def objects(self) -> list:
        """The prototype's object names, in the item's order."""
        return [n for n, _a, _k, _v in self.spans]

    def sample_vertices(self, at_most, names=None):
        """[(object name, vertex indices into item, instances k, vertices v)]: the vertices of
        at most ``at_most`` of each object's instances, evenly spread over them (every one when
        there are no more), instance-major, so AO at them reshapes to (k, v)."""
        out = []
        for name, a, k, v in self.spans:
            if names is not None and name not in names:
                continue
            pick = np.unique(np.linspace(0, k - 1, min(k, int(at_most))).round().astype(np.int64))
            idx = (a + v * pick[:, None] + np.arange(v)[None, :]).reshape(-1)
            out.append((name, idx, len(pick), v))
        return out


def realize(items, matrices, name, role, tree):
    """The instances of ``items`` (SceneItems in the prototype's space) under ``matrices`` (one
    (N, 4, 4) array per item, as instances.Prototypes keeps them) as one world-space SceneItem
    named ``name``: positions moved by each matrix, normals by its inverse transpose, a mirrored
    instance's triangles wound the other way (its faces keep facing out), polygon ids kept
    per copy. Singular matrices (a zero-scaled instance) are dropped. Returns a Realized, or
    None when nothing is left."""
    from .scene import SceneItem
    pos, nor, tri, poly, spans = [], [], [], [], []
    base = npoly = 0
    for it, mats in zip(items, matrices):
        m = np.asarray(mats, np.float64).reshape(-1, 4, 4)
        a, t = m[:, :3, :3], m[:, :3, 3]
        det = np.linalg.det(a)
        keep = np.abs(det) > 1e-12
        a, t, det = a[keep], t[keep], det[keep]
        k, v = len(a), len(it.positions)
        if not k or not v:
            continue
        p = np.einsum("nij,vj->nvi", a, it.positions.astype(np.float64)) + t[:, None, :]
        inv_t = np.transpose(np.linalg.inv(a), (0, 2, 1))
        q = np.einsum("nij,vj->nvi", inv_t, it.normals.astype(np.float64))
        q /= np.maximum(np.linalg.norm(q, axis=2, keepdims=True), 1e-30)
        tris = np.broadcast_to(it.triangles, (k,) + it.triangles.shape).copy()
        tris[det < 0] = tris[det < 0][:, :, ::-1]
        tris += (base + v * np.arange(k))[:, None, None].astype(np.int32)
        pos.append(p.reshape(-1, 3))
        nor.append(q.reshape(-1, 3))
        tri.append(tris.reshape(-1, 3))
        if it.polygons is not None and len(it.polygons):
            per = int(it.polygons.max()) + 1
            poly.append((it.polygons[None, :] + npoly + per * np.arange(k)[:, None]).reshape(-1))
            npoly += per * k
        else:
            poly.append(None)
        spans.append((it.name, base, k, v))
        base += k * v
    if not spans:
        return None
    polygons = None if any(x is None for x in poly) else np.concatenate(poly)
    item = SceneItem(name, role, tree, np.concatenate(pos), np.concatenate(nor),
                     np.concatenate(tri), polygons=polygons)
    return Realized(item, spans)


def tracer_instances(prototypes):
    """The RayTracer's instance arguments for prototypes that carry a mesh: {"prototypes":
    [(vertices, triangles)], "instance_prototypes": int32 (K,), "instance_matrices": float32
    (K, 4, 4)}, or {} when none does. Singular matrices (a zero-scaled instance) are dropped:
    they occlude nothing."""
    meshes, which, mats = [], [], []
    for p in prototypes or ():
        if p.mesh is None or not len(p.mesh[1]):
            continue
        m = np.asarray(p.matrices, np.float64).reshape(-1, 4, 4)
        m = m[np.abs(np.linalg.det(m[:, :3, :3])) > 1e-12]
        if not len(m):
            continue
        which.append(np.full(len(m), len(meshes), np.int32))
        mats.append(m)
        meshes.append(p.mesh)
    if not meshes:
        return {}
    m = np.concatenate(mats)
    m[:, 3, :] = (0.0, 0.0, 0.0, 1.0)  # affine, as Embree's instance transform
    return {"prototypes": meshes, "instance_prototypes": np.concatenate(which),
            "instance_matrices": np.ascontiguousarray(m, np.float32)}


def traced_meshes(prototypes) -> list:
    """The prototypes that carry triangles for the ray tracer (forest.Prototype.mesh)."""
    return [p for p in prototypes or () if p.mesh is not None and len(p.mesh[1])]


def attach(plan, prototypes, epsilon) -> None:
    """plan.forest: the instances' shells and trunks as occluders, and the note saying so."""
    t0 = time.perf_counter()
    eps = plan.settings.forest_epsilon if epsilon is None else float(epsilon)
    plan.forest = Forest(prototypes, epsilon=eps, distance=plan.settings.distance) \
        if prototypes else None
    plan.timings["forest"] = time.perf_counter() - t0
    if plan.forest is not None:
        # The scene's own trees may all be instances: then "no CANOPY object" is not news.
        plan.notes = [n for n in plan.notes if not n.startswith("no CANOPY object")]
        plan.notes.append(
            f"forest: {plan.forest.instances} instance(s) of {len(plan.forest.prototypes)} "
            f"prototype(s), {plan.forest.shell_count} shells, {plan.forest.solid_count} trunks "
            f"as occluders (ε {plan.forest.epsilon:g}, at most {plan.forest.max_candidates} "
            "per receiver)")
