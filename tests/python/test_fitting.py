"""canopy_ao._core fitting: Sphere / Ellipsoid types, fit_sphere, fit_ellipsoid, fit_shells —
round trips through the bindings, known answers, and the README's argument errors."""
import pickle

import numpy as np
import pytest

_core = pytest.importorskip("canopy_ao._core")
if not hasattr(_core, "fit_sphere"):
    pytest.skip("this build of canopy_ao._core has no fitting", allow_module_level=True)


def cloud(n=2000, seed=0, scale=(3.0, 2.0, 1.0), offset=(0.0, 0.0, 0.0)):
    rng = np.random.default_rng(seed)
    p = rng.standard_normal((n, 3)) * np.asarray(scale) + np.asarray(offset)
    return np.ascontiguousarray(p, dtype=np.float32)


def unit_norm2(e, p):
    """|diag(1/r) Q^T (p - c)|^2 per point, in float64."""
    d = p.astype(np.float64) - e.center.astype(np.float64)
    u = d @ e.axes.astype(np.float64) / e.radii.astype(np.float64)
    return (u * u).sum(axis=1)


# === Types

def test_sphere_type_round_trip():
    s = _core.Sphere((1, 2, 3), 2.5)
    assert s.center.dtype == np.float32 and s.center.shape == (3,)
    np.testing.assert_array_equal(s.center, [1, 2, 3])
    assert s.radius == 2.5
    s.radius = 1.0
    s.center = np.array([0, 0, 1.0])
    assert s.radius == 1.0 and s.center[2] == 1
    q = pickle.loads(pickle.dumps(s))
    np.testing.assert_array_equal(q.center, s.center)
    assert q.radius == s.radius
    pts = np.array([[0, 0, 2], [0, 0, 2.01], [0, 0, 0]], np.float32)
    np.testing.assert_array_equal(s.contains(pts), [True, False, True])
    assert "Sphere" in repr(s)


def test_ellipsoid_type_round_trip():
    c = np.cos(0.3)
    s = np.sin(0.3)
    axes = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    e = _core.Ellipsoid([1, 0, 0], axes, [3, 2, 1])
    assert e.axes.shape == (3, 3) and e.axes.dtype == np.float32
    np.testing.assert_allclose(e.axes, axes, atol=1e-6)
    np.testing.assert_array_equal(e.radii, [3, 2, 1])
    # A point on the first axis at distance 3 is on the surface; a bit further is outside.
    tip = np.array([[1 + 3 * c, 3 * s, 0], [1 + 3.1 * c, 3.1 * s, 0]], np.float32)
    np.testing.assert_array_equal(e.contains(tip), [True, False])
    q = pickle.loads(pickle.dumps(e))
    np.testing.assert_array_equal(q.axes, e.axes)
    sp = _core.Ellipsoid.from_sphere(_core.Sphere((0, 0, 0), 2))
    np.testing.assert_array_equal(sp.radii, [2, 2, 2])
    np.testing.assert_array_equal(sp.axes, np.eye(3))
    assert sp.volume() == pytest.approx(4 / 3 * np.pi * 8, rel=1e-6)


def test_ellipsoid_left_handed_axes_made_right_handed():
    e = _core.Ellipsoid([0, 0, 0], np.diag([1.0, 1.0, -1.0]), [1, 2, 3])
    assert np.linalg.det(e.axes) > 0.999


@pytest.mark.parametrize(
    "args, match",
    [
        (([0, 0], 1.0), "center"),
        (([0, 0, np.nan], 1.0), "center"),
        (([0, 0, 0], -1.0), "radius"),
        (([0, 0, 0], np.inf), "radius"),
    ],
)
def test_sphere_type_errors(args, match):
    with pytest.raises(ValueError, match=match):
        _core.Sphere(*args)


