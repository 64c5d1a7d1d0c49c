"""Seeded random-argument fuzz of the add-on's command line, through its documented entry point.

    /usr/bin/python3 bench/fuzz_cli.py [--cases 600] [--seed 1] [--timeout 120]

Each case is one argument list for `canopy_ao.cli.main(argv)` — the arguments after `--` in the
documented `blender -b scene.blend --addons canopy_ao --python-exit-code 1 --python-expr
"import canopy_ao.cli; canopy_ao.cli.main()" -- ...` — drawn from the documented options with
hostile values (nan, inf, 1e400, negative, huge integers, empty and odd names, unwritable
paths, unknown flags), the scene's objects given random visibility settings (disabled in
renders or viewports, hidden, no shadow rays, holdout, in a collection disabled in renders or
excluded). Many cases run in one Blender process (a worker started once, which
reopens a fresh copy of a small tree scene before every case), fed one at a time with a time
limit like bench/fuzz.py, so a hang or a crash is attributed to its case and a new Blender
takes over. A case passes when the CLI
  - exits 0 and every baked attribute holds finite values in [0, 1] (and --report is JSON), or
  - exits 2 with an argparse message, or 1 with a message, and no traceback;
and a non-finite or out-of-range number (nan, inf, 1e400, a negative or non-integer count)
must exit 2.
Anything else fails: another exit code, a traceback, an exception out of main(), NaN or
out-of-range AO, a hang, a crash; a bad number that does not exit 2 is counted as
"wrong_exit".
"""
import argparse
import contextlib
import io
import json
import os
import shutil
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import fuzz  # noqa: E402  (bench/fuzz.py: the value pools, the runner and the tally)

REPO = os.path.abspath(os.path.join(os.path.dirname(__file__), ".."))
METHODS = ["auto", "sphere", "ellipsoid", "shells", "medium", "reeves_blau", "grid", "raytrace"]
NUMBERS = ["0", "1", "0.5", "2", "-1", "nan", "inf", "-inf", "1e400", "1e-45", "1e4", "1e5",
           "abc", "", "1e-30", "1e300", "1e11"]
COUNTS = ["1", "4", "16", "0", "-1", "2.5", "65536", "99999999999", "abc"]
NAMES = ["CanopyAO", "X", "", "UVMap", "position", "a" * 80, "\u00fcml\u00e4ut", "Col/or",
         "CanopyAO_Error"]
OBJECTS = ["Leaves", "Trunk", "Ground", "NoSuchObject", "", "Leaves.001", "\u00c4rbol"]


def draw_argv(seed, case, tmp):
    """One argument list (the part after `--`), from case's own random stream."""
    g = fuzz.Gen(seed, case)
    argv = []
    if g.chance(0.5):
        argv += ["--objects"] + [g.pick(OBJECTS) for _ in range(int(g.r.integers(1, 4)))]
    elif g.chance(0.5):
        argv += ["--all"]
    argv += ["--method", g.pick(METHODS + ["bogus"]) if g.chance(0.1) else
             g.pick(METHODS[1:6] + ["grid", "raytrace"])]
    def value(good, hostile):
        return g.pick(good) if g.chance(0.6) else g.pick(hostile)
    options = [
        ("--tau", lambda: value(["auto", "1.5", "3", "0.2"], NUMBERS)),
        ("--distance", lambda: value(["5", "0.5", "0", "100"], NUMBERS)),
        ("--samples", lambda: value(["1", "4", "16"], COUNTS)),
        ("--time-budget", lambda: value(["0.5", "1", "0"], NUMBERS)),
        ("--target-error", lambda: value(["0.05", "0.01"], NUMBERS)),
        ("--threads", lambda: value(["1", "2", "0"], COUNTS + ["100000"])),
        ("--attribute", lambda: value(["CanopyAO", "AO2"], NAMES)),
        ("--aov", lambda: g.pick(["BakedAO", "AO", "", "x" * 70])),
        ("--report", lambda: g.pick([os.path.join(tmp, "r.json"), "/nonexistent/dir/r.json",
                                     tmp, "", os.path.join(tmp, "r\u00e9.json")])),
    ]
    for flag, draw in options:
        if g.chance(0.25):
            argv += [flag, draw()]
    for flag in ("--overwrite", "--no-proxies", "--wire-material", "--save"):
        if g.chance(0.15):
            argv.append(flag)
    if g.chance(0.2):
        argv += ["--mode", g.pick(["texel", "texel", "vertex", "bogus"]),
                 "--resolution", g.pick(["4", "16", "64", "0", "-5", "99999", "abc"]),
                 "--image-dir", g.pick([os.path.join(tmp, "img"), "//canopy_ao",
                                        "/nonexistent/x", os.path.join(tmp, "r.json")])]
        if g.chance(0.5):
            argv += ["--uv", g.pick(["", "UVMap", "NoSuchUV"])]
    if g.chance(0.03):
        argv += ["--check-cycles", "--cycles-samples", g.pick(["1", "2", "0", "-1"])]
    if g.chance(0.05):
        argv.insert(int(g.r.integers(len(argv) + 1)), g.pick(["--bogus", "--samples", "-x"]))
    return argv


