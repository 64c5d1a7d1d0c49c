"""The real-generator scenes (examples/sapling_scenes.py) as numpy, their references, buried vertices.

Shared by bench/real_assets.py and the tests; needs ``canopy_ao._core`` but no Blender.

- :func:`load` reads ``bench/out/real/<scene>[_quick].npz`` into a :class:`RealScene`.
- :func:`reference` is Embree AO per vertex at many rays (cached beside the scene, keyed by its
  geometry hash and the tracer's build), the AO distance the scene's diagonal (Cycles' meaning).
- :func:`buried` marks leaf and branch vertices whose rays all stop within a tiny distance — a
  fraction :data:`BURIED_FRACTION` of their object's bounding-box diagonal, so the test is
  scale-free: leaf bases inside the branch tube, and branch bases inside their parent's tube
  (Sapling bevels each branch separately; ray-traced AO 0 there, whatever the model). Every
  error figure is reported over all vertices and with these left out.
"""
from __future__ import annotations

import json
import os

import harness  # noqa: E402  (addon/ and examples/ on sys.path)

HERE, REPO = harness.HERE, harness.REPO

import numpy as np  # noqa: E402


REAL = harness.REAL
REF_SEED = 12345
BURIED_FRACTION = 0.01   # of the object's bbox diagonal
BURIED_RAYS = 32


class RealScene:
    """Objects of one exported scene, merged: V (N,3), N (N,3), T (M,3), role/tree/object per vertex."""

    def __init__(self, path):
        self.path = path
        with np.load(path) as z:
            self.names = [str(n) for n in z["names"]]
            self.parts = {}
            for n in self.names:
                self.parts[n] = dict(positions=z[f"{n}/positions"].astype(np.float32),
                                     normals=z[f"{n}/normals"].astype(np.float32),
                                     triangles=z[f"{n}/triangles"].astype(np.int32),
                                     polygons=(z[f"{n}/polygons"].astype(np.int64)
                                               if f"{n}/polygons" in z.files else None),
                                     role=str(z[f"{n}/role"]), tree=str(z[f"{n}/tree"]))
            self.distance = float(z["distance"])
            self.geometry = str(z["geometry"])
            self.info = json.loads(str(z["info"]))
        self.name = os.path.basename(path)[:-4]
        offs = np.cumsum([0] + [len(self.parts[n]["positions"]) for n in self.names])
        self.offsets = offs
        self.V = np.concatenate([self.parts[n]["positions"] for n in self.names])
        self.N = np.concatenate([self.parts[n]["normals"] for n in self.names])
        self.T = np.concatenate([self.parts[n]["triangles"] + o
                                 for n, o in zip(self.names, offs[:-1])]).astype(np.int32)
        self.role = np.concatenate([np.full(b - a, self.parts[n]["role"], dtype=object)
                                    for n, a, b in zip(self.names, offs[:-1], offs[1:])])
        self.tree = np.concatenate([np.full(b - a, self.parts[n]["tree"], dtype=object)
                                    for n, a, b in zip(self.names, offs[:-1], offs[1:])])
        self.object = np.repeat(np.arange(len(self.names)), np.diff(offs))

    @property
    def n_vertices(self):
        return len(self.V)

    def items(self):
        """(name, role, tree, positions, normals, triangles) per object."""
        for n in self.names:
            p = self.parts[n]
            yield n, p["role"], p["tree"], p["positions"], p["normals"], p["triangles"]

    def engine_items(self):
        """The add-on's SceneItems of this scene (roles, trees and faces as exported)."""
        from canopy_ao import core
        return [core.SceneItem(n, self.parts[n]["role"].upper(), self.parts[n]["tree"],
                               self.parts[n]["positions"], self.parts[n]["normals"],
                               self.parts[n]["triangles"], polygons=self.parts[n]["polygons"])
                for n in self.names]



def cycles_bake(sc: RealScene, samples, seed=0):
    """(AO float32 over all vertices, as sc.V; seconds) of the Cycles bake at ``samples`` with
    Cycles' seed ``seed`` cached beside the scene (examples/sapling_scenes.py --bake-cycles
    [--cycles-seed]), or None: not baked, or baked from other geometry."""
    path = sc.path[:-4] + f"_cycles_{samples}{f'_seed{seed}' if seed else ''}.npz"
    if not os.path.exists(path):
        return None
    with np.load(path) as z:
        if str(z["geometry"]) != sc.geometry:
            return None
        return (np.concatenate([z[f"ao/{n}"] for n in sc.names]).astype(np.float32),
                float(z["seconds"]))


