"""canopy_ao._core analytic AO models: the README's signatures, known answers, argument checks
(ValueError naming the argument), finite results in [0, 1], and the GIL being released."""
import math
import os
import sys
import threading
import time

import numpy as np
import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "addon"))
_core = pytest.importorskip("canopy_ao._core")
if not hasattr(_core, "ao_canopy_sphere") or not hasattr(_core, "Sphere"):
    pytest.skip("this build of canopy_ao._core has no models", allow_module_level=True)


def rows(*vs):
    return np.ascontiguousarray(np.array(vs, dtype=np.float32).reshape(-1, 3))


def random_receivers(n, centre, extent, seed=0):
    rng = np.random.default_rng(seed)
    p = (np.asarray(centre, np.float32) + extent * rng.uniform(-1, 1, (n, 3))).astype(np.float32)
    nrm = rng.normal(size=(n, 3)).astype(np.float32)
    return np.ascontiguousarray(p), np.ascontiguousarray(nrm)


def rot_z(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


SPHERE = None


@pytest.fixture
def sphere():
    return _core.Sphere(np.array([1, 2, 3], np.float32), 2.0)


def test_centre_is_exp_minus_tau_for_any_normal(sphere):
    p = rows(*([1, 2, 3] * 4))
    n = rows([1, 0, 0], [0, 0, -1], [0.2, 0.3, 0.9], [0, 0, 0])
    for tau in (0.0, 0.5, 2.0):
        v = _core.ao_canopy_sphere(p, n, sphere, tau)
        assert v.dtype == np.float32 and v.shape == (4,)
        np.testing.assert_allclose(v, math.exp(-tau), rtol=3e-6)


def test_shell_facing_out_is_open_and_far_outside_nearly_open(sphere):
    p = rows([3, 2, 3], [1, 2, -17])
    n = rows([1, 0, 0], [0, 0, 1])
    v = _core.ao_canopy_sphere(p, n, sphere, 1.0)
    assert v[0] == pytest.approx(1.0, abs=1e-6)
    # 20 radii... d = 20, r = 2: occluder law 1 - opacity (r/d)^2.
    assert v[1] == pytest.approx(1 - _core.shell_opacity(1.0) * 0.01, abs=1e-6)


def test_ellipsoid_equal_axes_matches_sphere_and_scale_invariance(sphere):
    e = _core.Ellipsoid(np.array([1, 2, 3], np.float32), rot_z(0.6), np.array([2, 2, 2], np.float32))
    p, n = random_receivers(20000, [1, 2, 3], 3.5)
    a = _core.ao_canopy_sphere(p, n, sphere, 1.3)
    b = _core.ao_canopy_ellipsoid(p, n, e, 1.3)
    np.testing.assert_allclose(a, b, atol=2e-5)
    big = _core.Sphere(np.array([10, 20, 30], np.float32), 20.0)
    c = _core.ao_canopy_sphere(np.ascontiguousarray(p * 10), n, big, 1.3)
    np.testing.assert_allclose(a, c, atol=2e-5)


def test_shells_product_and_nearest():
    a = _core.Ellipsoid.from_sphere(_core.Sphere(np.array([-0.5, 0, 0], np.float32), 1.0))
    b = _core.Ellipsoid.from_sphere(_core.Sphere(np.array([0.7, 0, 0], np.float32), 1.5))
    x = np.linspace(-0.2, 0.4, 301, dtype=np.float32)
    p = np.ascontiguousarray(np.stack([x, np.zeros_like(x), np.full_like(x, 0.3)], 1))
    n = np.ascontiguousarray(np.tile(np.float32([0, 0, 1]), (len(x), 1)))
    va = _core.ao_canopy_ellipsoid(p, n, a, 1.0)
    vb = _core.ao_canopy_ellipsoid(p, n, b, 1.0)
    prod = _core.ao_canopy_shells(p, n, [a, b], 1.0)
    near = _core.ao_canopy_shells(p, n, [a, b], 1.0, combine="nearest")
    np.testing.assert_allclose(prod, va * vb, atol=1e-6)
    assert np.abs(np.diff(prod)).max() < 0.01
    assert np.abs(np.diff(near)).max() > 0.1  # the paper's seam
    with pytest.raises(ValueError, match="combine"):
        _core.ao_canopy_shells(p, n, [a, b], 1.0, combine="mean")
    with pytest.raises(ValueError, match="empty"):
        _core.ao_canopy_shells(p, n, [], 1.0)


def test_reeves_blau():
    e = _core.Ellipsoid(np.zeros(3, np.float32), np.eye(3), np.array([2, 4, 1], np.float32))
    p = rows([0, 0, 0], [1, 0, 0], [0, 0, 1], [0, 0, 5])
    v = _core.ao_reeves_blau(p, rows(*([0, 0, 1] * 4)), e, 2.0)
    np.testing.assert_allclose(v, [math.exp(-2), math.exp(-1), 1, 1], rtol=1e-6)


def test_sphere_occlusion_closed_forms():
    assert _core.sphere_occlusion(0.8, 0.25) == pytest.approx(0.2, abs=1e-7)
    assert _core.sphere_occlusion(-0.8, 0.25) == 0.0
    assert _core.sphere_occlusion(0.3, 1.0) == pytest.approx(0.65, abs=1e-7)
    # Horizon-crossing: Monte Carlo with Malley's method (4M samples, tolerance 2e-3).
    rng = np.random.default_rng(3)
    r = np.sqrt(rng.uniform(size=4_000_000))
    phi = rng.uniform(0, 2 * np.pi, size=r.size)
    w = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1 - r * r)], 1)
    theta, s2 = 1.3, 0.3
    c = np.array([math.sin(theta), 0, math.cos(theta)])
    mc = np.mean(w @ c >= math.sqrt(1 - s2))
    assert _core.sphere_occlusion(math.cos(theta), s2) == pytest.approx(mc, abs=2e-3)


