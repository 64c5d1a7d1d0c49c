"""What a batch bake does, decided without running anything: which .blend files (manifest,
globs, folders), where each result goes, whether a file is already up to date (resume), how files
are grouped into tasks, the exact Blender command line of a task, and the summary of the results.

Pure Python (no bpy, no numpy, no native core): plain pytest tests it, the driver runs it under
any python3, and the Flamenco job type (scripts/flamenco/canopy_ao_batch.js) reproduces
``task_command`` argument for argument.
"""

from __future__ import annotations

import csv
import glob
import json
import os

# The Blender-side entry every task runs (worker.py); Flamenco's job type uses the same string.
WORKER_EXPR = "import canopy_ao.batch.worker as w; w.main()"
# Blender's own options before the script: no user preferences, the add-on enabled, and a
# script that fails (no add-on, no module) fails the process (Blender exits 0 without it).
BLENDER_ARGS = ("-b", "--factory-startup", "--addons", "canopy_ao", "--python-exit-code", "1")
# Bake options the batch sets itself per file; passing them through would fight it.
RESERVED_BAKE_OPTIONS = ("--save", "--report", "--threads")
REPORT_SUFFIX = ".canopy_ao.json"
SUMMARY_NAME = "summary.csv"
SUMMARY_FIELDS = ("source", "output", "status", "attempts", "method", "objects", "vertices",
                  "bake_seconds", "wall_seconds", "error", "report")
REPORT_VERSION = 1


class BatchError(ValueError):
    """A batch that cannot be run as asked (no files, a missing file, clashing outputs...)."""


# === Inputs
def read_manifest(path: str) -> list[str]:
    """The entries of a manifest: one path or glob per line, '#' starts a comment, blank lines
    ignored; relative entries are relative to the manifest's folder."""
    try:
        with open(path, encoding="utf-8") as f:
            lines = f.read().splitlines()
    except OSError as exc:
        raise BatchError(f"cannot read the manifest {path}: {exc.strerror}") from None
    base = os.path.dirname(os.path.abspath(path))
    entries = []
    for line in lines:
        line = line.split("#", 1)[0].strip()
        if line:
            entries.append(line if os.path.isabs(line) else os.path.join(base, line))
    return entries


def expand_inputs(entries: list[str]) -> list[str]:
    """Absolute paths of the .blend files named by ``entries`` (files, folders = their *.blend,
    globs with ``**`` for any depth), in the order given, each once. Raises BatchError for an
    entry that names nothing or a file that is not a .blend."""
    found, seen = [], set()
    for entry in entries:
        if glob.has_magic(entry):
            # A folder named *.blend is no file to open (each Blender would fail on it).
            paths = sorted(p for p in glob.glob(entry, recursive=True)
                           if p.endswith(".blend") and os.path.isfile(p))
            if not paths:
                raise BatchError(f"no .blend file matches {entry}")
        elif os.path.isdir(entry):
            paths = sorted(p for p in glob.glob(os.path.join(glob.escape(entry), "*.blend"))
                           if os.path.isfile(p))
            if not paths:
                raise BatchError(f"the folder {entry} has no .blend file")
        elif os.path.isfile(entry):
            if not entry.endswith(".blend"):
                raise BatchError(f"{entry} is not a .blend file")
            paths = [entry]
        else:
            raise BatchError(f"{entry}: no such file or folder")
        for p in paths:
            p = os.path.abspath(p)
            key = os.path.realpath(p)
            if key not in seen:
                seen.add(key)
                found.append(p)
    if not found:
        raise BatchError("no .blend files given")
    return found


def common_root(sources: list[str]) -> str:
    """The deepest folder holding every source: outputs mirror the sources' layout below it."""
    return os.path.commonpath([os.path.dirname(s) for s in sources])


def output_path(source: str, root: str, out_dir: str, in_place: bool = False) -> str:
    """Where the baked copy of ``source`` is saved: out_dir/<path below root>, or the source
    itself when baking in place."""
    if in_place:
        return source
    return os.path.join(out_dir, os.path.relpath(source, root))


def report_path(source: str, root: str, out_dir: str) -> str:
    """The JSON report of one file (kept in out_dir also when baking in place)."""
    rel = os.path.relpath(source, root)
    return os.path.join(out_dir, rel[:-len(".blend")] + REPORT_SUFFIX)


def check_outputs(sources: list[str], root: str, out_dir: str, in_place: bool) -> None:
    """Raises BatchError when an output would overwrite a source (not asked to) or the output
    folder lies where a later run would pick its own results up as inputs."""
    out_real = os.path.realpath(out_dir)
    for s in sources:
        if not in_place and os.path.realpath(output_path(s, root, out_dir)) == os.path.realpath(s):
            raise BatchError(f"the output of {s} would overwrite it; choose another --output "
                             "(or --in-place to bake the sources themselves)")
        if not in_place and os.path.realpath(s).startswith(out_real + os.sep):
            raise BatchError(f"{s} is inside the output folder {out_dir}; keep inputs and "
                             "outputs apart")
        output = output_path(s, root, out_dir, in_place)
        if not in_place and os.path.lexists(output):
            # Every copy the batch saves has a report naming its source first (worker.py): a
            # file without one is someone else's, never replaced unasked.
            rep = read_report(report_path(s, root, out_dir))
            if rep is None or os.path.realpath(str(rep.get("source", ""))) != \
                    os.path.realpath(s):
                raise BatchError(f"{output} already exists and is not a batch's copy of {s} "
                                 "(no report of it beside); move it away or choose another "
                                 "--output")