def cycles_ao(sc: RealScene, samples, seed=0):
    """The AO of cycles_bake, or None."""
    got = cycles_bake(sc, samples, seed)
    return got[0] if got is not None else None


def cycles_runs(sc: RealScene):
    """{samples: (AO, seconds)} of every seed-0 Cycles bake cached beside the scene, by sample
    count."""
    stem = os.path.basename(sc.path)[:-4] + "_cycles_"
    counts = sorted(int(f[len(stem):-4]) for f in os.listdir(os.path.dirname(sc.path))
                    if f.startswith(stem) and f.endswith(".npz") and f[len(stem):-4].isdigit())
    runs = {s: cycles_bake(sc, s) for s in counts}
    return {s: r for s, r in runs.items() if r is not None}


def scene_path(scene, quick=True, out_dir=REAL):
    return os.path.join(out_dir, f"{scene}{'_quick' if quick else ''}.npz")


def load(scene, quick=True, out_dir=REAL):
    path = scene_path(scene, quick, out_dir)
    if not os.path.exists(path):
        raise FileNotFoundError(
            f"{path} missing: run blender -b --factory-startup --python "
            f"examples/sapling_scenes.py -- --scenes {scene}{' --quick' if quick else ''}")
    return RealScene(path)


tracer_tag = harness.tracer_tag  # which tracer made a reference (tests/python/test_raytrace.py)


def scene_tracer(sc: RealScene):
    """The scene's ray tracer, built by the add-on's own lighting.build_tracer from its items:
    with the vertex normals and, where the export has them, Blender's faces, so every vertex
    starts at Cycles' bake point (the items' vertices in the scene's order, as sc.V)."""
    from canopy_ao.core import lighting
    return lighting.build_tracer(sc.engine_items())


def trace_vertices(tracer, sc, samples, distance, seed, rows=slice(None), per_corner=True,
                   shared=False):
    """AO at the scene's own vertices ``rows``, each skipping only its own triangles; samples
    per face corner (as Cycles), or dealt out to the corners (per_corner=False, an older rule).
    shared=True: as the add-on's exact rung bakes the scene's vertices (every one a receiver):
    Cycles' rays in all, spread evenly over the vertices (core/ray_budget.py)."""
    if shared:
        from canopy_ao.core import ray_budget
        return ray_budget.trace_mesh(tracer, sc.V, sc.N, samples, seed, distance, rows)
    ids = np.arange(sc.n_vertices, dtype=np.int32)[rows]
    return np.asarray(tracer.ao(sc.V[rows], sc.N[rows], samples=samples, distance=distance,
                                seed=seed, vertex_ids=ids, per_corner=per_corner), np.float32)


def reference(sc: RealScene, samples=1024, tracer=None):
    """(Embree AO over all vertices at ``samples`` rays, seconds), cached beside the scene."""
    path = sc.path[:-4] + f"_embree_{samples}.npz"
    key = dict(geometry=sc.geometry, tracer=harness.tracer_tag())
    z = harness.load_cached(path, **key)
    if z is not None:
        return z["ao"].astype(np.float32), float(z["seconds"])
    ao, dt = harness.timed(lambda: trace_vertices(tracer or scene_tracer(sc), sc, samples,
                                                  sc.distance, REF_SEED))
    harness.save_cached(path, dict(ao=ao, seconds=dt, samples=samples), **key)
    return ao, dt


def buried(sc: RealScene, tracer=None):
    """bool (N,): leaf and branch (canopy, trunk) vertices whose rays all stop within
    BURIED_FRACTION of their object's bounding-box diagonal (AO traced to that distance is 0)."""
    tracer = tracer or scene_tracer(sc)
    out = np.zeros(sc.n_vertices, bool)
    for k, n in enumerate(sc.names):
        p = sc.parts[n]
        if p["role"] not in ("canopy", "trunk") or not len(p["positions"]):
            continue
        a, b = sc.offsets[k], sc.offsets[k + 1]
        diag = float(np.linalg.norm(p["positions"].max(0) - p["positions"].min(0)))
        near = trace_vertices(tracer, sc, BURIED_RAYS, max(BURIED_FRACTION * diag, 1e-9), 7,
                              slice(a, b))
        out[a:b] = near <= 0.0
    return out
