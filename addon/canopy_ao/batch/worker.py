"""The Blender side of a batch task: bake several .blend files in one Blender process, one
after the other, each saved to the output folder with a JSON report beside it.

    blender -b --factory-startup --addons canopy_ao FIRST.blend \\
        --python-expr "import canopy_ao.batch.worker as w; w.main()" -- \\
        --root DIR --output OUT [--threads N] [--in-place] --files FIRST.blend MORE.blend ... \\
        -- <bake options of canopy_ao.cli>

(plan.task_command builds it.) A file already up to date is skipped; a file that fails gets a
report saying why and the others go on; the exit code is 1 when any file failed. The baked copy
is saved to its output path *before* the bake, so paths relative to the .blend (texel images,
``//canopy_ao``) land beside the copy and the source is never written to.
"""

import argparse
import os
import sys
import time
import traceback

from . import plan


def _parse(argv):
    ap = argparse.ArgumentParser(prog="canopy_ao.batch.worker")
    ap.add_argument("--root", required=True)
    ap.add_argument("--output", required=True)
    ap.add_argument("--threads", type=int, default=0)
    ap.add_argument("--in-place", action="store_true")
    ap.add_argument("--files", nargs="+", required=True)
    if "--" in argv:
        cut = argv.index("--")
        ours, bake_args = argv[:cut], argv[cut + 1:]
    else:
        ours, bake_args = argv, []
    return ap.parse_args(ours), bake_args


def main(argv=None):
    if argv is None:
        argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    args, bake_args = _parse(list(argv))
    import bpy
    # No .blend1 backups next to the outputs (the second save of a file would make one).
    bpy.context.preferences.filepaths.save_version = 0
    key = plan.options_key(bake_args, args.in_place)
    failed = 0
    for source in args.files:
        failed += not bake_one(source, args, bake_args, key)
    sys.stdout.flush()
    sys.exit(1 if failed else 0)


def bake_one(source, args, bake_args, key):
    """Bake one file; writes its report; True on success or when it was already up to date."""
    import bpy
    from .. import cli

    source = os.path.abspath(source)
    output = plan.output_path(source, args.root, args.output, args.in_place)
    report = plan.report_path(source, args.root, args.output)
    skip, why = plan.up_to_date(source, output, report, key)
    if skip:
        print(f"canopy_ao.batch: {source}: {why}, skipped", flush=True)
        return True
    # attempts: the driver that retries (runner.py) counts them and rewrites this field.
    rep = dict(version=plan.REPORT_VERSION, source=source, output=output, status="failed",
               attempts=1, options=key, threads=args.threads)
    t0 = time.perf_counter()
    saved_copy = False
    try:
        if os.path.realpath(bpy.data.filepath or "") != os.path.realpath(source):
            bpy.ops.wm.open_mainfile(filepath=source, load_ui=False)
        if not args.in_place:
            os.makedirs(os.path.dirname(output), exist_ok=True)
            # The report first: a copy left by a Blender killed mid-bake is still known as
            # the batch's own (plan.check_outputs), and the rerun replaces it.
            plan.write_report(dict(rep, error="stopped before it finished", started=True), report)
            bpy.ops.wm.save_as_mainfile(filepath=output, relative_remap=True)
            saved_copy = True
        cli_args = cli.build_parser().parse_args(
            [*bake_args, "--save", "--threads", str(args.threads)])
        rep["bake"] = cli.run(cli_args)
        rep["status"] = "ok"
        rep["output_mtime_ns"] = os.stat(output).st_mtime_ns
    except cli.BakeFailed as exc:
        rep["error"] = str(exc)
    except SystemExit as exc:  # argparse refusing the bake options
        rep["error"] = f"bad bake options (exit {exc.code}): {' '.join(bake_args)}"
    except Exception as exc:  # one file's failure must not stop the others
        traceback.print_exc()
        rep["error"] = f"{type(exc).__name__}: {exc}"
    rep["seconds"] = time.perf_counter() - t0
    if rep["status"] != "ok":
        print(f"canopy_ao.batch: {source}: failed: {rep['error']}", file=sys.stderr, flush=True)
        if saved_copy:  # a half-made copy must not look like a result
            _remove(output)
    plan.write_report(rep, report)
    return rep["status"] == "ok"


def _remove(path):
    try:
        os.remove(path)
    except OSError:
        pass
