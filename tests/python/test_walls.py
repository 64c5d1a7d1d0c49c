"""GROUND surfaces occlude in the proxy rungs (core/walls.py): a wall standing on a ground, a
block of leaves against it. Every ray-free proxy rung is held to a constant (each object's mean
traced AO) on the wall and on the ground near it; without the patches every one is worse."""

import numpy as np
import pytest

from canopy_ao import core
from canopy_ao.core import lighting, native, walls

from tree_scene import leaves, plane, vertex_normals

RUNGS = ("sphere", "ellipsoid", "shells", "medium", "reeves_blau", "grid", "hybrid")


def _wall(width=6.0, height=4.0, cuts=12):
    """A vertical quad grid in the plane y = 0, facing −y, from z = 0 to height."""
    p, t = plane(size=1.0, cuts=cuts)
    q = np.column_stack([p[:, 0] * width, np.zeros(len(p)), (p[:, 1] + 0.5) * height])
    return q.astype(np.float32), t[:, ::-1].copy()


def _items(scale=1.0):
    ground = plane(size=16.0, cuts=32)
    wall = _wall()
    lp, lt = leaves(count=900, center=(0.0, -0.5, 1.6), radius=1.0, size=0.12, seed=4)
    lp = lp.copy()
    lp[:, 1] = np.minimum(lp[:, 1], -0.02)  # against the wall, in front of it
    out = []
    for name, role, tree, (p, t) in (("Ground", "GROUND", "", ground),
                                     ("Wall", "GROUND", "", wall),
                                     ("Ivy", "CANOPY", "Ivy", (lp, lt))):
        q = np.asarray(p, np.float32) * scale
        out.append(core.SceneItem(name, role, tree, q, vertex_normals(q, t), t))
    return out


def _near_wall(items, scale=1.0):
    """{object: vertex mask}: the wall, the ground within 3 units of it (in front or behind)."""
    ground, wall = items[0], items[1]
    g = ground.positions
    return {"Wall": np.ones(len(wall.positions), bool),
            "Ground": (np.abs(g[:, 1]) < 3 * scale) & (np.abs(g[:, 0]) < 4 * scale)}


@pytest.fixture(scope="module")
def scene():
    items = _items()
    ref = core.prepare(items, core.BakeSettings(method="raytrace", samples=512, distance=20.0))
    want = {it.name: core.evaluate_item(ref, it).ao for it in items}
    return items, want


def _errors(items, want, method, **prepare_kw):
    plan = core.prepare(items, core.BakeSettings(method=method, samples=16, tau=1.5,
                                                 distance=20.0))
    out = {}
    for it in items:
        if it.name not in ("Wall", "Ground"):
            continue
        m = _near_wall(items)[it.name]
        got = core.evaluate_item(plan, it).ao[m]
        ref = want[it.name][m]
        out[it.name] = (float(np.abs(got - ref).mean()), float(np.abs(ref - ref.mean()).mean()))
    return out


@pytest.mark.parametrize("method", RUNGS)
def test_no_rung_worse_than_a_constant_near_a_wall(scene, method):
    items, want = scene
    for name, (mae, const) in _errors(items, want, method).items():
        assert mae <= const, f"{method} on {name}: MAE {mae:.3f} > constant's {const:.3f}"


@pytest.mark.parametrize("method", ("sphere", "grid"))
def test_without_the_patches_the_wall_is_too_bright(scene, method, monkeypatch):
    """The control: with the GROUND surfaces left out of the proxies (as before them), the
    same check fails on the wall, so the test above measures the patches."""
    items, want = scene
    monkeypatch.setattr(walls, "build", lambda items: [])
    mae, const = _errors(items, want, method)["Wall"]
    assert mae > const


def _level_patches(ground):
    """The level patches of ``ground`` (a GROUND item)."""
    return [pt for pt in walls.build([ground]) if abs(pt.normal[2]) > 0.9]


