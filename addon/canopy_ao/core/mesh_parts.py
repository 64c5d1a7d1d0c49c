"""Parts of one mesh (issue #38 item 4; docs/DESIGN.md, 'Parts of one mesh'): a tree made as one
object (bark and leaves joined, a Sapling tree converted and joined) is cut into parts, each
given a role as if it were an object of its own, so it bakes like the same tree in two objects.

Faces are grouped first by material slot; a slot's role comes from its material (an alpha below
1 anywhere: leaf cards; a name that says leaf or bark) or else from its faces' shape
(roles.guess_role). Slots of one role form one part. When the slots tell nothing apart (one
material, or none), the mesh's loose pieces are grouped by shape: closed tubes and solids
(branches) apart from open cards (leaves), each group guessed again. A mesh is cut only when
its parts get different roles. No bpy here.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from . import roles
from .scene import SceneItem

# Words in a material's name that say what its faces are (whole words or their start, any case).
LEAF_WORDS = ("leaf", "leaves", "foliage", "needle", "frond", "petal", "blossom", "flower",
              "ivy", "canopy", "crown")
BARK_WORDS = ("bark", "trunk", "branch", "twig", "stem", "wood", "stalk")
_LEAF = re.compile(r"(?<![a-z])(" + "|".join(LEAF_WORDS) + ")", re.I)
_BARK = re.compile(r"(?<![a-z])(" + "|".join(BARK_WORDS) + ")", re.I)
# Loose pieces are grouped by shape only when each group holds at least this share of the
# mesh's area: a few stray closed pieces among many cards do not make a part.
MIN_SHARE = 0.02


@dataclass
class MaterialHint:
    """What a material slot says of its faces: its name and whether its alpha is below 1
    anywhere (an alpha-textured card, or a constant alpha)."""

    name: str = ""
    transparent: bool = False


@dataclass
class Part:
    """One part: its name, role and reason, and which of the mesh's triangles are its."""

    name: str
    role: str
    why: str
    triangles: np.ndarray  # bool (M,)


def material_role(hint: MaterialHint):
    """(role, reason) a material alone tells, or None."""
    if hint.transparent:
        return "CANOPY", f"material '{hint.name}' has an alpha below 1 (leaf cards)"
    leaf, bark = _LEAF.search(hint.name or ""), _BARK.search(hint.name or "")
    if leaf and not bark:
        return "CANOPY", f"material '{hint.name}' is named as leaves"
    if bark and not leaf:
        return "TRUNK", f"material '{hint.name}' is named as bark"
    return None


def _sub(positions, triangles, keep):
    """(positions, triangles) of the triangles ``keep`` and the vertices they use."""
    t = triangles[keep]
    used = np.unique(t)
    remap = np.full(len(positions), -1, np.int64)
    remap[used] = np.arange(len(used))
    return positions[used], remap[t]


def _by_slots(positions, triangles, tri_material, hints):
    """[Part] of the slots grouped by role, or None when they tell nothing apart."""
    slots = np.unique(tri_material)
    if len(slots) < 2:
        return None
    by_role = {}
    for s in slots:
        keep = tri_material == s
        hint = hints[s] if 0 <= s < len(hints) else MaterialHint(f"slot {s}")
        told = material_role(hint)
        if told is None:
            role, why = roles.guess_role(*_sub(positions, triangles, keep))
            told = role, f"material '{hint.name}': {why}"
        entry = by_role.setdefault(told[0], [np.zeros(len(triangles), bool), []])
        entry[0] |= keep
        entry[1].append(told[1])
    if len(by_role) < 2:
        return None
    return [Part(role.lower(), role, "; ".join(whys), keep)
            for role, (keep, whys) in by_role.items()]


def _by_shape(positions, triangles):
    """[Part] of the loose pieces grouped into closed (tubes, solids) and open (cards), or
    None when the mesh is not of both kinds."""
    labels = roles.connected_components(len(positions), triangles)
    k = int(labels.max()) + 1
    if k < 2:
        return None
    area, openness, plate = roles.piece_shape(positions, triangles, labels, k)
    closed = (openness < roles.CLOSED_OPENNESS) & (plate < roles.CLOSED_PLATE)
    total = area.sum()
    if not total > 0 or min(area[closed].sum(), area[~closed].sum()) < MIN_SHARE * total:
        return None
    out = []
    for name, pieces in (("closed pieces", closed), ("open pieces", ~closed)):
        keep = pieces[labels[triangles[:, 0]]]
        role, why = roles.guess_role(*_sub(positions, triangles, keep))
        out.append(Part(name, role, f"{int(pieces.sum())} {name}: {why}", keep))
    return out if len({p.role for p in out}) > 1 else None


def split(positions, triangles, tri_material=None, hints=()):
    """The parts of one mesh, or None when it is one part (docstring above).

    positions: V by 3 world-space; triangles: M by 3 vertex indices; tri_material: int (M,)
    each triangle's material slot (None: one slot); hints: a MaterialHint per slot.
    Parts cover every triangle once, ordered by their first triangle."""
    p = np.asarray(positions, np.float64).reshape(-1, 3)
    t = np.asarray(triangles, np.int64).reshape(-1, 3)
    if len(t) == 0:
        return None
    parts = None
    if tri_material is not None:
        parts = _by_slots(p, t, np.asarray(tri_material, np.int64), list(hints))
    if parts is None:
        parts = _by_shape(p, t)
    if parts is None:
        return None
    return sorted(parts, key=lambda q: int(np.argmax(q.triangles)))


def cut(item: SceneItem, parts):
    """[(SceneItem, vertex indices int64 into item)] of ``parts`` (split's), each an item of
    its own named '<item> [<part>]': its triangles and the vertices they use (a vertex two
    parts share is in both); vertices no triangle uses go with the largest part."""
    tris = np.asarray(item.triangles, np.int64)
    used = np.zeros(len(item.positions), bool)
    used[tris.reshape(-1)] = True
    largest = int(np.argmax([q.triangles.sum() for q in parts]))
    out = []
    for k, q in enumerate(parts):
        t = tris[q.triangles]
        idx = np.unique(t)
        if k == largest:
            idx = np.union1d(idx, np.flatnonzero(~used))
        remap = np.full(len(item.positions), -1, np.int64)
        remap[idx] = np.arange(len(idx))
        sub = SceneItem(f"{item.name} [{q.name}]", q.role, item.tree, item.positions[idx],
                        item.normals[idx], remap[t], tree_source=item.tree_source,
                        polygons=item.polygons[q.triangles] if item.polygons is not None
                        else None, corner_normals=item.corner_normals[q.triangles]
                        if item.corner_normals is not None else None)
        sub.opacity = opacity_of(item.opacity, q.triangles)
        out.append((sub, idx))
    return out


def opacity_of(op, keep):
    """An ItemOpacity restricted to the triangles ``keep`` (the same materials)."""
    if op is None or len(op.triangle_material) != len(keep):
        return op
    return type(op)(op.materials, op.triangle_material[keep],
                    op.uvs[keep] if op.uvs is not None else None, list(op.notes))


def merge(count, pieces):
    """float32 (count,): each vertex's mean over the parts holding it. pieces: [(vertex
    indices, values)] per part."""
    total = np.zeros(count, np.float64)
    n = np.zeros(count, np.float64)
    for idx, v in pieces:  # a part holds a vertex once
        total[idx] += v
        n[idx] += 1.0
    return (total / np.maximum(n, 1.0)).astype(np.float32)
