"""One settings schema (core/settings.py): every option declared once, checked the same way by
the core, Blender and the command line (no bpy here)."""
import math
import os
import sys

import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "addon"))

from canopy_ao import cli, core  # noqa: E402
from canopy_ao.core.settings import BY_NAME, OPTIONS, BakeSettings, defaults  # noqa: E402

NUMBERS = [o for o in OPTIONS if o.kind in ("int", "float")]


def test_bake_settings_are_the_bake_options():
    fields = BakeSettings.__dataclass_fields__
    assert list(fields) == [o.name for o in OPTIONS if o.group == "bake"]
    s = BakeSettings()
    for o in OPTIONS:
        if o.group == "bake":
            assert getattr(s, o.name) == o.default
    assert s.tau is None  # None = calibrate τ, the one spelling in the core
    assert {"time_budget", "target_rmse", "samples", "method"} <= set(fields)


@pytest.mark.parametrize("option", NUMBERS, ids=lambda o: o.name)
def test_every_number_is_refused_when_not_finite_or_out_of_range(option):
    bad = [math.nan, math.inf, -math.inf]
    if option.min is not None:
        bad.append(option.min - 1 if option.kind == "int" else option.min - 1e-3)
        if option.min_exclusive:
            bad.append(option.min)
    if option.max is not None:
        bad.append(option.max + 1)
        if option.max_exclusive:
            bad.append(option.max)
    for value in bad:
        with pytest.raises(core.CanopyAOError, match=option.name):
            option.check(value)
    good = option.number_default if option.none_prop else option.default
    assert option.check(good) == good
    if option.kind == "int":
        with pytest.raises(core.CanopyAOError, match="integer"):
            option.check(1.5)


def test_prepare_refuses_bad_settings_before_any_work():
    for kw, word in ((dict(samples=0), "samples"), (dict(distance=math.nan), "distance"),
                     (dict(tau=math.inf), "tau"), (dict(method="magic"), "method"),
                     (dict(time_budget=-1.0), "time_budget")):
        with pytest.raises(core.CanopyAOError, match=word):
            core.prepare([], BakeSettings(**kw))


def test_tau_auto_is_none_on_the_command_line():
    tau = BY_NAME["tau"]
    assert tau.parse("auto") is None and tau.parse("AUTO") is None and tau.parse("2") == 2.0
    assert tau.none_prop == "calibrate_tau" and tau.none_label == "Calibrate τ"


def test_command_line_has_one_argument_per_option():
    p = cli.build_parser()
    dests = {a.dest for a in p._actions}
    for o in OPTIONS:
        assert (o.name in dests) == (o.cli is not None), o.name
    args = p.parse_args(["--tau", "auto", "--mode", "texel", "--aov", "Occl", "--no-proxies",
                         "--time-budget", "5", "--target-error", "0.1", "--shells", "8"])
    opts = cli.options_from_args(args, world_distance=12.5)
    assert opts["tau"] is None and opts["mode"] == "TEXEL" and opts["distance"] == 12.5
    assert opts["add_aov"] and opts["aov_name"] == "Occl" and not opts["show_proxies"]
    assert opts["time_budget"] == 5.0 and opts["target_rmse"] == 0.1 and opts["shells"] == 8
    assert set(opts) == set(defaults())
    # given flags win over the world's distance; defaults fill the rest
    opts = cli.options_from_args(p.parse_args(["--distance", "0"]), world_distance=12.5)
    assert opts["distance"] == 0.0 and opts["samples"] == BY_NAME["samples"].default



def test_a_flag_that_turns_an_option_off_says_so_in_its_help():
    """--no-proxies turns Show Proxies off: its help must not read as the option's own."""
    helps = {a.dest: a.help for a in cli.build_parser()._actions}
    assert helps["show_proxies"].startswith("do not show the fitted shells"), helps["show_proxies"]
    assert helps["wire_material"] == BY_NAME["wire_material"].help  # a flag turning one on

@pytest.mark.parametrize("args", [["--samples", "99999999999"], ["--tau", "inf"],
                                  ["--tau", "1e400"], ["--distance", "nan"],
                                  ["--time-budget", "nan"], ["--target-error", "nan"],
                                  ["--samples", "1.5"], ["--mode", "pixel"]])
def test_command_line_refuses_bad_numbers_with_exit_2(args, capsys):
    with pytest.raises(SystemExit) as exc:
        cli.build_parser().parse_args(args)
    err = capsys.readouterr().err
    assert exc.value.code == 2 and "must be" in err and "Traceback" not in err
