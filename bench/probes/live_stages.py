"""Probe, answered: the largest part of a live frame's read was foreach_get on the vertex normals, element by element (2.0 ms per 100k vertices against 0.09 for one copy of Blender's cached array); the fits, the native evaluation and the ownership check with the two writes are what stays (docs/studies/speed.md, 'Live AO per frame').

Where a live AO frame's time goes, finer than bench/live_speed.py's four stages.

    blender -b --factory-startup --python bench/probes/live_stages.py -- \
        [--vertices 100000 1000000] [--methods sphere ellipsoid] [--frames 8]

On bench/live_speed.py's crown (a keyed Simple Deform bend over a ground plane), wraps the
functions a live frame calls with timers and prints, per size and rung, the median over the
frames of each one's milliseconds per frame (summed over its calls), beside the handler's total
and Blender's own frame (live off). Read's parts come from mesh_io.evaluated_arrays' own
timings (fetch, positions, normals, transform). Then the leaves' vertex normals at the last
frame read both ways, the median of 9 reads each: foreach_get on vertex_normals (element by
element) and mesh_io's one copy of the cached array, checked bit for bit equal. The machine
is shared: the load average is printed with the numbers.
"""

import functools
import os
import statistics
import sys
import time

import bpy

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # bench/
import harness  # noqa: E402
import live_speed  # noqa: E402

_FRAME = {}  # this frame's seconds per label


def _timed(owner, attr, label):
    fn = getattr(owner, attr)

    @functools.wraps(fn)
    def wrapper(*a, **kw):
        t0 = time.perf_counter()
        try:
            return fn(*a, **kw)
        finally:
            _FRAME[label] = _FRAME.get(label, 0.0) + time.perf_counter() - t0
    setattr(owner, attr, wrapper)


def _instrument():
    from canopy_ao.blender import live_render, live_session, loop, mesh_io
    from canopy_ao.core import live as core_live
    read = mesh_io.evaluated_arrays

    def evaluated_arrays(*a, **kw):
        kw.setdefault("timings", _FRAME)
        return read(*a, **kw)
    mesh_io.evaluated_arrays = evaluated_arrays
    for owner, attr, label in (
            (core_live, "frame_items", "frame_items"), (core_live, "refit", "refit"),
            (loop.Loop, "run", "loop.run"), (mesh_io, "check_attribute", "check_attribute"),
            (mesh_io, "write_evaluated_ao", "write evaluated"),
            (mesh_io, "write_ao_attribute", "write original"),
            (mesh_io, "mark_owned", "  of which mark_owned"),
            (live_render, "geometry_updated", "geometry_updated"),
            (mesh_io, "evaluated_ao_attribute", "evaluated_ao_attribute")):
        _timed(owner, attr, label)
    return live_session


def _normals_read(obj):
    """(ms of foreach_get, ms of mesh_io._vertex_normals) on obj's evaluated mesh, medians."""
    import numpy as np
    from canopy_ao.blender import mesh_io
    mesh = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
    n = len(mesh.vertices)
    slow, fast = [], []
    for _ in range(9):
        ref = np.empty((n, 3), np.float32)
        t0 = time.perf_counter()
        mesh.vertex_normals.foreach_get("vector", ref.reshape(-1))
        t1 = time.perf_counter()
        got = mesh_io._vertex_normals(mesh, n)
        t2 = time.perf_counter()
        assert np.array_equal(got, ref), "the copied normals differ from foreach_get's"
        slow.append(t1 - t0)
        fast.append(t2 - t1)
    return 1000 * statistics.median(slow), 1000 * statistics.median(fast)


def run(n, method, frames):
    from canopy_ao.blender import job, live, properties
    scene, names = live_speed.animated_tree(n)
    opts = dict(properties.scene_options(scene), method=method, tau=1.5, distance=0.0,
                show_proxies=False, live=True)
    job.run_bake(bpy.context, names, opts)
    session = live.session_of(scene)
    rows, whole = {}, []
    for f in range(2, 2 + frames):
        _FRAME.clear()
        t0 = time.perf_counter()
        scene.frame_set(f)
        whole.append(time.perf_counter() - t0)
        for k, v in list(_FRAME.items()) + [(f"live {k}", v) for k, v in session.timings.items()]:
            rows.setdefault(k, []).append(v)
    live.stop(scene)
    alone = []
    for f in range(2 + frames, 2 + 2 * frames):
        t0 = time.perf_counter()
        scene.frame_set(f)
        alone.append(time.perf_counter() - t0)
    print(f"{n:,} vertices, {method}: frame {1000 * statistics.median(whole):.2f} ms, "
          f"blender only {1000 * statistics.median(alone):.2f} ms")
    for k in sorted(rows):
        print(f"    {k:<26} {1000 * statistics.median(rows[k]):7.2f} ms")
    slow, fast = _normals_read(scene.objects[names[0]])
    print(f"    leaves' vertex normals: foreach_get {slow:.2f} ms, one copy {fast:.2f} ms "
          "(bit for bit equal)")


def main(argv):
    ap = harness.parser(__doc__, prog="live_stages.py")
    ap.add_argument("--vertices", type=int, nargs="+", default=[100_000])
    ap.add_argument("--methods", nargs="+", default=["sphere", "ellipsoid"])
    ap.add_argument("--frames", type=int, default=8)
    a = ap.parse_args(argv)
    harness.enable_addon()
    _instrument()
    print(f"live AO stages per frame, median of {a.frames} frames; {harness.load_note()}; "
          f"Blender {bpy.app.version_string}")
    for n in a.vertices:
        for m in a.methods:
            run(n, m, a.frames)


if __name__ == "__main__":
    harness.run_and_exit(main, "live_stages")
