"""Parts of one mesh in a bake (core/mesh_parts.py; docs/DESIGN.md, 'Parts of one mesh'): an
object whose role is guessed and whose faces make parts of different roles (bark and leaf
material slots, or branch tubes and leaf cards) bakes as one item per part; its target
evaluates each part's receivers with that part's item and writes one result onto the mesh."""

import numpy as np

from .. import core
from ..core import card_carry, mesh_parts
from . import opacity_io

# Options under which an object keeps one role: their per-object maps (bent normals,
# thickness), live frames and a frame range's (frames.py) read the object's item as a whole.
WHOLE_OPTIONS = (("bent_normals", "bent normals"), ("thickness", "thickness"), ("live", "live"),
                 ("frames", "a frame range"))


def _triangle_materials(obj, depsgraph, count):
    """int32 (M,): each loop triangle's material slot of obj's evaluated mesh, or None (one
    slot, or a triangle count other than the item's)."""
    if len(obj.material_slots) < 2:
        return None
    ob_eval = obj.evaluated_get(depsgraph)
    mesh = ob_eval.to_mesh()
    try:
        mesh.calc_loop_triangles()
        if len(mesh.loop_triangles) != count:
            return None
        tm = np.empty(count, np.int32)
        mesh.loop_triangles.foreach_get("material_index", tm)
    finally:
        ob_eval.to_mesh_clear()
    return np.minimum(tm, len(obj.material_slots) - 1)  # past the last slot: the last's


def _hints(obj, alphas):
    """A MaterialHint per material slot (alphas: gather's cache of each material's alpha)."""
    out = []
    for slot in obj.material_slots:
        mat = slot.material
        key = mat.name_full if mat is not None else None
        if key not in alphas:
            alphas[key] = opacity_io.material_alpha(mat)
        out.append(mesh_parts.MaterialHint(mat.name if mat else "(empty slot)",
                                           not alphas[key][0].opaque))
    return out


def split(obj, item, depsgraph, opts, alphas, notes=None):
    """[(part SceneItem, vertex indices)] of obj's item when its faces make parts of
    different roles, else None. Each part carries ``whole = (item, indices)`` for targets()."""
    if not len(item.triangles):
        return None
    parts = mesh_parts.split(item.positions, item.triangles,
                             _triangle_materials(obj, depsgraph, len(item.triangles)),
                             _hints(obj, alphas))
    if parts is None:
        return None
    blocked = [label for key, label in WHOLE_OPTIONS if opts.get(key) not in (None, False, "OFF")]
    if blocked:
        if notes is not None:
            notes.append(f"{obj.name}: its parts ({', '.join(p.name for p in parts)}) would "
                         f"bake with roles of their own, but {', '.join(blocked)} need one "
                         "role per object: baked whole; split the object to bake by parts")
        return None
    out = mesh_parts.cut(item, parts)
    for (sub, idx), q in zip(out, parts):
        sub.whole = (item, idx)
        sub.part_why = q.why
        sub.part_triangles = q.triangles  # which of the whole item's triangles are its
    return out


def set_opacity(item, parts, op):
    """Give ``item`` the opacity ``op`` (opacity_io.item_opacity), and each of its parts
    (split's, or None) the share of it on the part's triangles."""
    item.opacity = op
    for sub, _idx in parts or ():
        sub.opacity = mesh_parts.opacity_of(op, sub.part_triangles)


def describe(parts):
    """The whole object's role source: each part, its role and why."""
    return "parts: " + "; ".join(f"'{p.name}' {p.role} ({p.part_why})" for p, _ in parts)


def targets(kind, items, objects, target_names, opts, depsgraph):
    """One target of ``kind`` (loop.KINDS[opts["mode"]]) per split target object (its whole
    item), holding its parts."""
    groups = {}
    for it in items:
        whole = getattr(it, "whole", None)
        if whole is not None and whole[0].name in target_names:
            groups.setdefault(whole[0].name, (whole[0], []))[1].append((it, whole[1]))
    out = []
    for name, (item, parts) in groups.items():
        t = kind(item, objects[name], opts, depsgraph)
        t.parts = parts
        out.append(t)
    return out


def receivers(targets):
    """prepare's targets: {item name: (kind, count, group)}, a split target's receivers
    counted under its parts (the items the plan holds), split in proportion to their
    vertices."""
    out = {}
    for t in targets:
        parts = getattr(t, "parts", None)
        if not parts:
            out[t.item.name] = (t.kind, t.count, t.group)
            continue
        total = sum(len(idx) for _p, idx in parts) or 1
        for p, idx in parts:
            out[p.name] = (t.kind, int(round(t.count * len(idx) / total)), t.group)
    return out


def _texel_parts(t):
    """int (N,): the part of each of target t's receivers (a texel's, by its triangle; its
    sub-samples go with the first), and each part's local triangle index of each whole one."""
    masks = np.zeros(len(t.item.triangles), np.int64)
    local = np.zeros(len(t.item.triangles), np.int64)
    for k, (p, _idx) in enumerate(t.parts):
        keep = getattr(p, "part_triangles", None)
        if keep is None:
            continue
        masks[keep] = k
        local[keep] = np.arange(int(keep.sum()))
    return masks, local


def evaluate(plan, t, a, b, cards=True):
    """AO float32 (b − a,) of receivers a..b of the split target t (cards: its leaf cards'
    vertices carry their opaque part's AO, core/card_ao.py)."""
    t.item.tree = ", ".join(dict.fromkeys(p.tree for p, _idx in t.parts))  # as resolved
    if t.vertices(a, b) is not None:  # receivers a..b are the whole item's vertices a..b
        pieces = []
        for p, idx in t.parts:  # idx ascending: the chunk is one run of the part's vertices
            lo, hi = np.searchsorted(idx, [a, b])
            if hi > lo:
                ao = core.evaluate_receivers(plan, p, p.positions[lo:hi], p.normals[lo:hi],
                                             vertices=slice(int(lo), int(hi)))
                if cards:  # its leaf cards' vertices
                    card_carry.carry(plan, p, ao, slice(int(lo), int(hi)))
                pieces.append((idx[lo:hi] - a, ao))
        return mesh_parts.merge(b - a, pieces)
    part, local = _texel_parts(t)
    if t.triangles is not None:
        tri = np.asarray(t.triangles[a:b], np.int64)
        which = np.where(tri >= 0, part[np.maximum(tri, 0)], 0)
    else:  # the raster's triangles are not the item's: every texel on the largest part
        which = np.full(b - a, int(np.argmax([len(idx) for _p, idx in t.parts])))
        tri = None
    g = t.group
    if g > 1 and len(which) % g == 0:  # a texel's sub-samples stay together
        which = np.repeat(which[::g], g)
    ao = np.ones(b - a, np.float32)
    pos, nor = t.positions[a:b], t.normals[a:b]
    for k, (p, _idx) in enumerate(t.parts):
        sel = np.flatnonzero(which == k)
        if len(sel):
            own = None if tri is None or not len(p.triangles) else np.where(
                (tri[sel] >= 0) & (part[np.maximum(tri[sel], 0)] == k),
                local[np.maximum(tri[sel], 0)], -1).astype(np.int32)
            ao[sel] = core.evaluate_receivers(plan, p, np.ascontiguousarray(pos[sel]),
                                              np.ascontiguousarray(nor[sel]), group=g,
                                              triangles=own)
    return ao


def summary(t):
    """The report's "parts" entry of a split target: each part's name, role, why, vertices."""
    return [{"name": p.name, "role": p.role, "why": p.part_why, "vertices": int(len(idx)),
             "tree": p.tree} for p, idx in t.parts]
