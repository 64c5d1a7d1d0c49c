"""Forests (canopy_ao.forest): instance transforms of shells, and instances as occluders.

Known answers: an identity instance is the prototype; a translated / rotated / scaled instance
is the exact image of the ellipsoid (checked on boundary points, to float32 precision); the
ground under an instance gets the AO it gets under the same tree placed there for real (to
1e-4: the two fits differ only by float rounding of the shifted points).
"""
import math
import os
import sys

import numpy as np
import pytest

HERE = os.path.dirname(__file__)
sys.path.insert(0, os.path.join(HERE, "..", "..", "addon"))
sys.path.insert(0, HERE)

from canopy_ao import core  # noqa: E402
from canopy_ao.core import forest  # noqa: E402
from canopy_ao.core.native import _core  # noqa: E402
import tree_scene as ts  # noqa: E402

assert core.core_status()[0], core.core_status()[1]  # an unbuilt module fails, not skips



def rot_z(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]], float)


def affine(a=np.eye(3), t=(0, 0, 0)):
    m = np.eye(4)
    m[:3, :3] = a
    m[:3, 3] = t
    return m


def proto_shell():
    q = rot_z(0.4) @ np.array([[1, 0, 0], [0, math.cos(0.3), -math.sin(0.3)],
                               [0, math.sin(0.3), math.cos(0.3)]])
    return _core.Ellipsoid(np.float32([0.5, -0.2, 2.6]), q.astype(np.float32),
                           np.float32([1.2, 0.8, 1.5]))


def boundary(e, count=200, seed=0):
    """Points on the ellipsoid's surface."""
    u = np.random.default_rng(seed).normal(size=(count, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    q, r, c = (np.asarray(e.axes, float), np.asarray(e.radii, float),
               np.asarray(e.center, float))
    return c + (u * r) @ q.T


def implicit(e, x):
    """|diag(1/r) Qᵀ (x − c)| (1 on the surface)."""
    q, r, c = (np.asarray(e.axes, float), np.asarray(e.radii, float),
               np.asarray(e.center, float))
    return np.linalg.norm(((x - c) @ q) / r, axis=1)


def test_identity_instance_is_the_prototype():
    e = proto_shell()
    (w,) = forest.instance_shells([e], np.eye(4)[None])
    np.testing.assert_allclose(w.center, e.center, atol=1e-6)
    np.testing.assert_allclose(w.radii, np.sort(e.radii)[::-1], atol=1e-6)  # SVD order
    x = boundary(e)
    np.testing.assert_allclose(implicit(w, x), 1.0, atol=1e-5)


@pytest.mark.parametrize("name, a, t", [
    ("translated", np.eye(3), (10, -4, 0.5)),
    ("rotated", rot_z(1.1), (0, 0, 0)),
    ("uniform scale", 2.5 * np.eye(3), (3, 3, 0)),
    ("non-uniform scale + rotation", rot_z(0.7) @ np.diag([2.0, 0.5, 1.3]), (1, 2, 3)),
    ("mirrored, sheared", np.array([[-1.0, 0.3, 0], [0, 1, 0], [0, 0, 0.8]]), (5, 0, 0)),
])
def test_instance_is_the_exact_image(name, a, t):
    e = proto_shell()
    m = affine(a, t)
    (w,) = forest.instance_shells([e], m[None])
    q = np.asarray(w.axes, float)
    np.testing.assert_allclose(q.T @ q, np.eye(3), atol=1e-5, err_msg=name)
    assert np.linalg.det(q) > 0, name
    x = boundary(e) @ a.T + np.asarray(t, float)  # image of the surface is the surface
    np.testing.assert_allclose(implicit(w, x), 1.0, atol=2e-5, err_msg=name)
    np.testing.assert_allclose(w.center, a @ np.asarray(e.center, float) + t, atol=1e-4)
    vol = np.prod(np.asarray(w.radii, float))
    assert vol == pytest.approx(np.prod(np.asarray(e.radii, float)) * abs(np.linalg.det(a)),
                                rel=1e-5)


def test_many_instances_order_and_degenerate_scale():
    shells = [proto_shell(), _core.Ellipsoid.from_sphere(_core.Sphere(np.float32([0, 0, 1]), 0.5))]
    mats = np.stack([affine(t=(i, 0, 0)) for i in range(3)] + [affine(np.zeros((3, 3)))])
    out = forest.instance_shells(shells, mats)
    assert len(out) == 6  # the zero-scaled instance is dropped
    np.testing.assert_allclose(out[3].center, [1, 0, 1], atol=1e-6)  # instance-major
    u = forest.unique_matrices(np.concatenate([mats, mats[:2]]))
    assert len(u) == 4


def items(offset=(0.0, 0.0, 0.0), ground=True, tree=True):
    role = {"Trunk": "TRUNK", "Leaves": "CANOPY", "Ground": "GROUND"}
    out = []
    for name, (p, t) in ts.scene(False).items():
        if (name == "Ground" and not ground) or (name != "Ground" and not tree):
            continue
        if name != "Ground":
            p = p + np.float32(offset)
        out.append(core.SceneItem(name, role[name], "" if name == "Ground" else "T", p,
                                    ts.vertex_normals(p, t), t))
    return out


def test_ground_under_an_instance_equals_a_real_tree():
    settings = core.BakeSettings(method="ellipsoid", tau=2.0)
    offset = (3.0, 1.5, 0.0)
    real = core.bake(items(offset), settings)[0]
    want = {r.name: r.ao for r in real}["Ground"]
    proto = core.prepare(items(ground=False), settings)  # the tree at the origin, baked once
    plan = core.prepare(items(tree=False), settings)
    # ε as the scene's own occluders use it (the core's default), to compare one law.
    core.attach_forest(plan, [forest.prototype_from_plan(proto, "T", affine(t=offset)[None])],
                         epsilon=forest.DEFAULT_EPSILON)
    (ground,) = [it for it in items(tree=False)]
    got = core.evaluate_item(plan, ground).ao
    assert want.min() < 0.8  # the tree does shade the ground
    np.testing.assert_allclose(got, want, atol=1e-4)
    assert any("forest: 1 instance" in n for n in plan.notes)


def test_forest_cost_is_bounded_by_the_cut_off():
    """400 instances on a lattice: a receiver tests at most the occluders in reach, and the
    cut-off changes the AO by < ε per occluder in reach (stated bound: 0.05 here)."""
    sh = [_core.Ellipsoid.from_sphere(_core.Sphere(np.float32([0, 0, 3]), 1.0))]
    mats = np.stack([affine(t=(6.0 * i, 6.0 * j, 0)) for i in range(20) for j in range(20)])
    cut = forest.Forest([forest.Prototype("T", sh, 1.0, mats)], epsilon=1e-2)
    full = forest.Forest([forest.Prototype("T", sh, 1.0, mats)], epsilon=0.0)
    assert cut.instances == 400 and cut.max_candidates < 100 and full.max_candidates == 400
    rng = np.random.default_rng(1)
    p = np.c_[rng.uniform(0, 114, (2000, 2)), np.zeros(2000)].astype(np.float32)
    n = np.tile(np.float32([0, 0, 1]), (2000, 1))
    a, b = cut.ao(p, n), full.ao(p, n)
    assert np.all(a >= b - 1e-6) and (a - b).max() < 0.05