def test_a_ground_alone_is_a_patch_but_not_live():
    """Flat or sloped, a ground alone is a patch in a bake (it occludes what stands above it);
    live frames (live.refit: patches only where walls.has_wall) keep the model without patches
    there, at no cost per frame, and make them all once a wall stands on the ground."""
    for tilt in (0.0, 0.5):
        p, t = plane(size=10.0, cuts=4)
        p = p.copy()
        p[:, 2] = tilt * p[:, 0]
        g = core.SceneItem("G", "GROUND", "", p, vertex_normals(p, t), t)
        (patch,) = walls.build([g])
        assert patch.normal @ [-tilt, 0, 1] == pytest.approx(np.hypot(tilt, 1))
        assert not walls.has_wall([patch])
    items = _items()
    assert len(walls.build(items[:1])) == 1 and len(walls.build(items[:2])) == 2
    assert not walls.has_wall(walls.build(items[:1])) and walls.has_wall(walls.build(items[:2]))


def test_a_flat_ground_sees_itself_edge_on():
    """A receiver on a flat ground (any scale) gets no occlusion from it; one just above it,
    facing sideways, sees it fill half its hemisphere; one facing a big plane sees it all."""
    for s in (1e-3, 1.0, 1e3):
        g = core.SceneItem("G", "GROUND", "", *(lambda p, t: (p * s, vertex_normals(p, t), t))(
            *plane(size=10.0, cuts=4)))
        patches = _level_patches(g)
        assert len(patches) == 1
        p = np.array([[0.3, 0.2, 0.0], [1.0, 1.0, 0.0], [0.0, 0.0, 1e-3]]) * s
        n = np.array([[0, 0, 1.0], [1.0, 0, 0], [0, 0, -1.0]])
        v = walls.visibility(patches, p, n)
        assert v[0] == pytest.approx(1.0, abs=1e-5)
        assert v[1] == pytest.approx(0.5, abs=1e-3)
        assert v[2] == pytest.approx(0.0, abs=1e-3)


def test_the_ao_distance_cuts_a_plane_to_its_disc():
    """A big plane at height h facing the receiver, cut at distance D: the disc of radius
    sqrt(D² − h²), form factor r²/(r² + h²) = 1 − h²/D²; and between near and D the difference."""
    g = core.SceneItem("G", "GROUND", "", *(lambda p, t: (p, vertex_normals(p, t), t))(
        *plane(size=1000.0, cuts=2, z=1.0)))
    patches = _level_patches(g)
    p, n = np.zeros((1, 3)), np.array([[0, 0, 1.0]])
    assert 1 - walls.visibility(patches, p, n, 2.0)[0] == pytest.approx(0.75, abs=2e-3)
    assert 1 - walls.visibility(patches, p, n, 2.0, near=1.25)[0] == pytest.approx(
        0.75 - (1 - 1 / 1.25 ** 2), abs=2e-3)
    assert walls.visibility(patches, p, n, 0.5)[0] == 1.0  # the plane out of reach


def test_no_ground_no_patches():
    items = [it for it in _items() if it.role != "GROUND"]
    assert walls.build(items) == []
    plan = core.prepare(items, core.BakeSettings(method="sphere", tau=1.5))
    p = items[0].positions[:5]
    assert np.all(lighting.walls_ao(plan, p, items[0].normals[:5]) == 1.0)


def test_a_bumpy_terrain_is_no_sheet_over_the_scene():
    """Facets of a rough ground that share a plane far apart are no solid piece of it: their
    hull would be a sheet through the scene (receivers above it facing sideways: AO 0.008
    without COVERAGE, where rays see the ground below fill about half the hemisphere). Such a
    terrain is left out (AO 1 there, as before the patches): never darker than the ground."""
    rng = np.random.default_rng(3)
    p, t = plane(size=50.0, cuts=100)
    p = p.copy()
    p[:, 2] = rng.normal(0.0, 0.05, len(p))
    g = core.SceneItem("G", "GROUND", "", p, vertex_normals(p, t), t)
    patches = walls.build([g])
    q = np.column_stack([rng.uniform(-20, 20, (400, 2)), rng.uniform(0.5, 5, 400)])
    v = walls.visibility(patches, q, np.tile([0.0, 1.0, 0.0], (400, 1)), 10.0)
    assert v.min() > 0.45


