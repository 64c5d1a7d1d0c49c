"""Which tree each canopy and trunk piece belongs to, from where the pieces stand (no bpy).

Objects loose in one collection, or one mesh holding several trees' leaves, would otherwise
be fitted as one tree. Names come first (the user's tree, a parent chain); this module splits
what only a collection or the scene groups (docs/DESIGN.md, 'How each role is lit').
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .roles import connected_components, piece_shape


@dataclass
class TreeGuess:
    """Where an object's vertices belong: ``trees[labels[v]]`` is vertex v's tree (one name
    when the object holds one tree), and why."""

    trees: list
    labels: np.ndarray = field(repr=False)
    why: str = ""


class _Cells:
    """The xy cells of size h that points fall in, joined into 8-neighbour groups."""

    def __init__(self, xy, h):
        self.h, self.origin = h, xy.min(axis=0) - h  # a margin: neighbours stay >= 0
        ij = self._ij(xy)
        self.width = int(ij[:, 1].max()) + 2
        key = ij[:, 0] * self.width + ij[:, 1]
        self.keys, point_cell = np.unique(key, return_inverse=True)
        point_cell = point_cell.reshape(-1)
        m = len(self.keys)
        edges = []
        for di, dj in ((1, -1), (1, 0), (1, 1), (0, 1)):
            hit, pos = self._find(self.keys + di * self.width + dj)
            src = np.nonzero(hit)[0]
            edges.append(np.stack([src, pos[hit], pos[hit]], 1))
        self.cell_group = connected_components(m, np.concatenate(edges))
        self.point_group = self.cell_group[point_cell]

    def _ij(self, xy):
        return np.floor((xy - self.origin) / self.h).astype(np.int64)

    def _find(self, key):
        pos = np.searchsorted(self.keys, key)
        pos = np.minimum(pos, len(self.keys) - 1)
        return self.keys[pos] == key, pos

    def group_at(self, xy):
        """Group of the occupied cell each point falls in, or of an occupied neighbour; -1."""
        ij = self._ij(np.asarray(xy, np.float64).reshape(-1, 2))
        out = np.full(len(ij), -1, np.int64)
        for di, dj in ((0, 0), (0, 1), (1, 0), (0, -1), (-1, 0), (1, 1), (1, -1), (-1, 1),
                       (-1, -1)):
            key = (ij[:, 0] + di) * self.width + ij[:, 1] + dj
            ok = (ij[:, 0] + di >= 0) & (ij[:, 1] + dj >= 0) & (ij[:, 1] + dj < self.width)
            hit, pos = self._find(key)
            take = (out < 0) & ok & hit
            out[take] = self.cell_group[pos[take]]
        return out


def _pieces_xy(p, t):
    """Connected pieces of a mesh: (vertex labels, k, centroid xy (k, 2), lowest z (k,),
    xy of each piece's lowest vertex (k, 2))."""
    lab = connected_components(len(p), t)
    k = int(lab.max()) + 1
    cnt = np.bincount(lab, minlength=k).astype(np.float64)
    cen = np.stack([np.bincount(lab, p[:, j], k) for j in range(2)], 1) / cnt[:, None]
    order = np.lexsort((p[:, 2], lab))  # by piece, then height: the first of each is lowest
    first = order[np.searchsorted(lab[order], np.arange(k))]
    return lab, k, cen, p[first, 2], p[first, :2]


def assign_trees(objects, group="Scene"):
    """Tell the trees of one group of objects apart by where their pieces stand (no names).

    objects: list of (name, role, positions (V, 3), triangles (F, 3)), all in one group (a
    collection, or loose in the scene) whose trees the user did not name. Returns
    {name: TreeGuess} for the CANOPY and TRUNK objects (others get no tree of their own).

    Crowns: the canopy's connected pieces (leaves) are projected on the ground plane and joined
    when they fall in 8-neighbouring cells of size h = 2 sqrt(B / K) (B: the area of the pieces'
    bounding rectangle, K: their number; twice the mean spacing were they spread over all of
    it, so a crown's leaves join and a gap between crowns wider than h splits them: scale-free).
    Groups with under 1 % of the leaf area join the nearest group. Stems: trunk pieces whose
    lowest point lies in the lowest tenth of their object's height, joined like the leaves (a
    bole made of several segments is one stem). A crown over two or more stems (crowns that
    touch) is split between them by the nearest stem; a stem with no crown over it is a tree of
    its own; every other trunk piece (a branch) goes with the crown above it."""
    canopy = [(n, np.asarray(p, np.float64).reshape(-1, 3), t) for n, r, p, t in objects
              if r == "CANOPY" and len(p)]
    trunks = [(n, np.asarray(p, np.float64).reshape(-1, 3), t) for n, r, p, t in objects
              if r == "TRUNK" and len(p)]
    leaf = [_pieces_xy(p, t) for _n, p, t in canopy]
    wood = [_pieces_xy(p, t) for _n, p, t in trunks]
    cen = np.concatenate([lf[2] for lf in leaf]) if leaf else np.zeros((0, 2))
    owner = np.concatenate([np.full(lf[1], i) for i, lf in enumerate(leaf)]) if leaf \
        else np.zeros(0, np.int64)
    wts = np.concatenate([piece_shape(p, t, lf[0], lf[1])[0] + 1e-12
                          for (_n, p, t), lf in zip(canopy, leaf)]) if leaf else np.zeros(0)
    # Stems and their base points.
    stem_xy, stem_of, stem_area, stem_z = [], [], [], []  # per piece: base xy, (trunk,
    # piece), area, lowest z
    for i, ((_n, p, t), (lab, k, _c, z_low, xy_low)) in enumerate(zip(trunks, wood)):
        z0, z1 = p[:, 2].min(), p[:, 2].max()
        area = piece_shape(p, t, lab, k)[0] + 1e-12
        for c in np.nonzero(z_low <= z0 + 0.1 * (z1 - z0))[0]:
            stem_xy.append(xy_low[c])
            stem_of.append((i, c))
            stem_area.append(area[c])
            stem_z.append(z_low[c])
    stem_z = np.array(stem_z, np.float64)
    stem_xy = np.array(stem_xy, np.float64).reshape(-1, 2)
    stem_area = np.array(stem_area, np.float64)
    both = np.concatenate([cen, stem_xy])
    ext = np.ptp(both, axis=0) if len(both) else np.zeros(2)
    n_ref = len(cen) if len(cen) else max(len(stem_xy), 1)
    h = 2.0 * math.sqrt(max(ext[0] * ext[1], 1e-12 * max(ext.max(), 1e-12) ** 2) / n_ref)
    if not h > 0:
        h = 1.0
    g = 0
    if len(cen):
        cells = _Cells(cen, h)
        glab = cells.point_group
        g = int(glab.max()) + 1
        gw = np.bincount(glab, wts, g)
        gc = np.stack([np.bincount(glab, wts * cen[:, j], g) for j in range(2)], 1) / gw[:, None]
        big = gw >= 0.01 * gw.sum()
        bigs = np.nonzero(big)[0]
        d = ((gc[:, None, :] - gc[None, bigs, :]) ** 2).sum(axis=2)
        remap = np.where(big, np.arange(g), bigs[np.argmin(d, axis=1)])
        _, remap = np.unique(remap, return_inverse=True)  # specks join the nearest crown
        remap = remap.reshape(-1)
        glab, g = remap[glab], int(remap.max()) + 1
        gc = np.stack([np.bincount(glab, wts * cen[:, j], g) for j in range(2)], 1) \
            / np.bincount(glab, wts, g)[:, None]

        def crown_at(xy):
            got = cells.group_at(xy)
            return np.where(got >= 0, remap[np.maximum(got, 0)], -1)
    else:
        glab = np.zeros(0, np.int64)

        def crown_at(xy):
            return np.full(len(xy), -1, np.int64)
    # Stems: joined when close (segments of one bole), each under the crown over it.
    if len(stem_xy):
        slab = _Cells(stem_xy, h).point_group
        ns = int(slab.max()) + 1
        sxy = np.stack([np.bincount(slab, stem_xy[:, j], ns) for j in range(2)], 1) \
            / np.bincount(slab, minlength=ns)[:, None]
        s_crown = crown_at(sxy)
        # Under one crown, a low twig is no stem: keep stems with >= 20 % of the biggest's
        # area. Nor is a fork (Sapling's base splits): a base inside the 45° cone above a lower
        # stem's base stands on that stem.
        s_area = np.bincount(slab, stem_area, ns)
        s_z = np.full(ns, np.inf)
        np.minimum.at(s_z, slab, stem_z)
        for gi in np.unique(s_crown[s_crown >= 0]):
            sel = s_crown == gi
            s_crown[sel & (s_area < 0.2 * s_area[sel].max())] = -2
        kept = []
        for si in np.argsort(s_z, kind="stable"):
            if s_crown[si] < 0:
                continue
            if any(np.hypot(*(sxy[si] - sxy[o])) < s_z[si] - s_z[o] for o in kept):
                s_crown[si] = -2
            else:
                kept.append(si)
    else:
        slab, ns, sxy, s_crown = np.zeros(0, np.int64), 0, np.zeros((0, 2)), np.zeros(0, np.int64)
    # Trees: a crown with its stems (split when several), then stems without a crown.
    crown_tree, crown_stems = [], []
    stem_tree = np.full(ns, -1, np.int64)
    n_trees = 0
    for gi in range(g):
        mine = np.nonzero(s_crown == gi)[0]
        crown_stems.append(mine)
        crown_tree.append(n_trees)
        stem_tree[mine] = n_trees + np.arange(len(mine))
        n_trees += max(1, len(mine))
    for si in np.nonzero(s_crown == -1)[0]:
        stem_tree[si] = n_trees
        n_trees += 1
    for si in np.nonzero(s_crown == -2)[0]:  # a twig: the tree of the crown above it
        stem_tree[si] = -1

    def tree_at(xy, crown):
        """Tree of points with these crowns (-1: none): the crown's, or its nearest stem's."""
        out = np.full(len(xy), -1, np.int64)
        for gi in np.unique(crown[crown >= 0]):
            sel = crown == gi
            mine = crown_stems[gi]
            if len(mine) <= 1:
                out[sel] = crown_tree[gi]
            else:
                d = ((xy[sel][:, None, :] - sxy[None, mine, :]) ** 2).sum(axis=2)
                out[sel] = stem_tree[mine][d.argmin(axis=1)]
        return out
    leaf_tree = tree_at(cen, glab)
    # Names: the canopy object holding most of a tree's leaf area, else its trunk's.
    names = [None] * n_trees
    if len(cen):
        wt = np.zeros((n_trees, len(canopy)))
        np.add.at(wt, (leaf_tree, owner), wts)
        for tr in range(n_trees):
            if wt[tr].sum() > 0:
                names[tr] = canopy[int(wt[tr].argmax())][0]
    for (ti, _c), si in zip(stem_of, slab):
        if stem_tree[si] >= 0 and names[stem_tree[si]] is None:
            names[stem_tree[si]] = trunks[ti][0]
    seen = {}
    for tr in range(n_trees):
        base = names[tr] or group
        seen[base] = seen.get(base, 0) + 1
        names[tr] = base if seen[base] == 1 else f"{base}.{seen[base] - 1}"
    out = {}
    start = 0
    for (name, _p, _t), (lab, k, _c, _z, _xy) in zip(canopy, leaf):
        out[name] = _guess(names, leaf_tree[start:start + k][lab],
                           f"leaves grouped by where they stand: {g} crown(s) in '{group}' "
                           f"(cells of {h:.3g})")
        start += k
    for i, ((name, _p, _t), (lab, k, tc, _z, _xy)) in enumerate(zip(trunks, wood)):
        piece_tree = tree_at(tc, crown_at(tc))
        own = [stem_tree[si] for (ti, c), si in zip(stem_of, slab)
               if ti == i and stem_tree[si] >= 0]
        for (ti, c), si in zip(stem_of, slab):
            if ti == i and stem_tree[si] >= 0:
                piece_tree[c] = stem_tree[si]
        fallback = own[0] if own else (leaf_tree[0] if len(leaf_tree) else 0)
        piece_tree[piece_tree < 0] = fallback
        if not names:
            names = [name]
        out[name] = _guess(names, piece_tree[lab], f"{len(set(own))} stem(s), branches with "
                                                   "the crown above them")
    return out


def _guess(names, vertex_tree, why):
    used, lab = np.unique(vertex_tree, return_inverse=True)
    return TreeGuess([names[int(u)] for u in used], lab.reshape(-1).astype(np.int64), why)


def resolve(items) -> None:
    """Split the CANOPY and TRUNK items whose tree is only a group (tree_source "collection"
    or "scene") into the trees assign_trees() finds among the group's items; sets each item's
    tree (and tree_labels, tree_names when it holds several) and tree_why. Items whose tree
    was set keep it."""
    groups = {}
    for it in items:
        if it.role in ("CANOPY", "TRUNK") and it.tree_source in ("collection", "scene"):
            groups.setdefault(it.tree, []).append(it)
    for group, members in groups.items():
        if not any(it.role == "CANOPY" for it in members):
            continue  # no crowns: nothing to split a trunk group by
        got = assign_trees([(it.name, it.role, it.positions, it.triangles) for it in members],
                           group)
        if len({t for g in got.values() for t in g.trees}) == 1:  # one tree: the group's name
            for it in members:
                if it.name in got:
                    it.tree_why = got[it.name].why
            continue
        for it in members:
            g = got.get(it.name)
            if g is None:
                continue
            it.tree_why = g.why
            if len(g.trees) == 1:
                it.tree, it.tree_labels, it.tree_names = g.trees[0], None, ()
            else:
                it.tree, it.tree_labels, it.tree_names = ", ".join(g.trees), g.labels, \
                    tuple(g.trees)
