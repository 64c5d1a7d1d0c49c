"""The command line's stage profile (core/stage_profile.py): its lines parse back, and the
process's age is a real duration."""
import io
import time

from canopy_ao.core import stage_profile


def test_lines_parse_back_in_order_and_sum_repeats():
    log = stage_profile.StageLog()
    log.add("Blender start, file load (to the script)", 1.25)
    log.add("bake: evaluate", 0.5)
    log.add("bake: evaluate", 0.25)
    log.add_report({"stage_seconds": {"write": 0.125}, "timings": {"tracer": 0.0625}})
    log.add_native({"rays: tracing (CPU)": (2.0, 7)})
    out = io.StringIO()
    log.print(out)
    got = stage_profile.parse("noise\n" + out.getvalue() + "canopy_ao: profile: bad x s\n")
    assert list(got)[:5] == ["Blender start, file load (to the script)", "bake: evaluate",
                             "bake: write", "plan: tracer", "native: rays: tracing (CPU)"]
    assert got["bake: evaluate"] == 0.75
    assert got["native: rays: tracing (CPU)"] == 2.0
    assert "bad" not in got


def test_timer_adds_its_block():
    log = stage_profile.StageLog()
    with log.timer("sleep"):
        time.sleep(0.02)
    assert 0.015 < log.seconds["sleep"] < 1.0


def test_process_age_is_positive_and_grows():
    a = stage_profile.process_age()
    if a is None:  # not Linux
        return
    assert a > 0
    time.sleep(0.05)
    assert stage_profile.process_age() >= a


def test_enabled_by_the_environment(monkeypatch):
    monkeypatch.delenv(stage_profile.ENV, raising=False)
    assert not stage_profile.enabled()
    monkeypatch.setenv(stage_profile.ENV, "0")
    assert not stage_profile.enabled()
    monkeypatch.setenv(stage_profile.ENV, "1")
    assert stage_profile.enabled()
