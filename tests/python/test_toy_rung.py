"""Adding a rung is one file and one registry line (docs/DESIGN.md, 'Architecture'): a toy
rung — constant AO, written as a file of its own in a temporary package — registered with one
call is bakeable through the core's bake path, offered by the settings and the command line,
weighed by auto with a cost prediction, and refused by auto's registration without one."""
import importlib
import os
import sys
import textwrap

import numpy as np
import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "addon"))
from canopy_ao import cli, core  # noqa: E402
from canopy_ao.core import cost, ladder, settings  # noqa: E402
from canopy_ao.core.rungs import base as rungs  # noqa: E402
import tree_scene as ts  # noqa: E402

pytestmark = pytest.mark.skipif(not core.core_status()[0], reason="no native module")

# The toy rung's whole file, as a new rung's author writes it beside the others.
TOY = '''
"""constant: every receiver reads AO 0.5 (a toy rung for the tests)."""
import numpy as np

from canopy_ao.core.rungs.base import Rung, always


def _evaluate(rung, plan, role, tree, grass_key, p, n, tau, own, group):
    return np.full(len(p), 0.5, np.float32)


def _work(rung, plan, receivers, names=None, samples=None):
    return "shell", float(receivers)


RUNG = Rung("constant", "Constant", "AO 0.5 everywhere", evaluate=_evaluate, work=_work,
            climbs=always)
'''


@pytest.fixture
def toy(tmp_path, monkeypatch):
    pkg = tmp_path / "toy_rungs"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "constant.py").write_text(textwrap.dedent(TOY))
    monkeypatch.syspath_prepend(str(tmp_path))
    module = importlib.import_module("toy_rungs.constant")
    rungs.register(module.RUNG, before="raytrace")  # the registry line
    try:
        yield module.RUNG
    finally:
        rungs.unregister("constant")
        for name in ("toy_rungs.constant", "toy_rungs"):
            sys.modules.pop(name, None)


def _items():
    return ts.scene_items(core)


def test_the_toy_rung_is_offered(toy):
    assert "constant" in core.available_methods()
    option = next(o for o in settings.OPTIONS if o.name == "method")
    assert ("constant", "Constant", "AO 0.5 everywhere") in [i[:3] for i in option.items]
    assert option.parse("constant") == "constant"
    settings.validate(core.BakeSettings(method="constant"))
    args = cli.build_parser().parse_args(["--method", "constant"])
    assert args.method == "constant"
    assert "constant: AO 0.5 everywhere" in cli.build_parser().format_help().replace("\n", " ")


def test_the_toy_rung_bakes_through_the_core(toy):
    results, report = core.bake(_items(), core.BakeSettings(method="constant", tau=2.0))
    assert report["method"] == "constant"
    for r in results:
        assert r.ao.dtype == np.float32 and np.all(r.ao == 0.5), r.name
    # Its cost model answers (the report's per-object prediction).
    assert all(o["predicted_seconds"] > 0 for o in report["objects"].values())
    # Without the rung, the name is refused as any unknown method is.
    rungs.unregister("constant")
    with pytest.raises(core.CanopyAOError, match="method must be one of"):
        core.bake(_items(), core.BakeSettings(method="constant", tau=2.0))
    rungs.register(toy, before="raytrace")


def test_auto_weighs_the_toy_rung_with_a_cost_prediction(toy):
    s = core.BakeSettings(method="auto", samples=16, calibration_points=64,
                          calibration_samples=16, seed=1)
    plan = core.prepare(_items(), s)
    cand = plan.calibration["candidates"]
    assert "constant" in cand, sorted(cand)
    assert cand["constant"]["predicted_seconds"] > 0 and cand["constant"]["rmse"] > 0
    # Its place on the ladder: after the ray-free rung, before the exact one.
    assert list(cand).index("constant") == list(cand).index("raytrace") - 1
    got = cost.predict(plan, "constant", 1000)
    assert got["unit"] == "shell" and got["work"] >= 1000  # + the buried test's rays


def test_a_climbing_rung_without_a_cost_model_is_refused():
    lazy = rungs.Rung("lazy", "Lazy", "no cost model",
                      evaluate=lambda *a: None, climbs=rungs.always)
    with pytest.raises(ValueError, match="no cost model"):
        rungs.register(lazy)
    assert "lazy" not in rungs.names()
    with pytest.raises(ValueError, match="already"):
        rungs.register(rungs.get("sphere"))
    assert ladder.METHODS == rungs.names()  # the registry, in order, untouched


def test_a_rung_keeps_its_saved_number_wherever_it_sits(toy):
    """Blender saves the method menu's choice as a number: the toy, placed before the exact
    rung, takes the next free one, and every rung keeps the number it had (a .blend saved with
    ray-traced still opens with ray-traced)."""
    numbers = {r.name: r.number for r in rungs.ladder()}
    assert numbers["auto"] == 0 and numbers["raytrace"] == 9
    assert numbers["constant"] == 10 == max(numbers.values())
    assert len(set(numbers.values())) == len(numbers)
    option = next(o for o in settings.OPTIONS if o.name == "method")
    assert [i[3] for i in option.items] == [numbers[i[0]] for i in option.items]
    with pytest.raises(ValueError, match="number 9 is another rung's"):
        rungs.register(rungs.Rung("twin", "Twin", "", evaluate=toy.evaluate, number=9))
