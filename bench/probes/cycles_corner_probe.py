"""Probe, answered: where ours and Cycles' vertex bake still differ on the Douglas fir, Cycles' own face corners differ (its twin rings; docs/DESIGN.md, 'Rays against Cycles' samples').

Cycles' AO per face corner at the vertices where our rays and Cycles' vertex bake disagree most.

    BLENDER_USER_SCRIPTS=<dir with addons/canopy_ao> blender -b --factory-startup \\
        --python bench/probes/cycles_corner_probe.py -- [--scene sap_douglas_fir] [--samples 256]
        [--worst 12] [--gap 0.05]

Needs the scene's export and its 1024-sample Cycles bake in bench/out/real (bench/README.md,
"Real trees"). A POINT-domain bake (the reference) is the mean of Cycles' corners at each
vertex; this bakes the CORNER domain of the same scene (rebuilt by examples/sapling_scenes.py,
checked against the export's geometry hash) so each corner's own value shows, beside our AO at
the vertex (the add-on's tracer, `samples` rays per corner). It prints the --worst vertices and,
over every vertex where ours and the reference differ by more than --gap, how many have a corner
Cycles finds fully blocked (< 0.01) and how many have a twin: another vertex within 1e-4 of the
AO distance (on Sapling's branches mostly the next piece's nearly coincident ring), and how many
have a corner whose start (Cycles' POSITION bake of the corner) lies less than half the move of
native raytrace.h 'Origins' from the vertex.
docs/DESIGN.md, 'Rays against Cycles' samples', says what it found.
"""
import os
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # bench/
import harness  # noqa: E402  (addon/, examples/ and bench/ on sys.path)

import addon_utils  # noqa: E402
import bpy  # noqa: E402
import numpy as np  # noqa: E402

addon_utils.enable("canopy_ao")
from canopy_ao.blender import cycles_check  # noqa: E402

import real_scenes as rs  # noqa: E402
import sapling_scenes  # noqa: E402

TWIN = 1e-4      # of the AO distance
DEAD = 0.01      # a corner this dark is fully blocked


def corner_bake(objs, distance, samples, kind="AO"):
    """{object name: (AO, or start position (n, 3), per loop; vertex per loop; loop start per
    polygon)}: Cycles' bake of the CORNER domain (a temporary attribute on each mesh, which
    stays in this session only). kind "POSITION": where Cycles starts each corner's rays."""
    out = {}
    name = f"CanopyAO_CornerProbe_{kind}"
    with cycles_check._cycles_bake_settings(bpy.context, objs, distance, samples):
        for o in objs:
            ca = o.data.color_attributes
            ca.active_color = ca.new(name, "FLOAT_COLOR", "CORNER")
        cycles_check._run_bake("VERTEX_COLORS", bake_type=kind)
    for o in objs:
        me = o.data
        n = len(me.loops)
        rgba = np.empty(4 * n, np.float32)
        me.color_attributes[name].data.foreach_get("color", rgba)
        ao = rgba.reshape(n, 4)[:, :3] if kind == "POSITION" else rgba[0::4]
        lv = np.empty(n, np.int64)
        me.loops.foreach_get("vertex_index", lv)
        ls = np.empty(len(me.polygons), np.int64)
        me.polygons.foreach_get("loop_start", ls)
        out[o.name] = (ao, lv, ls)
    return out


def twins(v, h):
    """bool (N,): vertices with another vertex closer than h (a grid of cells h wide)."""
    cell = np.floor(v / h).astype(np.int64)
    grid = {}
    for i, c in enumerate(map(tuple, cell)):
        grid.setdefault(c, []).append(i)
    out = np.zeros(len(v), bool)
    steps = [(x, y, z) for x in (-1, 0, 1) for y in (-1, 0, 1) for z in (-1, 0, 1)]
    for i, (cx, cy, cz) in enumerate(map(tuple, cell)):
        for dx, dy, dz in steps:
            for j in grid.get((cx + dx, cy + dy, cz + dz), ()):
                if j != i and np.sum((v[j] - v[i]) ** 2) < h * h:
                    out[i] = True
                    break
            if out[i]:
                break
    return out


