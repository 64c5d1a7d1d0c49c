"""canopy_ao._core under hostile input: every loop terminates, finite accepted input gives finite
results, and each documented guarantee holds at the edges of the accepted range
(native/python/README.md, "Accepted range"): coordinates within +-1e9, lengths in [1e-9, 1e10],
normals of any finite length, integers range-checked, paths passed byte for byte.
"""
import os
import subprocess
import sys

import numpy as np
import pytest

from canopy_ao import _core as core  # conftest.py puts addon/ on sys.path

ADDON = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..", "addon"))


def f32(a):
    return np.ascontiguousarray(a, dtype=np.float32)


def leaf_cloud(count=400, seed=0, scale=1.0):
    """Small random triangles in a unit ball (a crown), times scale."""
    rng = np.random.default_rng(seed)
    c = rng.normal(size=(count, 3))
    c *= (rng.random(count) ** (1 / 3) / np.linalg.norm(c, axis=1))[:, None]
    v = c[:, None, :] + 0.08 * rng.normal(size=(count, 3, 3))
    return f32(v.reshape(-1, 3) * scale), np.arange(3 * count, dtype=np.int32).reshape(count, 3)


def run_child(code, timeout=60):
    """Runs code in a fresh interpreter (a hang or crash cannot take pytest down)."""
    env = dict(os.environ, PYTHONPATH=ADDON)
    return subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                          timeout=timeout)


# === Loops bounded by the grid, not by input magnitudes
def test_optical_depth_with_a_huge_direction_returns_the_unit_direction_value():
    # A direction of length 1e20 squared overflowed float32 to a zero direction, and the march
    # then never advanced: the call hung.
    r = run_child(
        "import numpy as np; from canopy_ao import _core as c\n"
        "v = np.array([[0,0,0],[1,0,0],[0,1,0]], np.float32); t = np.array([[0,1,2]], np.int32)\n"
        "g = c.DensityGrid(v, t, 8)\n"
        "a = g.optical_depth((0.1, 0.1, 0.0), (1e20, 1e20, 0.0))\n"
        "b = g.optical_depth((0.1, 0.1, 0.0), (1.0, 1.0, 0.0))\n"
        "print(a, b)\n", timeout=30)
    assert r.returncode == 0, r.stderr
    a, b = map(float, r.stdout.split())
    assert b > 0 and a == pytest.approx(b, rel=1e-6)


def test_a_receiver_far_outside_the_grid_terminates():
    # From 1e8 away, t + dt rounded to t on every step: the march stalled.
    r = run_child(
        "import numpy as np, sys; sys.path.insert(0, %r)\n"
        "from test_reliability import leaf_cloud\n"
        "from canopy_ao import _core as c\n"
        "v, t = leaf_cloud(); g = c.DensityGrid(v, t, 16)\n"
        "d = g.optical_depth((-1e8, 0.0, 0.0), (1.0, 0.0, 0.0), self_skip=0.0)\n"
        "ao = g.ao(np.array([[-1e8, 0, 0]], np.float32), np.array([[1, 0, 0]], np.float32))\n"
        "print(d, ao[0])\n" % os.path.dirname(__file__), timeout=30)
    assert r.returncode == 0, r.stderr
    d, ao = map(float, r.stdout.split())
    assert np.isfinite(d) and d >= 0 and 0 <= ao <= 1


