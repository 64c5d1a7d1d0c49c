"""Scene → items: which objects a bake reads and writes, their role and tree, their world-space
arrays (the core's SceneItems). Nothing here changes the scene."""

import math
import time

import bpy
import numpy as np

from . import mesh_io, opacity_io, parts_io
from .visibility import RenderVisibility, casts_shadow
from ..core import ladder, roles
from ..core.native import CanopyAOError
from ..core.scene import SceneItem, ray_length


def tree_of(obj):
    """Which tree an object belongs to (the name of tree_and_source)."""
    return tree_and_source(obj)[0]


def tree_and_source(obj):
    """(tree, source): the user's name (or a generator's ``canopy_ao_tree`` tag), else the root
    of its parent chain (a trunk parenting its leaves): source "set"; else its first collection
    ("collection") or the scene ("scene"): groups, not trees, that the core splits by where
    the pieces stand (core/trees.py)."""
    if obj.canopy_ao.tree:
        return obj.canopy_ao.tree, "set"
    if isinstance(obj.get("canopy_ao_tree"), str) and obj["canopy_ao_tree"]:
        return obj["canopy_ao_tree"], "set"  # set by a scene generator (examples/blender_scene.py)
    if obj.parent is not None or obj.children:
        root = obj
        while root.parent is not None:
            root = root.parent
        return root.canopy_ao.tree or root.name, "set"
    if obj.users_collection:
        return obj.users_collection[0].name, "collection"
    return "Scene", "scene"


# Guesses of this session, keyed by a cheap signature of the geometry (the guess costs ~1 s
# per million vertices; re-bakes of an unchanged scene should not pay it again).
_GUESSES = {}


