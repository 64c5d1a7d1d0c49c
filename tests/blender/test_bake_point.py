"""The exact rung against Cycles' own vertex bake where it used to disagree: each vertex starts
at Cycles' bake point (native raytrace.h, 'Origins'; docs/DESIGN.md, 'Rays against Cycles'
samples'). Both bakes run here, on small scenes built in the test; the margins are 1024-sample
noise (a few 0.01) far below what the rule before got wrong (0.5–1.0 at these vertices).
Last, the bake job's buried test: what the approximate rungs read where rays stop at once."""

import bpy
import numpy as np
import pytest

from conftest import _clear_scene, add_mesh
from canopy_ao.blender import cycles_check, mesh_io, properties
from canopy_ao.blender.job import run_bake

SAMPLES = 1024


def _bake_both(names, distance):
    """(ours, Cycles) per object name: the add-on's exact rung and Cycles' vertex bake."""
    opts = properties.scene_options(bpy.context.scene)
    opts.update(method="raytrace", samples=SAMPLES, distance=distance, use_world_distance=False)
    run_bake(bpy.context, list(names), opts)
    ours = {n: mesh_io.read_ao_attribute(bpy.data.objects[n], "CanopyAO") for n in names}
    cyc = cycles_check.bake_cycles_vertex_ao(
        bpy.context, [bpy.data.objects[n] for n in names], distance, SAMPLES)
    return ours, cyc


def _smooth(ob):
    for p in ob.data.polygons:
        p.use_smooth = True
    ob.data.update()


@pytest.fixture
def clean():
    _clear_scene()
    yield
    _clear_scene()


def test_a_corner_bakes_where_cycles_moves_it(clean):
    """A 1 cm triangle 18 m from the origin, a roof 10 µm over it from 1 mm inside: Cycles bakes
    its corner vertex under the roof (moved 1.8 mm towards the centroid), dark; 21 m away with
    the roof from 3 mm, open. The rule before started a hair from the vertex: open both times."""
    L, h = 0.01, 1e-5
    for name, x, s in (("Near", 18.0, 0.1 * L), ("Far", 21.0, 0.3 * L)):
        o = np.array([x, 0.0, 0.0])
        v = np.float32([o, o + [L, 0, 0], o + [0, L, 0], o + [s, s, h], o + [L, s, h],
                        o + [L, L, h], o + [s, L, h]])
        add_mesh(name, v, np.int32([[0, 1, 2], [3, 4, 5], [3, 5, 6]]))
    ours, cyc = _bake_both(["Near", "Far"], 0.5)
    assert cyc["Near"][0] < 0.05 and cyc["Far"][0] > 0.95  # what Cycles does, as measured
    assert abs(ours["Near"][0] - cyc["Near"][0]) < 0.03
    assert abs(ours["Far"][0] - cyc["Far"][0]) < 0.03


def test_a_smooth_square_tube_is_open_as_in_cycles(clean):
    """An isolated smooth square tube 12 m from the origin: Cycles 1.0 at every vertex (its
    terminator lift keeps the rays that dive below a face); without the lift, 0.85–0.89."""
    w, length, base = 0.0022, 0.05, np.array([3.0, 3.0, 11.0])
    v = [base + [x, y, length * r / 4] for r in range(5)
         for x, y in ((-w / 2, -w / 2), (w / 2, -w / 2), (w / 2, w / 2), (-w / 2, w / 2))]
    t = []
    for r in range(4):
        for k in range(4):
            a, b = 4 * r + k, 4 * r + (k + 1) % 4
            t += [[a, b, b + 4], [a, b + 4, a + 4]]
    _smooth(add_mesh("Tube", np.float32(v), np.int32(t)))
    ours, cyc = _bake_both(["Tube"], 0.5)
    assert np.all(cyc["Tube"] > 0.99)
    assert np.all(np.abs(ours["Tube"] - cyc["Tube"]) < 0.02)


