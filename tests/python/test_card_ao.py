"""A card's vertices carry the AO of its opaque part (core/card_ao.py), no bpy: where their
receivers lie, which vertices they stand for, and the carried AO on a card under an occluder."""
import os
import sys

import numpy as np

HERE = os.path.dirname(__file__)
sys.path.insert(0, os.path.join(HERE, "..", "..", "addon"))

from canopy_ao import core  # noqa: E402
from canopy_ao.core import card_ao, card_carry, opacity  # noqa: E402
from canopy_ao.core.scene import SceneItem  # noqa: E402


def _card(tex, z=0.0, extra_opaque=False):
    """A 1 × 1 card in the xz plane (x, z in [0, 1]) at height z, two triangles, UVs (x, z);
    extra_opaque: a third, opaque triangle sharing vertex 1."""
    p = np.array([[0, 0, z], [1, 0, z], [1, 0, z + 1], [0, 0, z + 1], [2, 0, z]], np.float32)
    t = [[0, 1, 2], [0, 2, 3]] + ([[1, 4, 2]] if extra_opaque else [])
    t = np.array(t, np.int32)
    it = SceneItem("Card", "CANOPY", "T", p, np.tile([0, -1, 0], (5, 1)), t)
    uv = np.array([[[0, 0], [1, 0], [1, 1]], [[0, 0], [1, 1], [0, 1]]], np.float32)
    mats = [opacity.MaterialAlpha("Leaf", texture=tex, nearest=True), opacity.MaterialAlpha("X")]
    tm = np.array([0, 0] + ([1] if extra_opaque else []), np.int32)
    if extra_opaque:
        uv = np.concatenate([uv, np.zeros((1, 3, 2), np.float32)])
    it.opacity = opacity.ItemOpacity(mats, tm, uv)
    return it


def _top_half():
    tex = np.zeros((16, 16), np.float32)
    tex[8:] = 1.0  # v >= 0.5: opaque
    return tex


def test_receivers_lie_on_the_opaque_part():
    cv = card_ao.CardVertices(_card(_top_half()))
    assert sorted(set(cv.vertex.tolist())) == [0, 1, 2, 3]
    assert np.all(cv.points[:, 2] > 0.5) and np.all(cv.points[:, 2] < 1), cv.points  # the leaf
    assert np.all((cv.points[:, 0] > 0) & (cv.points[:, 0] < 1)) and len(cv.points) == 6
    # each the leaf's point nearest its vertex: the bottom corners' just above the middle
    bottom = cv.points[cv.vertex <= 1]
    assert np.all(bottom[:, 2] < 0.6), bottom
    # a vertex an opaque triangle shares keeps its own AO
    cv = card_ao.CardVertices(_card(_top_half(), extra_opaque=True))
    assert 1 not in cv.vertex.tolist() and 2 not in cv.vertex.tolist()


def test_carried_ao_is_the_opaque_parts():
    """A card standing on a ground: its bottom corners, carried up to the leaf in its top half,
    read brighter than the corners themselves, as bright as the leaf's own points."""
    g = np.array([[-5, -5, 0], [5, -5, 0], [5, 5, 0], [-5, 5, 0]], np.float32)
    ground = SceneItem("Ground", "GROUND", "", g, np.tile([0, 0, 1], (4, 1)),
                       np.array([[0, 1, 2], [0, 2, 3]], np.int32))
    card = _card(_top_half())
    plan = core.prepare([ground, card], core.BakeSettings(method="raytrace", samples=256,
                                                          distance=10.0))
    own = core.evaluate_receivers(plan, card, card.positions[:4], card.normals[:4],
                                  vertices=slice(0, 4))
    carried = own.copy()
    card_carry.carry(plan, card, carried, slice(0, 4))
    leaf = core.evaluate_receivers(plan, card, np.float32([[0.5, 0, 0.75]]),
                                   np.float32([[0, -1, 0]]), triangles=np.int32([1]))
    assert carried[:2].mean() > own[:2].mean() + 0.05, (own, carried)
    assert abs(float(carried.mean()) - float(leaf[0])) < 0.05, (carried, leaf)