def test_occluders_forest_and_field():
    forest = [
        _core.Ellipsoid.from_sphere(_core.Sphere(np.array([6.0 * i, 6.0 * j, 3], np.float32), 1.0))
        for i in range(20)
        for j in range(20)
    ]
    rng = np.random.default_rng(1)
    p = np.ascontiguousarray(np.c_[rng.uniform(0, 114, (5000, 2)), np.zeros(5000)].astype(np.float32))
    n = np.ascontiguousarray(np.tile(np.float32([0, 0, 1]), (5000, 1)))
    cut = _core.ao_occluders(p, n, forest, 1.0, epsilon=1e-2)
    full = _core.ao_occluders(p, n, forest, 1.0, epsilon=0.0)
    assert np.all((cut >= full) & (cut <= 1) & (full >= 0))
    assert (cut - full).max() < 0.05
    field = _core.OccluderField(forest, 1.0, epsilon=1e-2)
    assert len(field) == 400 and field.max_candidates < 100
    np.testing.assert_array_equal(field.ao(p, n), cut)
    solid = _core.ao_occluders(rows([0, 0, 0]), rows([0, 0, 1]), forest[:1], 1.0, solid=True)
    assert solid[0] == pytest.approx(1 - 1 / 9, abs=1e-6)


def test_occluder_laws():
    # One sphere overhead: "solid_opacity" = opacity × (r/d)²; "medium" = the medium table's AO
    # (ao_medium_sphere outside the ball); below the horizon both block nothing.
    c = np.array([0, 0, 5], np.float32)
    sph = _core.Sphere(c, 1.0)
    e = [_core.Ellipsoid.from_sphere(sph)]
    p = rows([0, 0, 0], [0.5, 0, 0.5], [3, 0, 5])
    n = rows([0, 0, 1], [1, 0, 0.4], [1, 0, 0])
    old = _core.ao_occluders(p, n, e, 0.7, epsilon=0.0, law="solid_opacity")
    assert old[0] == pytest.approx(1 - _core.shell_opacity(0.7) / 25, abs=1e-6)
    med = _core.ao_occluders(p, n, e, 0.7, epsilon=0.0, law="medium")
    np.testing.assert_allclose(med, _core.ao_medium_sphere(p, n, sph, 0.7), atol=1e-5)
    assert med[2] == 1.0 and old[2] == 1.0
    assert med[0] > old[0]  # short rim chords: a medium ball blocks less than the mean chord says
    field = _core.OccluderField(e, 0.7, epsilon=0.0, law="medium")
    np.testing.assert_array_equal(field.ao(p, n), med)
    with pytest.raises(ValueError, match="law"):
        _core.ao_occluders(p, n, e, 0.7, law="opaque")


