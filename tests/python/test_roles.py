"""Role guessing and connected components (canopy_ao.roles), no bpy."""
import os
import sys

import numpy as np
import pytest

HERE = os.path.dirname(__file__)
sys.path.insert(0, os.path.join(HERE, "..", "..", "addon"))
sys.path.insert(0, os.path.join(HERE, "..", "..", "examples"))
sys.path.insert(0, HERE)

from canopy_ao.core import roles, trees  # noqa: E402
import tree_scene as ts  # noqa: E402
from real_shapes import bent_tubes, ivy_on_wall, join, leaves, stem  # noqa: E402


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


def test_components_numbered_by_first_vertex_and_bad_indices_refused():
    rng = np.random.default_rng(3)
    for v in (40, 5000):
        e = rng.integers(0, v, (v // 3, 3))
        lab = roles.connected_components(v, e)
        _, first = np.unique(lab, return_index=True)
        assert np.all(np.diff(first) > 0) and lab[0] == 0
        # any integer dtype and a flat layout of rows of 3 give the same labels
        assert np.array_equal(roles.connected_components(v, e.astype(np.int64).ravel()), lab)
    for bad in ([[0, 1, 5]], [[0, -1, 2]]):
        with pytest.raises(ValueError, match="outside"):
            roles.connected_components(5, np.array(bad))


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


# === Real-asset shapes: bent branch tubes, thick leaves, trees sharing one collection =========

def test_bent_branch_tubes_are_a_trunk():
    """A Sapling trunk is many disconnected, bent, tapering tubes: their points' covariance is
    as flat as a leaf's (the old guess said CANOPY), but each tube's cross-section is closed
    (its mean normal is ~0)."""
    p, t = bent_tubes(np.random.default_rng(1))
    role, why = roles.guess_role(p, t)
    assert role == "TRUNK", why
    lab = roles.connected_components(len(p), t)
    _a, openness, plate = roles.piece_shape(p, t, lab, lab.max() + 1)
    assert openness.max() < 0.2 and plate.max() < 0.8


def test_flat_and_thick_leaves_are_a_canopy():
    rng = np.random.default_rng(2)
    for thick in (0.0, 0.004):  # cards, and cards given a thickness (closed, but plates)
        p, t = leaves(rng, thick=thick)
        role, why = roles.guess_role(p, t)
        assert role == "CANOPY", (thick, why)


def test_two_trees_in_one_collection_are_told_apart():
    """Two trees loose in one collection (no parents, no names): their leaves and branches
    are split by where they stand, both as separate objects and joined into one mesh each."""
    pytest.importorskip("canopy_scenes")
    rng = np.random.default_rng(3)
    la, lb = leaves(rng, centre=(0, 0, 5)), leaves(rng, centre=(9, 1, 5))
    ba = join(stem((0, 0)), bent_tubes(rng, 20, base=(0, 0)))
    bb = join(stem((9, 1)), bent_tubes(rng, 20, base=(9, 1)))
    objs = [("leaves_a", "CANOPY", *la), ("leaves_b", "CANOPY", *lb),
            ("wood_a", "TRUNK", *ba), ("wood_b", "TRUNK", *bb), ]
    got = trees.assign_trees(objs, "Collection")
    for name in ("leaves_a", "leaves_b", "wood_a", "wood_b"):
        assert len(got[name].trees) == 1, (name, got[name])
    assert got["leaves_a"].trees == got["wood_a"].trees
    assert got["leaves_b"].trees == got["wood_b"].trees
    assert got["leaves_a"].trees != got["leaves_b"].trees
    # Joined: one leaf mesh and one wood mesh holding both trees.
    lv, wd = join(la, lb), join(ba, bb)
    got = trees.assign_trees([("L", "CANOPY", *lv), ("W", "TRUNK", *wd)])
    truth_l = np.r_[np.zeros(len(la[0])), np.ones(len(lb[0]))]
    truth_w = np.r_[np.zeros(len(ba[0])), np.ones(len(bb[0]))]
    assert len(got["L"].trees) == 2 and got["L"].trees == got["W"].trees
    for g, truth in ((got["L"], truth_l), (got["W"], truth_w)):
        assert len(set(zip(g.labels.tolist(), truth.tolist()))) == 2  # the same partition
    assert got["L"].labels[0] == got["W"].labels[0]  # the same tree for a's leaves and wood


def test_touching_crowns_split_by_their_stems_and_a_fork_is_nostem():
    pytest.importorskip("canopy_scenes")
    rng = np.random.default_rng(4)
    la, lb = leaves(rng, centre=(0, 0, 5)), leaves(rng, centre=(4, 0, 5))  # crowns overlap
    got = trees.assign_trees([("L", "CANOPY", *join(la, lb)),
                              ("W", "TRUNK", *join(stem((0, 0)), stem((4, 0))))])
    assert len(got["L"].trees) == 2
    lab = got["L"].labels
    side = join(la, lb)[0][:, 0] > 2.0
    assert np.mean(lab[side] == lab[side][0]) > 0.9 and lab[side][0] != lab[~side][0]
    # A fork: a second tube starting 1 m up, 0.3 m beside the bole, stands on it.
    fork = stem((0.3, 0))
    fork = (fork[0] + np.float32([0, 0, 1.0]), fork[1])
    got = trees.assign_trees([("L", "CANOPY", *la), ("W", "TRUNK", *join(stem((0, 0)), fork))])
    assert len(got["L"].trees) == 1 and len(got["W"].trees) == 1, got


def test_assign_trees_degenerate_input():
    """No objects, a faceless canopy, coincident points, a trunk alone: an answer for every
    CANOPY and TRUNK object, one label per vertex, no error."""
    z = np.zeros((0, 3), np.int32)
    assert trees.assign_trees([]) == {}
    pts = np.random.default_rng(0).normal(size=(100, 3)).astype(np.float32)
    for objs in ([("L", "CANOPY", pts, z)], [("L", "CANOPY", np.zeros((10, 3), np.float32), z)],
                 [("T", "TRUNK", pts, z)],
                 [("L", "CANOPY", np.zeros((0, 3), np.float32), z), ("T", "TRUNK", pts, z)],
                 [("G", "GROUND", pts, z)]):
        got = trees.assign_trees(objs)
        for name, role, p, _t in objs:
            if role in ("CANOPY", "TRUNK") and len(p):
                g = got[name]
                assert len(g.labels) == len(p) and g.labels.max() < len(g.trees)
            else:
                assert name not in got


# === Walls and rock faces an ivy climbs (issue #38 item 5) =================================

def test_a_wall_under_ivy_is_a_surface_not_a_trunk():
    """A wall (a quad or a 10 cm slab, 3 m × 2 m) is guessed GROUND — a surface that receives
    and occludes like the ground — where it used to be '1 solid piece', a TRUNK and a tree of
    its own; the ivy's leaves are CANOPY, its branches TRUNK. The rule is scale-free (the same
    answers at 1/100 and 100 times the size) and does not care how the wall is turned."""
    rng = np.random.default_rng(5)
    want = {"Wall": "GROUND", "IvyLeaves": "CANOPY", "IvyBranches": "TRUNK", "Ground": "GROUND"}
    for thick in (0.0, 0.1):
        scene = ivy_on_wall(rng, thick=thick)
        for scale in (0.01, 1.0, 100.0):
            for name, (p, t) in scene.items():
                role, why = roles.guess_role(p * np.float32(scale), t)
                assert role == want[name], (thick, scale, name, why)
        # A rock face leaning 35° from vertical, turned 60° about z: still a surface.
        c, s = np.cos(np.radians(35)), np.sin(np.radians(35))
        tilt = np.array([[1, 0, 0], [0, c, -s], [0, s, c]]) @ np.array(
            [[0.5, -0.866, 0], [0.866, 0.5, 0], [0, 0, 1]])
        p, t = scene["Wall"]
        assert roles.guess_role((p @ tilt.T).astype(np.float32), t)[0] == "GROUND"


def test_rough_rock_face_is_a_surface_and_thick_solids_stay_trunks():
    """A rock face (a 3 × 2 m grid in bumps of ±20 cm over ~1 m and ±2 cm of noise at its
    10 cm spacing) is a surface; a tube (a bole),
    a cube and a thick block (3 × 2 × 1.5 m) stay TRUNK: only a sheet or a slab whose
    normals agree is a surface."""
    rng = np.random.default_rng(6)
    n = 30
    x, z = np.meshgrid(np.linspace(-1.5, 1.5, n), np.linspace(0, 2, n), indexing="ij")
    y = (0.2 * np.sin(5 * x + 1) * np.cos(4 * z) + 0.1 * np.sin(9 * x * z)
         + rng.uniform(-0.02, 0.02, x.shape))
    p = np.stack([x, y, z], -1).reshape(-1, 3).astype(np.float32)
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij")
    a = (i * n + j).ravel()
    t = np.concatenate([np.stack([a, a + n, a + n + 1], 1), np.stack([a, a + n + 1, a + 1], 1)])
    role, why = roles.guess_role(p, t.astype(np.int32))
    assert role == "GROUND", why
    pytest.importorskip("canopy_scenes")
    from real_shapes import cubes
    assert roles.guess_role(*stem((0, 0)))[0] == "TRUNK"
    v, ct = cubes([[0, 0, 0]], 1.0)
    assert roles.guess_role(v, ct)[0] == "TRUNK"
    assert roles.guess_role(v * np.float32([1.5, 0.75, 1.0]), ct)[0] == "TRUNK"