# Visibility settings a case may give each object of the scene (docs/DESIGN.md, 'What
# occludes'): render, viewport and ray visibility, holdout, and collections disabled in renders
# or excluded from the view layer.
VISIBILITY = ["hide_render", "hide_viewport", "hide", "no_shadow", "holdout",
              "collection_hide_render", "collection_exclude"]


def draw_visibility(seed, case):
    """{object name: [settings]} for one case, from a stream of its own (the argument list's
    draws stay as they were)."""
    g = fuzz.Gen(seed + 1_000_003, case)
    out = {}
    for name in ("Leaves", "Trunk", "Ground"):
        if g.chance(0.15):
            out[name] = [g.pick(VISIBILITY) for _ in range(int(g.r.integers(1, 3)))]
    return out


def apply_visibility(settings):
    import bpy
    for name, flags in settings.items():
        ob = bpy.data.objects[name]
        for flag in flags:
            if flag in ("hide_render", "hide_viewport"):
                setattr(ob, flag, True)
            elif flag == "hide":
                try:
                    ob.hide_set(True)
                except RuntimeError:  # excluded from the view layer: Blender cannot hide it
                    pass
            elif flag == "no_shadow":
                ob.visible_shadow = False
            elif flag == "holdout":
                ob.is_holdout = True
            else:
                coll = bpy.data.collections.new(f"{name}_{flag}")
                bpy.context.scene.collection.children.link(coll)
                coll.objects.link(ob)
                if bpy.context.scene.collection.objects.get(ob.name) is not None:
                    bpy.context.scene.collection.objects.unlink(ob)  # a second one: in both
                if flag == "collection_hide_render":
                    coll.hide_render = True
                else:
                    bpy.context.view_layer.layer_collection.children[coll.name].exclude = True


# === Worker (inside Blender)
def build_scene(path):
    import bpy
    import numpy as np

    bpy.ops.wm.read_factory_settings(use_empty=True)
    rng = np.random.default_rng(0)

    def add(name, v, t, role):
        me = bpy.data.meshes.new(name)
        me.from_pydata([tuple(map(float, p)) for p in v], [], [tuple(map(int, f)) for f in t])
        me.uv_layers.new(name="UVMap")
        ob = bpy.data.objects.new(name, me)
        ob["canopy_ao_role"] = role
        bpy.context.scene.collection.objects.link(ob)

    c = rng.normal(size=(150, 1, 3)) + [0, 0, 3]
    add("Leaves", (c + 0.15 * rng.normal(size=(150, 3, 3))).reshape(-1, 3),
        np.arange(450).reshape(150, 3), "CANOPY")
    ang = np.linspace(0, 2 * np.pi, 9)[:-1]
    ring = np.stack([0.15 * np.cos(ang), 0.15 * np.sin(ang), np.zeros(8)], 1)
    tv = np.concatenate([ring, ring + [0, 0, 2.5]])
    tt = [(i, (i + 1) % 8, 8 + i) for i in range(8)] + \
         [((i + 1) % 8, 8 + (i + 1) % 8, 8 + i) for i in range(8)]
    add("Trunk", tv, tt, "TRUNK")
    g = np.linspace(-4, 4, 9)
    gv = np.array([(x, y, 0.0) for y in g for x in g])
    gt = [(j * 9 + i, j * 9 + i + 1, (j + 1) * 9 + i + 1) for j in range(8) for i in range(8)] + \
         [(j * 9 + i, (j + 1) * 9 + i + 1, (j + 1) * 9 + i) for j in range(8) for i in range(8)]
    add("Ground", gv, gt, "GROUND")
    bpy.ops.wm.save_as_mainfile(filepath=path)


