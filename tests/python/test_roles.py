"""Role guessing and connected components (canopy_ao.roles), no bpy."""
import os
import sys

import numpy as np
import pytest

HERE = os.path.dirname(__file__)
sys.path.insert(0, os.path.join(HERE, "..", "..", "addon"))
sys.path.insert(0, os.path.join(HERE, "..", "..", "examples"))
sys.path.insert(0, HERE)

from canopy_ao.core import roles  # noqa: E402
import tree_scene as ts  # noqa: E402


def _same_partition(a, b):
    return a.max() == b.max() and len(set(zip(a.tolist(), b.tolist()))) == a.max() + 1


def test_components_known_answer():
    # two triangles sharing an edge, one lone triangle, one unused vertex
    tris = np.array([[0, 1, 2], [2, 1, 3], [4, 5, 6]], np.int32)
    lab = roles.connected_components(8, tris)
    assert lab.tolist() == [0, 0, 0, 0, 1, 1, 1, 2]


def test_components_long_chain_and_random_graphs():
    n = 20000  # a path 0-1-2-...: the worst case for label propagation, few rounds here
    chain = np.stack([np.arange(n - 2), np.arange(1, n - 1), np.arange(2, n)], 1)
    rev = chain[::-1].copy()
    assert roles.connected_components(n, rev).max() == 0
    sp = pytest.importorskip("scipy.sparse")
    csgraph = pytest.importorskip("scipy.sparse.csgraph")
    rng = np.random.default_rng(0)
    for v in (50, 3000):
        e = rng.integers(0, v, (v // 2, 3))
        m = sp.coo_matrix((np.ones(2 * len(e)), (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 2]])),
                          shape=(v, v))
        _, ref = csgraph.connected_components(m, directed=False)
        assert _same_partition(roles.connected_components(v, e), ref)


def test_empty_mesh():
    assert roles.connected_components(0, np.zeros((0, 3), np.int32)).shape == (0,)
    assert roles.guess_role(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int32))[0] == "IGNORE"


def test_fixture_scene_roles():
    want = {"Trunk": "TRUNK", "Leaves": "CANOPY", "Ground": "GROUND", "Grass": "GRASS"}
    for name, (p, t) in ts.scene(with_grass=True).items():
        assert roles.guess_role(p, t)[0] == want[name], name


def test_generated_scenes_roles():
    """Every part of the example scenes (their role is known) is guessed right, including
    trunks made of many unwelded branch tubes and curved grass blades."""
    cs = pytest.importorskip("canopy_scenes")
    for name in cs.SCENES:
        if name == "large_tree":
            continue
        for part in cs.make_scene(name, quick=True):
            got, why = roles.guess_role(part.vertices, part.triangles)
            assert got.lower() == part.role, f"{name}/{part.name}: {got} ({why})"


def test_blade_heights():
    p, t = ts.grass(height=0.3)
    ground, blade = roles.blade_heights(p + np.float32([0, 0, 2.0]), t)
    assert ground == pytest.approx(2.0, abs=1e-6)
    assert blade == pytest.approx(0.3, abs=1e-6)
