"""The benchmark harness (bench/harness.py) and the studies built on it: every study that runs
without Blender answers --help (so it imports and parses), the Blender ones compile,
scripts/bench.sh --help works, and the harness's caches, timing, tables and the equal-error
interpolation give known answers on tiny inputs."""
import glob
import math
import os
import py_compile
import re
import subprocess
import sys

import numpy as np
import pytest

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BENCH = os.path.join(REPO, "bench")
sys.path.insert(0, BENCH)

import harness  # noqa: E402

SCRIPTS = sorted(glob.glob(os.path.join(BENCH, "*.py")) + glob.glob(os.path.join(BENCH, "probes", "*.py")))
LIBRARIES = {"harness.py", "real_scenes.py"}  # imported by studies, no command line of their own


def needs_blender(path):
    """A script run inside Blender: its docstring's command is `blender -b ... --python` it."""
    with open(path, encoding="utf-8") as f:
        head = re.sub(r"\\+\n\s*", " ", f.read(3000))
    return bool(re.search(r"blender -b[^\n]*--python\S* \S*" + re.escape(os.path.basename(path)),
                          head))


def test_the_scripts_are_found():
    names = {os.path.basename(p) for p in SCRIPTS}
    assert {"harness.py", "equal_error.py", "bake_timer.py", "accuracy.py", "forest.py",
            "live_speed.py"} <= names
    assert any(os.sep + "probes" + os.sep in p for p in SCRIPTS)


def test_every_script_compiles(tmp_path):
    for p in SCRIPTS:
        py_compile.compile(p, cfile=str(tmp_path / "x.pyc"), doraise=True)


HELP_DRIVER = r"""
import contextlib, io, json, os, runpy, sys
out = {}
for path in sys.argv[1:]:
    buf = io.StringIO()
    sys.argv = [path, "--help"]
    sys.path.insert(0, os.path.dirname(path))  # as `python path` puts the script's folder first
    try:
        with contextlib.redirect_stdout(buf):
            runpy.run_path(path, run_name="__main__")
        code = "returned without exiting"
    except SystemExit as e:
        code = e.code or 0
    except BaseException as e:  # noqa: BLE001
        code = f"{type(e).__name__}: {e}"
    out[path] = [code, buf.getvalue()[:2000]]
sys.stdout = sys.__stdout__
print(json.dumps(out))
"""


