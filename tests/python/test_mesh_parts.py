"""Parts of one mesh (core/mesh_parts.py), no bpy: a tree's faces split by material slot (the
material's alpha or name, else its faces' shape) or by the shape of its loose pieces, each part
a role and a reason; a mesh of one kind stays whole."""
import os
import sys

import numpy as np

HERE = os.path.dirname(__file__)
sys.path.insert(0, os.path.join(HERE, "..", "..", "addon"))
sys.path.insert(0, os.path.join(HERE, "..", "..", "examples"))
sys.path.insert(0, HERE)

from canopy_ao.core import mesh_parts  # noqa: E402
from canopy_ao.core.scene import SceneItem  # noqa: E402
from real_shapes import bent_tubes, join, leaves  # noqa: E402


def _tree(rng):
    b, l = bent_tubes(rng), leaves(rng)
    p, t = join(b, l)
    return p, t, len(b[1])


def test_slots_by_alpha_name_and_shape():
    p, t, nb = _tree(np.random.default_rng(1))
    slot = np.r_[np.zeros(nb, int), np.ones(len(t) - nb, int)]
    for hints, bark_why, leaf_why in [
            ([mesh_parts.MaterialHint("Mat.001"), mesh_parts.MaterialHint("Mat.002", True)],
             "closed tubes", "alpha below 1"),
            ([mesh_parts.MaterialHint("Tree bark"), mesh_parts.MaterialHint("Leaves")],
             "named as bark", "named as leaves"),
            ([mesh_parts.MaterialHint("A"), mesh_parts.MaterialHint("B")],
             "closed tubes", "small pieces")]:
        parts = mesh_parts.split(p, t, slot, hints)
        assert [q.role for q in parts] == ["TRUNK", "CANOPY"]
        assert bark_why in parts[0].why and leaf_why in parts[1].why, [q.why for q in parts]
        assert parts[0].triangles.sum() == nb
        assert not (parts[0].triangles & parts[1].triangles).any()


def test_loose_pieces_by_shape_without_slots():
    p, t, nb = _tree(np.random.default_rng(2))
    for slot in (None, np.zeros(len(t), int)):  # no slot, or one for everything
        parts = mesh_parts.split(p, t, slot, [mesh_parts.MaterialHint("Material")])
        assert [q.role for q in parts] == ["TRUNK", "CANOPY"]
        assert np.flatnonzero(parts[0].triangles).tolist() == list(range(nb))


def test_one_kind_stays_whole():
    rng = np.random.default_rng(3)
    for p, t in (bent_tubes(rng), leaves(rng)):
        assert mesh_parts.split(p, t) is None
    # two slots of one role (two leaf materials) are one part: still whole
    p, t = leaves(rng)
    slot = np.arange(len(t)) % 2
    hints = [mesh_parts.MaterialHint("Leaf A", True), mesh_parts.MaterialHint("Leaf B", True)]
    assert mesh_parts.split(p, t, slot, hints) is None


def test_cut_and_merge_give_every_vertex_back():
    """A vertex two parts share is in both, one no triangle uses goes with the largest part,
    and merge averages them back onto the whole mesh."""
    p = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [5, 5, 5]], np.float32)
    t = np.array([[0, 1, 2], [1, 3, 2]], np.int32)
    it = SceneItem("M", "CANOPY", "T", p, np.tile([0, 0, 1], (5, 1)), t)
    parts = [mesh_parts.Part("a", "TRUNK", "", np.array([True, False])),
             mesh_parts.Part("b", "CANOPY", "", np.array([False, True]))]
    cut = mesh_parts.cut(it, parts)
    assert [c.name for c, _ in cut] == ["M [a]", "M [b]"]
    assert cut[0][1].tolist() == [0, 1, 2, 4] and cut[1][1].tolist() == [1, 2, 3]
    np.testing.assert_array_equal(cut[1][0].positions[cut[1][0].triangles[0]], p[t[1]])
    ao = mesh_parts.merge(5, [(idx, np.full(len(idx), k, np.float32))
                              for k, (_c, idx) in enumerate(cut)])
    assert ao.tolist() == [0, 0.5, 0.5, 1, 0]
