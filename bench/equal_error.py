"""Equal error against Cycles on the real-tree scenes: our rungs, the Cycles samples that match them, both timed in one run.

    /usr/bin/python3 bench/equal_error.py [--scenes NAME ...] [--samples 16 64 256]
        [--repeats 3] [--whole-repeats 2] [--no-whole] [--md OUT.md] [--quick]

Scenes: the Sapling exports in bench/out/real (examples/sapling_scenes.py --quick) that have
a saved .blend (``--blend bench/out/real/blend``), a Cycles reference at 1024 samples with
Cycles' seed 1 (``--bake-cycles 1024 --cycles-seed 1``) and a seed-0 ladder of Cycles bakes at
fewer samples (``--bake-cycles 4 8 16 32 64 128 256``); scripts/bench.sh --equal-error makes
what is missing.

1. **Error.** MAE over every vertex against the 1024-sample reference (independent noise: the
   ladder is seed 0's) of our rays at 16 / 64 / 256 samples and of the ray-free
   ``regression`` rung, each baked by the add-on's engine (``core.bake``, what the operator
   runs), and of every Cycles bake of the ladder.
2. **Equal error.** For each of ours, the Cycles sample count S* whose MAE equals it: the
   ladder interpolated in log-log; beyond the ladder, its MAE² = a/S + b fitted on the
   ladder's three counts nearest (noise a/S plus the reference's and any systematic part b),
   marked ≈; "–" where ours is
   below the fitted floor b (no Cycles count reaches it).
3. **Bake only.** In one Blender process with the scene's .blend (bench/bake_timer.py), Cycles'
   bake at each S* and our bake of each rung through the add-on (read, bake, write), timed
   round after round, the order rotated (harness.interleave): min seconds and ratio ours /
   Cycles. The MAE of that Cycles bake at S* is printed beside it (a check of the
   interpolation).
4. **Whole process.** The same pairs as separate Blender processes, each timed from launch
   to exit: Blender started, the .blend loaded, baked, the AO written into a colour attribute
   and the .blend saved (ours: the CLI, ``--all --method M [--samples S] --no-proxies --save``;
   Cycles: bench/bake_timer.py ``--bake-cycles S* --write --save``), alternated round after round,
   each on a fresh copy of the file.

The machine is shared: read the ratios (each measured within this one run), not the seconds.
"""
from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np

import harness

REFERENCE = 1024
REFERENCE_SEED = 1
BLEND = os.path.join(harness.REAL, "blend")


def blend_path(scene):
    return os.path.join(BLEND, f"{scene}_quick.blend")


def scenes_ready():
    """Exports with a .blend, the seed-1 reference and at least two ladder bakes below it."""
    import real_scenes as rs
    out = []
    for name in harness.real_names(cycles=REFERENCE, seed=REFERENCE_SEED):
        if not os.path.exists(blend_path(name)):
            continue
        sc = rs.load(name)
        if len(rs.cycles_runs(sc)) >= 2:
            out.append(name)
    return out


def mae(a, b):
    return float(np.mean(np.abs(np.asarray(a, np.float64) - np.asarray(b, np.float64))))


def ours_ao(sc, rung, samples):
    """AO over every vertex (sc.V's order) of the add-on's engine bake of the scene."""
    from canopy_ao import core
    settings = dict(method=rung, distance=sc.distance)
    if samples:
        settings["samples"] = samples
    res, _rep = core.bake(sc.engine_items(), core.BakeSettings(**settings))
    return np.concatenate([r.ao for r in res]).astype(np.float32)


def equal_samples(ladder, target):
    """(S*, extrapolated) for a target MAE on a Cycles ladder {samples: MAE}; S* None when the
    target is below the fitted floor. Inside the ladder: log-log interpolation; outside: the
    fit MAE² = a/S + b (least squares on the ladder's three nearest counts)."""
    s = np.array(sorted(ladder), float)
    m = np.array([ladder[int(k)] for k in s])
    for i in range(len(s) - 1):
        hi, lo = m[i], m[i + 1]
        if lo <= target <= hi:
            t = (math.log(target) - math.log(hi)) / (math.log(lo) - math.log(hi))
            return math.exp(math.log(s[i]) + t * (math.log(s[i + 1]) - math.log(s[i]))), False
    end = slice(0, 3) if target > m[0] else slice(-3, None)  # the nearest end of the ladder
    a, b = np.linalg.lstsq(np.stack([1.0 / s[end], np.ones_like(s[end])], 1), m[end] ** 2,
                           rcond=None)[0]
    if target ** 2 <= b or a <= 0:
        return None, True
    return a / (target ** 2 - b), True


