"""The benchmark scenes (examples/canopy_scenes.py): deterministic, well-formed, roles present."""
import os
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "examples"))
import canopy_scenes as cs  # noqa: E402

SMALL = [n for n in cs.SCENES if n != "large_tree"]

EXPECTED_ROLES = {
    "round_tree": {"canopy", "trunk", "ground"},
    "columnar_tree": {"canopy", "trunk", "ground"},
    "weeping_tree": {"canopy", "trunk", "ground"},
    "conifer": {"canopy", "trunk", "ground"},
    "grass_field": {"grass", "ground"},
    "grove": {"canopy", "trunk", "ground"},
    "ideal_sphere": {"canopy"},
    "ideal_ellipsoid": {"canopy"},
}


@pytest.mark.parametrize("name", SMALL)
def test_well_formed(name):
    s = cs.make_scene(name, quick=True)
    assert s.roles == EXPECTED_ROLES[name]
    assert len({p.name for p in s}) == len(s), "part names must be unique (Blender object names)"
    for p in s:
        assert p.vertices.dtype == np.float32 and p.vertices.shape[1] == 3
        assert p.triangles.dtype == np.int32 and p.triangles.shape[1] == 3
        assert p.uvs.dtype == np.float32 and p.uvs.shape == (p.n_vertices, 2)
        assert p.vertices.flags.c_contiguous and p.triangles.flags.c_contiguous
        assert np.isfinite(p.vertices).all() and np.isfinite(p.uvs).all()
        assert p.triangles.min() >= 0 and p.triangles.max() < p.n_vertices
        # every vertex is used and no triangle is degenerate (index-wise or in area)
        assert np.unique(p.triangles).size == p.n_vertices
        e = p.vertices[p.triangles]
        area = np.linalg.norm(np.cross(e[:, 1] - e[:, 0], e[:, 2] - e[:, 0]), axis=1)
        assert area.min() > 0
    V, T, part = s.merged()
    assert len(V) == s.n_vertices and len(T) == s.n_triangles and len(part) == len(V)
    assert T.max() < len(V)
    assert s.ao_distance() > 0


@pytest.mark.parametrize("name", SMALL)
def test_deterministic(name):
    a, b = cs.make_scene(name, quick=True), cs.make_scene(name, quick=True)
    for p, q in zip(a, b):
        assert p.name == q.name and p.role == q.role
        np.testing.assert_array_equal(p.vertices, q.vertices)
        np.testing.assert_array_equal(p.triangles, q.triangles)
    c = cs.make_scene(name, seed=1, quick=True)
    assert not np.array_equal(a[0].vertices, c[0].vertices), "the seed must matter"


@pytest.mark.parametrize("name,kw,leaves", [
    ("round_tree", dict(leaves=1234), 1234),
    ("conifer", dict(leaves=999), 999),
    ("ideal_sphere", dict(n_tris=500), None),
])
def test_counts(name, kw, leaves):
    s = cs.make_scene(name, **kw)
    canopy = s.parts_by_role("canopy")
    if leaves is not None:  # one quad = 4 vertices, 2 triangles per leaf
        assert sum(p.n_vertices for p in canopy) == 4 * leaves
        assert sum(len(p.triangles) for p in canopy) == 2 * leaves
    else:
        assert canopy[0].n_vertices == 3 * kw["n_tris"]


def test_default_sizes_are_realistic():
    # benchmark sizes: tens of thousands to a million vertices; the large variant has ≥ 1M
    for name in ("round_tree", "columnar_tree", "weeping_tree", "conifer", "grove"):
        n = sum(p.n_vertices for p in cs.make_scene(name).parts_by_role("canopy"))
        assert 20_000 <= n <= 1_000_000, (name, n)


def test_ideal_sphere_is_inside_its_sphere():
    s = cs.ideal_sphere(n_tris=2000, radius=2.0, edge=0.05)
    r = np.linalg.norm(s[0].vertices, axis=1)
    assert r.max() < 2.0 + 0.1


def test_vertex_normals_unit_and_face_aligned():
    s = cs.round_tree(leaves=200, ground=False)
    leaves = s.parts_by_role("canopy")[0]
    n = cs.vertex_normals(leaves.vertices, leaves.triangles)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1, atol=1e-5)
    v = leaves.vertices[leaves.triangles[0]]
    fn = np.cross(v[1] - v[0], v[2] - v[0])
    fn /= np.linalg.norm(fn)
    np.testing.assert_allclose(n[leaves.triangles[0]], np.tile(fn, (3, 1)), atol=1e-5)


def test_unknown_scene_message():
    with pytest.raises(ValueError, match="unknown scene"):
        cs.make_scene("oak")