def _signature(obj, positions, triangles):
    step = max(1, len(positions) // 997)
    return (obj.name, len(positions), len(triangles),
            float(np.asarray(positions[::step], np.float64).sum()),
            int(np.asarray(triangles[::step], np.int64).sum()))


def declared_role(obj):
    """(role, how) when the user set the role or a scene generator tagged it, else None (the
    role must be guessed from the geometry, which needs its triangles)."""
    if obj.canopy_ao.role != 'AUTO':
        return obj.canopy_ao.role, "set"
    tagged = obj.get("canopy_ao_role")  # set by a scene generator (examples/blender_scene.py)
    if isinstance(tagged, str) and tagged.upper() in roles.ROLES:
        return tagged.upper(), "tagged canopy_ao_role"
    return None


def role_of(obj, positions, triangles):
    """(role, how) — the user's override, or a guess from the geometry."""
    declared = declared_role(obj)
    if declared is not None:
        return declared
    key = _signature(obj, positions, triangles)
    if key not in _GUESSES:
        if len(_GUESSES) > 4096:
            _GUESSES.clear()
        _GUESSES[key] = roles.guess_role(positions, triangles)
    role, why = _GUESSES[key]
    return role, f"guessed: {why}"


# Cycles' AO distance when the scene has no World (its sync_world; measured in 3.4's AO bake).
NO_WORLD_DISTANCE = 10.0


def world_ao_distance(scene, bake=False):
    """The AO distance Cycles' AO bake uses for this scene: World > Ambient Occlusion >
    Distance, even with the checkbox off, and NO_WORLD_DISTANCE without a World (docs/DESIGN.md,
    'Facts measured in Blender'). The World's 0 means no occlusion (Cycles reads 1.0
    everywhere), not the add-on's 'unlimited': bake=True (the distance a bake will use) refuses
    it with a message instead of baking all-white or a different AO from Cycles'."""
    d = float(scene.world.light_settings.distance) if scene.world else NO_WORLD_DISTANCE
    if bake and d <= 0.0:
        raise CanopyAOError(f"World '{scene.world.name}' has AO distance 0, with which Cycles' AO "
                            "bake reads 1.0 everywhere (nothing is within reach); set World > "
                            "Ambient Occlusion > Distance, or turn off From World (on the "
                            "command line: --distance) and give a distance (0 = unlimited)")
    return d


def is_candidate(obj):
    """A mesh that may take part in a bake (not one of our proxy displays)."""
    return obj.type == 'MESH' and not obj.get(mesh_io.PROXY_PROP)


# Objects Cycles renders as the mesh Blender makes of them (Object > Convert > Mesh): they
# occlude as that mesh, a role guessed for it as for any mesh; never targets.
SOLID_TYPES = frozenset(('CURVE', 'SURFACE', 'FONT', 'META'))


def object_names(text):
    """The names an operator's ``objects`` argument gives: the whole text when it is an
    object's exact name (one with a comma, or spaces at its ends), else the comma-separated
    names, stripped."""
    if text and bpy.data.objects.get(text) is not None:
        return [text]
    return [s.strip() for s in text.split(",") if s.strip()]


def bake_targets(context, object_names, opts=None, on_mesh=True, notes=None):
    """The objects a bake writes: the named ones, else the selected meshes, else every visible
    mesh that renders and occludes (visibility.py) and holds a result: not an instancer whose
    modifiers leave it no vertices of its own (geometry nodes scattering leaves), nor, per
    vertex (opts' mode), one whose modifiers change its vertex count (they realise the
    scattered leaves): those only occlude. Raises CanopyAOError when there are none, a name is
    wrong, a target casts no shadow (Cycles' AO of it leaves it out of its own rays, which a
    bake here cannot do) or does not render (it would occlude the other targets, which Cycles
    does not). notes: a list to which a line is added per target whose mesh (on_mesh: the
    result is written onto it) other objects show too."""
    scene = context.scene
    vis = RenderVisibility(context.view_layer)
    if object_names:
        object_names = list(dict.fromkeys(object_names))  # a name given twice is one target
        missing = [n for n in object_names if n not in scene.objects]
        if missing:
            raise CanopyAOError(f"no object named {', '.join(missing)} in scene "
                                f"'{scene.name}'")
        targets = [scene.objects[n] for n in object_names]
        bad = [o.name for o in targets if o.type != 'MESH']
        if bad:
            raise CanopyAOError(f"not a mesh: {', '.join(bad)}")
    else:
        targets = [o for o in context.selected_objects if is_candidate(o)]
        if not targets:
            dg = context.evaluated_depsgraph_get()
            vertex_mode = (opts or {}).get("mode", 'VERTEX') == 'VERTEX'
            targets = [o for o in scene.objects
                       if is_candidate(o) and o.visible_get(view_layer=context.view_layer)
                       and vis.mesh_renders(o) and _holds_result(o, dg, vertex_mode)]
    if not targets:
        raise CanopyAOError("nothing to bake: no mesh objects selected or visible")
    check_writable(targets, on_mesh)
    for o in targets if on_mesh and notes is not None else ():
        others = sorted(x.name for x in scene.objects if x.data == o.data and x not in targets
                        ) if o.data.users > 1 else ()
        if others:  # linked duplicates: each shows the one result, baked where o stands
            notes.append(f"{o.name}: its mesh is also {', '.join(others)}'s, so they show this "
                         f"AO too, baked where {o.name} stands; give each its own mesh "
                         "(Object > Relations > Make Single User) to bake each")
    custom = [o.name for o in targets if getattr(o.data, "has_custom_normals", False)
              and getattr(o.data, "use_auto_smooth", True)]  # before 4.1: used with it only
    if custom and notes is not None:
        notes.append(f"{', '.join(custom)}: custom split normals, which Cycles' bake follows "
                     "and so do this one's rays, but not its proxies, grid and medium, which "
                     "take the vertex normals")
    shadowless = [o.name for o in targets if not casts_shadow(o)]
    if shadowless:
        raise CanopyAOError(f"{', '.join(shadowless)}: Ray Visibility > Shadow is off, so "
                            "Cycles' AO rays pass through it, its own included, which this "
                            "bake cannot do; turn Shadow on, or bake other objects (nothing "
                            "was changed)")
    # A target is an occluder like any other (what renders occludes): one that does not render
    # would darken the other targets only when baked with them, and Cycles refuses to bake it.
    unrendered = [o.name for o in targets if not vis.object_renders(o)]
    if unrendered:
        raise CanopyAOError(f"{', '.join(unrendered)}: disabled in renders (the object, a "
                            "collection holding it, or excluded from the view layer), so "
                            "Cycles neither renders it nor lets it occlude, and refuses to bake "
                            "it; enable it in renders, or bake other objects (nothing was "
                            "changed)")
    return targets


def _holds_result(obj, depsgraph, vertex_mode):
    """Whether obj's evaluated mesh can take a bake's result (bake_targets)."""
    if mesh_io.evaluated_is_original(obj):
        return True
    n = len(obj.evaluated_get(depsgraph).data.vertices)
    return n > 0 and not (vertex_mode and n != len(obj.data.vertices))


def check_writable(targets, on_mesh=True):
    """Refuse, before anything is read or written, what a bake could not write back whole: a
    mesh in Edit Mode (its data is the edit copy until Blender leaves it), linked library data
    (a write would be lost on save), and, when the results go onto the mesh (on_mesh: per
    vertex, not into each object's images), one mesh shared by several targets (each would
    overwrite the other's result)."""
    editing = [o.name for o in targets if o.mode == 'EDIT']
    if editing:
        raise CanopyAOError(f"{', '.join(editing)}: in Edit Mode; leave it (Tab) and bake "
                            "again (nothing was changed)")
    dyntopo = [o.name for o in targets
               if o.mode == 'SCULPT' and getattr(o, "use_dynamic_topology_sculpting", False)]
    if dyntopo:  # its mesh lives in a BMesh, which replaces the mesh when the mode is left
        raise CanopyAOError(f"{', '.join(dyntopo)}: sculpted with Dynamic Topology, whose "
                            "mesh replaces the object's when Sculpt Mode is left; leave it or "
                            "turn Dyntopo off and bake again (nothing was changed)")
    linked = [o.name for o in targets if o.library is not None or o.data.library is not None]
    if linked:
        raise CanopyAOError(f"{', '.join(linked)}: linked from another .blend file, so a bake "
                            "could not be saved; make it local (Object > Relations > Make "
                            "Local) first (nothing was changed)")
    by_mesh = {}
    for o in targets if on_mesh else ():
        by_mesh.setdefault(o.data.name_full, []).append(o.name)
    shared = [names for names in by_mesh.values() if len(names) > 1]
    if shared:
        raise CanopyAOError("these objects share one mesh, so only one result could stay on "
                            f"it: {'; '.join(', '.join(n) for n in shared)}; bake one of them, "
                            "or give each its own mesh (Object > Relations > Make Single User)"
                            " (nothing was changed)")


def _instances_anything(obj):
    """True for an object that instances others (a collection, its vertices or faces, or
    particles drawn as an object or a collection)."""
    return obj.instance_type != 'NONE' or any(
        ps.settings.render_type in ('OBJECT', 'COLLECTION')
        for ps in getattr(obj, "particle_systems", ()))


def _render_differs(obj):
    """True when a modifier of obj is shown in viewports or renders only, or subdivides to
    other levels in renders."""
    return any(m.show_viewport != m.show_render
               or getattr(m, "levels", None) != getattr(m, "render_levels", None)
               for m in obj.modifiers)


def _viewport_notes(context, depsgraph, vis, members):
    """What the viewport's depsgraph hides from a bake that Cycles renders (docs/DESIGN.md,
    'What occludes'): meshes disabled in viewports (not evaluated: read without modifiers and
    shape keys), modifiers set otherwise for renders, and the instances of instancers hidden in
    the viewport (not listed)."""
    notes = []
    unevaluated = sorted(n for n, o in members.items()
                         if not o.evaluated_get(depsgraph).is_evaluated
                         and not mesh_io.evaluated_is_original(o))
    if unevaluated:
        notes.append(f"{', '.join(unevaluated)}: disabled in viewports, so occluding as the "
                     "mesh without its modifiers and shape keys (Cycles renders them "
                     "deformed); enable them in viewports for the deformed shape")
    differ = sorted(n for n, o in members.items() if _render_differs(o))
    if differ:
        notes.append(f"{', '.join(differ)}: modifiers set differently for viewport and render "
                     "(shown in one only, or other subdivision levels): the bake reads the "
                     "viewport's shape, Cycles renders the other")
    strands = sorted(o.name for o in context.scene.objects if vis.object_renders(o) and (any(
        p.settings.render_type == 'PATH' and p.settings.count for p in o.particle_systems)
        or o.type == 'CURVES' and len(o.evaluated_get(depsgraph).data.curves)))
    if strands:
        notes.append(f"{', '.join(strands)}: hair drawn as strands (hair curves, or particles "
                     "rendered as Path), which Cycles renders and which occludes there, is not "
                     "traced here; render it as an object or collection (a blade) for it to "
                     "occlude")
    hidden = sorted(o.name for o in context.scene.objects
                    if _instances_anything(o) and vis.object_renders(o)
                    and not o.visible_get(view_layer=context.view_layer))
    if hidden:
        notes.append(f"{', '.join(hidden)}: hidden in the viewport, so their instances do not "
                     "occlude here (Cycles renders them); show them for the bake")
    return notes


def scene_items(context, depsgraph, targets, opts, timings, notes=None):
    """Every mesh Cycles renders (visibility.py: trees shade a selected ground, also when hidden
    in the viewport), every curve, text, surface and metaball it renders (SOLID_TYPES, as the
    mesh Blender makes of it) and every target as SceneItems.

    Returns (items, objects {name: object}, how {name: why this role}); IGNORE objects are left
    out. Triangles are fetched only where the bake or a role guess needs them. notes: a list to
    which a line is added for each occluder read without its modifiers (hidden in the viewport,
    so the depsgraph did not evaluate it)."""
    vis = RenderVisibility(context.view_layer)
    members = {o.name: o for o in context.scene.objects
               if (is_candidate(o) or o.type in SOLID_TYPES) and vis.mesh_renders(o)}
    if notes is not None:
        notes.extend(_viewport_notes(context, depsgraph, vis, members))
    for o in targets:
        members.setdefault(o.name, o)
    target_names = {o.name for o in targets}
    items, objects, how, alphas = [], {}, {}, {}  # alphas: each material's, read once
    for name, obj in members.items():
        # A declared role costs nothing; a guess needs the triangles (connected components).
        declared = declared_role(obj)
        if declared is not None and declared[0] == "IGNORE":
            continue
        bent = opts.get("bent_normals", "OFF") != "OFF"  # ray-traced: every triangle counts
        tris_needed = declared is None or bent or ladder.triangles_needed(
            opts["method"], opts["tau"], declared[0])
        # Only a target's result goes back onto its mesh: a non-target may change its
        # vertex count (it only occludes and shapes the proxies).
        faces, corners = [], []
        pos, nor, tris = mesh_io.evaluated_arrays(
            obj, depsgraph, same_count=opts["mode"] == 'VERTEX' and name in target_names,
            triangles=tris_needed, timings=timings, polygons=faces, corners=corners)
        t0 = time.perf_counter()
        role, why = declared or role_of(obj, pos, tris)
        timings["roles"] = timings.get("roles", 0.0) + time.perf_counter() - t0
        if role == "IGNORE":
            continue
        tree, source = tree_and_source(obj)
        polys = faces[0] if faces and len(faces[0]) == len(tris) else None
        item = SceneItem(name, role, tree, pos, nor, tris, tree_source=source, polygons=polys,
                         corner_normals=corners[0] if corners else None)
        # A guessed mesh of parts of different roles (bark and leaves) bakes part by part.
        cut = parts_io.split(obj, item, depsgraph, opts, alphas, notes) if declared is None \
            else None
        kept = {id(it) for it, _idx in cut or [(item, None)]
                if declared is not None or bent or ladder.triangles_needed(
                    opts["method"], opts["tau"], it.role)}
        if len(tris) and kept:  # which triangles rays pass (the materials' alpha)
            parts_io.set_opacity(item, cut, opacity_io.item_opacity(obj, depsgraph, len(tris),
                                                                    alphas))
        for it, _idx in cut or [(item, None)]:
            if id(it) not in kept:  # not part of this bake (kept only for the guess)
                it.triangles, it.polygons, it.opacity = it.triangles[:0], None, None
                it.corner_normals = None
            items.append(it)
            objects[it.name] = obj
            how[it.name] = f"part of {name}: {it.part_why}" if cut else why
        objects[name] = obj
        how[name] = parts_io.describe(cut) if cut else why
    return items, objects, how


def cycles_distance(depsgraph, distance):
    """The World AO distance with which Cycles bakes what this bake baked: the bake's own, or
    for its unlimited (core.scene.ray_length) twice the diagonal of the bounds of everything
    that renders, which no ray starting inside reaches past: unlimited for this scene, at any
    scale. Cycles' own 0 would mean no occlusion at all."""
    if math.isfinite(ray_length(distance)):
        return float(distance)
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for inst in depsgraph.object_instances:
        m = np.array(inst.matrix_world)
        box = np.array(inst.object.bound_box) @ m[:3, :3].T + m[:3, 3]
        lo, hi = np.minimum(lo, box.min(axis=0)), np.maximum(hi, box.max(axis=0))
    diagonal = float(np.linalg.norm(hi - lo)) if np.isfinite(hi - lo).all() else 0.0
    return 2.0 * diagonal if diagonal > 0 else 1.0
