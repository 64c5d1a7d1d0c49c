"""Measure the cost model's constants (addon/canopy_ao/core/cost.py, SECONDS_PER_UNIT).

    /usr/bin/python3 bench/cost_constants.py [--scene round_tree] [--quick] [--samples 64]
                                             [--repeats 3]

Bakes every receiver of a scene with each rung on ONE thread, takes the best of a few runs
(the least disturbed by other work on the machine), and divides by the work the cost model
counts for that rung: seconds per unit. Prints the measured constants next to the ones in the
code and the model's prediction against the measured time per rung. Auto never times itself
while it bakes; it uses the constants in the code, so its choice does not follow the load.
"""

import harness  # noqa: E402  (addon/ and examples/ on sys.path)

HERE, REPO = harness.HERE, harness.REPO

import canopy_scenes as cs  # noqa: E402
from canopy_ao import _core, core  # noqa: E402
from canopy_ao.core import cost, lighting  # noqa: E402

UNIT_OF = {"ellipsoid": "shell", "medium": "medium", "grid": "voxel_step",
           "raytrace": "bvh_step"}


def main():
    ap = harness.parser(__doc__)
    ap.add_argument("--scene", default="round_tree")
    ap.add_argument("--quick", action="store_true", help="the scene's quick size")
    ap.add_argument("--samples", type=int, default=64, help="rays per point (the default's)")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    scene = cs.make_scene(args.scene, quick=args.quick)
    items = [core.SceneItem(p.name, p.role.upper(), p.tree or "T", p.vertices,
                            cs.vertex_normals(p.vertices, p.triangles), p.triangles)
             for p in scene]
    receivers = sum(len(it.positions) for it in items)
    previous = _core.set_max_threads(1)
    try:
        rows = []
        for method in ("sphere", "ellipsoid", "shells", "medium", "grid", "raytrace"):
            s = core.BakeSettings(method=method, tau=1.5, samples=args.samples)
            plan = core.prepare(items, s)
            if method in ("raytrace",) or plan.tracer is None:
                plan.tracer = plan.tracer or lighting.build_tracer(items)
            _, best = harness.timed(lambda: [core.evaluate_item(plan, it) for it in items],
                                    args.repeats)
            unit, count = cost.work(plan, method, receivers)
            rows.append((method, unit, count, best))
    finally:
        _core.set_max_threads(previous)
    print(f"{args.scene}: {receivers} receivers, one thread, best of {args.repeats}")
    print(f"{'method':10s} {'unit':11s} {'work':>12s} {'seconds':>9s} {'s/unit':>9s} "
          f"{'in code':>9s} {'predicted':>9s}")
    for method, unit, count, best in rows:
        code = cost.SECONDS_PER_UNIT[unit]
        print(f"{method:10s} {unit:11s} {count:12.4g} {best:9.4f} {best / count:9.3g} "
              f"{code:9.3g} {count * code:9.4f}")


if __name__ == "__main__":
    main()
