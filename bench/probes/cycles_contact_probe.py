"""Probe, answered: Cycles starts a vertex's rays 1e-4 × max(1, largest |coordinate|) towards each face corner's centroid (its bake point), which the tracer now does (native raytrace.h, 'Origins').

Where our rays and Cycles' disagree on a real tree: the smallest scene that shows it, in Blender.

    BLENDER_USER_SCRIPTS=<dir with addons/canopy_ao> blender -b --factory-startup \\
        --python bench/probes/cycles_contact_probe.py -- [--scene sap_white_birch] [--vertices 3]

Needs the scene's export and its 1024-sample Cycles bake in bench/out/real (bench/README.md,
"Real trees": examples/sapling_scenes.py, then bench/cycles_reference.py). docs/DESIGN.md,
'Rays against Cycles' samples', says what it found.

It takes the contact vertices (a ray blocked within 1e-4 of the AO distance) where our rays
(256, the rule before the bake point: own triangles skipped, a hair from the vertex) and
Cycles' 1024-sample bake disagree most, the
--vertices most positive and most negative. For each it cuts the smallest scene that still
disagrees: the vertex's own piece (the connected part of its mesh within 1e-3 of the AO distance)
and the one nearest triangle of any other piece whose plane it lies close to. Cycles bakes that
little mesh (1024 samples, AO distance 3e-3 of the scene's, smooth shading as exported), our
tracer traces it with the rule before and at Cycles' bake point (given the vertex normals, as
the add-on builds it), and then the other triangle is moved along its normal so that its plane
passes at the printed signed gaps from the vertex (positive: the vertex is on the side the
triangle's normal points to), to show where Cycles' answer turns over and where ours does.
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # bench/
import harness  # noqa: E402  (addon/, examples/ and bench/ on sys.path)

import addon_utils  # noqa: E402
import bpy  # noqa: E402
import numpy as np  # noqa: E402

addon_utils.enable("canopy_ao")
from canopy_ao import _core  # noqa: E402
from canopy_ao.blender import cycles_check  # noqa: E402

REAL = harness.REAL
CONTACT = 1e-4  # of the AO distance (bench/real_rays.py)
GAPS_UM = (-300, -150, -75, 0, 75, 150, 300)  # signed gaps to try, micrometres


def load(scene):
    path = os.path.join(REAL, f"{scene}_quick.npz")
    ref_path = os.path.join(REAL, f"{scene}_quick_cycles_1024.npz")
    for p in (path, ref_path):
        if not os.path.exists(p):
            sys.exit(f"cycles_contact_probe: {p} is missing (bench/README.md, 'Real trees')")
    with np.load(path) as z:
        names = [str(n) for n in z["names"]]
        parts = [(z[f"{n}/positions"].astype(np.float32), z[f"{n}/normals"].astype(np.float32),
                  z[f"{n}/triangles"].astype(np.int64)) for n in names]
        distance, geometry = float(z["distance"]), str(z["geometry"])
    with np.load(ref_path) as z:
        if str(z["geometry"]) != geometry:
            sys.exit(f"cycles_contact_probe: {ref_path} was baked from other geometry")
        ref = np.concatenate([z[f"ao/{n}"] for n in names]).astype(np.float32)
    offs = np.cumsum([0] + [len(p[0]) for p in parts])
    v = np.concatenate([p[0] for p in parts])
    n = np.concatenate([p[1] for p in parts])
    t = np.concatenate([p[2] + o for p, o in zip(parts, offs[:-1])])
    return v, n, t, ref, distance


def pieces(tris):
    """Connected-component label per triangle (shared vertices), by union-find."""
    parent = np.arange(tris.max() + 1 if len(tris) else 0)

    def find(x):
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    for a, b, c in tris:
        ra, rb, rc = find(a), find(b), find(c)
        parent[rb] = ra
        parent[rc] = ra
    return np.array([find(a) for a in tris[:, 0]])


def nearest_other(v, t, k, own_mask):
    """(triangle, signed plane distance) of the other piece's triangle nearest vertex k whose
    plane projection of k lies inside it."""
    a, b, c = (v[t[:, i]].astype(np.float64) for i in range(3))
    ng = np.cross(b - a, c - a)
    ng /= np.maximum(np.linalg.norm(ng, axis=1, keepdims=True), 1e-300)
    p = v[k].astype(np.float64)
    s = np.einsum("ij,ij->i", p - a, ng)
    q = p - s[:, None] * ng
    e0, e1, e2 = b - a, c - a, q - a
    d00, d01, d11 = (np.einsum("ij,ij->i", x, y) for x, y in ((e0, e0), (e0, e1), (e1, e1)))
    d20, d21 = np.einsum("ij,ij->i", e2, e0), np.einsum("ij,ij->i", e2, e1)
    den = np.where(d00 * d11 - d01 * d01 == 0, 1e-300, d00 * d11 - d01 * d01)
    bv = (d11 * d20 - d01 * d21) / den
    bw = (d00 * d21 - d01 * d20) / den
    inside = (bv >= 0) & (bw >= 0) & (bv + bw <= 1) & ~own_mask
    if not inside.any():
        return None, None, None
    i = np.flatnonzero(inside)[np.argmin(np.abs(s[inside]))]
    return int(i), float(s[i]), ng[i]


def bake_little(v, tris, k_local, distance):
    """(Cycles, ours before, ours at the bake point) AO at local vertex k_local of the mesh
    (v, tris), 1024 samples/rays: the tracer without and with vertex normals."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    me = bpy.data.meshes.new("probe")
    me.from_pydata(v.tolist(), [], tris.tolist())
    me.update()
    for poly in me.polygons:
        poly.use_smooth = True
    ob = bpy.data.objects.new("probe", me)
    bpy.context.scene.collection.objects.link(ob)
    res = cycles_check.bake_cycles_vertex_ao(bpy.context, [ob], distance, 1024)
    cyc = float(np.asarray(res["probe"])[k_local])
    vv = np.array([x.co[:] for x in me.vertices], np.float32)
    nn = np.array([x.normal[:] for x in me.vertices], np.float32)
    tri32 = np.ascontiguousarray(tris, np.int32)
    one = dict(samples=1024, distance=distance, vertex_ids=np.array([k_local], np.int32))
    before = float(_core.RayTracer(vv, tri32).ao(vv[k_local:k_local + 1],
                                                 nn[k_local:k_local + 1], **one)[0])
    bake = float(_core.RayTracer(vv, tri32, normals=nn).ao(vv[k_local:k_local + 1],
                                                           nn[k_local:k_local + 1], **one)[0])
    return cyc, before, bake