@pytest.mark.parametrize(
    "axes, radii, match",
    [
        (np.ones((3, 3)), [1, 1, 1], "orthonormal"),
        (np.eye(2), [1, 1, 1], "axes"),
        (np.eye(3), [1, 0, 1], "radii"),
        (np.eye(3), [1, 1], "radii"),
    ],
)
def test_ellipsoid_type_errors(axes, radii, match):
    with pytest.raises(ValueError, match=match):
        _core.Ellipsoid([0, 0, 0], axes, radii)


# === fit_sphere

def test_fit_sphere_contains_all_and_is_tight():
    p = cloud(5000, 1, offset=(10, -5, 2))
    s = _core.fit_sphere(p)
    d = np.linalg.norm(p.astype(np.float64) - s.center.astype(np.float64), axis=1)
    assert d.max() <= s.radius
    assert d.max() >= s.radius * (1 - 1e-5)  # the farthest point is on the surface
    assert s.contains(p).all()


def test_fit_sphere_known_answer_tetrahedron():
    p = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], np.float32)
    s = _core.fit_sphere(p)
    assert s.radius == pytest.approx(np.sqrt(3), rel=1e-5)
    np.testing.assert_allclose(s.center, 0, atol=1e-6)


def test_fit_sphere_degenerate_single_point():
    s = _core.fit_sphere(np.array([[3, 4, 0]], np.float32))
    np.testing.assert_array_equal(s.center, [3, 4, 0])
    assert s.radius == pytest.approx(1e-6 * (5 + 1), rel=1e-3)


def test_fit_sphere_trim_ignores_outlier():
    p = np.vstack([cloud(999, 2, scale=(1, 1, 1)), [[100, 0, 0]]]).astype(np.float32)
    assert _core.fit_sphere(p).radius > 50
    t = _core.fit_sphere(p, trim=0.01)
    assert t.radius < 5


# === fit_ellipsoid

