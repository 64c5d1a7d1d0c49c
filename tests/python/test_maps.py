"""Canopy thickness (core/maps.py): 0 on the fitted shells' outer surface, rising inward to 1 at
a shell's centre, the same for a scaled, moved tree; and on a baked tree through prepare()."""

import numpy as np
import pytest

from canopy_ao import _core, core
from canopy_ao.core import maps

import tree_scene


def _rotation(seed):
    q, _ = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))


def _shell(center=(0.0, 0.0, 0.0), radii=(2.0, 1.0, 0.5), seed=0):
    return _core.Ellipsoid(np.asarray(center, np.float32), _rotation(seed).astype(np.float32),
                           np.asarray(radii, np.float32))


def _on_shell(e, u):
    """Points center + Q diag(r) u for unit-frame points u (N, 3)."""
    q = np.asarray(e.axes, np.float64) * np.asarray(e.radii, np.float64)
    return np.asarray(e.center, np.float64) + u @ q.T


def _directions(n, seed=3):
    d = np.random.default_rng(seed).normal(size=(n, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def test_zero_on_the_shell_one_at_the_centre_rising_inward():
    e = _shell()
    u = _directions(200)
    assert np.abs(maps.shell_depth([e], _on_shell(e, u))).max() < 1e-5
    assert maps.shell_depth([e], [e.center])[0] == pytest.approx(1.0, abs=1e-6)
    # Along each ray from the surface to the centre it rises strictly, as 1 - radius.
    radii = np.linspace(1.0, 0.0, 11)
    depth = np.stack([maps.shell_depth([e], _on_shell(e, u * s)) for s in radii], axis=1)
    assert np.all(np.diff(depth, axis=1) > 0.09)
    assert np.allclose(depth, 1.0 - radii, atol=1e-5)
    # Outside: 0, never negative.
    assert np.all(maps.shell_depth([e], _on_shell(e, u * 1.5)) == 0.0)


def test_scale_free_and_moved_with_the_tree():
    e = _shell(center=(1.0, -2.0, 3.0))
    u = _directions(300) * np.random.default_rng(4).uniform(0, 1.3, size=(300, 1))
    p = _on_shell(e, u)
    base = maps.shell_depth([e], p)
    for s, t in ((1e-3, (5.0, 0.0, 0.0)), (1e3, (0.0, -7.0, 2.0))):
        t = np.float32(t) * s  # moved by a few crown sizes: float32 positions hold that
        e2 = _core.Ellipsoid(np.asarray(e.center) * s + t, e.axes, np.asarray(e.radii) * s)
        assert np.abs(maps.shell_depth([e2], p * s + t) - base).max() < 2e-5


def test_union_of_shells_zero_only_on_the_outer_surface():
    a, b = _shell((0.0, 0.0, 0.0), (1.0, 1.0, 1.0)), _shell((1.0, 0.0, 0.0), (1.0, 1.0, 1.0))
    # (0.5, 0, 0) lies half way into both; a's surface point (1, 0, 0) is b's centre.
    d = maps.shell_depth([a, b], [(0.5, 0, 0), (1.0, 0, 0), (-1.0, 0, 0), (2.0, 0, 0)])
    assert d == pytest.approx([0.5, 1.0, 0.0, 0.0], abs=1e-6)


def test_thickness_of_a_baked_tree_and_its_scaled_copy():
    """Through prepare(): the leaves get values in [0, 1] reaching 0 at the crown's rim, deep
    leaves more than outer ones, the ground far from the crown 0, and a tree 100 times larger,
    or lit by another rung, the same thickness."""
    def items(scale):
        return tree_scene.scene_items(core, scale)

    results = []
    for scale in (1.0, 100.0):
        its = items(scale)
        for method in ("ellipsoid", "shells"):  # the crown's, whichever rung lights
            plan = core.prepare(its, core.BakeSettings(method=method, tau=2.0))
            results.append({it.name: maps.thickness(plan, it, it.positions, slice(None))
                            for it in its})
    leaves = results[0]["Leaves"]
    assert 0.0 <= leaves.min() < 0.02 and leaves.max() <= 1.0 and leaves.max() > 0.5
    it = next(i for i in items(1.0) if i.name == "Leaves")
    r = np.linalg.norm(it.positions - it.positions.mean(axis=0), axis=1)
    inner, outer = r < np.quantile(r, 0.2), r > np.quantile(r, 0.8)
    assert leaves[inner].mean() > leaves[outer].mean() + 0.3
    ground = next(i for i in items(1.0) if i.name == "Ground")
    far = np.linalg.norm(ground.positions[:, :2], axis=1) > 5.0
    assert np.all(results[0]["Ground"][far] == 0.0)
    for name in results[0]:
        for other in results[1:]:
            assert np.abs(results[0][name] - other[name]).max() < 1e-3, name


def test_command_line_takes_the_channel_and_the_thickness():
    from canopy_ao import cli
    args = cli.build_parser().parse_args(["--channel", "g", "--thickness",
                                          "--thickness-name", "Depth"])
    opts = cli.options_from_args(args, 0.0)
    assert (opts["channel"], opts["thickness"], opts["thickness_name"]) == ("G", True, "Depth")
    assert cli.options_from_args(cli.build_parser().parse_args([]), 0.0)["channel"] == "RGBA"
    with pytest.raises(SystemExit) as exc:
        cli.build_parser().parse_args(["--channel", "X"])
    assert exc.value.code == 2


def test_a_texel_takes_the_crown_it_lies_in_whatever_the_crowns_rotation():
    """Receivers without a vertex (texels) of a mesh holding two trees take the crown nearest
    in its own unit frame, where the Ellipsoid's axes are its columns."""
    import importlib
    from canopy_ao.core.scene import Plan
    bake = importlib.import_module("canopy_ao.core.bake")  # core.bake is also the function
    long = _core.Ellipsoid(np.zeros(3, np.float32), _rotation(5).astype(np.float32),
                           np.float32([4.0, 0.3, 0.3]))
    ball = _core.Ellipsoid(np.float32([2.5, 2.5, 2.5]), np.eye(3, dtype=np.float32),
                           np.float32([1.0, 1.0, 1.0]))
    plan = Plan(settings=None, method="ellipsoid", tau=1.0,
                fits={"A": (None, long, [long]), "B": (None, ball, [ball])})
    tip = _on_shell(long, np.array([[0.95, 0.0, 0.0], [-0.95, 0.0, 0.0]]))
    assert np.all(long.contains(tip.astype(np.float32)))
    assert list(bake._nearest_crown(plan, ("A", "B"), tip)) == [0, 0]