def test_blades_and_a_capped_trunk_on_the_ground_agree_with_cycles(clean):
    """bench/cycles_contact.py's scene, smaller: blades standing on the ground (roots
    (1 + n·up)/2) and a capped 16-sided trunk whose bottom cap lies in the ground plane (Cycles
    ~0.13 at its bottom ring; the rule before read 0.17, tracing from the vertex without
    Cycles' ROBUST hit test 0.44)."""
    n = 10
    gx, gy = np.meshgrid(np.linspace(-20, 20, n + 1), np.linspace(-20, 20, n + 1))
    gv = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], 1)
    q = (np.arange(n)[:, None] * (n + 1) + np.arange(n)[None, :]).ravel()
    gt = np.concatenate([np.stack([q, q + 1, q + n + 2], 1), np.stack([q, q + n + 2, q + n + 1], 1)])
    add_mesh("Ground", np.float32(gv), np.int32(gt))
    for k, beta in enumerate((0.0, 25.0, -25.0)):
        b, x = np.radians(beta), 0.37 + 3 * k
        up = np.array([0.0, np.sin(b), np.cos(b)])
        r0, r1 = np.array([x - 0.01, 0.23, 0.0]), np.array([x + 0.01, 0.23, 0.0])
        add_mesh(f"Blade{k}", np.float32([r0, r1, r1 + 0.3 * up, r0 + 0.3 * up]),
                 np.int32([[0, 1, 2], [0, 2, 3]]))
    s = 16
    me = bpy.data.meshes.new("Trunk")
    rim = [(10 + 0.2 * np.cos(2 * np.pi * i / s), 0.2 * np.sin(2 * np.pi * i / s), 3.0 * e)
           for e in range(2) for i in range(s)]
    faces = [(i, (i + 1) % s, (i + 1) % s + s, i + s) for i in range(s)]
    faces += [tuple(range(s))[::-1], tuple(range(s, 2 * s))]
    me.from_pydata(rim, [], faces)
    me.update()
    trunk = bpy.data.objects.new("Trunk", me)
    bpy.context.scene.collection.objects.link(trunk)
    _smooth(trunk)
    names = ["Ground", "Blade0", "Blade1", "Blade2", "Trunk"]
    ours, cyc = _bake_both(names, 20.0)
    for k in range(3):
        roots = slice(0, 2)
        assert np.all(np.abs(ours[f"Blade{k}"][roots] - cyc[f"Blade{k}"][roots]) < 0.03)
    assert cyc["Trunk"][:s].mean() < 0.2  # Cycles: the cap corner, in the ground, is dark
    # Per vertex: the 16-gon cap is one face corner of each rim vertex (Blender's polygons reach
    # the tracer), not the 1 to 14 fan triangles it is cut into (0.095–0.143 that way).
    assert np.all(np.abs(ours["Trunk"] - cyc["Trunk"]) < 0.02)


def _quads_mesh(name, verts, faces):
    me = bpy.data.meshes.new(name)
    me.from_pydata([tuple(map(float, v)) for v in verts], [], faces)
    me.update()
    ob = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(ob)
    _smooth(ob)
    return ob


def test_at_the_same_samples_our_rays_beat_cycles(clean):
    """Samples mean rays at every face corner, as in Cycles' bake, so a vertex on four quads
    casts four times the samples, as Cycles does; our corners share one stratified set where
    Blender seeds all corners of a vertex alike. Against Cycles at 1024 samples our 16 samples
    err less than Cycles' 16: 0.38 of it here, on quads (Blender 3.4; dealing 16 rays out to the
    corners, the rule before, 0.97)."""
    n = 16
    g = np.linspace(-2.0, 2.0, n + 1)
    gv = [(x, y, 0.0) for y in g for x in g]
    gf = [(j * (n + 1) + i, j * (n + 1) + i + 1, (j + 1) * (n + 1) + i + 1, (j + 1) * (n + 1) + i)
          for j in range(n) for i in range(n)]
    _quads_mesh("Ground", gv, gf)
    s, rings = 12, 10
    for k, (cx, tilt) in enumerate(((0.0, 0.0), (0.45, 0.6))):
        tv = [(cx + 0.15 * np.cos(2 * np.pi * i / s) + tilt * r / rings,
               0.15 * np.sin(2 * np.pi * i / s), 2.0 * r / rings) for r in range(rings + 1)
              for i in range(s)]
        tf = [(r * s + i, r * s + (i + 1) % s, (r + 1) * s + (i + 1) % s, (r + 1) * s + i)
              for r in range(rings) for i in range(s)]
        _quads_mesh(f"Stem{k}", tv, tf)
    names = ["Ground", "Stem0", "Stem1"]
    distance = 3.0
    opts = properties.scene_options(bpy.context.scene)
    opts.update(method="raytrace", samples=16, distance=distance, use_world_distance=False)
    run_bake(bpy.context, names, opts)
    ours = np.concatenate([mesh_io.read_ao_attribute(bpy.data.objects[m], "CanopyAO")
                           for m in names])
    obs = [bpy.data.objects[m] for m in names]
    ref = cycles_check.bake_cycles_vertex_ao(bpy.context, obs, distance, 1024)
    c16 = cycles_check.bake_cycles_vertex_ao(bpy.context, obs, distance, 16)
    ref = np.concatenate([ref[m] for m in names])
    c16 = np.concatenate([c16[m] for m in names])
    assert 0.05 < ref.mean() < 0.95  # the stems shade the ground and each other
    e_ours, e_cycles = np.abs(ours - ref).mean(), np.abs(c16 - ref).mean()
    assert e_ours < 0.85 * e_cycles, (e_ours, e_cycles)


