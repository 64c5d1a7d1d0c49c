"""What Cycles' bake point costs on a real tree: one exact-rung trace of every vertex.

    /usr/bin/python3 bench/real_rays_cost.py SCENE bake|before [--samples 256]

SCENE is a Sapling export in bench/out/real (bench/real_scenes.py). `bake` builds the tracer as
the add-on does (vertex normals: each vertex at Cycles' bake point, a ROBUST scene), `before`
without them (the rule before). Time the two against each other with farm-bench, e.g.

    farm-bench -n 5 --timeout 400 \\
        --vs "/usr/bin/python3 bench/real_rays_cost.py sap_white_birch before" \\
        -- /usr/bin/python3 bench/real_rays_cost.py sap_white_birch bake
"""
import argparse
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

import numpy as np  # noqa: E402

import real_scenes as rs  # noqa: E402
from canopy_ao import _core  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scene")
    ap.add_argument("rule", choices=("bake", "before"))
    ap.add_argument("--samples", type=int, default=256)
    a = ap.parse_args()
    sc = rs.load(a.scene)
    tracer = rs.scene_tracer(sc) if a.rule == "bake" else _core.RayTracer(sc.V, sc.T)
    ids = np.arange(sc.n_vertices, dtype=np.int32)
    tracer.ao(sc.V, sc.N, samples=a.samples, distance=sc.distance, vertex_ids=ids)


if __name__ == "__main__":
    main()
