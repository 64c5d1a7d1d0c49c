"""The panel asks the rung (core/rungs/): its Method menu lists every registered rung in the
ladder's order, and Samples is drawn under exactly the rungs that use it (Rung.uses_samples),
the time budget under the one that chooses (auto)."""
from types import SimpleNamespace

import bpy

from canopy_ao import core
from canopy_ao.blender import panels
from canopy_ao.core.rungs import base as rungs
from test_addon import FakeLayout


def _drawn(method):
    s = bpy.context.scene.canopy_ao
    old = s.method
    try:
        s.method = method
        log = []
        panels.CANOPY_AO_PT_main.draw(SimpleNamespace(layout=FakeLayout(log)), bpy.context)
    finally:
        s.method = old
    return {name for kind, name in log if kind == "prop"}


def test_the_method_menu_is_the_ladder():
    items = bpy.context.scene.canopy_ao.bl_rna.properties["method"].enum_items
    assert [i.identifier for i in items] == list(rungs.names())
    assert [i.name for i in items] == [r.label for r in rungs.ladder()]


def test_samples_under_every_rung_that_uses_them():
    assert core.core_status()[0]
    with_samples = set()
    for rung in rungs.ladder():
        drawn = _drawn(rung.name)
        assert ("samples" in drawn) == rung.uses_samples, rung.name
        assert ("time_budget" in drawn) == rung.chooses, rung.name
        if "samples" in drawn:
            with_samples.add(rung.name)
    assert {"auto", "hybrid", "raytrace"} <= with_samples


def test_a_rung_registered_at_run_time_is_in_the_menu_after_registration():
    """A rung registered (rungs.base.register) is in the panel's menu once the add-on
    registers its properties again, under its own saved number; taken off, the menu is the
    ladder again."""
    import addon_utils
    import numpy as np
    toy = rungs.Rung("constant", "Constant", "AO 0.5 everywhere",
                     evaluate=lambda rung, plan, role, tree, key, p, *a: np.full(
                         len(p), 0.5, np.float32))
    addon_utils.disable("canopy_ao", default_set=True)
    rungs.register(toy, before="raytrace")
    try:
        addon_utils.enable("canopy_ao", default_set=True, handle_error=None)
        items = bpy.context.scene.canopy_ao.bl_rna.properties["method"].enum_items
        assert [i.identifier for i in items] == list(rungs.names())
        by_name = {i.identifier: i.value for i in items}
        assert by_name["constant"] == rungs.get("constant").number == 10
        assert by_name["raytrace"] == 9  # a saved ray-traced choice keeps its meaning
    finally:
        addon_utils.disable("canopy_ao", default_set=True)
        rungs.unregister("constant")
        addon_utils.enable("canopy_ao", default_set=True, handle_error=None)
    items = bpy.context.scene.canopy_ao.bl_rna.properties["method"].enum_items
    assert [i.identifier for i in items] == list(rungs.names())
