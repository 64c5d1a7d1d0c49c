"""Headless bake (issue 3, item 7).

    blender -b scene.blend --python-expr "import canopy_ao.cli; canopy_ao.cli.main()" -- \
        --objects Tree Leaves Ground --method auto --save --report out.json

Prints one line per object (role, method, vertices, seconds, and the error against Cycles when
asked), writes a JSON report, and exits non-zero with the message on stderr on bad arguments,
missing objects or a failed bake. Run ``... -- --help`` for every option.
"""

import argparse
import json
import sys


def _tau(text):
    if text.lower() == "auto":
        return None
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number > 0 or 'auto', got {text!r}")
    if not v > 0:
        raise argparse.ArgumentTypeError(f"tau must be > 0, got {v}")
    return v


def _nonneg(text):
    v = float(text)
    if v < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {v}")
    return v


def _positive_int(text):
    v = int(text)
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {v}")
    return v


def _nonneg_int(text):
    v = int(text)
    if v < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {v}")
    return v


class BakeFailed(Exception):
    """A bake that could not be done; the message says why (printed as canopy_ao: error:)."""


def build_parser():
    from .core.ladder import METHODS

    p = argparse.ArgumentParser(
        prog="blender -b scene.blend --python-expr 'import canopy_ao.cli; canopy_ao.cli.main()' --",
        description="Bake Canopy AO into a color attribute of mesh objects.")
    which = p.add_mutually_exclusive_group()
    which.add_argument("--objects", nargs="+", metavar="NAME", help="objects to bake")
    which.add_argument("--all", action="store_true",
                       help="bake every visible mesh (the default when --objects is not given)")
    p.add_argument("--method", default="auto", choices=METHODS,
                   help="model to use (default: auto)")
    p.add_argument("--tau", type=_tau, default=None,
                   help="optical depth, or 'auto' to calibrate (default: auto)")
    p.add_argument("--distance", type=_nonneg, default=None,
                   help="AO distance, 0 = unlimited (default: the World's AO distance, as "
                        "Cycles uses it; unlimited without a world)")
    p.add_argument("--samples", type=_positive_int, default=64,
                   help="rays per vertex for --method raytrace (default: 64)")
    p.add_argument("--time-budget", type=_nonneg, default=2.0,
                   help="auto: seconds the bake may take; richer models predicted to take "
                        "longer are not chosen (0 = no limit; default 2)")
    p.add_argument("--target-error", type=_nonneg, default=0.06,
                   help="auto: stop climbing the ladder once a rung's RMSE on the ray-traced "
                        "sample is below this (default 0.06, about an MAE of 0.05)")
    p.add_argument("--attribute", default="CanopyAO", help="color attribute name")
    p.add_argument("--overwrite", action="store_true",
                   help="replace a same-named attribute Canopy AO did not make")
    p.add_argument("--mode", choices=("vertex", "texel"), default="vertex")
    p.add_argument("--resolution", type=_positive_int, default=1024, help="texel mode: image size")
    p.add_argument("--uv", default="", help="texel mode: UV map (default: active)")
    p.add_argument("--image-dir", default="//canopy_ao", help="texel mode: output folder")
    p.add_argument("--no-proxies", action="store_true", help="do not add proxy empties")
    p.add_argument("--wire-material", action="store_true",
                   help="connect the attribute into the objects' materials")
    p.add_argument("--aov", metavar="NAME", default=None,
                   help="also add a shader + view-layer AOV of this name (not 'AO')")
    p.add_argument("--check-cycles", action="store_true",
                   help="also bake Cycles AO and report the error per object (slow)")
    p.add_argument("--cycles-samples", type=_positive_int, default=64)
    p.add_argument("--report", metavar="FILE.json", help="write a JSON report here")
    p.add_argument("--save", action="store_true", help="save the .blend after baking")
    p.add_argument("--threads", type=_nonneg_int, default=0,
                   help="cap the native core's worker threads (0 = every core; results do "
                        "not depend on it), so several bakes can share a machine")
    return p


def _argv(argv):
    if argv is not None:
        return list(argv)
    return sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []


def _fail(message, code=1):
    sys.stdout.flush()
    print(f"canopy_ao: error: {message}", file=sys.stderr, flush=True)
    sys.exit(code)


def main(argv=None):
    """Parse the args after ``--``, bake, report; sys.exit with 0 on success."""
    args = build_parser().parse_args(_argv(argv))  # exits 2 with usage on bad arguments
    try:
        run(args)
        code = 0
    except BakeFailed as exc:
        _fail(str(exc))
    except SystemExit:
        raise
    except Exception as exc:  # an unexpected failure must still fail the process
        import traceback
        traceback.print_exc()
        _fail(f"{type(exc).__name__}: {exc}")
    sys.stdout.flush()
    sys.exit(code)


def run(args):
    """Bake the open file as ``args`` (from build_parser) say, print one line per object, and
    return the report; raises BakeFailed with a message when the bake cannot be done."""
    import addon_utils
    import bpy

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
    from .blender import gather, job
    from .core.native import CanopyAOError, core_status, require

    ok, msg = core_status()
    if not ok:
        raise BakeFailed(msg)
    if args.threads:
        require().set_max_threads(args.threads)
    if args.save and not bpy.data.filepath:
        raise BakeFailed("--save needs a saved .blend (give the .blend before --python-expr)")
    distance = (args.distance if args.distance is not None
                else gather.world_ao_distance(bpy.context.scene))
    opts = dict(method=args.method, tau=args.tau, distance=distance, samples=args.samples,
                time_budget=args.time_budget, target_rmse=args.target_error,
                attribute=args.attribute, overwrite=args.overwrite,
                wire_material=args.wire_material, add_aov=args.aov is not None,
                aov_name=args.aov or "BakedAO", mode=args.mode.upper(), uv_map=args.uv,
                resolution=args.resolution, image_dir=args.image_dir,
                show_proxies=not args.no_proxies, check_cycles=args.check_cycles,
                cycles_samples=args.cycles_samples)
    context = bpy.context
    if args.objects is None:
        # Headless: "the selection" means nothing here, so bake every visible mesh.
        for ob in context.view_layer.objects:
            ob.select_set(False)
    try:
        bake_job, rep = job.run_bake(context, args.objects or [], opts)
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
    # τ means nothing to the exact rung or the density grid (physical density).
    tau = "" if rep["method"] in ("raytrace", "grid") else f" tau {rep['tau']:.4g}"
    print(f"canopy_ao: {rep['method']}{tau}, {len(bake_job.results)} object(s), "
          f"{rep['seconds']:.2f} s", flush=True)
    for note in rep["notes"]:
        print(f"canopy_ao: note: {note}", flush=True)
    if args.report:
        try:
            with open(bpy.path.abspath(args.report), "w") as f:
                json.dump(rep, f, indent=1, default=float)
        except OSError as exc:
            raise BakeFailed(f"cannot write the report: {exc}") from None
    if args.save:
        bpy.ops.wm.save_mainfile()
        print(f"canopy_ao: saved {bpy.data.filepath}", flush=True)
    return rep