# === Finite accepted input gives finite results; the rest is a ValueError
@pytest.mark.parametrize("call", [
    lambda p, n: core.ao_medium_sphere(p, n, core.Sphere((0, 0, 0), 1e-40), 1.0),
    lambda p, n: core.ao_grass(p, n, 0.0, 1e-40),
    lambda p, n: core.ao_medium_ellipsoid(p, n, core.Ellipsoid((0, 0, 0), np.eye(3),
                                                               (1e-40, 1, 1)), 1.0),
    lambda p, n: core.OccluderField([core.Ellipsoid((0, 0, 0), np.eye(3), (1, 1e-41, 1))], 1.0),
    lambda p, n: core.ao_medium_shells(p * np.float32(1e20), n, [core.Ellipsoid.from_sphere(
        core.Sphere((0, 0, 0), 1.0))], 1.0),
    lambda p, n: core.ao_reeves_blau(p * np.float32(1e38), n, core.Ellipsoid.from_sphere(
        core.Sphere((0, 0, 0), 1.0)), 1.0),
    lambda p, n: core.DensityGrid(*leaf_cloud(scale=1e19)),
    lambda p, n: core.fit_sphere(p * np.float32(1e30)),
    lambda p, n: core.fit_ellipsoid(p * np.float32(1e30)),
    lambda p, n: core.ao_canopy_sphere(p, n, core.Sphere((1e20, 0, 0), 1.0), 1.0),
    lambda p, n: core.ao_grass(p, n, 1e30, 1.0),
], ids=["medium_sphere_r", "grass_h", "medium_ellipsoid_r", "occluder_field_r",
        "medium_shells_xyz", "reeves_blau_xyz", "density_grid_extent", "fit_sphere_xyz",
        "fit_ellipsoid_xyz", "sphere_centre", "ground_height"])
def test_out_of_range_magnitudes_are_a_value_error_naming_the_range(call):
    p = f32([[0.5, 0, 0], [2, 0, 0]])
    n = f32([[0, 0, 1], [1, 0, 0]])
    with pytest.raises(ValueError, match=r"1e[+-]?0?9|1e\+10"):
        call(p, n)


def test_tau_beyond_the_accepted_range_is_refused_not_garbage():
    p, n = f32([[0.5, 0, 0], [0.2, 0.1, 0]]), f32([[0, 0, 1], [-1, 0, 0]])
    e = core.Ellipsoid((0, 0, 0), np.eye(3), (1.0, 0.8, 0.6))
    for call in (core.ao_canopy_ellipsoid, core.ao_medium_ellipsoid, core.ao_reeves_blau):
        with pytest.raises(ValueError, match="tau"):
            call(p, n, e, 3e38)
        assert np.all(call(p, n, e, 1e4) <= 1e-30)  # deep inside: black, not garbage


def test_ao_near_far_refuses_a_denormal_near_and_far_coordinates():
    v, t = leaf_cloud()
    tracer, grid = core.RayTracer(v, t), core.DensityGrid(v, t, 16)
    p, n = f32([[0, 0, 2]]), f32([[0, 0, 1]])
    with pytest.raises(ValueError, match="near"):
        core.ao_near_far(tracer, grid, p, n, 1e-40)
    with pytest.raises(ValueError, match="points"):
        core.ao_near_far(tracer, grid, p * np.float32(1e20), n, 0.1)
    assert np.all(np.isfinite(core.ao_near_far(tracer, grid, p, n, 0.1)))


@pytest.mark.parametrize("scale", [1e-8, 1.0, 4e8])
def test_density_grid_is_scale_free_across_the_accepted_range(scale):
    v, t = leaf_cloud()
    p = f32([[0, 0, 0], [0, 0, 1.5], [0.3, -0.2, 0.1]])
    n = f32([[0, 0, 1], [0, 0, -1], [1, 0, 0]])
    ref = core.DensityGrid(v, t, 16).ao(p, n)
    s = np.float32(scale)
    got = core.DensityGrid(v * s, t, 16).ao(p * s, n)
    assert np.all(np.isfinite(got))
    np.testing.assert_allclose(got, ref, atol=2e-3)


