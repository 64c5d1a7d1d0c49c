"""Runs one batch task (a group of files in one Blender process) with one retry per failed file,
under plain python3. Both back ends run exactly this: the local pool calls ``run_task`` in a
thread per slot, each Slurm array element runs

    python3 -m canopy_ao.batch.runner OUT/.canopy_ao_batch/plan.json [INDEX]

(INDEX defaults to $SLURM_ARRAY_TASK_ID). The plan file is what ``make_plan`` returns.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time

from . import plan

PLAN_DIR = ".canopy_ao_batch"

# Blender processes this process is running, and whether the run was cancelled (stop_all):
# a cancelled run starts no new Blender, retries included.
_LIVE = set()
_LIVE_LOCK = threading.Lock()
CANCELLED = threading.Event()


def make_plan(sources, root, out_dir, bake_args, tasks, *, blender="blender", threads=0,
              in_place=False, timeout=3600.0):
    """Everything a task needs, JSON-serialisable: the back ends hand it to run_task."""
    return dict(version=plan.REPORT_VERSION, blender=blender, root=root, output=out_dir,
                bake_args=list(bake_args), threads=threads, in_place=in_place,
                timeout=timeout, sources=list(sources), tasks=[list(t) for t in tasks],
                logs=os.path.join(out_dir, PLAN_DIR, "logs"))


def command(p, sources):
    return plan.task_command(p["blender"], sources, p["root"], p["output"], p["bake_args"],
                             p["threads"], p["in_place"])


def paths(p, source):
    """(output, report) of one source under plan p."""
    return (plan.output_path(source, p["root"], p["output"], p["in_place"]),
            plan.report_path(source, p["root"], p["output"]))


def is_done(p, source):
    output, report = paths(p, source)
    return plan.up_to_date(source, output, report, plan.options_key(p["bake_args"],
                                                                     p["in_place"]))[0]


def _run_blender(p, sources, log_path):
    """Runs one Blender process on ``sources``; returns a one-line outcome for the reports.
    A process that outlives its time limit is killed with its whole process group."""
    os.makedirs(os.path.dirname(log_path), exist_ok=True)
    limit = p["timeout"] * len(sources) if p["timeout"] else None
    with open(log_path, "wb") as log:
        log.write(("$ " + " ".join(command(p, sources)) + "\n").encode())
        log.flush()
        with _LIVE_LOCK:
            if CANCELLED.is_set():
                return "the run was cancelled"
            # Its own session, so a terminal's Ctrl-C reaches only the driver, which then
            # stops each Blender itself (stop_all) instead of leaving some half-saved.
            proc = subprocess.Popen(command(p, sources), stdout=log, stderr=subprocess.STDOUT,
                                    stdin=subprocess.DEVNULL, start_new_session=True)
            _LIVE.add(proc)
        try:
            code = proc.wait(timeout=limit)
        except subprocess.TimeoutExpired:
            _kill(proc)
            return f"Blender was stopped after {limit:.0f} s (--timeout)"
        finally:
            with _LIVE_LOCK:
                _LIVE.discard(proc)
    if code < 0:
        return f"Blender was killed by signal {-code}"
    return f"Blender exited with code {code}"


def _kill(proc):
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    proc.wait()


def stop_all():
    """Cancels the run: no new Blender starts, and every running one is killed."""
    with _LIVE_LOCK:
        CANCELLED.set()
        live = list(_LIVE)
    for proc in live:
        _kill(proc)


def _log_tail(path, lines=6):
    try:
        with open(path, errors="replace") as f:
            text = f.read().splitlines()
    except OSError:
        return ""
    # "Error: ..." up to Blender 4.x, "... | ERROR ..." from 5.x.
    errors = [t for t in text if "error" in t.lower() and not t.startswith("$ ")]
    return " | ".join((errors or text)[-lines:])


def run_task(p, index):
    """Bakes task ``index`` of plan p: the whole group in one Blender process, then each file
    that did not succeed once more on its own (a crash in one file must not cost the others,
    and a transient failure gets a second chance). Returns the sources that failed twice."""
    group = [s for s in p["tasks"][index] if not is_done(p, s)]
    if not group:
        return []
    _run_blender(p, group, os.path.join(p["logs"], f"task-{index}.log"))
    failed = []
    for attempt in (1, 2):
        retry = [s for s in group if not is_done(p, s)]
        for s in group:
            if s not in retry:
                _set_attempts(p, s, attempt)
        if not retry or attempt == 2:
            failed = retry
            break
        group = retry
        for n, s in enumerate(retry):
            log = os.path.join(p["logs"], f"task-{index}-retry-{n}.log")
            outcome = _run_blender(p, [s], log)
            _record_failure(p, s, 2, outcome, log)
    return failed


def _set_attempts(p, source, attempts):
    report = paths(p, source)[1]
    rep = plan.read_report(report)
    if rep is not None and rep.get("attempts") != attempts:
        rep["attempts"] = attempts
        plan.write_report(rep, report)


def _record_failure(p, source, attempts, outcome, log):
    """After a failed attempt: keep the worker's own report (it says why) but count the
    attempt; write one when the worker never reported (a crash, a file Blender cannot open)."""
    if is_done(p, source):
        return
    output, report = paths(p, source)
    rep = plan.read_report(report)
    key = plan.options_key(p["bake_args"], p["in_place"])
    fresh = (rep is not None and rep.get("status") == "failed" and rep.get("options") == key
             and not rep.get("started")  # the worker's note before the copy: no reason yet
             and os.path.getmtime(report) >= os.path.getmtime(log))
    if not fresh:
        tail = _log_tail(log)
        rep = plan.failed_report(source, output, key, attempts,
                                 f"{outcome}; log {log}" + (f": {tail}" if tail else ""))
    rep["attempts"] = attempts
    rep["log"] = log
    plan.write_report(rep, report)


def collect(p, sources):
    """Summary rows for ``sources`` after the back end ran: every file gets one, also a file
    whose task never reported (its Slurm task was lost, say)."""
    rows = []
    key = plan.options_key(p["bake_args"], p["in_place"])
    for s in sources:
        output, report = paths(p, s)
        rep = plan.read_report(report)
        if not is_done(p, s) and (rep is None or rep.get("status") == "ok"
                                  or rep.get("options") != key):
            rep = plan.failed_report(s, output, key, 0,
                                     f"no report from its task; logs in {p['logs']}")
            plan.write_report(rep, report)
        rows.append(plan.summary_row(rep, report))
    return rows


def save_plan(p):
    path = os.path.join(p["output"], PLAN_DIR, "plan.json")
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w", encoding="utf-8") as f:
        json.dump(p, f, indent=1)
    return path


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if not argv or len(argv) > 2:
        print("usage: python3 -m canopy_ao.batch.runner PLAN.json [INDEX]", file=sys.stderr)
        return 2
    with open(argv[0], encoding="utf-8") as f:
        p = json.load(f)
    index = int(argv[1] if len(argv) > 1 else os.environ["SLURM_ARRAY_TASK_ID"])
    t0 = time.perf_counter()
    failed = run_task(p, index)
    print(f"canopy_ao.batch: task {index}: {len(p['tasks'][index]) - len(failed)} of "
          f"{len(p['tasks'][index])} file(s) done in {time.perf_counter() - t0:.1f} s"
          + (f"; failed: {', '.join(failed)}" if failed else ""), flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
