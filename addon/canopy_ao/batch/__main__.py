"""Batch bakes of many .blend files: ``python3 -m canopy_ao.batch --help``.

    PYTHONPATH=addon python3 -m canopy_ao.batch scenes/ --output baked/ -j 2 -- --method sphere
    PYTHONPATH=addon python3 -m canopy_ao.batch --manifest files.txt --output baked/ \\
        --backend slurm -j 8 --files-per-task 4 -- --method auto

Everything after ``--`` is passed to the bake command line (canopy_ao.cli) unchanged. Writes
each baked copy and its JSON report under --output, then --output/summary.csv. Exit code 0 when
every file is baked or already up to date, 1 when any failed (after one retry), 2 on bad
arguments.
"""

import argparse
import math
import os
import shlex
import signal
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor, wait

from . import plan, runner


def build_parser():
    p = argparse.ArgumentParser(
        prog="python3 -m canopy_ao.batch",
        description="Bake Canopy AO into many .blend files, locally or on Slurm.",
        epilog="Bake options go after '--' (see the command line's --help); --save, --report "
               "and --threads are set per file by the batch.")
    p.add_argument("inputs", nargs="*", metavar="PATH",
                   help=".blend files, folders (their *.blend) or globs ('**' for any depth)")
    p.add_argument("--manifest", action="append", default=[], metavar="FILE",
                   help="a text file, one path or glob per line ('#' comments)")
    p.add_argument("--output", required=True, metavar="DIR",
                   help="where the baked copies (same layout as the inputs), reports and "
                        "summary.csv go")
    p.add_argument("--in-place", action="store_true",
                   help="save the bake into the source files themselves (reports still go "
                        "to --output)")
    p.add_argument("--backend", choices=("local", "parallel", "slurm"), default="local",
                   help="local: a process pool here; parallel: GNU parallel here; slurm: an "
                        "array job")
    p.add_argument("-j", "--jobs", type=_positive, default=1, metavar="N",
                   help="bakes at once: local processes, or the Slurm array's %%N cap")
    p.add_argument("--files-per-task", type=_positive, default=None, metavar="K",
                   help="files per Blender process (default 1 locally, 4 on Slurm: Blender's "
                        "start-up is paid once per task)")
    p.add_argument("--threads", type=int, default=None, metavar="N",
                   help="native-core threads per bake (default: cores / -j locally, 1 on "
                        "Slurm, where it is also the task's --cpus-per-task)")
    p.add_argument("--blender", default="blender", help="the Blender executable")
    p.add_argument("--timeout", type=_seconds, default=3600.0, metavar="S",
                   help="seconds one file may take before its Blender is stopped (0 = none)")
    p.add_argument("--sbatch-arg", action="append", default=[], metavar="ARG",
                   help="extra sbatch option, e.g. --sbatch-arg=--partition=bake (repeatable)")
    p.add_argument("--poll", type=_seconds, default=2.0, metavar="S",
                   help="Slurm: seconds between queue checks while waiting")
    p.add_argument("--dry-run", action="store_true",
                   help="print the plan (skipped files, one command line per task) and stop")
    return p


def _positive(text):
    v = int(text)
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {v}")
    return v


def _seconds(text):
    """A time in seconds: a finite number >= 0."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number of seconds, got {text!r}") from None
    if not (v >= 0 and math.isfinite(v)):
        raise argparse.ArgumentTypeError(f"must be a finite number of seconds >= 0, got {text}")
    return v


# Parses bake options as each file's bake will, in a child Python: the command line's parser
# imports the core, whose native module starts threads, and the batch's own process must keep
# only its pool's (Ctrl-C handling, run_local) and import neither bpy nor the native core.
_CHECK = """import sys
from canopy_ao import cli
parser = cli.build_parser()
def refuse(message):
    print(message, file=sys.stderr)
    sys.exit(2)
parser.error = refuse
cli.check_args(parser, parser.parse_args(sys.argv[1:]))
"""


def check_bake_options(bake_args, threads):
    """Refuse (BatchError, exit 2) bake options each file's bake would refuse (canopy_ao.cli:
    every number against its option's range), before any Blender starts. A Python that cannot
    import the core (no numpy) skips the check: each file's bake then refuses them."""
    r = subprocess.run([sys.executable, "-c", _CHECK, *bake_args, "--threads", str(threads)],
                       env=_package_env(), capture_output=True, text=True)
    if r.returncode == 2:
        lines = r.stderr.strip().splitlines()
        raise plan.BatchError(f"bake option after '--': {lines[-1] if lines else '?'}")