@pytest.mark.parametrize("scale", [1e-3, 1.0, 5e8])
def test_fits_are_finite_and_scale_with_the_points(scale):
    pts = leaf_cloud()[0]
    s = np.float32(scale)
    sph, ell = core.fit_sphere(pts * s), core.fit_ellipsoid(pts * s)
    assert np.isfinite(sph.radius) and np.all(np.isfinite(ell.radii))
    assert sph.radius == pytest.approx(core.fit_sphere(pts).radius * scale, rel=1e-4)
    np.testing.assert_allclose(ell.radii, core.fit_ellipsoid(pts).radii * scale, rtol=1e-3)


# === Normals of any finite length give the unit normal's result
def receivers_calls():
    v, t = leaf_cloud()
    sph = core.Sphere((0, 0, 0), 1.0)
    ell = core.Ellipsoid((0, 0, 0), np.eye(3), (1.0, 0.7, 0.5))
    tracer, grid = core.RayTracer(v, t), core.DensityGrid(v, t, 16)
    return {
        "canopy_sphere": lambda p, n: core.ao_canopy_sphere(p, n, sph, 1.0),
        "canopy_ellipsoid": lambda p, n: core.ao_canopy_ellipsoid(p, n, ell, 1.0),
        "canopy_shells": lambda p, n: core.ao_canopy_shells(p, n, [ell], 1.0),
        "occluders": lambda p, n: core.ao_occluders(p, n, [ell], 1.0),
        "occluders_solid": lambda p, n: core.ao_occluders(p, n, [ell], 1.0, law="solid_opacity"),
        "medium_sphere": lambda p, n: core.ao_medium_sphere(p, n, sph, 1.0),
        "medium_ellipsoid": lambda p, n: core.ao_medium_ellipsoid(p, n, ell, 1.0),
        "grass": lambda p, n: core.ao_grass(p, n, -1.0, 2.0),
        "raytrace": lambda p, n: tracer.ao(p, n, samples=16),
        "grid": lambda p, n: grid.ao(p, n),
        "near_far": lambda p, n: core.ao_near_far(tracer, grid, p, n, 0.2, samples=16),
    }


CALLS = receivers_calls()


@pytest.mark.parametrize("name", sorted(CALLS))
@pytest.mark.parametrize("length", [3e38, 1e19, 1e-20, 1e-37])
def test_normal_length_does_not_change_results(name, length):
    rng = np.random.default_rng(1)
    p = f32(rng.normal(size=(64, 3)) * 0.9)
    n = rng.normal(size=(64, 3))
    n = f32(n / np.linalg.norm(n, axis=1)[:, None])
    n[0] = 0  # a zero normal stays a zero normal
    ref = CALLS[name](p, n)
    got = CALLS[name](p, f32(n.astype(np.float64) * length))
    np.testing.assert_allclose(got, ref, atol=1e-5)


def test_texel_normals_are_unit_even_for_a_triangle_without_3d_area():
    uvs = f32([[0, 0], [1, 0], [0, 1]])
    flat = f32([[0, 0, 0], [1, 0, 0], [2, 0, 0]])  # collinear in 3D: no face normal
    t = core.rasterize_uv(uvs, flat, None, resolution=8)
    assert len(t) > 0
    np.testing.assert_allclose(np.linalg.norm(t.normals, axis=1), 1.0, rtol=1e-6)
    opposite = f32([[0, 0, 1], [0, 0, -1], [0, 0, 0]])
    t = core.rasterize_uv(uvs, flat, opposite, resolution=8)
    np.testing.assert_allclose(np.linalg.norm(t.normals, axis=1), 1.0, rtol=1e-6)
    tiny = f32([[0, 0, 1e-30]] * 3)  # tiny but valid: must not fall back to the face
    t = core.rasterize_uv(uvs, f32([[0, 0, 0], [1, 0, 0], [0, 1, 0]]), tiny, resolution=8)
    np.testing.assert_allclose(t.normals, np.tile([0, 0, 1], (len(t), 1)), atol=1e-6)