def accuracy(scene, samples):
    """Per scene: the ladder's MAEs, ours (rung label -> MAE) and S* for each."""
    import real_scenes as rs
    sc = rs.load(scene)
    ref = rs.cycles_ao(sc, REFERENCE, REFERENCE_SEED)
    ladder = {s: mae(ao, ref) for s, (ao, _t) in rs.cycles_runs(sc).items()}  # seed 0
    rows = []
    for label, rung, s in [(f"rays {s}", "raytrace", s) for s in samples] + [
            ("regression", "regression", 0)]:
        e = mae(ours_ao(sc, rung, s), ref)
        star, extra = equal_samples(ladder, e)
        rows.append(dict(label=label, rung=rung, samples=s, mae=e,
                         star=None if star is None else max(1, int(math.ceil(star))),
                         extrapolated=extra))
    return sc, ref, ladder, rows


def user_scripts():
    """A throw-away BLENDER_USER_SCRIPTS with addons/canopy_ao linked to this checkout."""
    d = tempfile.mkdtemp(prefix="canopy_bench_")
    os.makedirs(os.path.join(d, "addons"))
    os.symlink(os.path.join(harness.ADDON, "canopy_ao"), os.path.join(d, "addons", "canopy_ao"))
    return d


def blender(args, env, check=True):
    """Run Blender headless; (seconds from launch to exit, stdout)."""
    t0 = time.perf_counter()
    p = subprocess.run(["blender", "-b", "--factory-startup", *args], env=env,
                       capture_output=True, text=True)
    dt = time.perf_counter() - t0
    if check and p.returncode:
        raise RuntimeError(f"blender {' '.join(args)} exited {p.returncode}:\n"
                           f"{p.stderr[-2000:]}")
    return dt, p.stdout


def spec(row):
    return f"{row['rung']}:{row['samples']}" if row["samples"] else row["rung"]


def bake_only(scene, rows, repeats, env, work):
    """{contender: min seconds} from one bench/bake_timer.py run on the scene's .blend, and
    {S*: Cycles' AO there}; also saves the .blend with roles set, for the whole processes."""
    stars = sorted({r["star"] for r in rows if r["star"]})
    out_json, out_ao = os.path.join(work, "times.json"), os.path.join(work, "ao.npz")
    args = [blend_path(scene), "--python-exit-code", "1", "--python",
            os.path.join(harness.HERE, "bake_timer.py"), "--",
            "--roles", os.path.join(harness.REAL, f"{scene}_quick.npz"),
            "--save-roles", os.path.join(work, "roles.blend"),
            "--repeats", str(repeats), "--json", out_json, "--ao", out_ao,
            "--ours", *[spec(r) for r in rows]]
    if stars:
        args += ["--bake-cycles", *map(str, stars)]
    blender(args, env)
    with open(out_json) as fh:
        got = json.load(fh)
    times = {k: min(v) for k, v in got["seconds"].items()}
    with np.load(out_ao) as z:
        files = list(z.files)
        cyc = {s: {k.split("/", 1)[1]: z[k] for k in files if k.startswith(f"cycles:{s}/")}
               for s in stars}
    return times, cyc, got["load"]


def whole_process(rows, repeats, env, work):
    """{contender: min seconds from launch to exit} over ``repeats`` alternating rounds."""
    roles = os.path.join(work, "roles.blend")
    cli = "import canopy_ao.cli; canopy_ao.cli.main()"
    runs = {}
    for r in rows:
        cmd = ["--addons", "canopy_ao", "--python-exit-code", "1", "--python-expr", cli, "--",
               "--all", "--method", r["rung"], "--no-proxies", "--save"]
        if r["samples"]:
            cmd += ["--samples", str(r["samples"])]
        runs[spec(r)] = cmd
    for s in sorted({r["star"] for r in rows if r["star"]}):
        runs[f"cycles:{s}"] = ["--python-exit-code", "1", "--python",
                               os.path.join(harness.HERE, "bake_timer.py"), "--",
                               "--bake-cycles", str(s), "--write", "--save"]
    copy = os.path.join(work, "run.blend")

    def launch(args):
        def go():
            shutil.copyfile(roles, copy)  # a fresh file each time (the copy is in the time:
            return blender([copy, *args], env)  # a few ms against a Blender start)
        return go

    timing = harness.interleave({k: launch(v) for k, v in runs.items()}, repeats)
    return {k: t.min for k, t in timing.items()}


