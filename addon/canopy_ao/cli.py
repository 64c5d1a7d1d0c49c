"""Headless bake.

    blender -b scene.blend --python-expr "import canopy_ao.cli; canopy_ao.cli.main()" -- \
        --objects Tree Leaves Ground --method auto --save --report out.json

Prints one line per object (role, method, vertices, seconds, and the error against Cycles when
asked), writes a JSON report, and exits non-zero with the message on stderr: 2 on bad arguments
(every number is checked against its option's range, core/settings.py), 1 on missing objects
or a failed bake, 130 when Ctrl-C stopped it (nothing written or saved). Progress goes to
stderr (core/progress.py). Run ``... -- --help`` for every option.
"""

import argparse
import json
import sys

from .core.settings import OPTIONS


def _arg_type(option):
    """argparse's type for an option: its checked value, or a clean usage error (exit 2)."""
    def convert(text):
        try:
            return option.parse(text)
        except ValueError as exc:  # CanopyAOError
            raise argparse.ArgumentTypeError(str(exc)) from None
    convert.__name__ = option.name  # argparse names the type in some messages
    return convert


class BakeFailed(Exception):
    """A bake that could not be done; the message says why (printed as canopy_ao: error:)."""


def _add_option(p, o):
    """One option's argument; dest is the option's name, None when not given."""
    default = o.cli_default or ("auto" if o.none_prop else o.default)
    text = f"{o.help} (default: {default})"
    if o.kind == "bool":
        p.add_argument(o.flag, dest=o.name, action="store_false" if o.default else "store_true",
                       default=None,  # a flag that turns an option off says so (--no-proxies)
                       help=f"do not {o.help[0].lower()}{o.help[1:]}" if o.default else o.help)
    elif o.kind == "enum":
        ids = [i[0].lower() for i in o.items]
        each = "; ".join(f"{i[0].lower()}: {i[2]}" for i in o.items if len(i) > 2 and i[2])
        p.add_argument(o.flag, dest=o.name, type=_arg_type(o), default=None,
                       metavar="{" + ",".join(ids) + "}",
                       help=f"{text}. {each}" if each else text)
    else:
        p.add_argument(o.flag, dest=o.name, type=_arg_type(o), default=None,
                       metavar="auto|N" if o.none_prop else o.flag.lstrip("-").upper(),
                       help=text)


def build_parser():
    """The command line: object selection and output switches, then one argument per option
    of core/settings.py's OPTIONS."""
    p = argparse.ArgumentParser(
        prog="blender -b scene.blend --python-exit-code 1 --python-expr "
             "'import canopy_ao.cli; canopy_ao.cli.main()' --",
        description="Bake Canopy AO into a color attribute of mesh objects.")
    which = p.add_mutually_exclusive_group()
    which.add_argument("--objects", nargs="+", metavar="NAME", help="objects to bake")
    which.add_argument("--all", action="store_true",
                       help="bake every visible mesh (the default when --objects is not given)")
    for o in OPTIONS:
        if o.cli is not None:
            _add_option(p, o)
    p.add_argument("--frames", nargs=2, type=int, metavar=("START", "END"),
                   help="bake every frame of START..END into per-frame attributes read back "
                        "by a geometry-nodes modifier (blender/frames.py)")
    p.add_argument("--report", metavar="FILE.json", help="write a JSON report here")
    p.add_argument("--save", action="store_true", help="save the .blend after baking")
    p.add_argument("--threads", type=int, default=0, metavar="N",
                   help="cap the native core's worker threads (0 = every core; results do "
                        "not depend on it), so several bakes can share a machine")
    return p


def options_from_args(args, world_distance):
    """Every option's value: the argument when given, else its default. An omitted --distance
    is the World's AO distance (``world_distance``), as Cycles' AO bake uses it."""
    opts = {}
    for o in OPTIONS:
        given = getattr(args, o.name, None)
        opts[o.name] = o.default if given is None else given
        if given is not None and o.cli_enables:
            opts[o.cli_enables] = True
    if args.distance is None:
        opts["distance"] = world_distance
    return opts


def check_args(parser, args):
    """What parse_args cannot check by one argument's type: parser.error (exit 2) names it.
    The batch runs it too, before any Blender starts."""
    from .core.native import LIMITS
    if not 0 <= args.threads <= LIMITS["threads"]:
        parser.error(f"--threads must be an integer in [0, {LIMITS['threads']}], got "
                     f"{args.threads}")
    if args.report is not None and not args.report.strip():
        parser.error("--report needs a file name")


def _argv(argv):
    if argv is not None:
        return list(argv)
    return sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []


# Blender's own arguments that render when Blender reaches them, after this script.
RENDER_FLAGS = ("-a", "--render-anim", "-f", "--render-frame")


