"""Where the seconds of a whole ray bake go, from Blender's start to its exit, beside Blender's
floor and Cycles' bake of the same file (issue #39 items 1 and 2).

    /usr/bin/python3.11 bench/stage_profile.py FILE.blend [--samples 16 64] \
        [--cycles-samples 32 128] [--repeats 3] [--threads 0]

FILE.blend: a real tree, e.g. a Sapling one (bench/README.md):

    blender -b --factory-startup --python-exit-code 1 --python examples/sapling_scenes.py -- \
        --scenes sap_callistemon --out-dir /tmp/real --blend /tmp/real

Runs, each ``--repeats`` times on a fresh copy of FILE (nothing is written to FILE itself), the
best wall time kept:

- Blender's floor: ``blender -b FILE --python-expr pass`` (start, load, exit);
- our bake per ``--samples`` S: the command line as a user runs it (``--method raytrace
  --samples S --save``, every visible mesh) with CANOPY_AO_PROFILE=1, whose stage lines
  (core/stage_profile.py) give Blender's start and load, the add-on's imports and
  registration, the bake's stages (gather, tracer: checks, corner tables, BVH build; rays:
  sampling, tracing, reduction as CPU seconds the workers ran, summed; write), the save, and the
  exit (the command's wall time less the process's age at its last line);
- Cycles per ``--cycles-samples`` C: a plain-bpy script (no add-on) baking AO per vertex into a
  colour attribute of every visible mesh (denoising and adaptive sampling off, the file's
  World AO distance), then saving: the bake call's seconds and the whole command's.

Each time is given as wall seconds and as CPU seconds of every thread (the command's rusage;
the bake's process_time), which hold their ratios when other jobs load the machine.

The pairs are compared in order (S with C): by default each S with 2 S, the Cycles sample count
whose error our rays matched on the real Sapling trees (issue #39: ours at 16 against Cycles at
32, 64 against 128; bench/real_rays.py measures it). Prints the stage table of the last
(best) run of each S, then the bake-only and whole-process ratios. The add-on is this
repository's (through BLENDER_USER_SCRIPTS), the module the one built into addon/canopy_ao.
The machine is shared: the load average is printed; compare ratios within one run.
"""

import argparse
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(REPO, "addon"))

from canopy_ao.core.stage_profile import parse  # noqa: E402  (bpy-free)

CLI_EXPR = "import canopy_ao.cli; canopy_ao.cli.main()"

# Cycles' vertex AO bake of every visible mesh, as a user scripts it (no add-on involved).
CYCLES_SCRIPT = r"""
import sys, time, bpy
samples = int(sys.argv[sys.argv.index("--") + 1])
t0 = time.perf_counter()
scene = bpy.context.scene
scene.render.engine = "CYCLES"
scene.cycles.device = "CPU"
scene.cycles.samples = samples
scene.cycles.use_denoising = False
scene.cycles.use_adaptive_sampling = False
layer = bpy.context.view_layer
meshes = [o for o in layer.objects if o.type == "MESH" and o.visible_get()]
for o in layer.objects:
    o.select_set(o in meshes)
layer.objects.active = meshes[0]
for o in meshes:
    ca = o.data.color_attributes
    ca.active_color = ca.get("AO") or ca.new("AO", "FLOAT_COLOR", "POINT")
t1 = time.perf_counter()
c1 = time.process_time()
bpy.ops.object.bake(type="AO", target="VERTEX_COLORS", margin=0, use_selected_to_active=False)
t2 = time.perf_counter()
c2 = time.process_time()
bpy.ops.wm.save_mainfile()
t3 = time.perf_counter()
print(f"cycles_profile: setup {t1 - t0:.4f} bake {t2 - t1:.4f} bake_cpu {c2 - c1:.4f} "
      f"save {t3 - t2:.4f}", flush=True)
"""


