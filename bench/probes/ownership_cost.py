"""Probe, answered: the ownership fingerprint costs 1.2 ms per 1M-vertex colour attribute against SHA-1's 9.5 ms (docs/DESIGN.md, 'Ownership of what a bake writes').

What the ownership check costs a write (docs/DESIGN.md, 'Ownership of what a bake writes').

    blender -b --factory-startup --python bench/probes/ownership_cost.py -- [--vertices 100000 1000000]

The add-on is found as in scripts/test.sh (BLENDER_USER_SCRIPTS with addons/canopy_ao) or,
without it, from this repository's addon/. Per size, the median of 9 rounds, each round timing
in turn: the fingerprint of the colour values (numpy), SHA-1 over the same bytes (for scale),
the check (read the attribute back and fingerprint it), the write (build the colours,
foreach_set, fingerprint them), and check + write (what Live AO does per object per frame).
The machine is shared: the load average is printed with the numbers.
"""

import hashlib
import os
import statistics
import sys
import time

import bpy
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # bench/
import harness  # noqa: E402  (addon/ and examples/ on sys.path)


def _addon():
    harness.enable_addon()
    from canopy_ao.blender import mesh_io, ownership
    from canopy_ao.core.fingerprint import fingerprint
    return mesh_io, ownership, fingerprint


def main(argv):
    ap = harness.parser(__doc__)
    ap.add_argument("--vertices", type=int, nargs="+", default=[100_000, 1_000_000])
    ap.add_argument("--rounds", type=int, default=9)
    args = ap.parse_args(argv)
    mesh_io, ownership, fingerprint = _addon()
    print(f"load average {os.getloadavg()[0]:.1f}; ms, median of {args.rounds} rounds")
    print("| vertices | fingerprint | SHA-1 (same bytes) | check | write | check + write |")
    print("|---|---|---|---|---|---|")
    for n in args.vertices:
        me = bpy.data.meshes.new(f"M{n}")
        me.vertices.add(n)
        ob = bpy.data.objects.new(f"M{n}", me)
        bpy.context.scene.collection.objects.link(ob)
        ao = np.random.default_rng(n).random(n).astype(np.float32)
        mesh_io.write_ao_attribute(ob, "CanopyAO", ao)
        rgba = ownership.read_attribute(me.attributes["CanopyAO"])

        def check():
            assert mesh_io.check_attribute(ob, "CanopyAO", False) is None

        def write():
            mesh_io.write_ao_attribute(ob, "CanopyAO", ao, checked=True)

        def both():
            check()
            write()

        stages = {"fingerprint": lambda: fingerprint(rgba, "x"),
                  "sha1": lambda: hashlib.sha1(rgba).digest(),
                  "check": check, "write": write, "both": both}
        times = {k: [] for k in stages}
        for _ in range(args.rounds):
            for k, fn in stages.items():
                t0 = time.perf_counter()
                fn()
                times[k].append(1e3 * (time.perf_counter() - t0))
        m = {k: statistics.median(v) for k, v in times.items()}
        print(f"| {n:,} | {m['fingerprint']:.1f} | {m['sha1']:.1f} | {m['check']:.1f} | "
              f"{m['write']:.1f} | {m['both']:.1f} |")
        bpy.data.objects.remove(ob)
        bpy.data.meshes.remove(me)


if __name__ == "__main__":
    main(sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else [])