def test_every_study_without_blender_answers_help():
    """Each as `python bench/x.py --help` would run it, in one interpreter (the imports are
    most of each one's time, and the machine is shared): exits 0 with its usage."""
    import json
    plain = [p for p in SCRIPTS if not needs_blender(p) and os.path.basename(p) not in LIBRARIES]
    assert len(plain) >= 15, plain
    proc = subprocess.run([sys.executable, "-c", HELP_DRIVER, *plain], capture_output=True,
                          text=True, cwd=REPO, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    got = json.loads(proc.stdout.strip().splitlines()[-1])
    failed = [f"{os.path.relpath(p, REPO)}: {code}" for p, (code, text) in got.items()
              if code != 0 or "usage:" not in text]
    assert sorted(got) == sorted(plain)
    assert not failed, "\n".join(failed)


def test_bench_sh_help():
    out = subprocess.run(["bash", os.path.join(REPO, "scripts", "bench.sh"), "--help"],
                         capture_output=True, text=True, timeout=30)
    assert out.returncode == 0, out.stderr
    assert "Usage: scripts/bench.sh" in out.stdout and "--quick" in out.stdout
    bad = subprocess.run(["bash", os.path.join(REPO, "scripts", "bench.sh"), "--nonsense"],
                         capture_output=True, text=True, timeout=30)
    assert bad.returncode == 2 and "unknown option --nonsense" in bad.stderr


def test_paths_are_set_once():
    """setup_paths puts each folder on sys.path and adds nothing when it is already there
    (other tests' imports may have put a folder there before: counted, not assumed)."""
    harness.setup_paths()
    before = [sys.path.count(p) for p in (harness.ADDON, harness.EXAMPLES, harness.HERE)]
    harness.setup_paths()
    after = [sys.path.count(p) for p in (harness.ADDON, harness.EXAMPLES, harness.HERE)]
    assert after == before and min(after) >= 1, (before, after)


def test_reference_cache_on_a_tiny_scene(tmp_path):
    """A tiny synthetic scene traced once, cached, read back only under the same key."""
    _core = pytest.importorskip("canopy_ao._core")
    import canopy_scenes
    scene = harness.synthetic("ideal_sphere", n_tris=60)
    V, T, _ = scene.merged()
    N = canopy_scenes.vertex_normals(V, T)
    geometry = canopy_scenes.geometry_hash(scene)
    tracer = _core.RayTracer(V, T)
    ao, dt = harness.timed(lambda: np.asarray(tracer.ao(V, N, samples=16, distance=5.0),
                                              np.float32))
    assert ao.shape == (len(V),) and 0.0 <= ao.min() and ao.max() <= 1.0 and dt > 0
    path = str(tmp_path / "cache" / "embree_tiny_16.npz")
    harness.save_cached(path, dict(ao=ao, seconds=dt), geometry=geometry, distance=5.0,
                        tracer="t1")
    got = harness.load_cached(path, geometry=geometry, distance=5.0, tracer="t1")
    assert got is not None and np.array_equal(got["ao"], ao)
    assert harness.load_cached(path, geometry=geometry, distance=5.0000001, tracer="t1") is None
    assert harness.load_cached(path, geometry="other", distance=5.0, tracer="t1") is None
    assert harness.load_cached(path, geometry=geometry, distance=5.0, tracer="t2") is None
    assert harness.load_cached(path, geometry=geometry, missing_key=1) is None
    assert harness.load_cached(str(tmp_path / "absent.npz")) is None


def test_interleave_rotates_and_keeps_every_round():
    order = []
    runs = harness.interleave({n: (lambda n=n: order.append(n) or n) for n in "abc"}, repeats=3)
    assert order == list("abc") + list("bca") + list("cab")
    for n, t in runs.items():
        assert len(t.seconds) == 3 and t.result == n
        assert t.min <= t.median and t.min >= 0
    assert math.isnan(harness.Timing("x").min)
    assert harness.ratio(1.0, 4.0) == 0.25 and math.isnan(harness.ratio(1.0, 0.0))


def test_timed_stops_after_a_long_run():
    calls = []
    res, best = harness.timed(lambda: calls.append(1) or len(calls), repeats=5, stop_after=0.0)
    assert calls == [1] and res == 1 and best >= 0
    res, _ = harness.timed(lambda: calls.append(1) or len(calls), repeats=3)
    assert res == 4


def test_markdown_table():
    text = harness.markdown(["a", "b"], [[1, "x"], [2.5, "y"]], align="lr")
    assert text.splitlines() == ["| a | b |", "|---|---:|", "| 1 | x |", "| 2.5 | y |"]
    assert harness.fmt_seconds(0.01234) == "0.012 s" and harness.fmt_seconds(1234) == "1234 s"
    assert harness.fmt_seconds(float("nan")) == "–"


def test_equal_samples_known_curves():
    import equal_error
    # MAE = c / sqrt(S): log-log interpolation is exact inside the ladder.
    ladder = {s: 0.2 / math.sqrt(s) for s in (4, 16, 64, 256)}
    star, extra = equal_error.equal_samples(ladder, 0.2 / math.sqrt(32))
    assert not extra and star == pytest.approx(32, rel=1e-9)
    # MAE² = a/S + b beyond the ladder: the fit on its end is exact.
    a, b = 0.04, 1e-6
    ladder = {s: math.sqrt(a / s + b) for s in (16, 64, 128, 256)}
    star, extra = equal_error.equal_samples(ladder, math.sqrt(a / 1000 + b))
    assert extra and star == pytest.approx(1000, rel=1e-6)
    star, extra = equal_error.equal_samples(ladder, math.sqrt(a / 2 + b))
    assert extra and star == pytest.approx(2, rel=1e-6)
    assert equal_error.equal_samples(ladder, 0.5 * math.sqrt(b)) == (None, True)


def test_real_names_filters_by_cycles_bake(tmp_path, monkeypatch):
    monkeypatch.setattr(harness, "REAL", str(tmp_path))
    assert harness.real_names() == []
    for f in ("sap_a_quick.npz", "sap_b_quick.npz", "sap_a_quick_cycles_1024_seed1.npz",
              "sap_b_quick_cycles_1024.npz", "sap_a_quick_embree_1024.npz", "sap_c.npz"):
        (tmp_path / f).write_bytes(b"")
    assert harness.real_names() == ["sap_a", "sap_b"]
    assert harness.real_names(cycles=1024, seed=1) == ["sap_a"]
    assert harness.real_names(cycles=1024) == ["sap_b"]
    assert harness.real_names(quick=False) == ["sap_c"]


def test_foliage_cycles_opaque_texels_lie_inside_the_leaf():
    """bench/foliage_cycles.py compares card texels only where the whole texel is leaf: every
    such texel's centre maps (through its tile's inset) to a card point inside the lens, the
    one-texel gutter is never compared, every tile of the atlas has the same mask, and most of
    the lens's texels are kept (only its rim is dropped)."""
    import foliage_cycles
    import foliage_scenes
    tile, g = 32, 2
    ok = foliage_cycles.opaque_texels(g * tile, g, tile)
    assert ok.shape == (g * tile, g * tile)
    one = ok[:tile, :tile]
    for r in range(g):
        for c in range(g):
            assert np.array_equal(ok[r * tile:(r + 1) * tile, c * tile:(c + 1) * tile], one)
    assert not one[0].any() and not one[-1].any() and not one[:, 0].any() and not one[:, -1].any()
    inset = 1.0 / tile
    local = ((np.arange(tile) + 0.5) / tile - inset) / (1 - 2 * inset) * 2 - 1  # card x = 2u - 1
    x, y = np.meshgrid(local, local)
    lens = (x / foliage_scenes.LEAF_WIDTH) ** 2 + y ** 2 < 1.0
    assert not (one & ~lens).any()
    assert 0.6 * lens.sum() < one.sum() < lens.sum()


def test_chart_foliage_draws_every_scene_from_the_csv(tmp_path):
    """bench/chart_foliage.py reads bench/foliage.py's CSV (empty and "nan" cells as NaN) and
    draws one panel per scene into a PNG."""
    pytest.importorskip("matplotlib")
    import chart_foliage
    path = tmp_path / "f.csv"
    lines = ["scene,method,role,mae_all,mae_unburied,bias,seconds"]
    for scene in ("a", "b"):
        lines += [f"{scene},constant,all,0.2,0.19,0.0,nan",
                  f"{scene},grid,all,0.1,0.09,0.01,0.5", f"{scene},grid,TRUNK,0.1,,0.01,0.5",
                  f"{scene},rays 16,all,0.02,0.02,0.0,0.2",
                  f"{scene},rays 64,all,0.01,0.01,0.0,0.6"]
    path.write_text("\n".join(lines) + "\n")
    rows = chart_foliage.load(str(path))
    assert len(rows) == 10 and math.isnan(rows[0]["seconds"]) and math.isnan(rows[2]["mae_unburied"])
    png = tmp_path / "f.png"
    chart_foliage.draw(rows, str(png))
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
