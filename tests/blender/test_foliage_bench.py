"""bench/foliage.py's buried vertices (issue #38: every foliage figure with and without them,
as for the Sapling trees): a leaf strip whose base lies inside a 1 cm twig has that base, and
only that, marked buried; the ground is never tested."""

import os
import sys

import bpy
import numpy as np

from conftest import REPO, _clear_scene, add_grid_ground, add_mesh

sys.path.insert(0, os.path.join(REPO, "bench"))
import foliage  # noqa: E402


def _box(name, centre, half):
    c = np.float32(centre)
    p = np.float32([[x, y, z] for z in (-1, 1) for y in (-1, 1) for x in (-1, 1)]) * half + c
    t = [[0, 2, 3], [0, 3, 1], [4, 5, 7], [4, 7, 6], [0, 1, 5], [0, 5, 4],
         [2, 6, 7], [2, 7, 3], [0, 4, 6], [0, 6, 2], [1, 3, 7], [1, 7, 5]]
    return add_mesh(name, p, np.int32(t))


def test_buried_masks_mark_a_leaf_base_inside_its_twig():
    _clear_scene()
    add_grid_ground(6.0, 3)
    twig = _box("Twig", (0, 0, 1), 0.005)
    twig["canopy_ao_role"] = "TRUNK"
    # A strip along x from the twig's centre to 2 m out, 0.1 m wide: 2 m across, so 1 % of
    # its size is 2 cm and every ray from its base stops on the twig's walls within 0.9 cm.
    x = np.float32([0.0, 0.5, 1.0, 1.5, 2.0])
    p = np.float32([[xi, y, 1.0] for xi in x for y in (0.0, 0.1)])
    p[:2, 1] = [-0.002, 0.002]  # the base's two corners, both inside the twig
    t = [[2 * i, 2 * i + 2, 2 * i + 3] for i in range(4)] + \
        [[2 * i, 2 * i + 3, 2 * i + 1] for i in range(4)]
    leaf = add_mesh("Leaf", p, np.int32(t))
    leaf["canopy_ao_role"] = "CANOPY"
    bpy.context.view_layer.update()
    got = foliage.buried_masks({"Ground": "GROUND", "Twig": "TRUNK", "Leaf": "CANOPY"})
    assert got["Leaf"].tolist() == [True, True] + [False] * 8, got["Leaf"]
    assert not got["Twig"].any() and not got["Ground"].any()
    _clear_scene()