def test_a_twig_whose_tip_quads_are_slivers_is_open_as_in_cycles(clean):
    """A quaking aspen twig from Sapling Tree Gen, as exported (float32 coordinates: the float
    rounding is the point): four quads 0.6 m long, 9 mm wide at the base and 2 mm at the open
    tip, 7 m from the origin. Cycles moves each tip corner 0.67 mm towards its triangle's
    centroid, then projects the moved point back onto the sliver in float, which cancels
    catastrophically: one corner starts 5.6 mm down the twig on the neighbouring face's edge.
    Traced from there without Cycles' self-intersection offset (its edge test fails there, and
    Cycles then starts the rays 256 float spacings off the face: native raytrace.h, 'Origins')
    that corner read 0.18 (the vertex 0.71, or 0.86 from the projection emulated bit for bit);
    Cycles: open, 0.97-0.99."""
    verts = [(-0.44911670684814453, 2.3062329292297363, 6.589840888977051),
             (-0.4406889081001282, 2.3107075691223145, 6.580926418304443),
             (-0.44997870922088623, 2.3099799156188965, 6.571778297424316),
             (-0.4584065079689026, 2.3055052757263184, 6.580692768096924),
             (-0.6577109098434448, 2.851618766784668, 6.705838680267334),
             (-0.6563780903816223, 2.852452516555786, 6.704414367675781),
             (-0.6578521728515625, 2.852231025695801, 6.702905178070068),
             (-0.659184992313385, 2.8513972759246826, 6.704329490661621)]
    faces = [(0, 4, 7, 3), (1, 5, 4, 0), (2, 6, 5, 1), (3, 7, 6, 2)]
    _quads_mesh("Twig", verts, faces)
    ours, cyc = _bake_both(["Twig"], 0.1)
    tip = slice(4, 8)
    assert np.all(cyc["Twig"][tip] > 0.9), cyc["Twig"]  # what Cycles does, as measured
    assert np.all(np.abs(ours["Twig"] - cyc["Twig"]) < 0.03), (ours["Twig"], cyc["Twig"])


def test_a_branch_tip_collapsed_to_a_point_bakes_as_in_cycles(clean):
    """A Sapling-like twig (square rings of 10 mm and 5 mm, then a tip where four vertices
    coincide) inside a closed box: every ray is blocked, yet Cycles reads 1/4 at ring vertices
    whose tip quad the bake triangulates differently from the mesh (Blender's quad-flip test
    with and without the face normal), so one of their four corners is baked on a triangle with
    a NaN face normal, whose rays nothing stops (native raytrace.h, 'Origins'). The
    first-triangle rule read 0 there. Whether the mesh's cached triangulation flips these quads
    depends on the Blender version (3.4 does, 4.3 does not); ours follows the one it is given."""
    base = np.array([-8.26, 2.16, 27.57])
    axis = np.array([-0.24, 0.63, -0.01])
    up = np.array([0.0, 0.0, 1.0])
    side = np.cross(axis, up)
    side /= np.linalg.norm(side)
    top = np.cross(side, axis / np.linalg.norm(axis))
    verts, faces = [], []
    for r, radius in enumerate((0.01, 0.005, 0.0)):
        c = base + r * axis
        for k in range(4):
            a = np.pi / 2 * k
            verts.append(tuple(c + radius * (np.cos(a) * top + np.sin(a) * side)))
    for r in range(2):
        for k in range(4):
            k1 = (k + 1) % 4
            faces.append((4 * r + k1, 4 * (r + 1) + k1, 4 * (r + 1) + k, 4 * r + k))
    _quads_mesh("Twig", verts, faces)
    lo, hi = base - 1.0, base + 2 * axis + 1.0
    box = [(x, y, z) for z in (lo[2], hi[2]) for y in (lo[1], hi[1]) for x in (lo[0], hi[0])]
    box_faces = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2),
                 (1, 3, 7, 5)]
    _quads_mesh("Box", box, box_faces)
    ours, cyc = _bake_both(["Twig"], 10.0)
    assert np.all(np.abs(ours["Twig"] - cyc["Twig"]) < 0.03), (ours["Twig"], cyc["Twig"])
    if bpy.app.version < (4, 0):  # measured: Blender 3.4 caches the flipped triangulation here
        assert cyc["Twig"].max() > 0.2, cyc["Twig"]  # (4.3 does not: Cycles reads 0 there)


