"""Live and per-frame AO in the core (canopy_ao.core.live, no bpy): a frame refitted with the
first bake's rung and τ equals a full bake of that frame."""
import os
import sys

import numpy as np
import pytest

HERE = os.path.dirname(__file__)
sys.path.insert(0, os.path.join(HERE, "..", "..", "addon"))
sys.path.insert(0, HERE)

from canopy_ao import core  # noqa: E402
from canopy_ao.core import live  # noqa: E402
from canopy_ao.core.native import CanopyAOError  # noqa: E402
import tree_scene as ts  # noqa: E402

if not core.core_status()[0]:
    pytest.skip(core.core_status()[1], allow_module_level=True)

ROLE = {"Trunk": "TRUNK", "Leaves": "CANOPY", "Ground": "GROUND", "Grass": "GRASS"}


def scene_items(sway=0.0):
    """The tree scene, its crown bent sideways by ``sway`` h² at height h above its base."""
    out = []
    for name, (p, t) in ts.scene(True).items():
        p = p.copy()
        if name == "Leaves":
            p[:, 0] += np.float32(sway) * (p[:, 2] - 1.4) ** 2
        out.append(core.SceneItem(name, ROLE[name], "Oak" if name != "Ground" else "", p,
                                  ts.vertex_normals(p, t), t))
    return out


@pytest.mark.parametrize("method", live.LIVE_METHODS)
def test_a_refitted_frame_equals_a_full_bake_of_that_frame(method):
    first = core.prepare(scene_items(0.0), core.BakeSettings(method=method, tau=1.7))
    template = live.template_items(scene_items(0.0))
    frame = scene_items(0.15)
    plan = live.refit(first, live.frame_items(template, {i.name: i.positions for i in frame},
                                              {i.name: i.normals for i in frame}))
    full = core.prepare(scene_items(0.15), core.BakeSettings(method=method, tau=1.7))
    moved = False
    for it in frame:
        got = core.evaluate_receivers(plan, it, it.positions, it.normals, vertices=slice(None))
        want = core.evaluate_receivers(full, it, it.positions, it.normals, vertices=slice(None))
        np.testing.assert_allclose(got, want, atol=1e-6, err_msg=it.name)
        was = core.evaluate_receivers(first, it, it.positions, it.normals, vertices=slice(None))
        moved |= bool(np.abs(got - was).max() > 0.02)
    assert moved  # the proxies followed the leaves


def test_a_frame_keeps_the_first_bakes_tau_per_tree():
    first = core.prepare(scene_items(0.0), core.BakeSettings(method="ellipsoid", tau=1.7))
    first.tau_by_tree = {"Oak": 3.0}
    frame = scene_items(0.2)
    plan = live.refit(first, live.frame_items(live.template_items(frame),
                                              {i.name: i.positions for i in frame},
                                              {i.name: i.normals for i in frame}))
    assert plan.tau == 1.7 and plan.tau_by_tree == {"Oak": 3.0} and plan.method == "ellipsoid"


@pytest.mark.parametrize("method", ["raytrace", "grid", "auto"])
def test_rungs_that_rebuild_from_triangles_are_refused(method):
    with pytest.raises(CanopyAOError, match="analytic rungs only"):
        live.check_method(method)


def test_a_changed_vertex_count_is_refused():
    its = scene_items()
    pos = {i.name: i.positions for i in its}
    nor = {i.name: i.normals for i in its}
    pos["Leaves"], nor["Leaves"] = pos["Leaves"][:-4], nor["Leaves"][:-4]
    with pytest.raises(CanopyAOError, match="Leaves: .*topology changed"):
        live.frame_items(live.template_items(its), pos, nor)
