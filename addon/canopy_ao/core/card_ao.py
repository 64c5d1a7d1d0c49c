"""A card's own AO at its vertices (docs/DESIGN.md, 'Opacity of leaf cards'; issue #38 item 3).

A leaf card's vertices sit in its clear corners. Cycles' vertex bake reads 0 there (the bake
point's surface is transparent), so vertex AO baked in Cycles leaves cards black; the AO at the
corner itself is the card plane's, not the leaf's. Here a card vertex carries the AO its card's
opaque part receives: the AO at the opaque point of each of its card triangles nearest it
(card_area.opaque_corners: on the card, the rays skipping that triangle, as a texel on it
would), a vertex shared by several card triangles taking the mean. A vertex that also
belongs to an opaque triangle, or to none with an opaque point, keeps its own AO. The
calibration samples take a card vertex at one of the same points (sample_points); the bake's
carry is core/card_carry.py (it evaluates, so it imports bake, which this module must not). No bpy.
"""

from __future__ import annotations

import numpy as np

from . import card_area


class CardVertices:
    """The receivers standing for an item's card vertices: vertex (K,) int64 ascending, the
    point float32 (K, 3) and normal float32 (K, 3) of each, the triangle int32 (K,) it lies on."""

    def __init__(self, item):
        got = card_area.opaque_corners(item)
        self.vertex = np.zeros(0, np.int64)
        if got is None or not len(got[1]):
            return
        near, src = got
        tris = np.asarray(item.triangles, np.int64)
        opaque = np.ones(len(tris), bool)
        opaque[card_area._clear_triangles(item)[1]] = False
        on_opaque = np.zeros(len(item.positions), bool)
        on_opaque[tris[opaque].reshape(-1)] = True
        vertex = tris[src].reshape(-1)
        keep = ~on_opaque[vertex]
        order = np.argsort(vertex[keep], kind="stable")
        self.vertex = vertex[keep][order]
        self.points = np.ascontiguousarray(near.reshape(-1, 3)[keep][order], np.float32)
        self.normals = np.ascontiguousarray(item.normals[self.vertex], np.float32)
        self.triangle = np.ascontiguousarray(np.repeat(src, 3)[keep][order], np.int32)


def card_vertices(item) -> CardVertices:
    """The item's CardVertices, made once per item."""
    got = getattr(item, "_card_vertices", None)
    if got is None:
        got = item._card_vertices = CardVertices(item)
    return got


def sample_points(item, idx):
    """Where a calibration sample (auto's τ fit, ladder.calibrate; the ray-free rung's fit,
    regression.py) takes the item's sample vertices ``idx`` (int, ascending), so it sees a card
    as the bake shows it (carry): None when none is a card vertex, else (card int64 (K,), the
    positions in idx of the card vertices, and their receivers: points float32 (K, 3), normals
    float32 (K, 3), triangle int32 (K,)), each card vertex's the first of its receivers (its
    card triangle of lowest index: one ray-traced point per sample vertex, as before)."""
    cv = card_vertices(item)
    idx = np.asarray(idx, np.int64)
    if not len(cv.vertex) or not len(idx):
        return None
    row = np.minimum(np.searchsorted(cv.vertex, idx), len(cv.vertex) - 1)
    card = np.flatnonzero(cv.vertex[row] == idx)
    if not len(card):
        return None
    row = row[card]
    return card, cv.points[row], cv.normals[row], cv.triangle[row]


def move_to_cards(items, owner, rows, points, normals, own, ids):
    """A calibration sample over several items (regression.py), row i item owner[i]'s vertex
    rows[i], its card vertices moved to their receivers (sample_points) in place: points,
    normals float32 (n, 3) and own int32 (n,), the tracer's vertex ids (-1 there after).
    ids(item, idx, "triangle_ids"): the tracer's ids of the item's triangles idx, or None.
    Returns (tri int64 (n,): the item's triangle of a moved row, -1 elsewhere; the tracer's
    triangle ids int32 (n,), or None when no row moved)."""
    tri, own_tri = np.full(len(rows), -1, np.int64), None
    for k, it in enumerate(items):
        m = np.flatnonzero(owner == k)
        # a part of an item (vertex_map) has no opacity: its vertices stay where they are
        got = sample_points(it, rows[m]) if it.vertex_map is None else None
        if got is None:
            continue
        c = m[got[0]]
        points[c], normals[c], tri[c], own[c] = got[1], got[2], got[3], -1
        own_tri = np.full(len(rows), -1, np.int32) if own_tri is None else own_tri
        t_ids = ids(it, got[3], "triangle_ids")
        if t_ids is not None:
            own_tri[c] = t_ids
    return tri, own_tri
