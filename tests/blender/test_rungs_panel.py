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
