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


def _face_normals(item):
    """float32 (M, 3, 3): every corner of each triangle given its face's normal (flat shading)."""
    p = item.positions.astype(np.float64)[item.triangles]
    f = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    f /= np.linalg.norm(f, axis=1, keepdims=True)
    return np.repeat(f[:, None, :], 3, axis=1).astype(np.float32)


def _vertex_ao(items):
    """The exact rung's AO at every vertex of the merged items, each at Cycles' bake point."""
    tracer = lighting.build_tracer(items)
    p, _t = meshes.merged(items)
    n = meshes.bake_shading(items)["normals"]
    return np.asarray(tracer.ao(p, n, samples=64, vertex_ids=np.arange(len(p), dtype=np.int32)))


def test_bake_shading_hands_the_tracer_corner_normals_where_an_item_has_them():
    trunk, _hidden, _empty, ground = _items()
    assert "corner_normals" not in meshes.bake_shading([trunk, ground])
    trunk.corner_normals = _face_normals(trunk)
    shading = meshes.bake_shading([trunk, ground])
    cn = shading["corner_normals"]
    assert cn.shape == (len(trunk.triangles) + len(ground.triangles), 3, 3)
    assert np.array_equal(cn[:len(trunk.triangles)], trunk.corner_normals)
    assert np.array_equal(cn[len(trunk.triangles):], ground.normals[ground.triangles])


def test_the_rays_turn_around_the_corner_normals_and_equal_ones_change_nothing():
    """A flat-shaded trunk on the ground bakes other hemispheres than its smooth vertex normals
    (Cycles' corners, native raytrace.h 'Origins'); its vertex normals handed as corner normals
    change no bit."""
    trunk, _hidden, _empty, ground = _items()
    smooth = _vertex_ao([trunk, ground])
    trunk.corner_normals = trunk.normals[trunk.triangles]
    assert np.array_equal(_vertex_ao([trunk, ground]), smooth)
    trunk.corner_normals = _face_normals(trunk)
    flat = _vertex_ao([trunk, ground])
    k = len(trunk.positions)
    assert np.abs(flat[:k] - smooth[:k]).max() > 0.05
    assert np.array_equal(flat[k:], smooth[k:])  # the ground's corners are its vertex normals


def test_corner_normals_of_the_wrong_shape_are_refused():
    trunk, _hidden, _empty, ground = _items()
    with pytest.raises(core.CanopyAOError, match="corner normals"):
        core.SceneItem("T", "TRUNK", "T", trunk.positions, trunk.normals, trunk.triangles,
                       corner_normals=np.zeros((1, 3, 3), np.float32))
    p, t = meshes.merged([ground])
    n = ground.normals
    with pytest.raises(ValueError, match="corner_normals must be float32"):
        _core.RayTracer(p, t, normals=n, corner_normals=np.zeros((len(t), 3), np.float32))
    with pytest.raises(ValueError, match="corner_normals need normals"):
        _core.RayTracer(p, t, corner_normals=n[t])
