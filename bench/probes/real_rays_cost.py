"""Probe, answered: Cycles' rays (S at every face corner) cost 1.5–5× S per vertex, the mean corners per vertex (white birch: 1.95× the CPU time, timed with hyperfine).

What Cycles' bake point costs on a real tree: one exact-rung trace of every vertex.

    /usr/bin/python3 bench/probes/real_rays_cost.py SCENE bake|corner|dealt|before [--samples 256]

SCENE is a Sapling export in bench/out/real (bench/real_scenes.py). `bake` traces as the add-on
does (vertex normals: each vertex at Cycles' bake point, a ROBUST scene, Cycles' rays at
`--samples` in all spread evenly over the vertices: core/ray_budget.py), `corner` the same
tracer with `--samples` rays at every face corner (Cycles' deal, the add-on's rule before),
`dealt` with `--samples` rays per vertex dealt out to its corners (per_corner=False, a k-th of
the rays), `before` without normals (the rule before the bake point). Time
them against each other with hyperfine (Debian's package), e.g.

    hyperfine -r 5 "/usr/bin/python3 bench/probes/real_rays_cost.py sap_white_birch bake" \\
        "/usr/bin/python3 bench/probes/real_rays_cost.py sap_white_birch dealt"
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # bench/
import harness  # noqa: E402  (addon/, examples/ and bench/ on sys.path)

import numpy as np  # noqa: E402

import real_scenes as rs  # noqa: E402
from canopy_ao import _core  # noqa: E402


def main():
    ap = harness.parser(__doc__)
    ap.add_argument("scene")
    ap.add_argument("rule", choices=("bake", "corner", "dealt", "before"))
    ap.add_argument("--samples", type=int, default=256)
    a = ap.parse_args()
    sc = rs.load(a.scene)
    tracer = rs.scene_tracer(sc) if a.rule != "before" else _core.RayTracer(sc.V, sc.T)
    ids = np.arange(sc.n_vertices, dtype=np.int32)
    if a.rule == "bake":
        rs.trace_vertices(tracer, sc, a.samples, sc.distance, 0, shared=True)
    else:
        tracer.ao(sc.V, sc.N, samples=a.samples, distance=sc.distance, vertex_ids=ids,
                  per_corner=a.rule == "corner")


if __name__ == "__main__":
    main()