def main(argv):
    ap = harness.parser(__doc__, prog="cycles_corner_probe.py")
    ap.add_argument("--scene", default="sap_douglas_fir")
    ap.add_argument("--samples", type=int, default=256)
    ap.add_argument("--worst", type=int, default=12)
    ap.add_argument("--gap", type=float, default=0.05)
    a = ap.parse_args(argv)
    sc = rs.load(a.scene)
    ref = rs.cycles_ao(sc, 1024, 1)
    ref = rs.cycles_ao(sc, 1024) if ref is None else ref
    if ref is None:
        sys.exit(f"cycles_corner_probe: no 1024-sample Cycles bake of {a.scene} in {rs.REAL}")
    objs, _ = sapling_scenes.build(a.scene, True)
    with tempfile.TemporaryDirectory() as d:
        _, ghash = sapling_scenes.export(os.path.join(d, "probe.npz"), objs, {})
    if ghash != sc.geometry:
        sys.exit("cycles_corner_probe: the rebuilt scene is not the exported one (re-export it)")
    obs = [o for o, _, _ in objs]
    corners = corner_bake(obs, sc.distance, a.samples)
    starts = corner_bake(obs, sc.distance, 1, "POSITION")
    tracer = rs.scene_tracer(sc)
    ours = rs.trace_vertices(tracer, sc, a.samples, sc.distance, 0)
    # Every loop of the scene: its vertex, Cycles' AO there, its start's move / the rule's.
    vert, ao, move, poly_of = [], [], [], []
    for o in obs:
        a_o, lv, ls = corners[o.name]
        base = sc.offsets[sc.names.index(o.name)]
        x = sc.V[base + lv].astype(np.float64)
        rule = 1e-4 * np.maximum(1.0, np.abs(x).max(axis=1))  # native raytrace.h 'Origins'
        vert.append(base + lv)
        ao.append(a_o)
        move.append(np.linalg.norm(starts[o.name][0] - x, axis=1) / rule)
        ends = np.append(ls, len(lv))
        poly_of += [base + lv[ends[p]:ends[p + 1]] for p in range(len(ls))
                    for _ in range(ends[p], ends[p + 1])]
    vert, ao, move = np.concatenate(vert), np.concatenate(ao), np.concatenate(move)
    darkest = np.full(sc.n_vertices, np.inf)
    np.minimum.at(darkest, vert, ao)
    shortest = np.full(sc.n_vertices, np.inf)
    np.minimum.at(shortest, vert, move)
    twin = twins(sc.V.astype(np.float64), TWIN * sc.distance)
    diff = ours - ref
    bad = np.abs(diff) > a.gap
    dead = darkest < DEAD
    share = np.abs(diff[bad]).sum() / np.abs(diff).sum()
    print(f"{a.scene}: {bad.sum()} of {sc.n_vertices} vertices differ by > {a.gap} (ours "
          f"{a.samples} rays per corner against Cycles 1024), {share:.0%} of the summed "
          f"difference; ours brighter at {(diff[bad] > 0).mean():.0%} of them")
    print(f"  a corner Cycles finds blocked (< {DEAD}): {dead[bad].mean():.0%} of them "
          f"({dead[~bad].mean():.0%} elsewhere); a twin within {TWIN:g} D: {twin[bad].mean():.0%} "
          f"({twin[~bad].mean():.0%} elsewhere)")
    short = shortest < 0.5
    print(f"  a corner Cycles starts less than half the rule's move from its vertex: "
          f"{short[bad].mean():.0%} of them ({short[~bad].mean():.0%} elsewhere)")
    for i in np.argsort(-np.abs(diff))[:a.worst]:
        print(f"  vertex {i} ({sc.role[i]}): ours {ours[i]:.3f}, Cycles {ref[i]:.3f}; Cycles' "
              "corners " + ", ".join(f"{ao[l]:.3f} on {list(poly_of[l])} (start {move[l]:.3f} "
                                    "of the rule's move)" for l in np.flatnonzero(vert == i)))
    return 0


if __name__ == "__main__":
    from blender_script import run
    run(main, "cycles_corner_probe")
