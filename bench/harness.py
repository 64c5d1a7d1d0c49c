"""What every benchmark study shares: import paths, scenes, reference caches, timing, tables, arguments.

A study starts with ``import harness`` (bench/ is the script's own folder, so it is on the path)
and gets:

- **paths**: ``addon/`` (``canopy_ao``), ``examples/`` (the scenes) and ``bench/`` on
  ``sys.path``, once; :data:`REPO`, :data:`OUT` (``bench/out``, not tracked), :data:`CACHE`
  (``bench/out/cache``: the synthetic scenes' Embree and Cycles references), :data:`REAL`
  (``bench/out/real``: the Sapling exports and their Cycles bakes), :data:`RESULTS`;
- **scenes**: :func:`synthetic` (examples/canopy_scenes.py, quick or full size) and
  :func:`real` / :func:`real_names` (the Sapling exports, read by bench/real_scenes.py);
- **caches**: :func:`load_cached` / :func:`save_cached`, ``.npz`` files keyed by what made them
  (geometry hash, tracer rule, distance), so a stale reference is traced again, never reused;
- **timing**: :func:`timed` (best of a few runs) and :func:`interleave` (several contenders
  timed in turn, round after round, so a load spike on this shared machine hits them alike:
  min and median per contender, ratios taken within that one run);
- **tables**: :func:`markdown`;
- **arguments**: :func:`parser` (the common ``--quick``, ``--scenes``, ``--repeats``) and, for
  scripts run inside Blender, :func:`blender_args` / :func:`run_in_blender`.

Nothing here imports Blender or the native module at import time.
"""
from __future__ import annotations

import argparse
import math
import os
import statistics
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
ADDON = os.path.join(REPO, "addon")
EXAMPLES = os.path.join(REPO, "examples")
OUT = os.path.join(HERE, "out")
CACHE = os.path.join(OUT, "cache")
REAL = os.path.join(OUT, "real")
RESULTS = os.path.join(HERE, "results")


def setup_paths():
    """Put addon/, examples/ and bench/ on sys.path (each once, in that order of precedence)."""
    for p in (HERE, EXAMPLES, ADDON):
        if p not in sys.path:
            sys.path.insert(0, p)


setup_paths()


def log(*a):
    print(*a, flush=True)


# === Scenes ==================================================================================

def synthetic(name, quick=False, seed=0, **kwargs):
    """One of examples/canopy_scenes.py's scenes (quick: the small sizes the tests use)."""
    import canopy_scenes
    return canopy_scenes.make_scene(name, seed=seed, quick=quick, **kwargs)


def synthetic_names(large=False):
    """The synthetic scenes a study runs by default (the ≥ 1M-vertex large_tree only if asked)."""
    import canopy_scenes
    return [n for n in canopy_scenes.SCENES if large or n != "large_tree"]


def real(name, quick=True):
    """A Sapling export (bench/real_scenes.RealScene); FileNotFoundError names the command
    that writes it."""
    import real_scenes
    return real_scenes.load(name, quick)


def real_names(quick=True, cycles=None, seed=0):
    """The Sapling exports in bench/out/real, sorted; with ``cycles=N`` only those with a
    Cycles bake at N samples (Cycles' seed ``seed``) cached beside them."""
    if not os.path.isdir(REAL):
        return []
    tail = "_quick.npz" if quick else ".npz"
    names = sorted(f[:-len(tail)] for f in os.listdir(REAL)
                   if f.endswith(tail) and "_cycles_" not in f and "_embree_" not in f
                   and (quick or not f.endswith("_quick.npz")))
    if cycles is None:
        return names
    stem = f"_cycles_{cycles}{f'_seed{seed}' if seed else ''}"
    return [n for n in names
            if os.path.exists(os.path.join(REAL, f"{n}{'_quick' if quick else ''}{stem}.npz"))]


# === Reference caches ========================================================================

def load_cached(path, **key):
    """The arrays of the ``.npz`` at ``path`` as a dict if it exists and every ``key`` matches
    what it was saved with (numbers by value, anything else as text: hashes, tags), else
    None."""
    import numbers

    import numpy as np
    if not os.path.exists(path):
        return None
    with np.load(path) as z:
        for k, v in key.items():
            if k not in z.files:
                return None
            got = z[k].item() if z[k].ndim == 0 else z[k]
            same = (float(got) == float(v) if isinstance(v, numbers.Number)
                    and isinstance(got, numbers.Number) else str(got) == str(v))
            if not same:
                return None
        return {k: z[k] for k in z.files}


def save_cached(path, arrays, **key):
    """Write ``arrays`` and the ``key`` they were made from to ``path`` (compressed .npz)."""
    import numpy as np
    os.makedirs(os.path.dirname(path), exist_ok=True)
    np.savez_compressed(path, **arrays, **key)


def tracer_tag():
    """Which ray tracer made a reference (native raytrace.h's rule for vertex starts): a cache
    made by another rule is traced again."""
    from canopy_ao import _core
    return _core.TRACER_RULE


# === Timing ==================================================================================

def timed(fn, repeats=1, stop_after=math.inf):
    """(fn's last result, best seconds of up to ``repeats`` runs); stops repeating once a run
    took longer than ``stop_after`` seconds (its noise is then small against its length)."""
    best, res = math.inf, None
    for _ in range(max(1, repeats)):
        t0 = time.perf_counter()
        res = fn()
        dt = time.perf_counter() - t0
        best = min(best, dt)
        if dt > stop_after:
            break
    return res, best