def _random_patches(rng, count):
    """Convex polygons (3 to 12 corners on an ellipse, random size, place and orientation)."""
    out = []
    for _ in range(count):
        m = rng.normal(size=3)
        m /= np.linalg.norm(m)
        u = np.cross(m, [1.0, 0, 0] if abs(m[0]) < 0.9 else [0, 1.0, 0])
        u /= np.linalg.norm(u)
        v = np.cross(m, u)
        k = int(rng.integers(3, 13))
        a = np.sort(rng.uniform(0, 2 * np.pi, k))
        r = rng.uniform(0.2, 3.0, 2)
        c = rng.normal(scale=2.0, size=3)
        corners = c + np.outer(r[0] * np.cos(a), u) + np.outer(r[1] * np.sin(a), v)
        area = 0.5 * abs(float(np.cross(corners, np.roll(corners, -1, 0)).sum(0) @ m))
        out.append(walls.Patch(corners, m, area))
    return out


def test_native_patch_visibility_equals_numpy():
    """walls.visibility (native patch_visibility) and visibility_numpy, the reference: the same
    within 1e-6 on random receivers and patches, some receivers on a patch's plane, with and
    without the AO distance and near; and on the wall scene's own patches."""
    assert native._core is not None, native.core_status()[1]  # else both would be numpy's
    rng = np.random.default_rng(5)
    for case in range(12):
        patches = _random_patches(rng, int(rng.integers(1, 6)))
        p = rng.normal(scale=3.0, size=(600, 3))
        n = rng.normal(size=(600, 3))
        n[:20] = 0.0  # no normal: no occlusion
        on = patches[0]  # receivers on the first patch's plane, near its corners
        p[20:80] = on.corners[rng.integers(len(on.corners), size=60)] + 0.1 * rng.normal(size=(
            60, 3))
        p[20:80] -= np.outer(p[20:80] @ on.normal - on.offset, on.normal)
        distance, near = [(np.inf, 0.0), (2.5, 0.0), (4.0, 1.0), (0.7, 0.3)][case % 4]
        want = walls.visibility_numpy(patches, p, n, distance, near)
        got = walls.visibility(patches, p, n, distance, near)
        assert got.dtype == np.float32 and got.shape == (600,)
        np.testing.assert_allclose(got, want, atol=1e-6, rtol=0)
        assert want.min() < 0.9  # the receivers do see the patches
    items = _items()
    patches = walls.build(items)
    p = np.concatenate([it.positions for it in items]).astype(np.float64)
    n = np.concatenate([it.normals for it in items]).astype(np.float64)
    for distance, near in ((20.0, 0.0), (np.inf, 0.0), (20.0, 1.5)):
        np.testing.assert_allclose(walls.visibility(patches, p, n, distance, near),
                                   walls.visibility_numpy(patches, p, n, distance, near),
                                   atol=1e-6, rtol=0)


def test_native_patch_visibility_refuses_bad_patches():
    _core = native._core
    c = np.array([[0, 0, 1], [1, 0, 1], [0, 1, 1.0]])
    ok = np.array([[0, 0, -1.0, -1.0, 1.5]])
    p, n = np.zeros((1, 3)), np.array([[0, 0, 1.0]])
    assert _core.patch_visibility(c, np.int32([3]), ok, p, n)[0] < 1.0
    for counts, planes, match in ((np.int32([2]), ok, "counts"), (np.int32([4]), ok, "counts"),
                                  (np.int32([3]), ok * [1, 1, 2, 1, 1], "unit length"),
                                  (np.int32([3]), ok * [1, 1, 1, 1, 0], "diameters"),
                                  (np.int32([3]), ok[:, :4], "planes")):
        with pytest.raises(ValueError, match=match):
            _core.patch_visibility(c, counts, planes, p, n)
    with pytest.raises(ValueError, match="corners"):
        _core.patch_visibility(c * np.nan, np.int32([3]), ok, p, n)
    with pytest.raises(ValueError, match="float64"):
        _core.patch_visibility(c, np.int32([3]), ok, p.astype(np.float32), n)
    with pytest.raises(ValueError, match="distance"):
        _core.patch_visibility(c, np.int32([3]), ok, p, n, 0.0)

