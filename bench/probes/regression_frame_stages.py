"""Probe, answered: one core's time of the ray-free rung's live frame goes to the features at the receivers (the 24 directions' scattered look-ups), the sweeps, the density grid, the proxy fits it never reads, the prediction and, on Sapling leaves, the leaf tables in numpy (docs/studies/speed.md, 'Live AO per frame').

Where the ray-free (regression) rung's live frame spends its CPU, stage by stage.

    blender -b --factory-startup --python-exit-code 1 --python bench/probes/regression_frame_stages.py -- \
        [--vertices 100000] [--trees crown sapling] [--frames 6]

On bench/live_speed.py's trees (a keyed Simple Deform bend over a ground plane), starts live
AO with the regression rung, caps the native core at one thread (_core.set_max_threads(1), so
a stage's CPU is all on the thread that calls it) and wraps the functions a frame calls with
time.thread_time: the whole frame (live_session.Session.evaluate: read, refit, evaluate, on
the calling thread, plus the grid's own thread), and inside it the proxy fits, the density
grid, the sweeps (OcclusionFeatures), the tree frame, the leaf tables, the features
(RegressionRung._compute, the leaf tables' columns included) and the prediction. Prints the
mean milliseconds of one core per frame.
Thread CPU time counts only while the thread runs, so a shared machine's load inflates it far
less than the wall clock (the load average is printed with the numbers).
"""

import collections
import os
import sys
import time

import bpy

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # bench/
import harness  # noqa: E402
import live_speed  # noqa: E402

_CPU = collections.defaultdict(float)  # label -> thread CPU seconds over the frames


def _timed(owner, attr, label):
    fn = getattr(owner, attr)

    def wrapper(*a, **kw):
        t0 = time.thread_time()
        try:
            return fn(*a, **kw)
        finally:
            _CPU[label] += time.thread_time() - t0
    setattr(owner, attr, wrapper)


class _TimedCore:
    """The native module, its DensityGrid and OcclusionFeatures constructors timed."""

    def __init__(self, core):
        self._core = core

    def __getattr__(self, name):
        value = getattr(self._core, name)
        if name not in ("DensityGrid", "OcclusionFeatures"):
            return value

        def made(*a, **kw):
            t0 = time.thread_time()
            try:
                return value(*a, **kw)
            finally:
                _CPU[f"{name} (grid)" if name == "DensityGrid" else f"{name} (sweeps)"] += \
                    time.thread_time() - t0
        return made


def _instrument():
    from canopy_ao.blender import live_session
    from canopy_ao.core import (leaf_features, proxies, regression, regression_fit,
                                regression_geometry)
    core = regression.native.require()
    timed_core = _TimedCore(core)
    regression.native.require = lambda: timed_core
    for owner, attr, label in (
            (live_session.Session, "evaluate", "frame"), (proxies, "fit_scene", "proxy fits"),
            (regression_geometry, "tree_frame", "tree frame"),
            (leaf_features.LeafTable, "__init__", "leaf tables"),
            (leaf_features.LeafTable, "features", "leaf table columns"),
            (regression.RegressionRung, "_compute", "features (with leaf columns)"),
            (regression_fit.Model, "predict", "prediction")):
        _timed(owner, attr, label)
    return core


def run(tree, n, frames):
    from canopy_ao.blender import job, live, properties
    scene, names = live_speed.TREES[tree](n)
    opts = dict(properties.scene_options(scene), method="regression", tau=1.5, distance=0.0,
                show_proxies=False, live=True)
    job.run_bake(bpy.context, names, opts)
    scene.frame_set(2)
    _CPU.clear()
    for f in range(3, 3 + frames):
        scene.frame_set(f)
    live.stop(scene)
    n_vertices = sum(len(scene.objects[nm].data.vertices) for nm in names[:-1])
    print(f"{tree} {n_vertices:,} vertices: ms of one core per frame")
    # The grid and its sweeps run on a thread of their own (core/regression_geometry.py),
    # beside the frame's: the whole frame is the two threads' time.
    whole = _CPU.pop("frame") + sum(v for k, v in _CPU.items() if k.startswith(
        ("DensityGrid", "OcclusionFeatures")))
    for label, seconds in list(_CPU.items()) + [("whole frame (read, refit, evaluate)", whole)]:
        print(f"    {label:<36} {1000.0 * seconds / frames:7.1f}")


def main(argv):
    ap = harness.parser(__doc__, prog="regression_frame_stages.py")
    ap.add_argument("--vertices", type=int, nargs="+", default=[100_000])
    ap.add_argument("--trees", nargs="+", choices=sorted(live_speed.TREES),
                    default=["crown", "sapling"])
    ap.add_argument("--frames", type=int, default=6)
    a = ap.parse_args(argv)
    harness.enable_addon()
    core = _instrument()
    core.set_max_threads(1)
    print(f"the regression rung's live frame, one core; {harness.load_note()}; "
          f"Blender {bpy.app.version_string}")
    for tree in a.trees:
        for n in a.vertices:
            run(tree, n, a.frames)


if __name__ == "__main__":
    harness.run_and_exit(main, "regression_frame_stages")
