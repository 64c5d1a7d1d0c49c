"""The grass laws on grass made differently from the benchmark's field (held out).

    /usr/bin/python3 bench/grass_styles.py

The blade layer (core/grass_layer.py) was designed on examples/canopy_scenes.py's grass_field
(two-segment tapered blades, uniformly scattered; printed first at three densities on 8 m ×
8 m, the figures docs/DESIGN.md quotes). This checks it on two other ways grass is
built, each on a ground mesh, against Embree at 128 samples per face corner: clumped tufts of
four-segment curved blades of mixed heights (0.4-1.2 x), and game-style grass cards (two or
three crossed vertical quads per tuft, much wider than a blade), each at a sparse and a dense
count. Prints, per field, the blades' MAE and bias under Hegeman's Eq. 9 (the ellipsoid rung
with the layer switched off) and under the blade layer (the ellipsoid rung as it bakes), and
the ground's. Then a round tree (8,000 leaves) over the benchmark's field (20,000 blades on
8 m): the hybrid's bias per role against Embree at 256 samples (its near rays see the blades,
so no grass layer is multiplied on top of them: docs/DESIGN.md, 'The near/far hybrid').
"""
from __future__ import annotations

import numpy as np

import harness  # noqa: E402  (addon/ and examples/ on sys.path)

HERE, REPO = harness.HERE, harness.REPO

from canopy_ao import core  # noqa: E402
import canopy_scenes as cs  # noqa: E402

SIZE, DISTANCE = 8.0, 20.0


def tufts(n_tufts, per_tuft=12, seed=1, height=0.3, segments=4):
    """Clumped curved blades: per_tuft blades around each tuft centre, heights 0.4-1.2 x."""
    rng = np.random.default_rng(seed)
    centres = rng.uniform(-SIZE / 2, SIZE / 2, (n_tufts, 2))
    n = n_tufts * per_tuft
    xy = np.repeat(centres, per_tuft, 0) + rng.normal(0, 0.03, (n, 2))
    h = height * rng.uniform(0.4, 1.2, n)
    phi = rng.uniform(0, 2 * np.pi, n)
    side = np.stack([np.cos(phi), np.sin(phi), np.zeros(n)], 1)
    out = np.stack([-np.sin(phi), np.cos(phi), np.zeros(n)], 1)
    bend = rng.uniform(0.2, 0.8, (n, 1))
    w = 0.008 * rng.uniform(0.7, 1.3, (n, 1))
    verts = []
    for k in range(segments + 1):
        u = k / segments
        c = np.c_[xy, np.zeros(n)] + h[:, None] * (u * np.array([0, 0, 1.0]) + bend * u * u * out)
        half = w * (1 - 0.9 * u)
        verts += [c - half * side, c + half * side]
    v = np.stack(verts, 1).reshape(-1, 3)
    per = 2 * (segments + 1)
    loc = np.array([[2 * k, 2 * k + 1, 2 * k + 3] for k in range(segments)]
                   + [[2 * k, 2 * k + 3, 2 * k + 2] for k in range(segments)])
    t = (loc[None] + per * np.arange(n)[:, None, None]).reshape(-1, 3)
    return v.astype(np.float32), t.astype(np.int32)


def cards(n_tufts, seed=2, height=0.3, width=0.3):
    """Grass cards: two or three crossed vertical quads per tuft (each tuft its own piece)."""
    rng = np.random.default_rng(seed)
    verts, tris = [], []
    for c in rng.uniform(-SIZE / 2, SIZE / 2, (n_tufts, 2)):
        h = height * rng.uniform(0.7, 1.3)
        k = int(rng.integers(2, 4))
        phi0 = rng.uniform(0, np.pi)
        base = sum(len(x) for x in verts)
        quads = []
        for j in range(k):
            phi = phi0 + j * np.pi / k
            d = 0.5 * width * np.array([np.cos(phi), np.sin(phi), 0.0])
            p = np.array([c[0], c[1], 0.0])
            quads.append([p - d, p + d, p + d + [0, 0, h], p - d + [0, 0, h]])
        q = np.array(quads).reshape(-1, 3)
        verts.append(q)
        for j in range(k):
            o = base + 4 * j
            tris += [[o, o + 1, o + 2], [o, o + 2, o + 3]]
    return (np.concatenate(verts).astype(np.float32), np.array(tris, np.int32))


def scene(grass):
    v, t = grass
    g = cs._ground(SIZE * 1.2, 64)
    items = [core.SceneItem("grass", "GRASS", "", v, cs.vertex_normals(v, t), t),
             core.SceneItem("ground", "GROUND", "", g.vertices,
                            cs.vertex_normals(g.vertices, g.triangles), g.triangles)]
    return items


def errors(items, ref, eq9=False):
    """{role: (MAE, bias)} of the ellipsoid rung against ref; eq9: the blades without their
    layer (Hegeman's Eq. 9, as before it), the ground's cover the same."""
    plan = core.prepare(items, core.BakeSettings(method="ellipsoid", tau=1.0, distance=DISTANCE))
    if eq9:
        for g in plan.grass_layers:
            g.layer = None
    out = {}
    for it in items:
        ao = core.evaluate_receivers(plan, it, it.positions, it.normals,
                                     vertices=slice(0, len(it.positions)))
        out[it.role] = (float(np.abs(ao - ref[it.role]).mean()), float(np.mean(ao - ref[it.role])))
    return out


def main(argv=None):
    harness.parser(__doc__, prog="grass_styles.py").parse_args(argv)  # --help; no options

    def field(blades):
        f = cs.grass_field(blades=blades, size=SIZE)[0]
        return f.vertices, f.triangles

    fields = [(f"design field, {b} blades", field(b)) for b in (8000, 20000, 60000)]
    fields += [("tufts of curved blades, sparse", tufts(400)), ("tufts, dense", tufts(3000)),
              ("crossed grass cards, sparse", cards(300)), ("cards, dense", cards(2500))]
    print("field | blades: Eq. 9 MAE / bias -> layer MAE / bias | ground: Eq. 9 -> layer")
    for name, grass in fields:
        items = scene(grass)
        res, _ = core.bake(items, core.BakeSettings(method="raytrace", samples=128,
                                                    distance=DISTANCE))
        ref = {r.role: r.ao for r in res}
        layer, eq9 = errors(items, ref), errors(items, ref, eq9=True)
        b0, b1, g0, g1 = eq9["GRASS"], layer["GRASS"], eq9["GROUND"], layer["GROUND"]
        print(f"{name:32s} | {b0[0]:.3f} / {b0[1]:+.3f} -> {b1[0]:.3f} / {b1[1]:+.3f} | "
              f"{g0[0]:.3f} -> {g1[0]:.3f}", flush=True)
    parts = (list(cs.round_tree(leaves=8000, ground=False))
             + list(cs.grass_field(blades=20000, size=SIZE)))
    items = [core.SceneItem(p.name, p.role.upper(), "", p.vertices,
                            cs.vertex_normals(p.vertices, p.triangles), p.triangles)
             for p in parts]
    res, _ = core.bake(items, core.BakeSettings(method="raytrace", samples=256, distance=DISTANCE))
    ref = {r.name: r.ao for r in res}
    res, _ = core.bake(items, core.BakeSettings(method="hybrid", samples=64, distance=DISTANCE))
    print("round tree over the field, hybrid (64 samples) bias against rays: " + ", ".join(
        f"{r.role.lower()} {float(np.mean(r.ao - ref[r.name])):+.3f}" for r in res))


if __name__ == "__main__":
    main()