def test_tip_faces_whose_last_two_corners_coincide_bake_as_in_cycles(clean):
    """Twigs closing on a point, each tip face a triangle (r_k, t_k, t_k+1) whose last two
    vertices coincide (Sapling's collapsed tips). Cycles' face normal there is its fused cross
    product's rounding residue, a direction at random; where it opposes the smooth normal
    Cycles takes the corner as backfacing and bakes the hemisphere into the twig (native
    raytrace.h, 'Origins'). Over six such twigs (two places, three tip lengths) the rule that
    dropped those corners read the ring and the tip 0.18 from Cycles on average, and 0.08
    without Cycles' self-intersection offset (where a start sits on a vertex or an edge,
    Cycles' edge test fails and its rays leave 256 float spacings off the face); now 0.02."""
    errs, dark = [], []
    for base, axis in (((-8.26, 2.16, 27.57), (-0.24, 0.63, -0.01)),
                       ((3.1, -1.7, 9.4), (0.02, 0.03, 0.05))):
        base, axis = np.array(base), np.array(axis)
        side = np.cross(axis, [0.0, 0.0, 1.0])
        side /= np.linalg.norm(side)
        top = np.cross(side, axis / np.linalg.norm(axis))
        ring = lambda c, r: [c + r * (np.cos(a) * top + np.sin(a) * side)
                             for a in np.pi / 2 * np.arange(4)]
        for tip in (0.01, 0.03, 0.2):
            _clear_scene()
            verts = ring(base, 0.01) + ring(base + axis, 0.005) + [base + (1 + tip) * axis] * 4
            tris = []
            for k in range(4):
                k1 = (k + 1) % 4
                tris += [[k, k1, 4 + k1], [k, 4 + k1, 4 + k]]  # the tube
                tris += [[4 + k, 4 + k1, 8 + k1], [4 + k, 8 + k1, 8 + k]]  # the tip
            _smooth(add_mesh("Twig", np.float32(verts), np.int32(tris)))
            ours, cyc = _bake_both(["Twig"], 1.0)
            errs.append(np.abs(ours["Twig"] - cyc["Twig"])[4:])
            dark.append(cyc["Twig"][4:])
    assert np.mean(dark) < 0.85  # the tips are not open sky: the case is exercised
    # Measured: 0.021 on Blender 3.4, 0.053 on 4.3 and 5.2, whose Cycles starts some of these
    # corners elsewhere (not modelled); the rule that dropped the corners read 0.084 on 3.4.
    assert np.mean(errs) < (0.04 if bpy.app.version < (4, 0, 0) else 0.07), np.mean(errs)