def run(cmd, env=None):
    """(wall seconds, CPU seconds of every thread, stdout, stderr) of cmd; raises with its
    stderr on a non-zero exit."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    p = subprocess.run(cmd, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if p.returncode != 0:
        raise SystemExit(f"stage_profile: {' '.join(cmd)} failed ({p.returncode}):\n"
                         f"{p.stderr[-3000:]}")
    return wall, cpu, p.stdout, p.stderr


def best_of(repeats, fn):
    """The result of fn() with the least wall time (its first element) over repeats calls."""
    return min((fn() for _ in range(repeats)), key=lambda r: r[0])


def main(argv=None):
    ap = argparse.ArgumentParser(prog="stage_profile.py", description=__doc__.split("\n")[0])
    ap.add_argument("blend", help="the scene (.blend; copied, never written)")
    ap.add_argument("--samples", type=int, nargs="+", default=[16, 64])
    ap.add_argument("--cycles-samples", type=int, nargs="+",
                    help="Cycles' samples matched to each --samples in order (default 2 S)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--threads", type=int, default=0, help="our --threads (0 = every core)")
    ap.add_argument("--blender", default=shutil.which("blender") or "blender")
    a = ap.parse_args(argv)
    cyc = a.cycles_samples or [2 * s for s in a.samples]
    if len(cyc) != len(a.samples):
        ap.error("--cycles-samples needs one count per --samples")
    if not os.path.isfile(a.blend):
        ap.error(f"no such file: {a.blend}")

    tmp = tempfile.mkdtemp(prefix="stage_profile_")
    try:
        scripts = os.path.join(tmp, "scripts")
        os.makedirs(os.path.join(scripts, "addons"))
        os.symlink(os.path.join(REPO, "addon", "canopy_ao"),
                   os.path.join(scripts, "addons", "canopy_ao"))
        env = dict(os.environ, BLENDER_USER_SCRIPTS=scripts, CANOPY_AO_PROFILE="1")
        cycles_py = os.path.join(tmp, "cycles_bake.py")
        with open(cycles_py, "w") as f:
            f.write(CYCLES_SCRIPT)
        work = os.path.join(tmp, "scene.blend")

        def fresh():
            shutil.copyfile(a.blend, work)
            return work

        def floor():
            return run([a.blender, "-b", fresh(), "--python-expr", "pass"])[:2]

        def ours(s):
            wall, cpu, out, err = run([a.blender, "-b", fresh(), "--python-exit-code", "1",
                                  "--python-expr", CLI_EXPR, "--", "--method", "raytrace",
                                  "--samples", str(s), "--threads", str(a.threads), "--save"],
                                 env)
            return wall, cpu, parse(err)

        def cycles(c):
            wall, cpu, out, _ = run([a.blender, "-b", fresh(), "--python-exit-code", "1",
                                     "--python", cycles_py, "--", str(c)])
            line = next(ln for ln in out.splitlines() if ln.startswith("cycles_profile:"))
            w = line.split()
            return wall, cpu, {w[i]: float(w[i + 1]) for i in range(1, len(w), 2)}

        print(f"stage_profile: {a.blend}, load average {os.getloadavg()[0]:.2f}, best of "
              f"{a.repeats}", flush=True)
        t_floor, cpu_floor = best_of(a.repeats, floor)
        rows = []
        for s, c in zip(a.samples, cyc):
            w_ours, c_ours, st = best_of(a.repeats, lambda: ours(s))
            w_cyc, c_cyc, cs = best_of(a.repeats, lambda: cycles(c))
            rows.append((s, c, w_ours, c_ours, st, w_cyc, c_cyc, cs))

        for s, c, w_ours, c_ours, st, w_cyc, c_cyc, cs in rows:
            print(f"\nours, rays at {s} samples: whole command {w_ours:.3f} s, "
                  f"{c_ours:.3f} CPU s")
            print(f"  {'stage':<48} {'seconds':>8}")
            for k, v in st.items():
                if k not in ("process age", "process CPU"):
                    print(f"  {k:<48} {v:8.4f}")
            if "process age" in st:
                print(f"  {'exit (wall less the process age at the end)':<48} "
                      f"{w_ours - st['process age']:8.4f}")
        print(f"\nBlender's floor (start, load, exit): {t_floor:.3f} s, {cpu_floor:.3f} CPU s")
        print("\nSeconds (wall, then CPU of every thread: steadier on a shared machine) and "
              "Cycles / ours")
        print(f"{'ours S':>6} {'Cycles C':>8} | {'bake ours':>9} {'Cycles':>7} {'ratio':>6} | "
              f"{'CPU ours':>8} {'Cycles':>7} {'ratio':>6} | {'whole ours':>10} {'Cycles':>7} "
              f"{'ratio':>6} | {'CPU ours':>8} {'Cycles':>7} {'ratio':>6} | "
              f"{'above the floor: ours':>21} {'Cycles':>7}")
        for s, c, w_ours, c_ours, st, w_cyc, c_cyc, cs in rows:
            b = st.get("bake: whole (job.run_bake)", float("nan"))
            bc = st.get("bake: whole, CPU of every thread", float("nan"))
            print(f"{s:6d} {c:8d} | {b:9.3f} {cs['bake']:7.3f} {cs['bake'] / b:6.1f} | "
                  f"{bc:8.3f} {cs['bake_cpu']:7.3f} {cs['bake_cpu'] / bc:6.1f} | "
                  f"{w_ours:10.3f} {w_cyc:7.3f} {w_cyc / w_ours:6.2f} | "
                  f"{c_ours:8.3f} {c_cyc:7.3f} {c_cyc / c_ours:6.2f} | "
                  f"{w_ours - t_floor:21.3f} {w_cyc - t_floor:7.3f}")
        print(f"\nload average now {os.getloadavg()[0]:.2f}")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