# === Scalars and integers
def test_scalar_laws_refuse_what_they_cannot_answer():
    for tau in (-10, 1e5, float("inf")):
        with pytest.raises(ValueError, match="tau"):
            core.shell_opacity(tau)
    with pytest.raises(ValueError, match="cos_theta"):
        core.sphere_occlusion(float("nan"), 0.5)
    with pytest.raises(ValueError, match="sin2_sigma"):
        core.sphere_occlusion(0.5, float("nan"))
    for tau in (0.0, 0.5, 1e4):
        assert 0.0 <= core.shell_opacity(tau) <= 1.0
    assert 0.0 <= core.sphere_occlusion(2.0, 0.5) <= 1.0  # cos clamped, as documented


def test_integers_out_of_range_are_value_errors_and_numpy_integers_pass():
    previous = core.set_max_threads(0)
    try:
        with pytest.raises(ValueError, match="n must be an integer"):
            core.set_max_threads(-1)
        core.set_max_threads(np.int64(1))
        assert core.max_threads() == 1
    finally:
        core.set_max_threads(previous)
    v, t = leaf_cloud(50)
    tracer = core.RayTracer(v, t)
    p, n = f32([[0, 0, 0]]), f32([[0, 0, 1]])
    for bad in (2**31, 2**64, -1, 0, 2.5):
        with pytest.raises(ValueError, match="samples"):
            tracer.ao(p, n, samples=bad)
    for bad in (2**32, -1, 2**80):
        with pytest.raises(ValueError, match="seed"):
            tracer.ao(p, n, seed=bad)
    assert tracer.ao(p, n, samples=np.int32(8)).shape == (1,)
    with pytest.raises(ValueError, match="directions"):
        core.DensityGrid(v, t).ao(p, n, directions=2**40)
    with pytest.raises(ValueError, match="resolution"):
        core.DensityGrid(v, t, resolution=2**31)
    with pytest.raises(ValueError, match="k must"):
        core.fit_shells(v, 2**31)
    with pytest.raises(ValueError, match="margin"):
        core.splat_texels(np.zeros(1, np.int32), f32([0.5]), 4, margin=2**31)


# === Paths: byte for byte, or refused
@pytest.mark.parametrize("name", [b"plain.exr", b"caf\xe9.exr", "\u00e9t\u00e9.exr".encode(),
                                  b"a#b%04d?x=1:y[1]*.exr", b"-lead space .png"])
@pytest.mark.parametrize("kind", ["bytes", "str"])
def test_a_path_reaches_the_file_system_exactly_as_given(tmp_path, name, kind):
    d = os.fsencode(str(tmp_path))
    path = d + b"/" + name
    arg = path if kind == "bytes" else os.fsdecode(path)  # str: surrogateescape round trip
    img = np.full((2, 3), 0.25, np.float32)
    core.write_image(arg, img)
    assert os.listdir(d) == [name]
    np.testing.assert_allclose(core.read_image(arg)[..., 0], img, atol=1e-4)


@pytest.mark.parametrize("bad", ["a\0b.exr", b"a\0b.exr", "", None, 3])
def test_a_path_that_cannot_reach_the_file_system_as_given_is_refused(tmp_path, bad):
    if isinstance(bad, (str, bytes)) and bad:
        bad = (str(tmp_path) + "/") + bad if isinstance(bad, str) else \
            os.fsencode(str(tmp_path)) + b"/" + bad
    img = np.zeros((2, 2), np.float32)
    with pytest.raises(ValueError, match="path"):
        core.write_image(bad, img)
    with pytest.raises(ValueError, match="path"):
        core.read_image(bad)
    assert os.listdir(tmp_path) == []


def test_medium_quadrature_stays_in_the_unit_interval():
    # On the surface facing out, round-off made the chord slightly negative: AO 1.0000000000000002.
    for cos_beta in (1.0, 3e38):
        assert 0.0 <= core.medium_ao_quadrature(1.0, cos_beta, 2.9316827441133224, 296) <= 1.0