def random_rotation(seed):
    q, r = np.linalg.qr(np.random.default_rng(seed).standard_normal((3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 2] = -q[:, 2]
    return q


def test_fit_ellipsoid_recovers_known_ellipsoid():
    rng = np.random.default_rng(3)
    u = rng.standard_normal((4000, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    R = random_rotation(4)
    radii = np.array([4.0, 2.0, 1.0])
    p = np.ascontiguousarray((u * radii) @ R.T + [5, 6, 7], dtype=np.float32)
    e = _core.fit_ellipsoid(p)
    np.testing.assert_allclose(e.radii, radii, rtol=0.02)
    np.testing.assert_allclose(np.abs(np.sum(e.axes * R, axis=0)), 1, atol=1e-3)
    np.testing.assert_allclose(e.center, [5, 6, 7], atol=0.05)
    assert unit_norm2(e, p).max() <= 1.0
    assert e.contains(p).all()


@pytest.mark.parametrize("method", ["auto", "khachiyan", "pca"])
def test_fit_ellipsoid_methods_contain_all(method):
    p = cloud(3000, 5, offset=(0, 0, 20))
    e = _core.fit_ellipsoid(p, method=method, tolerance=1e-2, max_points=500)
    assert unit_norm2(e, p).max() <= 1.0
    assert np.linalg.det(e.axes) > 0.999
    assert np.all(np.diff(e.radii) <= 0)


@pytest.mark.parametrize(
    "points",
    [
        np.array([[1, 2, 3]], np.float32),
        np.tile(np.array([[1, 2, 3]], np.float32), (100, 1)),
        np.outer(np.linspace(0, 1, 50), [1, 2, 2]).astype(np.float32),
        np.c_[np.random.default_rng(0).random((300, 2)), np.zeros(300)].astype(np.float32),
    ],
    ids=["one-point", "duplicates", "collinear", "flat"],
)
def test_fit_ellipsoid_degenerate_is_finite(points):
    e = _core.fit_ellipsoid(points)
    assert np.isfinite(e.center).all() and np.isfinite(e.axes).all()
    assert (e.radii > 0).all() and np.isfinite(e.radii).all()
    np.testing.assert_allclose(e.axes.T @ e.axes, np.eye(3), atol=1e-5)
    assert e.contains(points).all()
    if len(np.unique(points, axis=0)) > 1:
        assert e.radii[2] >= 0.01 * e.radii[0] * (1 - 1e-6)


# === fit_shells

def test_fit_shells_recovers_blobs():
    rng = np.random.default_rng(6)
    centres = np.array([[0, 0, 0], [30, 0, 0], [0, 30, 10]], np.float64)
    truth = np.repeat(np.arange(3), 500)
    rng.shuffle(truth)
    p = np.ascontiguousarray(centres[truth] + rng.standard_normal((1500, 3)), dtype=np.float32)
    shells, labels = _core.fit_shells(p, 3, seed=1)
    assert len(shells) == 3 and all(isinstance(s, _core.Ellipsoid) for s in shells)
    assert labels.dtype == np.int32 and labels.shape == (1500,)
    # One shell per blob: labels are the truth up to a permutation.
    perm = {t: labels[truth == t][0] for t in range(3)}
    assert sorted(perm.values()) == [0, 1, 2]
    np.testing.assert_array_equal(labels, np.vectorize(perm.get)(truth))
    for i, s in enumerate(shells):
        assert s.contains(p[labels == i]).all()
    again, labels2 = _core.fit_shells(p, 3, seed=1)
    np.testing.assert_array_equal(labels, labels2)
    spheres, _ = _core.fit_shells(p, 3, kind="sphere", seed=1)
    assert all(s.radii[0] == s.radii[2] for s in spheres)


def test_fit_shells_k_larger_than_distinct_points():
    p = np.repeat(np.array([[0, 0, 0], [5, 0, 0]], np.float32), 10, axis=0)
    shells, labels = _core.fit_shells(p, 6)
    assert len(shells) == 2
    assert set(labels.tolist()) == {0, 1}


# === Argument errors (README: ValueError naming the argument)

@pytest.mark.parametrize("fn", ["fit_sphere", "fit_ellipsoid", "fit_shells"])
@pytest.mark.parametrize(
    "points, match",
    [
        (np.zeros((4, 3), np.float64), "points must have dtype float32"),
        (np.zeros((4, 2), np.float32), r"points must have shape \(N, 3\)"),
        (np.zeros((4, 3, 1), np.float32), r"points must have shape \(N, 3\)"),
        (np.zeros((0, 3), np.float32), "points is empty"),
        (np.array([[0, 0, 0], [0, np.nan, 0]], np.float32), "non-finite.*row 1"),
        (np.array([[0, 0, np.inf]], np.float32), "non-finite"),
        (np.zeros((6, 3), np.float32)[::2], "C-contiguous"),
    ],
)
def test_points_errors(fn, points, match):
    args = (points, 2) if fn == "fit_shells" else (points,)
    with pytest.raises(ValueError, match=match):
        getattr(_core, fn)(*args)


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda p: _core.fit_sphere(p, trim=0.5), "trim"),
        (lambda p: _core.fit_sphere(p, trim=-0.1), "trim"),
        (lambda p: _core.fit_ellipsoid(p, trim=0.7), "trim"),
        (lambda p: _core.fit_ellipsoid(p, method="mvee"), "method"),
        (lambda p: _core.fit_ellipsoid(p, tolerance=0.0), "tolerance"),
        (lambda p: _core.fit_ellipsoid(p, max_points=2), "max_points"),
        (lambda p: _core.fit_ellipsoid(p, min_radius_ratio=0.0), "min_radius_ratio"),
        (lambda p: _core.fit_shells(p, 0), "k must be"),
        (lambda p: _core.fit_shells(p, 2, kind="cube"), "kind"),
        (lambda p: _core.fit_shells(p, 2, trim=0.5), "trim"),
        (lambda p: _core.fit_shells(p, 2, seed=-1), "seed"),
    ],
)
def test_option_errors(call, match):
    with pytest.raises(ValueError, match=match):
        call(cloud(50))