def split_argv(argv):
    """(batch arguments, bake arguments) around the first '--'."""
    if "--" in argv:
        i = argv.index("--")
        return argv[:i], argv[i + 1:]
    return argv, []


def main(argv=None):
    argv = sys.argv[1:] if argv is None else list(argv)
    ours, bake_args = split_argv(argv)
    parser = build_parser()
    args = parser.parse_args(ours)
    try:
        return run(args, bake_args)
    except plan.BatchError as exc:
        print(f"canopy_ao.batch: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("canopy_ao.batch: cancelled; rerun the same command to resume (finished files "
              "are kept)", file=sys.stderr)
        return 130


def run(args, bake_args):
    t0 = time.perf_counter()
    entries = list(args.inputs)
    for m in args.manifest:
        entries += plan.read_manifest(m)
    sources = plan.expand_inputs(entries)
    root = plan.common_root(sources)
    out_dir = os.path.abspath(args.output)
    plan.check_outputs(sources, root, out_dir, args.in_place)
    plan.check_bake_args(bake_args)
    slurm = args.backend == "slurm"
    per_task = args.files_per_task or (4 if slurm else 1)
    threads = args.threads if args.threads is not None else (
        1 if slurm else max(1, (os.cpu_count() or 1) // args.jobs))
    if threads < 0:
        raise plan.BatchError(f"--threads must be >= 0, got {threads}")
    check_bake_options(bake_args, threads)
    key = plan.options_key(bake_args, args.in_place)

    todo, skipped = [], []
    for s in sources:
        output = plan.output_path(s, root, out_dir, args.in_place)
        report = plan.report_path(s, root, out_dir)
        (skipped if plan.up_to_date(s, output, report, key)[0] else todo).append(s)
    p = runner.make_plan(sources, root, out_dir, bake_args, plan.group(todo, per_task),
                         blender=args.blender, threads=threads, in_place=args.in_place,
                         timeout=args.timeout)
    print(f"canopy_ao.batch: {len(sources)} file(s), {len(skipped)} up to date, "
          f"{len(todo)} to bake in {len(p['tasks'])} task(s) on {args.backend} "
          f"(-j {args.jobs}, {threads} thread(s) per bake)", flush=True)
    if args.dry_run:
        for s in skipped:
            print(f"skip {s}")
        for t in p["tasks"]:
            print(shlex.join(runner.command(p, t)))
        return 0
    if p["tasks"]:
        BACKENDS[args.backend](p, args)

    rows = runner.collect(p, todo)
    for s in skipped:
        report = plan.report_path(s, root, out_dir)
        rows.append(dict(plan.summary_row(plan.read_report(report), report), status="skipped"))
    order = {s: i for i, s in enumerate(sources)}
    rows.sort(key=lambda r: order.get(r["source"], len(order)))
    summary = os.path.join(out_dir, plan.SUMMARY_NAME)
    plan.write_summary(rows, summary)
    counts = {st: sum(r["status"] == st for r in rows) for st in ("ok", "skipped", "failed")}
    for r in rows:
        if r["status"] == "failed":
            print(f"canopy_ao.batch: FAILED {r['source']}: {r['error']}", file=sys.stderr)
    print(f"canopy_ao.batch: {counts['ok']} baked, {counts['skipped']} up to date, "
          f"{counts['failed']} failed in {time.perf_counter() - t0:.1f} s; summary {summary}",
          flush=True)
    return plan.exit_code(rows)


# === Back ends
def run_local(p, args):
    """A pool of -j Blender processes on this machine, each task as the Slurm tasks run it."""
    def one(i):
        failed = runner.run_task(p, i)
        print(f"canopy_ao.batch: task {i + 1}/{len(p['tasks'])} done"
              + (f", {len(failed)} failed" if failed else ""), flush=True)

    # Ctrl-C only raises a flag here; the loop below raises KeyboardInterrupt from our own
    # code. Raised where Python's handler would run it — inside concurrent.futures.wait, between
    # the release of one future's lock and the next — it would leave a future's lock held by
    # this thread, and the worker finishing that future would then block for ever in
    # set_result while shutdown() waits for it (the batch hung, once in many cancels).
    interrupted = []
    previous = signal.signal(signal.SIGINT, lambda *_: interrupted.append(True))
    pool = ThreadPoolExecutor(max_workers=args.jobs)
    try:
        pending = {pool.submit(one, i) for i in range(len(p["tasks"]))}
        while pending and not interrupted:
            # Wake up now and then: the kernel may hand Ctrl-C's SIGINT to a worker thread,
            # and then nothing interrupts a main thread blocked on a future.
            done, pending = wait(pending, timeout=0.25)
            for f in done:
                f.result()  # a worker's error stops the run as Ctrl-C does
        if interrupted:
            raise KeyboardInterrupt
    except BaseException:  # Ctrl-C: stop every Blender, start no other
        runner.stop_all()
        raise
    finally:
        signal.signal(signal.SIGINT, previous)
        pool.shutdown(wait=True, cancel_futures=True)


def _addon_parent():
    """The folder holding the canopy_ao package (what PYTHONPATH needs for the runner)."""
    return os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def _package_env():
    """This environment with the canopy_ao package first on PYTHONPATH (for a child python3)."""
    return dict(os.environ, PYTHONPATH=os.pathsep.join(
        [_addon_parent()] + ([os.environ["PYTHONPATH"]] if os.environ.get("PYTHONPATH") else [])))


def runner_command(plan_path, python=sys.executable):
    return [python, "-m", "canopy_ao.batch.runner", plan_path]


def run_parallel(p, args):
    """GNU parallel running -j runners at once, one per task, as the Slurm array does."""
    plan_path = runner.save_plan(p)
    env = _package_env()
    cmd = ["parallel", "--will-cite", "--halt", "never", "-j", str(args.jobs),
           *runner_command(plan_path), ":::", *map(str, range(len(p["tasks"])))]
    try:
        subprocess.run(cmd, env=env, check=False)  # failures are in the reports
    except FileNotFoundError:
        raise plan.BatchError("GNU parallel is not installed (apt install parallel), or use "
                              "--backend local") from None


def slurm_script(p, plan_path, python=sys.executable):
    """The sbatch script of one array element: the same runner the local back end calls."""
    return ("#!/bin/sh\n"
            f"export PYTHONPATH={shlex.quote(_addon_parent())}${{PYTHONPATH:+:$PYTHONPATH}}\n"
            f"exec {shlex.join(runner_command(plan_path, python))} \"$SLURM_ARRAY_TASK_ID\"\n")


def sbatch_command(p, args, script_path):
    n = len(p["tasks"])
    logs = p["logs"]
    # --threads 0 (every core) asks nothing: the cluster's default CPUs per task apply.
    cpus = [f"--cpus-per-task={p['threads']}"] if p["threads"] else []
    return ["sbatch", "--parsable", "--job-name=canopy_ao_batch",
            f"--array=0-{n - 1}%{args.jobs}", *cpus,
            f"--output={os.path.join(logs, 'slurm-%A_%a.out')}",
            *args.sbatch_arg, script_path]


def run_slurm(p, args):
    """Submits one array job (a task per group of files, at most -j running), waits for it to
    leave the queue, and lets the caller collect the reports the tasks wrote."""
    plan_path = runner.save_plan(p)
    os.makedirs(p["logs"], exist_ok=True)
    script_path = os.path.join(os.path.dirname(plan_path), "task.sh")
    with open(script_path, "w", encoding="utf-8") as f:
        f.write(slurm_script(p, plan_path))
    os.chmod(script_path, 0o755)
    cmd = sbatch_command(p, args, script_path)
    try:
        out = subprocess.run(cmd, capture_output=True, text=True, check=False)
    except FileNotFoundError:
        raise plan.BatchError("sbatch is not installed (Slurm's client commands are needed "
                              "for --backend slurm)") from None
    if out.returncode != 0:
        raise plan.BatchError(f"sbatch refused the job: {out.stderr.strip()}")
    job = out.stdout.strip().split(";")[0]
    print(f"canopy_ao.batch: submitted Slurm job {job} ({shlex.join(cmd)})", flush=True)
    try:
        while True:
            q = subprocess.run(["squeue", "-h", "-j", job, "-o", "%i %T"], capture_output=True,
                               text=True, check=False)
            if q.returncode != 0 and "Invalid job id" not in q.stderr:
                raise plan.BatchError(f"squeue failed while waiting for job {job}: "
                                      f"{q.stderr.strip()}")
            if not q.stdout.strip():
                return job
            time.sleep(args.poll)
    except KeyboardInterrupt:  # the job is ours: cancelling the batch cancels it
        subprocess.run(["scancel", job], check=False)
        print(f"canopy_ao.batch: cancelled Slurm job {job}", file=sys.stderr)
        raise


BACKENDS = {"local": run_local, "parallel": run_parallel, "slurm": run_slurm}

if __name__ == "__main__":
    sys.exit(main())