def test_a_leaf_base_inside_its_twig_reads_0_through_the_bake_job(clean):
    """The add-on's bake job (the CLI's and the panel's path), an approximate rung with τ
    calibrated: leaf corners inside a closed twig read 0, as rays and Cycles read them; the
    leaf's open corners keep the model's value, and the report counts what was set to 0."""
    rng = np.random.default_rng(3)
    n = 300
    base = np.float32([0, 0, 3]) + rng.normal(0, 0.8, (n, 3)).astype(np.float32)
    kite = np.float32([[0, 0, 0], [0.01, 0, 0], [0.12, 0.2, 0], [-0.1, 0.2, 0]])
    leaves = (base[:, None, :] + kite[None]).reshape(-1, 3)
    quads = np.arange(n)[:, None, None] * 4 + np.int32([[0, 1, 2], [0, 2, 3]])[None]
    add_mesh("Leaves", leaves, quads.reshape(-1, 3))
    corner = np.float32([[x, y, z] for z in (-1, 1) for y in (-1, 1) for x in (-1, 1)])
    cube = np.int32([[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4],
                     [2, 6, 3], [3, 6, 7], [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5]])
    knots = (base[:, None, :] + [0.005, 0, 0] + 0.012 * corner[None]).reshape(-1, 3)
    add_mesh("Twigs", knots, (np.arange(n)[:, None, None] * 8 + cube[None]).reshape(-1, 3))
    bpy.data.objects["Leaves"].canopy_ao.role = "CANOPY"
    bpy.data.objects["Twigs"].canopy_ao.role = "TRUNK"
    opts = properties.scene_options(bpy.context.scene)
    opts.update(method="sphere", tau=None, distance=10.0, use_world_distance=False)
    _job, rep = run_bake(bpy.context, ["Leaves", "Twigs"], opts)
    ao = mesh_io.read_ao_attribute(bpy.data.objects["Leaves"], "CanopyAO").reshape(n, 4)
    assert (ao[:, :2] == 0).all(), (ao[:, :2] > 0).sum()  # both base corners sit in the knot
    assert (ao[:, 2:] > 0).mean() > 0.99
    assert rep["objects"]["Leaves"]["buried_set_to_0"] == int((ao == 0).sum())


def test_a_branch_end_inside_the_next_piece_is_dark_as_in_cycles(clean):
    """Two branch pieces of Sapling's Douglas fir, as exported (float32): the last segment of
    one (quads 2.5 m by 2.9 cm: slivers) and the first of the next, whose start ring lies on
    the first one's end ring (vertices 0.3 mm apart, some coincident). The end ring's vertex
    4 lies 0.2 mm inside the next piece's face. Cycles projects its corners' moved bake points
    back onto the slivers in float and so starts them 0.3 mm and 0.03 mm from the vertex,
    inside the next piece, 2.9 mm from its open end: 0.00 and 0.36, where the second start, on
    its triangle's edges, fails Cycles' self-intersection test and its rays leave 256 float
    spacings (0.5 mm) off the face (native raytrace.h, 'Origins'). The move's exact point
    (2.3 mm) lies outside: the rule before read 1.00 (0.00 from Cycles' starts without the
    offset)."""
    verts = [(-4.946987152099609, -3.6654951572418213, 23.492666244506836),
             (-4.971913814544678, -3.6331987380981445, 23.454368591308594),
             (-4.934679985046387, -3.6498734951019287, 23.41607093811035),
             (-4.909753322601318, -3.6821699142456055, 23.454368591308594),
             (-6.483726501464844, -5.616130828857422, 22.821823120117188),
             (-6.4927473068237305, -5.604443073272705, 22.807964324951172),
             (-6.479272842407227, -5.610477447509766, 22.794105529785156),
             (-6.47025203704834, -5.622165203094482, 22.807964324951172),
             (-6.481955528259277, -5.613882541656494, 22.822263717651367),
             (-6.4927473068237305, -5.604443073272705, 22.807964324951172),
             (-6.481043815612793, -5.612725734710693, 22.793664932250977),
             (-6.47025203704834, -5.622165203094482, 22.807964324951172),
             (-7.120838642120361, -6.424849510192871, 22.764928817749023),
             (-7.129150390625, -6.418887138366699, 22.75473403930664),
             (-7.121572971343994, -6.425759315490723, 22.744539260864258),
             (-7.1132612228393555, -6.4317216873168945, 22.75473403930664)]
    faces = [(b + k, b + 4 + k, b + 4 + (k + 3) % 4, b + (k + 3) % 4)
             for b in (0, 8) for k in range(4)]
    _quads_mesh("Branches", verts, faces)
    ours, cyc = _bake_both(["Branches"], 10.0)
    assert cyc["Branches"][4] < 0.4, cyc["Branches"]  # what Cycles does, as measured
    # Measured: within 0.05 on Blender 3.4 and 4.3; 5.2's Cycles reads 0.25 where ours read
    # 0.17 (the rule before: 1.00).
    tol = 0.05 if bpy.app.version < (5, 0, 0) else 0.12
    assert abs(ours["Branches"][4] - cyc["Branches"][4]) < tol, (ours["Branches"],
                                                                 cyc["Branches"])