def test_grass():
    p = rows([0, 0, 1.25], [0, 0, 1.0], [0, 0, 9])
    n = rows([0, 0, 1], [0, 0, 1], [1, 0, 0])
    v = _core.ao_grass(p, n, 1.0, 0.5, floor=0.05)
    np.testing.assert_allclose(v, [0.5, 0.05, 0.5], atol=1e-6)
    v = _core.ao_grass(p, n, 1.0, 0.5, up=(0, 0, 2), floor=0.0)
    assert v[1] == 0.0
    with pytest.raises(ValueError, match="blade_height"):
        _core.ao_grass(p, n, 0.0, 0.0)
    with pytest.raises(ValueError, match="up"):
        _core.ao_grass(p, n, 0.0, 1.0, up=(0, 0, 0))


@pytest.mark.parametrize("fn", ["sphere", "ellipsoid", "shells", "reeves", "occluders", "grass"])
def test_finite_in_unit_range_with_zero_normals(fn, sphere):
    p, n = random_receivers(50000, [1, 2, 3], 6.0, seed=5)
    n[:100] = 0
    e = _core.Ellipsoid(np.array([1, 2, 3], np.float32), rot_z(0.3), np.array([3, 1, 2], np.float32))
    v = {
        "sphere": lambda: _core.ao_canopy_sphere(p, n, sphere, 3.0),
        "ellipsoid": lambda: _core.ao_canopy_ellipsoid(p, n, e, 3.0),
        "shells": lambda: _core.ao_canopy_shells(p, n, [e, _core.Ellipsoid.from_sphere(sphere)], 3.0),
        "reeves": lambda: _core.ao_reeves_blau(p, n, e, 3.0),
        "occluders": lambda: _core.ao_occluders(p, n, [e], 3.0),
        "grass": lambda: _core.ao_grass(p, n, 0.0, 2.0),
    }[fn]()
    assert v.shape == (50000,) and v.dtype == np.float32
    assert np.all(np.isfinite(v)) and v.min() >= 0 and v.max() <= 1


def test_bad_arguments(sphere):
    p, n = rows([0, 0, 0]), rows([0, 0, 1])
    for tau in (-1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="tau"):
            _core.ao_canopy_sphere(p, n, sphere, tau)
    with pytest.raises(ValueError, match="positions"):
        _core.ao_canopy_sphere(p.astype(np.float64), n, sphere, 1.0)
    with pytest.raises(ValueError, match="normals"):
        _core.ao_canopy_sphere(p, rows([0, 0, 1], [0, 0, 1]), sphere, 1.0)
    with pytest.raises(ValueError, match="positions"):
        _core.ao_canopy_sphere(rows([np.nan, 0, 0]), n, sphere, 1.0)
    with pytest.raises(ValueError, match="radius"):
        _core.ao_canopy_sphere(p, n, _core.Sphere(np.zeros(3, np.float32), 0.0), 1.0)
    with pytest.raises(ValueError, match="epsilon"):
        _core.ao_occluders(p, n, [_core.Ellipsoid.from_sphere(sphere)], 1.0, epsilon=2.0)
    empty = np.zeros((0, 3), np.float32)
    assert _core.ao_canopy_sphere(empty, empty, sphere, 1.0).shape == (0,)


def test_releases_the_gil(sphere):
    # With a long switch interval the main thread keeps the GIL across the call unless the call
    # itself releases it; only then can the counter thread tick while the model runs.
    p, n = random_receivers(1_000_000, [1, 2, 3], 3.0)
    shells = [_core.Ellipsoid.from_sphere(sphere)] * 4
    ticks = []
    stop = threading.Event()

    def count():
        while not stop.is_set():
            ticks.append(1)

    old = sys.getswitchinterval()
    sys.setswitchinterval(0.5)
    t = threading.Thread(target=count)
    t.start()
    try:
        time.sleep(0.01)  # let the counter start
        before = len(ticks)
        _core.ao_canopy_shells(p, n, shells, 1.0)
        during = len(ticks) - before
    finally:
        stop.set()
        t.join()
        sys.setswitchinterval(old)
    assert during > 0