def main():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    ap = harness.parser(__doc__)
    ap.add_argument("--scene", default="sap_white_birch")
    ap.add_argument("--vertices", type=int, default=3)
    args = ap.parse_args(argv)
    v, n, t, ref, distance = load(args.scene)
    tracer = _core.RayTracer(v, np.ascontiguousarray(t, np.int32))
    ids = np.arange(len(v), dtype=np.int32)
    ours = np.asarray(tracer.ao(v, n, samples=256, distance=distance, seed=1, vertex_ids=ids))
    # (the tracer without normals: the rule before the bake point, where they disagreed)
    contact = np.asarray(tracer.ao(v, n, samples=64, distance=CONTACT * distance, seed=7,
                                   vertex_ids=ids)) < 1.0
    idx = np.flatnonzero(contact)
    diff = ours[idx] - ref[idx]
    picks = list(idx[np.argsort(-diff)][:args.vertices]) + list(idx[np.argsort(diff)][:args.vertices])
    print(f"{args.scene}: {len(v)} vertices, {contact.sum()} contact; AO distance {distance:.2f}; "
          f"probing {len(picks)} vertices (local AO distance {3e-3 * distance:.3f})")
    for k in map(int, picks):
        near = np.linalg.norm(v[t].astype(np.float64) - v[k], axis=2).min(1) < 1e-3 * distance
        local = t[near]
        label = pieces(local)
        own_label = label[np.flatnonzero((local == k).any(1))[0]]
        own_piece = local[label == own_label]
        own_all = np.zeros(len(t), bool)
        own_all[np.flatnonzero(near)[label == own_label]] = True
        found = nearest_other(v, t, k, own_all)
        if found[0] is None:
            print(f"  v{k}: no other piece's triangle lies over it; skipped")
            continue
        other, gap, ng = found
        print(f"  v{k} (whole scene: Cycles {ref[k]:.3f}, ours {ours[k]:.3f}): own piece "
              f"{len(own_piece)} triangles + triangle {other}, gap {gap * 1e6:+.0f} um")
        for g_um in (None,) + GAPS_UM:
            tris = np.concatenate([own_piece, t[other][None]])
            used, inv = np.unique(tris, return_inverse=True)
            lv = v[used].astype(np.float64)
            if g_um is not None:  # move the other triangle's vertices (not k's) along its normal
                shift = gap - g_um * 1e-6
                for vid in t[other]:
                    if vid != k:
                        lv[np.searchsorted(used, vid)] += shift * ng
            cyc, before, bake = bake_little(lv, inv.reshape(-1, 3),
                                            int(np.searchsorted(used, k)), 3e-3 * distance)
            what = "as found" if g_um is None else f"gap {g_um:+5d} um"
            print(f"     {what:14s} Cycles {cyc:.3f}  rule before {before:.3f}  "
                  f"bake point {bake:.3f}", flush=True)


main()