# Values the README's promise ("2 on bad arguments") and the checks it implies (every numeric
# argument finite and in range) must refuse with exit 2.
BAD_VALUES = {
    **{f: {"nan", "inf", "-inf", "1e400", "-1", "abc", ""}
       for f in ("--tau", "--distance", "--time-budget", "--target-error")},
    **{f: {"0", "-1", "-5", "2.5", "99999999999", "abc", ""}
       for f in ("--samples", "--resolution", "--cycles-samples")},
    "--report": {""},  # an empty path names no file: silently writing nothing is a lie
    # Values argparse's own type takes but the native core refuses (its accepted range,
    # core.native.LIMITS): the option's range holds them, so they exit 2 too.
    "--threads": {"-1", "2.5", "100000", "99999999999", "abc", ""},
}
BAD_VALUES["--tau"] |= {"1e5", "1e300", "1e11"}
BAD_VALUES["--distance"] |= {"1e-45", "1e-30", "1e300", "1e11"}


def bad_argument(argv):
    for i, a in enumerate(argv[:-1]):
        if a in BAD_VALUES and argv[i + 1] in BAD_VALUES[a]:
            return f"{a} {argv[i + 1]}"
    return None


def check_outcome(code, err, argv, tmp):
    """status, detail for one CLI run."""
    import bpy
    import numpy as np

    bad = bad_argument(argv)
    if bad and code != 2:
        return "wrong_exit", f"{bad}: exit {code}, expected 2 (bad argument): " \
            f"{err.strip()[-200:]}"
    if "Traceback" in err:
        return "fail", f"exit {code} with a traceback: {err.strip()[-300:]}"
    if code in (1, 2):
        if not err.strip():
            return "fail", f"exit {code} without a message"
        if code == 2 and "error:" not in err:
            return "fail", f"exit 2 without an argparse message: {err.strip()[-200:]}"
        return "rejected", err.strip().splitlines()[-1][:200]
    if code != 0:
        return "fail", f"exit code {code!r}: {err.strip()[-200:]}"
    name = argv[argv.index("--attribute") + 1] if "--attribute" in argv else "CanopyAO"
    for ob in bpy.data.objects:
        attr = ob.data.attributes.get(name) if ob.type == "MESH" else None
        if attr is None or attr.data_type != "FLOAT_COLOR" or len(attr.data) == 0:
            continue
        v = np.empty(4 * len(attr.data), np.float32)
        attr.data.foreach_get("color", v)
        if not (np.all(np.isfinite(v)) and v.min() >= 0 and v.max() <= 1):
            return "fail", f"{ob.name}.{name}: AO not finite in [0, 1] ({v.min()} .. {v.max()})"
    if "--report" in argv:
        path = argv[argv.index("--report") + 1]
        try:
            with open(path, encoding="utf-8") as f:
                json.load(f)
        except (OSError, ValueError) as e:
            return "fail", f"exit 0 but the report is unreadable: {e}"
    return "ok", ""