def _render_flags(blender_argv):
    """Blender's render arguments that follow the script (--python-expr / --python) and come
    before '--' in Blender's command line."""
    cut = blender_argv.index("--") if "--" in blender_argv else len(blender_argv)
    head = blender_argv[:cut]
    starts = [i for i, a in enumerate(head) if a in ("--python-expr", "--python", "-P")]
    return [a for a in head[starts[0] + 2:] if a in RENDER_FLAGS] if starts else []


def _fail(message, code=1):
    sys.stdout.flush()
    print(f"canopy_ao: error: {message}", file=sys.stderr, flush=True)
    sys.exit(code)


def main(argv=None):
    """Parse the args after ``--``, bake, report; sys.exit with 0 on success."""
    parser = build_parser()
    args = parser.parse_args(_argv(argv))  # exits 2 with usage on bad arguments
    check_args(parser, args)
    render = _render_flags(sys.argv) if argv is None else []
    if render and not args.live:
        parser.error(f"Blender's {' '.join(render)} before '--' renders after this script only "
                     "with --live (live AO, re-evaluated at every frame); without it the bake "
                     "exits Blender first and nothing is rendered: add --live, or render in a "
                     "second command (blender -b FILE.blend -a)")
    from .core.progress import Cancelled
    from .core import stage_profile
    profile = stage_profile.StageLog() if stage_profile.enabled() else None
    if profile is not None:
        profile.add("Blender start, file load (to the script)", stage_profile.process_age() or 0)
    try:
        run(args, profile)
        code = 0
    except BakeFailed as exc:
        _fail(str(exc))
    except (Cancelled, KeyboardInterrupt) as exc:  # Ctrl-C: once (stopped cleanly) or twice
        _fail(str(exc) or "interrupted (Ctrl-C)", 130)
    except SystemExit:
        raise
    except Exception as exc:  # an unexpected failure must still fail the process
        import traceback
        traceback.print_exc()
        _fail(f"{type(exc).__name__}: {exc}")
    sys.stdout.flush()
    if profile is not None:
        profile.print()
    if args.live:
        # Blender goes on with its own arguments before "--" (-a renders the animation, live
        # AO re-evaluated at every frame by the handler this bake armed).
        return
    sys.exit(code)


def run(args, profile=None):
    """Bake the open file as ``args`` (from build_parser) say, print one line per object, and
    return the report; raises BakeFailed with a message when the bake cannot be done.
    profile: a core.stage_profile.StageLog to add the stages' seconds to, or None."""
    import time
    import addon_utils
    import bpy

    t_enable = time.perf_counter()
    if not hasattr(bpy.types.Scene, "canopy_ao"):
        # Imported by a plain `import canopy_ao.cli`: mark the package current so enable()
        # registers it as it is instead of reloading it ("module changed on disk").
        import os
        pkg = sys.modules[__package__]
        pkg.__time__ = os.path.getmtime(pkg.__file__)
        addon_utils.enable(__package__, default_set=False, handle_error=None)
        if not hasattr(bpy.types.Scene, "canopy_ao"):
            raise BakeFailed("the canopy_ao add-on could not be enabled (see the messages "
                             "above)")
    from . import core
    from .blender import gather, job
    from .core.native import CanopyAOError, core_status, require

    ok, msg = core_status()
    if not ok:
        raise BakeFailed(msg)
    if profile is not None:
        reg = sys.modules[__package__].REGISTER_SECONDS
        profile.add("add-on: module imports", reg.get("imports", 0.0))
        profile.add("add-on: registration", reg.get("registration", 0.0))
        profile.add("add-on: enable (rest)", time.perf_counter() - t_enable - sum(reg.values()))
        require().set_stage_profiling(True)
        require().take_stage_seconds()  # only this bake's
    require().set_max_threads(args.threads)  # 0 also lifts a cap an earlier bake here set
    if args.save and not bpy.data.filepath:
        raise BakeFailed("--save needs a saved .blend (give the .blend before --python-expr)")
    if args.report:  # before the bake: a run that fails on its report leaves no images
        _check_report_path(bpy.path.abspath(args.report), args.overwrite)
    try:
        world = None if args.distance is not None else gather.world_ao_distance(
            bpy.context.scene, bake=True)
    except CanopyAOError as exc:
        raise BakeFailed(str(exc)) from None
    opts = options_from_args(args, world)
    context = bpy.context
    if args.objects is None:
        # Headless: "the selection" means nothing here, so bake every visible mesh.
        for ob in context.view_layer.objects:
            ob.select_set(False)
    if args.frames:
        return _run_frames(args, context, opts)
    cpu0 = time.process_time()
    try:
        bake_job, rep = _with_progress(
            lambda progress: job.run_bake(context, args.objects or [], opts, progress))
    except CanopyAOError as exc:
        raise BakeFailed(str(exc)) from None
    for r in bake_job.results:
        e = rep["objects"][r.name]
        line = (f"{r.name}: role {e['role']}, method {e['method']}, {e['vertices']} vertices, "
                f"{e['seconds']:.3f} s, mean AO {e['ao_mean']:.3f}")
        if "texel" in e:
            line += f", {e['texel'].get('texels', 0)} texels -> {e['texel'].get('path', '?')}"
        if "cycles" in e:
            c = e["cycles"]
            line += (f", vs Cycles MAE {c.get('mae', float('nan')):.4f} "
                     f"RMSE {c.get('rmse', float('nan')):.4f}")
        print(line, flush=True)
    # τ means nothing to a rung that takes none (the exact rung, the density grid's physical
    # density, the ray-free fit, the hybrid).
    tau = "" if not core.rung(rep["method"]).takes_tau else f" tau {rep['tau']:.4g}"
    print(f"canopy_ao: {rep['method']}{tau}, {len(bake_job.results)} object(s), "
          f"{rep['seconds']:.2f} s", flush=True)
    for note in rep["notes"]:
        print(f"canopy_ao: note: {note}", flush=True)
    if profile is not None:
        profile.add_report(rep)
        profile.add_native(require().take_stage_seconds())
        profile.add("bake: whole (job.run_bake)", rep["seconds"])
        profile.add("bake: whole, CPU of every thread", time.process_time() - cpu0)
    t_finish = time.perf_counter()
    _finish(args, rep)
    if profile is not None:
        profile.add("report file, save", time.perf_counter() - t_finish)
    return rep