# === Options
def check_bake_args(bake_args: list[str]) -> None:
    """Raises BatchError for options the batch sets itself."""
    for a in bake_args:
        name = a.split("=", 1)[0]
        if name in RESERVED_BAKE_OPTIONS:
            raise BatchError(f"{name} is set by the batch per file; leave it out of the bake "
                             "options (use the batch's own --threads)")


def options_key(bake_args: list[str], in_place: bool = False) -> list[str]:
    """What decides whether an earlier result is still valid: the bake options as given (the
    thread count is not in it: results do not depend on it) and where the result is saved."""
    return list(bake_args) + (["<in-place>"] if in_place else [])


# === Resume
def up_to_date(source: str, output: str, report: str, key: list[str]) -> tuple[bool, str]:
    """(skip, why): True when the earlier bake of ``source`` is still valid: its report says
    it succeeded with the same options, and the output it saved is still there, unchanged
    since (same modification time) and not older than the source."""
    rep = read_report(report)
    if rep is None:
        return False, "no readable report (not baked yet)"
    if rep.get("status") != "ok":
        return False, "the last bake failed"
    if rep.get("options") != key:
        return False, "the options changed"
    if os.path.realpath(rep.get("source", "")) != os.path.realpath(source):
        return False, "the report is for another source"
    try:
        out_stat = os.stat(output)
        src_stat = os.stat(source)
    except OSError:
        return False, "the output is missing"
    if out_stat.st_mtime_ns != rep.get("output_mtime_ns"):
        return False, "the output was changed since"
    if src_stat.st_mtime_ns > out_stat.st_mtime_ns:
        return False, "the source is newer than its output"
    return True, "up to date"


# === Tasks
def group(items: list, per_task: int) -> list[list]:
    """Consecutive chunks of ``per_task`` items (the last may be shorter)."""
    if per_task < 1:
        raise BatchError(f"files per task must be >= 1, got {per_task}")
    return [items[i:i + per_task] for i in range(0, len(items), per_task)]


def task_command(blender: str, sources: list[str], root: str, out_dir: str,
                 bake_args: list[str], threads: int = 0, in_place: bool = False) -> list[str]:
    """The Blender command line baking ``sources`` in one process. Blender opens the first file
    itself; the worker opens the others in turn. Everything after the second ``--`` goes to the
    bake command line (canopy_ao.cli) unchanged."""
    worker = ["--root", root, "--output", out_dir]
    if threads:
        worker += ["--threads", str(threads)]
    if in_place:
        worker.append("--in-place")
    return ([blender, *BLENDER_ARGS, sources[0], "--python-expr", WORKER_EXPR, "--", *worker,
             "--files", *sources, "--", *bake_args])


# === Reports and summary
def failed_report(source: str, output: str, key: list[str], attempts: int, error: str) -> dict:
    """The report of a file whose bake did not report for itself (Blender crashed, timed out,
    or could not open it)."""
    return dict(version=REPORT_VERSION, source=source, output=output, status="failed",
                attempts=attempts, options=key, error=error)


def read_report(path: str) -> dict | None:
    """A file's report, or None when there is none (or it is unreadable)."""
    try:
        with open(path, encoding="utf-8") as f:
            rep = json.load(f)
    except (OSError, ValueError):
        return None
    return rep if isinstance(rep, dict) else None


def write_report(rep: dict, path: str) -> None:
    """Writes a report atomically: a crash never leaves half a JSON file."""
    os.makedirs(os.path.dirname(path), exist_ok=True)
    tmp = path + ".tmp"
    with open(tmp, "w", encoding="utf-8") as f:
        json.dump(rep, f, indent=1, default=float)
    os.replace(tmp, path)


def summary_row(rep: dict, report: str) -> dict:
    """One CSV row from a file's report."""
    bake = rep.get("bake") or {}
    objects = bake.get("objects") or {}
    return dict(source=rep.get("source", ""), output=rep.get("output", ""),
                status=rep.get("status", "failed"), attempts=rep.get("attempts", 0),
                method=bake.get("method", ""), objects=len(objects) if objects else "",
                vertices=sum(int(o.get("vertices", 0)) for o in objects.values()) if objects
                else "",
                bake_seconds=_fmt(bake.get("seconds")), wall_seconds=_fmt(rep.get("seconds")),
                error=(rep.get("error") or "").strip().replace("\n", " | ")[:500],
                report=report)


def _fmt(v):
    return "" if v is None else f"{float(v):.3f}"


def write_summary(rows: list[dict], path: str) -> None:
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.DictWriter(f, fieldnames=SUMMARY_FIELDS)
        w.writeheader()
        w.writerows(rows)


def exit_code(rows: list[dict]) -> int:
    """0 when every file was baked or already up to date, 1 when any failed."""
    return 0 if all(r["status"] in ("ok", "skipped") for r in rows) else 1
