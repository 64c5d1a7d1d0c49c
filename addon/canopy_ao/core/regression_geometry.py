"""The ray-free rung's geometry of one frame (core/regression.py; docs/DESIGN.md, 'The ray-free
rung'): the occluders' density grid swept toward the feature directions, the leaf tables and the
tree frames. A bake builds it once, a live frame again from its moved vertices. No bpy."""
from __future__ import annotations

import threading

import numpy as np

from . import card_area, native
from .leaf_features import LeafTable, tree_frame
from .meshes import merged

# Meshes whose connected pieces (a leaf card, a branch tube) give a receiver piece features.
LEAF_TABLE_ROLES = ("CANOPY", "TRUNK")


def geometry(items, occ, meshes, resolution, directions, before=None, tables=True):
    """(OcclusionFeatures over the occluders' density grid, {mesh: LeafTable or None} of the
    CANOPY and TRUNK meshes (meshes: unsplit items; a name seen twice gets none; before: an
    earlier frame's, pieces kept; tables=False: none at all, {}), the scene's tree frame,
    {tree: its frame})."""
    _core = native.require()
    mesh = merged([card_area.counted_item(it) for it in occ])  # cards by their opaque area
    built = {}

    # The grid's area deposit runs on one core (its sums in one order) and the native calls
    # release the GIL: the leaf tables and tree frames are made beside it.
    def sweep():
        try:
            built["features"] = _core.OcclusionFeatures(
                _core.DensityGrid(*mesh, resolution=resolution), directions=directions)
        except BaseException as exc:  # noqa: BLE001 (raised again on the caller's thread)
            built["error"] = exc
    worker = threading.Thread(target=sweep, name="canopy_ao grid")
    worker.start()
    try:
        leaves, scene_frame, frames = _tables_and_frames(items, occ, meshes, before, tables)
    finally:
        worker.join()
    if "error" in built:
        raise built["error"]
    return built["features"], leaves, scene_frame, frames


def _tables_and_frames(items, occ, meshes, before, tables):
    """geometry's numpy part: the leaf tables, the scene's tree frame and each tree's."""
    whole = meshes if meshes is not None else [it for it in items if it.vertex_map is None]
    leaves = {}
    for it in whole if tables else ():
        if it.role in LEAF_TABLE_ROLES:
            old = (before or {}).get(it.name)
            keep = old is not None and len(old.labels) == len(it.positions)
            leaves[it.name] = None if it.name in leaves or (before and old is None) else \
                LeafTable(it.positions, it.triangles, labels=old.labels if keep else None)
    scene_frame = tree_frame(np.concatenate([it.positions for it in occ]))
    frames = {}
    for tree in sorted({it.tree for it in items if it.tree}):
        own = [it for it in items if it.tree == tree and it.role in ("CANOPY", "TRUNK")]
        same = len(own) == len(occ) and all(a is b for a, b in zip(own, occ))  # one tree
        frames[tree] = tree_frame(np.concatenate([it.positions for it in own])) \
            if own and not same else scene_frame
    return leaves, scene_frame, frames
