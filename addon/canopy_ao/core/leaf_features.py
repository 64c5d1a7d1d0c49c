"""Where a receiver sits on its own leaf and in its tree: the regression rung's leaf features
and tree frames (docs/DESIGN.md, 'The ray-free rung'). No bpy."""
from __future__ import annotations

import numpy as np

from .roles import connected_components


class LeafTable:
    """Where a receiver sits on its own leaf (docs/DESIGN.md, 'The ray-free rung'): each
    connected piece of a CANOPY or TRUNK mesh (a leaf card, a branch tube), its centroid and
    mean radius. Most of a real leaf's AO varies within the leaf (its base by the twig, its
    inner half toward the crown), below any voxel; the features say where on the leaf a point
    is, in the leaf's own size:
    its offset from the centroid, over the mean radius, along up, along the horizontal
    direction out of the tree's axis and toward the crown's middle, and its length. Scale-free;
    O(vertices) to build, O(1) per receiver."""

    COUNT = 4

    def __init__(self, positions, triangles, labels=None):
        """labels: an earlier table's (the same mesh, deformed: live AO), so the pieces are
        not searched again; only their centroids and sizes move."""
        P = np.asarray(positions, np.float64)
        lab = connected_components(len(P), triangles) if labels is None else labels
        cnt = np.maximum(np.bincount(lab), 1).astype(np.float64)
        self.centroid = np.stack([np.bincount(lab, P[:, a]) for a in range(3)], 1) / cnt[:, None]
        d = np.linalg.norm(P - self.centroid[lab], axis=1)
        self.size = np.bincount(lab, d) / cnt
        self.labels = lab
        self.tri_labels = lab[np.asarray(triangles, np.int64)[:, 0]] if len(triangles) \
            else np.zeros(0, np.int64)

    def labels_of(self, own, count):
        """Leaf of each of `count` points from own ({"vertex_ids", "triangle_ids"}, either or
        both: the item's vertex or triangle of each point, -1 = none; a vertex first); -1 where
        unknown."""
        out = np.full(count, -1, np.int64)
        for key, table in (("triangle_ids", self.tri_labels), ("vertex_ids", self.labels)):
            ids = None if not own else own.get(key)
            if ids is not None:
                ids = np.asarray(ids, np.int64)
                ok = (ids >= 0) & (ids < len(table))
                out[ok] = table[ids[ok]]
        return out

    def features(self, p, labels, frame):
        """(N, COUNT) float32; 0 (a leaf's centre) where the leaf is unknown or a point."""
        out = np.zeros((len(p), self.COUNT), np.float32)
        ok = labels >= 0
        ok[ok] = self.size[labels[ok]] > 0
        if not ok.any():
            return out
        # Every point on a leaf (a mesh's own vertices, as in a live frame): no masked copy.
        rows = slice(None) if ok.all() else ok
        lab = labels[rows]
        u = (np.asarray(p, np.float64)[rows] - self.centroid[lab]) / self.size[lab][:, None]
        # The directions per leaf, then gathered per point (the same values: a leaf's points
        # share its centroid), a quarter of the work for quads.
        center, _r, z0, z1 = frame
        out_dir = self.centroid - np.asarray(center, np.float64)
        out_dir[:, 2] = 0.0
        mid = np.array([center[0], center[1], 0.5 * (z0 + z1)], np.float64)
        out[rows, 0] = u[:, 2]
        out[rows, 1] = np.einsum("ij,ij->i", u, _unit(out_dir)[lab])
        out[rows, 2] = np.einsum("ij,ij->i", u, _unit(mid - self.centroid)[lab])
        out[rows, 3] = np.linalg.norm(u, axis=1)
        return out


def _unit(v):
    n = np.linalg.norm(v, axis=1)
    return v / np.where(n > 0, n, 1.0)[:, None]


def tree_frame(points):
    """(center (3,), radius, z_min, z_max) of a tree from its points: the vertical axis through
    the median xy, the 95th-percentile horizontal distance from it."""
    p = np.asarray(points, np.float64).reshape(-1, 3)
    # Column by column (contiguous): np.median along axis 0 of an (N, 3) array costs 1.6 x.
    x, y, z = (np.ascontiguousarray(p[:, a]) for a in range(3))
    c = np.array([np.median(x), np.median(y), np.median(z)])
    r = np.hypot(x - c[0], y - c[1])
    radius = float(np.percentile(r, 95))
    lo = np.array([x.min(), y.min(), z.min()])
    hi = np.array([x.max(), y.max(), z.max()])
    radius = max(radius, 1e-3 * float(np.linalg.norm(hi - lo)), 1e-9)
    return c.astype(np.float32), radius, float(lo[2]), float(hi[2])
