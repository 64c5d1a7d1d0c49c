"""Scene meshes: items' triangles merged into one mesh for the ray tracer, the density grid,
the ray-free rung's own tracer and an instanced tree's prototype, with the tracer's bake-point
data (one home for what lighting, forest and regression each built)."""

from __future__ import annotations

import numpy as np

from . import opacity
from .native import CanopyAOError


def merged(items):
    """(vertices float32 (V, 3), triangles int32 (M, 3)): the items' meshes in order, each
    item's triangles shifted by the vertices before it (every item counts, with or without
    triangles)."""
    verts, tris, off = [], [], 0
    for it in items:
        verts.append(it.positions)
        tris.append(it.triangles + off)
        off += len(it.positions)
    if not verts:
        return np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int32)
    return (np.ascontiguousarray(np.concatenate(verts), np.float32),
            np.ascontiguousarray(np.concatenate(tris), np.int32))


def bake_shading(items):
    """The tracer's bake-point data for items merged in order (native raytrace.h, 'Origins'):
    {"normals": float32 (V, 3), "polygons": int32 (M,)}, each item's faces numbered apart (an
    item without face ids counts every triangle a face), and "corner_normals" float32 (M, 3, 3)
    when an item has its own (SceneItem.corner_normals; the others' are their vertices')."""
    nrms, polys, first = [], [], 0
    corners = any(it.corner_normals is not None for it in items)
    cns = [it.normals[it.triangles] if it.corner_normals is None else it.corner_normals
           for it in items] if corners else []
    for it in items:
        nrms.append(it.normals)
        faces = it.polygons if it.polygons is not None else np.arange(len(it.triangles))
        polys.append(np.asarray(faces, np.int64) + first)
        first += int(faces.max()) + 1 if len(faces) else 0
    if not nrms:
        return {"normals": np.zeros((0, 3), np.float32), "polygons": np.zeros(0, np.int32)}
    out = {"normals": np.ascontiguousarray(np.concatenate(nrms), dtype=np.float32),
           "polygons": np.ascontiguousarray(np.concatenate(polys), dtype=np.int32)}
    if corners:
        out["corner_normals"] = np.ascontiguousarray(np.concatenate(cns), dtype=np.float32)
    return out


def scene_triangles(items, bases=None, shading=None):
    """Every non-ignored item's triangles in one mesh: (vertices float32, triangles int32).
    bases: a dict to fill with item name -> (its first vertex, its first triangle) there (None
    for a name seen twice: it cannot say which mesh it means). shading: a dict to fill with
    bake_shading of the same items, for the tracer's bake points. CanopyAOError when there
    are no triangles."""
    kept, base, tri_base = [], 0, 0
    for it in items:
        if it.role == "IGNORE" or not len(it.triangles):
            continue
        if bases is not None:
            bases[it.name] = None if it.name in bases else (base, tri_base)
        kept.append(it)
        base += len(it.positions)
        tri_base += len(it.triangles)
    if not kept:
        raise CanopyAOError("the scene has no triangles")
    if shading is not None:
        shading.update(bake_shading(kept), **opacity.tracer_args(kept))
    return merged(kept)
