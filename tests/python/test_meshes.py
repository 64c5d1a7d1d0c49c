"""Scene meshes (core/meshes.py): items merged into one mesh, the one helper behind the ray
tracer, the density grid, the ray-free rung's own tracer and an instanced tree's prototype."""
import os
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "addon"))
from canopy_ao import core  # noqa: E402
from canopy_ao.core import forest, lighting, meshes  # noqa: E402
from canopy_ao.core.native import _core  # noqa: E402
import tree_scene as ts  # noqa: E402


def _item(name, role, p, t):
    p = np.asarray(p, np.float32)
    return core.SceneItem(name, role, "T", p, ts.vertex_normals(p, t), t)


def _items():
    trunk = _item("Trunk", "TRUNK", *ts.cylinder())
    hidden = _item("Hidden", "IGNORE", *ts.plane(size=2.0, cuts=2))
    empty = core.SceneItem("Points", "GROUND", "", np.zeros((3, 3), np.float32),
                           np.tile([0, 0, 1], (3, 1)), np.zeros((0, 3), np.int32))
    ground = _item("Ground", "GROUND", *ts.plane(size=4.0, cuts=3))
    return trunk, hidden, empty, ground


def test_merged_keeps_every_item_in_order():
    trunk, hidden, empty, ground = _items()
    v, t = meshes.merged([trunk, empty, ground])
    assert v.dtype == np.float32 and t.dtype == np.int32
    assert len(v) == len(trunk.positions) + 3 + len(ground.positions)
    first = len(trunk.positions) + 3  # the ground's triangles index past the points' vertices
    np.testing.assert_array_equal(t[len(trunk.triangles):], ground.triangles + first)
    v0, t0 = meshes.merged([])
    assert v0.shape == (0, 3) and t0.shape == (0, 3)


def test_scene_triangles_skip_ignored_and_empty_items_and_name_their_bases():
    trunk, hidden, empty, ground = _items()
    bases = {}
    v, t = meshes.scene_triangles([trunk, hidden, empty, ground, ground], bases)
    # The ignored plane and the triangle-less points are not in the mesh; a name seen twice
    # has no base (it cannot say which mesh it means).
    assert len(v) == len(trunk.positions) + 2 * len(ground.positions)
    assert bases == {"Trunk": (0, 0), "Ground": None}
    np.testing.assert_array_equal(t[:len(trunk.triangles)], trunk.triangles)
    with pytest.raises(core.CanopyAOError, match="no triangles"):
        meshes.scene_triangles([hidden, empty])


@pytest.mark.skipif(_core is None, reason="no native module")
def test_a_tracer_of_instances_alone():
    """No item with triangles but an instanced tree with a mesh: the tracer holds the
    instances only (lighting.build_tracer's fallback, with an empty mesh's bake points)."""
    p, t = ts.leaves(count=50, seed=3)
    crown = [_core.Ellipsoid((0.0, 0.0, 2.6), np.eye(3, dtype=np.float32), (1.2, 1.2, 1.2))]
    m = np.eye(4)
    proto = forest.Prototype("T", crown, 1.5, m[None], [],
                             (np.ascontiguousarray(p, np.float32), t))
    _trunk, hidden, empty, _ground = _items()
    tracer = lighting.build_tracer([hidden, empty], {}, [proto])
    assert int(tracer.instance_count) == 1 and int(tracer.triangle_count) == 0
    up = np.array([[0.0, 0.0, 0.0]], np.float32), np.array([[0.0, 0.0, 1.0]], np.float32)
    assert float(tracer.ao(*up, samples=64)[0]) < 0.95  # the crown above shades the point
