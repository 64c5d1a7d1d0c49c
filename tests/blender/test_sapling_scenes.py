"""examples/sapling_scenes.py: real Sapling Tree Gen trees, built and exported as a user would.

The quick aspen (5k vertices, < 1 s) and the grove's collection: the branch curve becomes a
mesh of many disconnected tubes beside the leaves, the trunk stands on the ground, the export
holds what the benchmark needs, and the same seed gives the same bytes.
"""
import json
import os
import sys

import numpy as np
import pytest

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, os.path.join(REPO, "examples"))

import sapling_scenes as ss  # noqa: E402


def _components(tris, n):
    """Connected components of a triangle mesh (union-find over its edges)."""
    parent = np.arange(n)

    def find(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a
    for a, b in np.concatenate([tris[:, :2], tris[:, 1:], tris[:, ::2]]):
        ra, rb = find(a), find(b)
        if ra != rb:
            parent[ra] = rb
    return len({find(i) for i in np.unique(tris)})


def test_aspen_exports_branches_leaves_and_ground(tmp_path):
    objs, info = ss.build("sap_quaking_aspen", quick=True)
    path = str(tmp_path / "aspen.npz")
    distance, ghash = ss.export(path, objs, info)
    z = np.load(path)
    names = [str(n) for n in z["names"]]
    roles = {n: str(z[f"{n}/role"]) for n in names}
    assert sorted(roles.values()) == ["canopy", "ground", "trunk"]
    trunk = next(n for n in names if roles[n] == "trunk")
    leaves = next(n for n in names if roles[n] == "canopy")
    assert str(z[f"{trunk}/tree"]) == str(z[f"{leaves}/tree"]) == "quaking_aspen_5"
    t = z[f"{trunk}/triangles"]
    assert _components(t, len(z[f"{trunk}/positions"])) > 10  # one tube per branch
    assert len(z[f"{leaves}/triangles"]) > 100
    p = z[f"{trunk}/positions"]
    assert abs(float(p[:, 2].min())) < 1e-3 * distance  # the trunk base touches the ground
    n = z[f"{leaves}/normals"]
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-4)
    assert json.loads(str(z["info"]))["trees"][0]["preset"] == "quaking_aspen"
    # The same preset and seed give the same geometry.
    objs2, info2 = ss.build("sap_quaking_aspen", quick=True)
    assert ss.export(str(tmp_path / "again.npz"), objs2, info2)[1] == ghash


def test_grove_is_one_collection_of_four_trees():
    objs, info = ss.build("sap_grove", quick=True)
    cols = {c.name for o, _r, _t in objs for c in o.users_collection}
    assert cols == {"sap_grove"}
    trees = {t for _o, r, t in objs if r in ("trunk", "canopy")}
    assert len(trees) == 4 and len(objs) == 9
