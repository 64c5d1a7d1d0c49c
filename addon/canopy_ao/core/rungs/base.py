"""The Rung type and the ladder's lookup by name (docs/DESIGN.md, 'Architecture').

A rung file builds one Rung and registry.py registers it here, in the ladder's order; modules
below the rungs (lighting, cost) look a rung up by name with get() and ask it. Imports nothing
of the add-on but the native module, so any module may import it.
"""

from __future__ import annotations

import dataclasses
import enum
from dataclasses import dataclass
from typing import Callable

from ..native import CanopyAOError, _core


class Proxy(enum.Enum):
    """Which of a tree's fitted proxies a rung lights with (proxies.fit_tree fits only those)."""

    SPHERE = "the fitted sphere"
    ELLIPSOID = "the fitted ellipsoid"
    SHELLS = "k ellipsoid shells (k-means clusters)"


@dataclass(frozen=True)
class Rung:
    """One method of the ladder. Every field but name, label and help has the default of a rung
    that takes none of the special paths.

    evaluate(plan, role, tree, grass_key, p, n, tau, own, group) -> float32 (N,): AO of
    receiver points p, n (float32 (N, 3), N ≥ 1) of an item (lighting.evaluate_points: its
    arguments; the instanced forest is multiplied in there unless scene_plan or
    rays_see_instances). work(plan, receivers, names, samples) -> (unit, count): the counted
    work of ``receivers`` points, unit a key of cost.SECONDS_PER_UNIT (cost.py; the buried test
    is added there for a rung that does not find buried points)."""

    name: str
    label: str
    help: str
    evaluate: Callable | None = None
    work: Callable | None = None
    takes_tau: bool = False          # τ calibrated or given means something to it
    scene_plan: bool = False         # lit by the native ScenePlan (``native`` its PlanMethod)
    native: object = None            # _core.PlanMethod of a scene-plan rung
    proxy: Proxy = Proxy.ELLIPSOID   # the fitted proxy it lights with (and that occludes)
    needs_triangles: bool = False    # every item's triangles, whatever τ (rays, grids, features)
    needs_tracer: bool = False       # the ray tracer is its own input (a bake fails without)
    needs_grid: bool = False         # the leaf-density grid is its input
    needs_regression: bool = False   # the ray-free rung's fit is its input
    tracer_holds_instances: bool = True  # its tracer traces instanced trees' meshes
    rays_see_instances: bool = False  # its AO comes from rays alone, which see the instances
    finds_buried: bool = False       # reads 0 at buried receivers by itself (no buried test)
    live: bool = False               # refits and evaluates fast enough for every frame
    # its evaluate multiplies the GROUND patches in (lighting.walls_ao): a live frame of a
    # ground alone multiplies the first bake's instead (live.held_ground)
    ground_patches: bool = False
    # its evaluation reads the fitted proxies (plan.fits, trunks, grass heights and layers):
    # a live frame refits them (core/live.refit); the ray-free rung reads none of them
    reads_proxies: bool = True
    # roles whose triangles a live frame keeps (grass blades and the GROUND surfaces, whose
    # walls occlude: core/walls.py; the ray-free rung's grid and leaf table need every one)
    frame_triangle_roles: tuple = ("GRASS", "GROUND")
    uses_samples: bool = False       # settings.samples sets its rays
    exact: bool = False              # the reference rung: auto may halve its samples
    climbs: Callable | None = None   # climbs(plan): auto weighs it as a candidate on this plan
    chooses: bool = False            # picks another rung (auto); never a plan's method
    # The number a saved .blend stores for the rung's menu entry (Blender keeps an enum as its
    # number): fixed once a rung has one, whatever its place on the ladder; None = the next
    # free one when it is registered.
    number: int | None = None

    def own_shells(self, plan, tree) -> list:
        """The shells of ``tree`` (plan.fits) this rung lights with and that occlude for it."""
        sphere, ell, shells = plan.fits[tree]
        if self.proxy is Proxy.SPHERE:
            return [_core.Ellipsoid.from_sphere(sphere)]
        if self.proxy is Proxy.ELLIPSOID:
            return [ell]
        return list(shells)


def always(plan) -> bool:
    """climbs for a rung auto always weighs (the analytic rungs)."""
    return True


_LADDER: list = []  # the ladder's rungs, cheapest first (registry.py fills it)
_BY_NAME: dict = {}  # the same, by name (get() runs on every evaluate call)


def register(rung: Rung, before: str | None = None) -> Rung:
    """Add ``rung`` to the ladder (at the end, or before the rung named ``before``). A rung
    that auto may weigh needs a cost model: refused here, not when auto first meets it."""
    if not isinstance(rung, Rung):
        raise TypeError(f"not a Rung: {rung!r}")
    if any(r.name == rung.name for r in _LADDER):
        raise ValueError(f"rung {rung.name!r} is registered already")
    if rung.number is None:
        free = max((r.number for r in _LADDER), default=-1) + 1
        rung = dataclasses.replace(rung, number=free)
    elif any(r.number == rung.number for r in _LADDER):
        raise ValueError(f"rung {rung.name!r}: number {rung.number} is another rung's")
    if not rung.chooses and rung.evaluate is None:
        raise ValueError(f"rung {rung.name!r}: no evaluate")
    if rung.climbs is not None and rung.work is None:
        raise ValueError(f"rung {rung.name!r}: auto may weigh it but it has no cost model "
                         "(work)")
    at = len(_LADDER) if before is None else [r.name for r in _LADDER].index(before)
    _LADDER.insert(at, rung)
    _BY_NAME[rung.name] = rung
    return rung


def unregister(name: str) -> None:
    """Take the rung named ``name`` off the ladder (a test's toy rung)."""
    _LADDER[:] = [r for r in _LADDER if r.name != name]
    _BY_NAME.pop(name, None)


def ladder() -> tuple:
    """Every registered rung, in the ladder's order."""
    return tuple(_LADDER)


def names() -> tuple:
    """Every registered rung's name, in the ladder's order."""
    return tuple(r.name for r in _LADDER)


def exact() -> Rung:
    """The ladder's exact rung: the reference auto is scored against, whose samples it may
    halve to fit the time budget (Rung.exact)."""
    return next(r for r in _LADDER if r.exact)


def get(name) -> Rung:
    """The rung named ``name`` (a Rung is returned as it is). CanopyAOError when none is."""
    rung = _BY_NAME.get(name) if isinstance(name, str) else name
    if isinstance(rung, Rung):
        return rung
    raise CanopyAOError(f"unknown method {name!r} (one of {', '.join(names())})")


def plan_method(rung: Rung):
    """The native scene plan's PlanMethod a scene-plan rung names (``rung.native``); its name
    where the loaded module predates the enum (ScenePlan takes either)."""
    enum = getattr(_core, "PlanMethod", None)
    return getattr(enum, rung.native) if enum is not None else rung.native