class Timing:
    """Seconds of one contender over the rounds of an :func:`interleave`."""

    def __init__(self, name):
        self.name = name
        self.seconds = []
        self.result = None

    @property
    def min(self):
        return min(self.seconds) if self.seconds else math.nan

    @property
    def median(self):
        return statistics.median(self.seconds) if self.seconds else math.nan

    def __repr__(self):
        return f"Timing({self.name!r}, min {self.min:.4g} s, median {self.median:.4g} s)"


def interleave(contenders, repeats=3, warmup=False):
    """Time every contender (name -> zero-argument callable) once per round, ``repeats``
    rounds, the order rotated each round: {name: Timing} with every round's seconds and the
    last result. A shared machine's load then falls on all of them alike, so the ratios of
    one call's results are the figures to quote, not the seconds. ``warmup``: one untimed
    call of each first (imports, caches, thread pools)."""
    names = list(contenders)
    out = {n: Timing(n) for n in names}
    if warmup:
        for n in names:
            out[n].result = contenders[n]()
    for r in range(max(1, repeats)):
        k = r % len(names) if names else 0
        for n in names[k:] + names[:k]:
            t0 = time.perf_counter()
            out[n].result = contenders[n]()
            out[n].seconds.append(time.perf_counter() - t0)
    return out


def ratio(a, b):
    """a / b, NaN when b is not positive (a ratio of two times of one run)."""
    return a / b if b > 0 else math.nan


def load_note():
    """'load average X on N cores': printed with every timing, the machine being shared."""
    try:
        la = os.getloadavg()[0]
    except OSError:
        return f"{os.cpu_count()} cores"
    return f"load average {la:.2f} on {os.cpu_count()} cores"


# === Tables ==================================================================================

def write_text(path, text):
    """Write ``text`` to ``path`` (its folder made) and print it."""
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with open(path, "w", encoding="utf-8") as f:
        f.write(text)
    print(text)


def markdown(header, rows, align=None):
    """A markdown table: ``header`` a list of column titles, ``rows`` lists of cells (str()
    of each); ``align`` a string of 'l' / 'r' per column (default: left)."""
    def line(cells):
        return "| " + " | ".join(str(c) for c in cells) + " |"
    rule = ["---:" if a == "r" else "---" for a in (align or "l" * len(header))]
    return "\n".join([line(header), "|" + "|".join(rule) + "|"] + [line(r) for r in rows])


def fmt_seconds(s):
    """Seconds with two significant figures in plain notation (0.013 s, 1.2 s, 340 s)."""
    if not math.isfinite(s):
        return "–"
    if s >= 100:
        return f"{s:.0f} s"
    return f"{float(f'{s:.2g}'):g} s"


# === Arguments ===============================================================================

def parser(doc, prog=None, quick=False, scenes=None, repeats=None):
    """An ArgumentParser described by the first paragraph of ``doc`` (a module docstring);
    ``quick``: adds --quick; ``scenes``: adds --scenes NAME ... with that default (a list, or
    [] for 'every scene found'); ``repeats``: adds --repeats N with that default."""
    ap = argparse.ArgumentParser(prog=prog, description=(doc or "").strip().split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    if quick:
        ap.add_argument("--quick", action="store_true", help="small scenes / fewer cases")
    if scenes is not None:
        ap.add_argument("--scenes", nargs="*", default=scenes, metavar="NAME",
                        help="scenes to run (default: %(default)s)" if scenes
                        else "scenes to run (default: every one found)")
    if repeats is not None:
        ap.add_argument("--repeats", type=int, default=repeats,
                        help="timed runs per case, interleaved (default: %(default)s)")
    return ap


def blender_args():
    """The arguments after ``--`` of a ``blender -b --python script.py -- ...`` command."""
    return sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []


def enable_addon():
    """Enable the canopy_ao add-on in the running Blender (from BLENDER_USER_SCRIPTS, else
    this checkout's addon/), and check its native core loaded; RuntimeError says why not."""
    import importlib.util

    import addon_utils
    if importlib.util.find_spec("canopy_ao") is None:
        sys.path.insert(0, ADDON)
    if addon_utils.enable("canopy_ao", default_set=True, handle_error=None) is None:
        raise RuntimeError("the canopy_ao add-on did not enable")
    from canopy_ao import core
    ok, msg = core.core_status()
    if not ok:
        raise RuntimeError(msg)


def run_and_exit(main, name):
    """Run ``main(argv)`` inside Blender with the arguments after ``--``, then leave at once
    (os._exit: no teardown, so a live session's handlers still registered run no more); a
    failure prints its traceback and ``name: error: ...`` and exits 1."""
    try:
        main(blender_args())
    except Exception as exc:  # noqa: BLE001
        import traceback
        traceback.print_exc()
        print(f"{name}: error: {exc}", file=sys.stderr)
        sys.stdout.flush()
        os._exit(1)
    sys.stdout.flush()
    os._exit(0)


def run_in_blender(main, name):
    """Run ``main(argv)`` inside Blender with the arguments after ``--``; a failure prints
    ``name: error: ...`` and exits non-zero (examples/blender_script.run)."""
    from blender_script import run
    run(main, name)
