"""Cards in the proxies (core/opacity.py counted_triangles; issue #38 item 2): a tree whose leaves
are alpha-textured cards and the same tree with opaque leaves of the cards' opaque area light
the trunk and the ground under it alike, rung by rung: each rung's bias against the rays of its
own scene (which honour the alpha) within ±0.03 of the other's."""

import os
import sys

import bpy
import numpy as np
import pytest

from foliage_helpers import baked_ao, cli_bake
from conftest import REPO, _clear_scene, require_sapling

sys.path.insert(0, os.path.join(REPO, "examples"))
import foliage_scenes  # noqa: E402

RUNGS = ("sphere", "ellipsoid", "shells", "medium", "reeves_blau", "grid", "regression",
         "hybrid")


def _scene(cards):
    _clear_scene()
    col = bpy.data.collections.new("Tree")
    bpy.context.scene.collection.children.link(col)
    objs = foliage_scenes.sapling_card_tree(col, cards=cards, opaque_area=not cards)
    objs["ground"] = foliage_scenes.ground(col)
    for ob in bpy.context.scene.objects:
        ob.select_set(False)
    bpy.context.view_layer.update()
    return objs


def _biases(tmp_path, capsys, cards):
    """{rung: (trunk bias, ground bias)} against rays, the ground's within the crown's reach."""
    objs = _scene(cards)
    g = np.array([tuple(v.co) for v in objs["ground"].data.vertices])
    leaves = np.array([tuple(v.co) for v in objs["canopy"].data.vertices])
    reach = 1.5 * np.percentile(np.hypot(leaves[:, 0], leaves[:, 1]), 95)
    under = np.hypot(g[:, 0], g[:, 1]) < reach
    got = {}
    for method in ("raytrace",) + RUNGS:
        cli_bake(tmp_path, capsys, "--all", "--method", method, "--samples", "64")
        got[method] = (baked_ao(objs["trunk"].name).mean(), baked_ao("Ground")[under].mean())
    rays = got.pop("raytrace")
    return {m: (t - rays[0], g - rays[1]) for m, (t, g) in got.items()}


def test_card_tree_biases_as_the_opaque_tree(tmp_path, capsys):
    require_sapling()
    card = _biases(tmp_path, capsys, True)
    opaque = _biases(tmp_path, capsys, False)
    worst = 0.0
    for m in RUNGS:
        d = np.subtract(card[m], opaque[m])
        print(f"{m}: trunk bias {card[m][0]:+.3f} vs {opaque[m][0]:+.3f}, ground "
              f"{card[m][1]:+.3f} vs {opaque[m][1]:+.3f}")
        worst = max(worst, float(np.abs(d).max()))
    print(f"worst difference {worst:.3f}")
    assert worst <= 0.03
    _clear_scene()