def worker(seed):
    import bpy

    from canopy_ao import cli  # the add-on is on the path (BLENDER_USER_SCRIPTS)

    out = sys.__stdout__
    with tempfile.TemporaryDirectory() as base_dir:
        base = os.path.join(base_dir, "base.blend")
        build_scene(base)
        out.write(fuzz.Runner.PREFIX + "ready\n")
        out.flush()
        for line in sys.stdin:
            case = int(line)
            tmp = tempfile.mkdtemp(dir=base_dir)
            work = os.path.join(tmp, "scene.blend")
            shutil.copy(base, work)
            bpy.ops.wm.open_mainfile(filepath=work)
            argv = draw_argv(seed, case, tmp)
            visibility = draw_visibility(seed, case)
            apply_visibility(visibility)
            err, code = io.StringIO(), None
            try:
                with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
                    cli.main(argv)
            except SystemExit as e:
                code = e.code if isinstance(e.code, int) or e.code is None else 1
                if not isinstance(e.code, int) and e.code is not None:
                    err.write(str(e.code))
                code = 0 if code is None else code
            except BaseException as e:  # noqa: BLE001 - an exception out of main() is a finding
                status, detail = "fail", f"main() raised {type(e).__name__}: {e}"[:300]
            else:
                status, detail = "fail", "main() returned instead of exiting"
            if code is not None:
                status, detail = check_outcome(code, err.getvalue(), argv, tmp)
            name = label(argv)
            out.write(fuzz.Runner.PREFIX + json.dumps([case, name, status,
                                                      f"{detail} | argv {argv}"
                                                      f" | visibility {visibility}"]) + "\n")
            out.flush()
            shutil.rmtree(tmp, ignore_errors=True)


# === Parent
def label(argv):
    return "cli --method " + (argv[argv.index("--method") + 1] if "--method" in argv[:-1] else "?")


def cli_fuzz(cases, seed=1, timeout=120.0, first=0, verbose=False, blender="blender"):
    """Runs CLI cases [first, first + cases) in batched Blender workers; see fuzz.tally()."""
    scripts = tempfile.mkdtemp()
    try:
        os.makedirs(os.path.join(scripts, "addons"))
        os.symlink(os.path.join(REPO, "addon", "canopy_ao"),
                   os.path.join(scripts, "addons", "canopy_ao"))
        env = dict(os.environ, BLENDER_USER_SCRIPTS=scripts)
        cmd = [blender, "-b", "--factory-startup", "--addons", "canopy_ao",
               "--python-exit-code", "1", "--python", os.path.abspath(__file__), "--",
               "--worker", "--seed", str(seed)]
        runner = fuzz.Runner(cmd, timeout, env=env)
        # One row per --method; a hang or a crash is named by its argument list.
        by_name, kinds, failures = fuzz.tally(
            runner, lambda c: label(draw_argv(seed, c, tempfile.gettempdir())), cases, first,
            verbose)
        failures = [(c, n, o, d if o not in ("hang", "crash") else
                     f"{d} | argv {draw_argv(seed, c, tempfile.gettempdir())}")
                    for c, n, o, d in failures]
    finally:
        shutil.rmtree(scripts, ignore_errors=True)
    return by_name, kinds, failures


def main(argv=None):
    argv = sys.argv[sys.argv.index("--") + 1:] if argv is None and "--" in sys.argv else argv
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cases", type=int, default=600)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--timeout", type=float, default=120.0, help="seconds per CLI run")
    ap.add_argument("--case", type=int, help="run this one case (with its --seed)")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.worker:
        worker(a.seed)
        return 0
    first, cases = (a.case, 1) if a.case is not None else (0, a.cases)
    t0 = time.time()
    by_name, kinds, failures = cli_fuzz(cases, a.seed, a.timeout, first, verbose=True)
    failed = fuzz.print_table(by_name, kinds, "CLI fuzz", a.seed, time.time() - t0)
    return 1 if failed else 0


if __name__ == "__main__":
    code = main()
    if "--worker" not in sys.argv:
        sys.exit(code)