def _run_frames(args, context, opts):
    from .blender import frames
    from .core.native import CanopyAOError
    if args.live:
        raise BakeFailed("--frames and --live are two ways to animate AO: give one")
    try:
        rep = _with_progress(frames.FrameBake(context, args.objects or [], opts,
                                              *args.frames).run)
    except CanopyAOError as exc:
        raise BakeFailed(str(exc)) from None
    print(f"canopy_ao: frames {rep['frames'][0]}-{rep['frames'][1]}, {rep['method']} tau "
          f"{rep['tau']:.4g}, {len(rep['objects'])} object(s) into {rep['cache'][0]}.."
          f"{rep['cache'][1]}, {rep['ms_per_frame']:.1f} ms per frame, {rep['seconds']:.2f} s",
          flush=True)
    _finish(args, rep)
    return rep


def _with_progress(bake):
    """bake(progress) with its progress on stderr (stdout's lines are what scripts read) and
    Ctrl-C as a clean stop: the bake polls progress, which raises Cancelled once SIGINT came,
    and nothing is written, or what was is rolled back (core/progress.py)."""
    from .core.progress import Interrupt, Progress
    bar = Progress()
    with Interrupt() as stop:

        def progress(*state, **kw):
            stop.check()
            bar.update(*state, **kw)
        try:
            out = bake(progress)
        finally:
            bar.close()
        stop.check()  # a Ctrl-C while the writes were kept: nothing saved or reported
    return out


def _is_report(path):
    try:
        with open(path, encoding="utf-8") as f:
            rep = json.load(f)
    except (OSError, ValueError):
        return False
    return isinstance(rep, dict) and {"objects", "method", "notes"} <= set(rep)


def _check_report_path(path, overwrite=False):
    """Raise BakeFailed when the report could not be written at path, or would replace a file
    that is not an earlier report (the .blend itself, say) without --overwrite (nothing
    changed yet)."""
    import os
    folder = os.path.dirname(os.path.abspath(path))
    if os.path.isdir(path):
        why = "is a folder; give a file name"
    elif os.path.isfile(path) and not overwrite and not _is_report(path):
        why = ("already exists and is not a Canopy AO report; give another file name, or "
               "--overwrite to replace it")
    elif not os.path.isdir(folder):
        why = f"is in a folder that does not exist ({folder})"
    elif not os.access(folder, os.W_OK) or (os.path.exists(path)
                                            and not os.access(path, os.W_OK)):
        why = "cannot be written (permissions)"
    else:
        return
    raise BakeFailed(f"--report {path} {why} (nothing was baked)")


def _finish(args, rep):
    """The report file and --save."""
    import bpy
    if args.report:
        try:
            with open(bpy.path.abspath(args.report), "w") as f:
                json.dump(rep, f, indent=1, default=float)
        except OSError as exc:
            raise BakeFailed(f"cannot write the report: {exc}") from None
    if args.save:
        bpy.ops.wm.save_mainfile()
        print(f"canopy_ao: saved {bpy.data.filepath}", flush=True)