def table(results, whole):
    head = ["scene", "ours", "our MAE", "Cycles samples at that MAE", "Cycles MAE there (timed bake)",
            "bake only: ours / Cycles", "ratio"]
    if whole:
        head += ["whole process: ours / Cycles", "ratio"]
    out = []
    for scene, rows, bo, wp, cyc_mae in results:
        for r in rows:
            k, s = spec(r), r["star"]
            star = ("–" if s is None else f"{'≈' if r['extrapolated'] else ''}{s}")
            line = [scene, r["label"], f"{r['mae']:.4f}", star]
            if s is None:
                line += ["–", f"{harness.fmt_seconds(bo[k])} / –", "–"]
                line += ["–", "–"] if whole else []
            else:
                c = f"cycles:{s}"
                line += [f"{cyc_mae[s]:.4f}",
                         f"{harness.fmt_seconds(bo[k])} / {harness.fmt_seconds(bo[c])}",
                         f"{harness.ratio(bo[k], bo[c]):.2f}×"]
                if whole:
                    line += [f"{harness.fmt_seconds(wp[k])} / {harness.fmt_seconds(wp[c])}",
                             f"{harness.ratio(wp[k], wp[c]):.2f}×"]
            out.append(line)
    return harness.markdown(head, out)


def main(argv=None):
    ap = harness.parser(__doc__, prog="equal_error.py", quick=True, scenes=[], repeats=3)
    ap.add_argument("--samples", type=int, nargs="*", default=[16, 64, 256])
    ap.add_argument("--whole-repeats", type=int, default=2,
                    help="rounds of whole-process runs (default: %(default)s)")
    ap.add_argument("--no-whole", action="store_true", help="bake-only table alone")
    ap.add_argument("--md", help="also write the table to this markdown file")
    a = ap.parse_args(argv)
    if a.quick:
        a.repeats, a.whole_repeats = min(a.repeats, 2), 1
    ready = scenes_ready()
    picked = [s for s in (a.scenes or ready) if s in ready]
    if not picked:
        ap.error(f"no scene ready ({' '.join(a.scenes or []) or 'none found'}; ready: "
                 f"{' '.join(ready) or 'none'}): scripts/bench.sh --equal-error makes them")
    from canopy_ao import _core  # noqa: F401  (fail here, not in Blender, without the module)
    scripts_dir = user_scripts()
    try:
        return run(a, picked, dict(os.environ, BLENDER_USER_SCRIPTS=scripts_dir))
    finally:
        shutil.rmtree(scripts_dir, ignore_errors=True)


def run(a, picked, env):
    """Every picked scene's rows, timed; prints the table (and writes --md)."""
    results, notes = [], []
    harness.log(f"equal_error: {' '.join(picked)}; {harness.load_note()}")
    for scene in picked:
        with tempfile.TemporaryDirectory(prefix="canopy_ee_") as work:
            sc, ref, ladder, rows = accuracy(scene, a.samples)
            harness.log(f"equal_error: {scene}: {sc.n_vertices} vertices; Cycles ladder MAE "
                        + ", ".join(f"{s}: {m:.4f}" for s, m in sorted(ladder.items())))
            bo, cyc, load = bake_only(scene, rows, a.repeats, env, work)
            cyc_mae = {s: mae(np.concatenate([ao[n] for n in sc.names]), ref)
                       for s, ao in cyc.items()}
            harness.log(f"equal_error: {scene}: bake only timed ({load})")
            wp = {} if a.no_whole else whole_process(rows, a.whole_repeats, env, work)
            notes.append(f"{scene}: {sc.n_vertices:,} vertices; bake only, best of {a.repeats} "
                         f"rounds, {load}" + ("" if a.no_whole else
                                              f"; whole process, best of {a.whole_repeats}, "
                                              f"{harness.load_note()} after"))
            results.append((scene, rows, bo, wp, cyc_mae))
    text = table(results, not a.no_whole) + "\n\n" + "\n".join(f"- {n}" for n in notes)
    print(text, flush=True)
    if a.md:
        with open(a.md, "w") as fh:
            fh.write(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
