"""Files per minute of the batch bake (python3 -m canopy_ao.batch) with 1, 2 and 4 bakes at once.

    /usr/bin/python3 bench/batch_throughput.py                 # local back end, 8 quick trees
    /usr/bin/python3 bench/batch_throughput.py --slurm         # also through a one-node Slurm
    /usr/bin/python3 bench/batch_throughput.py --files 12 --per-task 1,3 --bake "--method auto"

Builds N variants of the quick round tree (examples/make_batch_scenes.py; cached in
bench/out/batch_scenes) and bakes all of them for each concurrency into a fresh output folder,
with --threads = cores / concurrency (at least 1). Prints wall time, files per minute, and the
mean bake time per file from the summary (the rest of a file's share is Blender's start-up,
opening and saving). The figures depend on the machine and its load: run it on the farm's own
nodes to size a batch.
"""
import argparse
import csv
import os
import shlex
import shutil
import subprocess
import sys
import tempfile
import time

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(REPO, "tests", "python"))


def make_scenes(n, folder, quick_leaves):
    have = sorted(f for f in os.listdir(folder) if f.endswith(".blend")) \
        if os.path.isdir(folder) else []
    if len(have) >= n:
        return [os.path.join(folder, f) for f in have[:n]]
    args = ["--out", folder, "--count", str(n)]
    args += ["--leaves", str(quick_leaves)] if quick_leaves else ["--quick"]
    subprocess.run(["blender", "-b", "--factory-startup", "--python",
                    os.path.join(REPO, "examples", "make_batch_scenes.py"), "--", *args],
                   check=True, capture_output=True)
    return make_scenes(n, folder, quick_leaves)


def run_batch(env, inputs, out, jobs, per_task, bake, backend="local"):
    threads = max(1, (os.cpu_count() or 1) // jobs)
    cmd = [sys.executable, "-m", "canopy_ao.batch", *inputs, "--output", out, "-j", str(jobs),
           "--files-per-task", str(per_task), "--threads", str(threads), "--backend", backend,
           "--poll", "0.5", "--", *bake]
    t0 = time.perf_counter()
    r = subprocess.run(cmd, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if r.returncode != 0:
        raise SystemExit(f"batch failed ({r.returncode}):\n{r.stdout}\n{r.stderr}")
    with open(os.path.join(out, "summary.csv"), newline="") as f:
        rows = list(csv.DictReader(f))
    bake_s = sum(float(row["bake_seconds"] or 0) for row in rows) / max(1, len(rows))
    return wall, threads, bake_s


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--files", type=int, default=8)
    ap.add_argument("--jobs", default="1,2,4")
    ap.add_argument("--per-task", default="1", help="files per Blender process, e.g. 1,4")
    ap.add_argument("--bake", default="--method sphere", help="bake options (one string)")
    ap.add_argument("--leaves", type=int, default=0, help="leaves per tree (default: --quick)")
    ap.add_argument("--slurm", action="store_true", help="also through a one-node Slurm")
    a = ap.parse_args()
    folder = os.path.join(REPO, "bench", "out", "batch_scenes" + (f"_{a.leaves}" if a.leaves
                                                                  else ""))
    inputs = make_scenes(a.files, folder, a.leaves)
    scripts = tempfile.mkdtemp(prefix="canopy_ao_bench_scripts_")
    os.makedirs(os.path.join(scripts, "addons"))
    os.symlink(os.path.join(REPO, "addon", "canopy_ao"),
               os.path.join(scripts, "addons", "canopy_ao"))
    env = dict(os.environ, BLENDER_USER_SCRIPTS=scripts, PYTHONPATH=os.path.join(REPO, "addon"))
    bake = shlex.split(a.bake)
    backends = [("local", None)]
    cluster = None
    if a.slurm:
        import slurm_cluster
        if slurm_cluster.missing():
            raise SystemExit(f"Slurm is not installed: {', '.join(slurm_cluster.missing())}")
        cluster = slurm_cluster.SlurmCluster().__enter__()
        backends.append(("slurm", cluster.env["SLURM_CONF"]))
    print(f"{len(inputs)} files ({os.path.basename(folder)}), bake options: {a.bake}; "
          f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}")
    print(f"{'backend':8} {'at once':>7} {'per task':>8} {'threads':>7} {'wall s':>7} "
          f"{'files/min':>9} {'bake s/file':>11}")
    try:
        for backend, conf in backends:
            benv = dict(env, SLURM_CONF=conf) if conf else env
            for per_task in (int(x) for x in a.per_task.split(",")):
                for jobs in (int(x) for x in a.jobs.split(",")):
                    out = tempfile.mkdtemp(prefix="canopy_ao_bench_batch_")
                    try:
                        wall, threads, bake_s = run_batch(benv, inputs, out, jobs, per_task,
                                                          bake, backend)
                    finally:
                        shutil.rmtree(out, ignore_errors=True)
                    print(f"{backend:8} {jobs:7d} {per_task:8d} {threads:7d} {wall:7.1f} "
                          f"{60 * len(inputs) / wall:9.1f} {bake_s:11.2f}", flush=True)
    finally:
        if cluster is not None:
            cluster.stop()
        shutil.rmtree(scripts, ignore_errors=True)


if __name__ == "__main__":
    main()
