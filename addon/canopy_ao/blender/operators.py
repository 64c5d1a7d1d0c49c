"""The bake operator and the job behind it (shared with the command line, cli.py)."""

import time

import bpy
import numpy as np
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, StringProperty

from . import instances, mesh_io
from ..core import bake as engine, roles
from .properties import method_items


class BakeError(RuntimeError):
    """A bake refused before anything was changed, with the reason for the user."""


# === Scene → items ===========================================================================

def tree_of(obj):
    """Which tree an object belongs to: the user's name (or a generator's ``canopy_ao_tree``
    tag), else the root of its parent chain (a
    trunk parenting its leaves), else its first collection (the scene's own collection makes
    one tree of everything loose in it)."""
    if obj.canopy_ao.tree:
        return obj.canopy_ao.tree
    if isinstance(obj.get("canopy_ao_tree"), str) and obj["canopy_ao_tree"]:
        return obj["canopy_ao_tree"]  # set by a scene generator (examples/blender_scene.py)
    if obj.parent is not None or obj.children:
        root = obj
        while root.parent is not None:
            root = root.parent
        return root.canopy_ao.tree or root.name
    if obj.users_collection:
        return obj.users_collection[0].name
    return "Scene"


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


def world_ao_distance(scene):
    """The AO distance Cycles uses for this scene (World > Ambient Occlusion > Distance, applied
    by the AO bake even with the checkbox off; DESIGN 9); 0 (unlimited) without a world."""
    return float(scene.world.light_settings.distance) if scene.world else 0.0


def ao_distance(scene, settings):
    """The panel's AO distance: the World's by default, so a bake and its Cycles check agree
    whatever the scene's scale; the typed value when 'From World' is off."""
    return world_ao_distance(scene) if settings.use_world_distance else settings.distance


# Seconds per stage of the last committed bake (for bench/blender_bake_speed.py).
LAST_TIMINGS = {}


def _is_candidate(obj):
    return obj.type == 'MESH' and not obj.get(mesh_io.PROXY_PROP)


def scene_settings_opts(scene):
    """The bake options as the scene's panel has them."""
    s = scene.canopy_ao
    return dict(method=s.method, tau=None if s.tau_auto else s.tau, distance=ao_distance(scene, s),
                samples=s.samples, attribute=s.attribute_name, overwrite=s.overwrite,
                wire_material=s.wire_material, add_aov=s.add_aov, aov_name=s.aov_name,
                mode=s.mode, uv_map=s.uv_map, resolution=s.resolution, image_dir=s.image_dir,
                show_proxies=s.show_proxies, check_cycles=s.check_cycles,
                cycles_samples=s.cycles_samples)


class BakeJob:
    """One bake: gather and check (nothing changed on failure), prepare, evaluate one target at
    a time, then commit every write at once, so a cancelled or failed bake changes nothing."""

    def __init__(self, context, object_names, opts):
        self.opts = opts
        self.scene = context.scene
        self.results = []
        # Seconds per stage of this bake (bench/blender_bake_speed.py prints them).
        self.timings = {}
        t_start = time.perf_counter()
        self.lines = []
        ok, msg = engine.core_status()
        if not ok:
            raise BakeError(msg)
        if opts["mode"] == 'TEXEL':
            import importlib.util
            if importlib.util.find_spec(f"{__package__}.texel_io") is None:
                raise BakeError("per-texel output is not available in this build (no "
                                "canopy_ao.texel); bake per vertex")
        if opts["wire_material"] or opts["add_aov"]:
            try:
                from . import materials
                materials.check_aov_name(opts["aov_name"])
            except ImportError:
                pass  # reported in the notes after the bake
            except ValueError as exc:
                raise BakeError(str(exc)) from None
        if opts["method"] not in engine.available_methods():
            raise BakeError(f"method '{opts['method']}' is not available; one of "
                            f"{', '.join(engine.available_methods())}")
        view_layer = context.view_layer
        if object_names:
            missing = [n for n in object_names if n not in self.scene.objects]
            if missing:
                raise BakeError(f"no object named {', '.join(missing)} in scene "
                                f"'{self.scene.name}'")
            targets = [self.scene.objects[n] for n in object_names]
            bad = [o.name for o in targets if o.type != 'MESH']
            if bad:
                raise BakeError(f"not a mesh: {', '.join(bad)}")
        else:
            targets = [o for o in context.selected_objects if _is_candidate(o)]
            if not targets:
                targets = [o for o in self.scene.objects
                           if _is_candidate(o) and o.visible_get(view_layer=view_layer)]
        if not targets:
            raise BakeError("nothing to bake: no mesh objects selected or visible")
        # The whole visible scene takes part (trees shade a selected ground), targets receive.
        members = {o.name: o for o in self.scene.objects
                   if _is_candidate(o) and o.visible_get(view_layer=view_layer)}
        for o in targets:
            members.setdefault(o.name, o)
        depsgraph = context.evaluated_depsgraph_get()
        self.items, self.objects, self.how = [], {}, {}
        target_names = {o.name for o in targets}
        for name, obj in members.items():
            # A declared role costs nothing; a guess needs the triangles (connected components).
            declared = declared_role(obj)
            if declared is not None and declared[0] == "IGNORE":
                continue
            tris_needed = declared is None or engine.triangles_needed(
                opts["method"], opts["tau"], declared[0])
            # Only a target's result goes back onto its mesh: a non-target may change its
            # vertex count (it only occludes and shapes the proxies).
            try:
                pos, nor, tris = mesh_io.evaluated_arrays(
                    obj, depsgraph, same_count=opts["mode"] == 'VERTEX' and name in target_names,
                    triangles=tris_needed, timings=self.timings)
            except mesh_io.MeshIOError as exc:
                raise BakeError(str(exc)) from None
            t0 = time.perf_counter()
            role, how = declared or role_of(obj, pos, tris)
            if declared is None and not engine.triangles_needed(opts["method"], opts["tau"],
                                                                role):
                tris = tris[:0]  # not part of this bake (kept only for the guess)
            self.timings["roles"] = self.timings.get("roles", 0.0) + time.perf_counter() - t0
            if role == "IGNORE":
                continue
            self.items.append(engine.SceneItem(name, role, tree_of(obj), pos, nor, tris))
            self.objects[name] = obj
            self.how[name] = how
        self.targets = [it for it in self.items if it.name in target_names]
        if not self.targets:
            raise BakeError("every object to bake has the role Ignore")
        for it in self.targets if opts["mode"] == 'VERTEX' else ():
            why = mesh_io.check_attribute(self.objects[it.name], opts["attribute"],
                                          opts["overwrite"])
            if why:
                raise BakeError(why + " (nothing was changed)")
        t0 = time.perf_counter()
        # Instanced trees (particles, collection instances, geometry nodes): each prototype is
        # baked once (its instances share its mesh) and every instance occludes (instances.py).
        try:
            self.prototypes = instances.Prototypes(depsgraph, role_of, tree_of,
                                                   vertex_mode=opts["mode"] == 'VERTEX')
        except mesh_io.MeshIOError as exc:
            raise BakeError(str(exc)) from None
        why = self.prototypes.check(opts["attribute"], opts["overwrite"], skip=target_names)
        if why:
            raise BakeError(why + " (nothing was changed)")
        self.settings = engine.BakeSettings(
            method=opts["method"], tau=opts["tau"], distance=opts["distance"],
            samples=opts["samples"], time_budget=opts.get("time_budget", 2.0),
            target_rmse=opts.get("target_rmse", 0.06),
            forest_epsilon=opts.get("forest_epsilon", 1e-2))
        self.plan = None
        self.index = 0
        self._lap("instances", t0)
        self._lap("gather (total)", t_start)

    def _lap(self, key, t0):
        """Add the seconds since t0 to timings[key]; returns now."""
        t1 = time.perf_counter()
        self.timings[key] = self.timings.get(key, 0.0) + t1 - t0
        return t1

    @property
    def steps(self):
        return len(self.targets) + 1

    def prepare(self):
        t0 = time.perf_counter()
        try:
            self.plan = engine.prepare(self.items, self.settings)
            t0 = self._lap("prepare (fit, calibrate)", t0)
            if self.prototypes:
                skip = {it.name for it in self.targets}
                engine.attach_forest(self.plan, self.prototypes.bake(self.settings, skip=skip))
                self.lines.extend(self.prototypes.lines())
                self._lap("instances", t0)
        except (engine.EngineError, ValueError, RuntimeError) as exc:
            raise BakeError(f"bake failed: {exc}") from exc

    def step(self):
        """Bake the next target; returns the line to report, or None when all are done."""
        if self.index >= len(self.targets):
            return None
        it = self.targets[self.index]
        self.index += 1
        t0 = time.perf_counter()
        try:
            r = engine.evaluate_item(self.plan, it)
        except (engine.EngineError, ValueError, RuntimeError) as exc:
            raise BakeError(f"{it.name}: bake failed: {exc}") from exc
        self._lap("evaluate", t0)
        self.results.append(r)
        line = (f"{r.name}: role {r.role} ({self.how[r.name]}), tree {r.tree}, method {r.method}, "
                f"{r.vertices} vertices, {r.seconds:.3f} s")
        return line

    def run(self, progress=None):
        self.prepare()
        while True:
            if progress:
                progress(self.index)
            if self.step() is None:
                break

    def commit(self, context):
        """Write every result, then the optional extras. Returns the JSON-ready report."""
        o = self.opts
        texel_stats = {}
        t0 = time.perf_counter()
        if o["mode"] == 'TEXEL':
            from . import texel_io as texel
            try:
                texel_stats = texel.bake_objects(context, self.plan, self.targets, o)
            except ValueError as exc:  # no UV map, bad resolution: said before any change
                raise BakeError(str(exc)) from None
        else:
            for r in self.results:
                obj = self.objects[r.name]
                mesh_io.write_ao_attribute(obj, o["attribute"], r.ao, overwrite=o["overwrite"])
            self.prototypes.commit(o["attribute"], o["overwrite"])
        t0 = self._lap("write", t0)
        if o["show_proxies"]:
            mesh_io.show_proxies(self.scene, engine.proxy_dicts(self.plan))
        elif mesh_io.PROXY_COLLECTION in bpy.data.collections:
            mesh_io.show_proxies(self.scene, {})  # stale proxies of an earlier bake go
        t0 = self._lap("proxies", t0)
        rep = engine.report(self.plan, self.results)
        rep["attribute"] = o["attribute"] if o["mode"] == 'VERTEX' else None
        rep["mode"] = o["mode"].lower()
        rep["instances"] = {
            "instances": self.prototypes.count if self.prototypes else 0,
            "prototypes": {r.name: {"tree": r.tree, "method": r.method, "vertices": r.vertices,
                                    "seconds": r.seconds, "ao_mean": float(r.ao.mean())
                                    if r.vertices else None}
                           for r in self.prototypes.results}}
        for name, st in texel_stats.items():
            rep["objects"][name]["texel"] = {k: v for k, v in st.items()
                                             if isinstance(v, (int, float, str, list))}
            rep["notes"].extend(st.get("warnings", []))
        for r in self.results:
            rep["objects"][r.name]["role_source"] = self.how[r.name]
        if o["mode"] == 'VERTEX' and o["wire_material"] or o["add_aov"]:
            self._wire(rep)
        if o["check_cycles"]:
            self._check_cycles(context, rep)
        for r in self.results:
            e = rep["objects"][r.name]
            text = (f"{e['role']}, {e['method']}, {e['vertices']} verts, {e['seconds']:.3f} s, "
                    f"mean AO {e['ao_mean']:.3f}")
            if "cycles" in e:
                text += f", vs Cycles MAE {e['cycles'].get('mae', float('nan')):.3f}"
            self.objects[r.name].canopy_ao.last_result = text
        self.scene.canopy_ao.last_report = (
            f"{rep['method']}, τ {rep['tau']:.3g}, {len(self.results)} object(s)")
        self._lap("report, extras", t0)
        rep["stage_seconds"] = dict(self.timings)
        LAST_TIMINGS.clear()
        LAST_TIMINGS.update(self.timings)
        self.report_dict = rep
        return rep

    def _wire(self, rep):
        o = self.opts
        try:
            from . import materials
        except ImportError:
            rep["notes"].append("material wiring not available in this build")
            return
        if o["wire_material"]:
            for r in self.results:
                materials.wire_vertex_ao(self.objects[r.name], o["attribute"], o["aov_name"])
            for r in self.prototypes.results:
                materials.wire_vertex_ao(self.prototypes.objects[r.name], o["attribute"],
                                         o["aov_name"])
        if o["add_aov"]:
            materials.ensure_view_layer_aov(self.scene, o["aov_name"])

    def _check_cycles(self, context, rep):
        try:
            from . import cycles_check
            from ..core import metrics
        except ImportError:
            raise BakeError("the Cycles check is not available in this build") from None
        objs = [self.objects[r.name] for r in self.results]
        d = self.opts["distance"]
        ref = cycles_check.bake_cycles_vertex_ao(context, objs, d if d > 0 else 1.0e6,
                                                 self.opts["cycles_samples"])
        for r in self.results:
            if r.name in ref and np.shape(ref[r.name]) != r.ao.shape:
                rep["notes"].append(f"{r.name}: Cycles check skipped (its modifiers change the "
                                    "vertex count)")
            elif r.name in ref:
                rep["objects"][r.name]["cycles"] = {
                    k: float(v) for k, v in metrics.compare(r.ao, ref[r.name]).items()}


# === The operator ============================================================================

class CANOPY_AO_OT_bake(bpy.types.Operator):
    """Bake approximate ambient occlusion into a color attribute of the selected objects (or
    every visible mesh), from proxies fitted to the canopies"""

    bl_idname = "canopy_ao.bake"
    bl_label = "Bake Canopy AO"
    bl_options = {'REGISTER', 'UNDO'}

    # Every setting can be given as an argument; one left unset takes the scene's panel value.
    objects: StringProperty(name="Objects", default="",
                            description="Comma-separated object names; empty = the selection, "
                                        "or every visible mesh")
    method: EnumProperty(name="Method", items=method_items)
    tau: FloatProperty(name="τ", default=0.0, min=0.0,
                       description="Optical depth; 0 = calibrate automatically")
    distance: FloatProperty(name="AO Distance", default=10.0, min=0.0)
    samples: IntProperty(name="Samples", default=64, min=1)
    attribute: StringProperty(name="Attribute", default="CanopyAO")
    overwrite: BoolProperty(name="Overwrite", default=False)
    show_proxies: BoolProperty(name="Show Proxies", default=True)
    wire_material: BoolProperty(name="Wire Material", default=False)
    add_aov: BoolProperty(name="Add AOV", default=False)
    aov_name: StringProperty(name="AOV Name", default="BakedAO")
    mode: EnumProperty(name="Output", items=[("VERTEX", "Per Vertex", ""),
                                             ("TEXEL", "Per Texel", "")], default="VERTEX")
    uv_map: StringProperty(name="UV Map", default="")
    resolution: IntProperty(name="Resolution", default=1024, min=16, max=16384)
    image_dir: StringProperty(name="Image Folder", default="//canopy_ao", subtype='DIR_PATH')
    check_cycles: BoolProperty(name="Check with Cycles", default=False)
    cycles_samples: IntProperty(name="Cycles Samples", default=64, min=1)

    _timer = None
    _job = None

    @classmethod
    def poll(cls, context):
        ok, _ = engine.core_status()
        if not ok:
            cls.poll_message_set("The native module is not loaded: see the Canopy AO panel "
                                 "(N panel) for how to build it")
            return False
        if context.scene is None or not any(o.type == 'MESH' for o in context.scene.objects):
            cls.poll_message_set("The scene has no mesh objects to bake")
            return False
        return True

    def _opts(self, context):
        opts = scene_settings_opts(context.scene)
        keymap = {"attribute": "attribute", "method": "method", "distance": "distance",
                  "samples": "samples", "overwrite": "overwrite", "show_proxies": "show_proxies",
                  "wire_material": "wire_material", "add_aov": "add_aov",
                  "aov_name": "aov_name", "check_cycles": "check_cycles",
                  "cycles_samples": "cycles_samples", "mode": "mode", "uv_map": "uv_map",
                  "resolution": "resolution", "image_dir": "image_dir"}
        for prop, key in keymap.items():
            if self.properties.is_property_set(prop):
                opts[key] = getattr(self, prop)
        if self.properties.is_property_set("tau"):
            opts["tau"] = self.tau if self.tau > 0 else None
        return opts

    def _names(self):
        return [s.strip() for s in self.objects.split(",") if s.strip()]

    def _report_error(self, exc):
        self.report({'ERROR'}, str(exc))
        return {'CANCELLED'}

    def _finish(self, context, job, lines_reported=False):
        try:
            job.commit(context)
        except (BakeError, mesh_io.MeshIOError, RuntimeError) as exc:
            return self._report_error(exc)
        rep = job.report_dict
        for line in job.lines if not lines_reported else ():
            self.report({'INFO'}, line)
        where = f"'{rep['attribute']}'" if rep["attribute"] else "images"
        self.report({'INFO'}, f"Canopy AO: {rep['method']}, τ {rep['tau']:.3g}, "
                              f"{len(job.results)} object(s) baked into {where}")
        for note in rep["notes"]:
            self.report({'WARNING'}, note)
        return {'FINISHED'}

    def execute(self, context):
        wm = context.window_manager
        try:
            job = BakeJob(context, self._names(), self._opts(context))
            wm.progress_begin(0, job.steps)
            try:
                job.prepare()
                while True:
                    wm.progress_update(job.index + 1)
                    line = job.step()
                    if line is None:
                        break
                    job.lines.append(line)
            finally:
                wm.progress_end()
        except BakeError as exc:
            return self._report_error(exc)
        return self._finish(context, job)

    def invoke(self, context, event):
        if context.window is None or bpy.app.background:
            return self.execute(context)
        try:
            self._job = BakeJob(context, self._names(), self._opts(context))
        except BakeError as exc:
            return self._report_error(exc)
        wm = context.window_manager
        wm.progress_begin(0, self._job.steps)
        self._timer = wm.event_timer_add(0.01, window=context.window)
        wm.modal_handler_add(self)
        context.workspace.status_text_set("Canopy AO: baking… (Esc to cancel)")
        return {'RUNNING_MODAL'}

    def _stop(self, context):
        wm = context.window_manager
        if self._timer is not None:
            wm.event_timer_remove(self._timer)
            self._timer = None
        wm.progress_end()
        context.workspace.status_text_set(None)

    def modal(self, context, event):
        if event.type == 'ESC' and event.value == 'PRESS':
            self._stop(context)
            self.report({'WARNING'}, "Canopy AO bake cancelled; nothing was changed")
            return {'CANCELLED'}
        if event.type != 'TIMER':
            return {'PASS_THROUGH'}
        job = self._job
        try:
            if job.plan is None:
                job.prepare()  # fitting and calibration: one tick
            else:
                line = job.step()
                if line is None:
                    self._stop(context)
                    return self._finish(context, job, lines_reported=True)
                job.lines.append(line)
                self.report({'INFO'}, line)
            context.window_manager.progress_update(job.index + 1)
        except BakeError as exc:
            self._stop(context)
            return self._report_error(exc)
        return {'RUNNING_MODAL'}


class CANOPY_AO_OT_guess_roles(bpy.types.Operator):
    """Set each selected mesh's role to the one guessed from its geometry, so it can be
    reviewed and changed"""

    bl_idname = "canopy_ao.guess_roles"
    bl_label = "Guess Roles"
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def poll(cls, context):
        if not any(o.type == 'MESH' for o in context.selected_objects):
            cls.poll_message_set("Select mesh objects")
            return False
        return True

    def execute(self, context):
        depsgraph = context.evaluated_depsgraph_get()
        for obj in context.selected_objects:
            if obj.type != 'MESH':
                continue
            try:
                pos, _nor, tris = mesh_io.evaluated_arrays(obj, depsgraph)
            except mesh_io.MeshIOError as exc:
                self.report({'WARNING'}, str(exc))
                continue
            role, why = roles.guess_role(pos, tris)
            obj.canopy_ao.role = role
            self.report({'INFO'}, f"{obj.name}: {role} ({why})")
        return {'FINISHED'}


class CANOPY_AO_OT_remove_wiring(bpy.types.Operator):
    """Remove exactly the nodes Canopy AO added to the materials of the selected objects (or
    of the named ones) and restore the original links; the baked attributes stay"""

    bl_idname = "canopy_ao.remove_wiring"
    bl_label = "Remove Material Wiring"
    bl_options = {'REGISTER', 'UNDO'}

    objects: bpy.props.StringProperty(
        name="Objects", default="",
        description="Comma-separated object names (default: the selected objects)")

    def execute(self, context):
        from . import materials
        if self.objects.strip():
            names = [n.strip() for n in self.objects.split(",") if n.strip()]
            missing = [n for n in names if n not in bpy.data.objects]
            if missing:
                self.report({'ERROR'}, f"no object named {', '.join(map(repr, missing))}")
                return {'CANCELLED'}
            targets = [bpy.data.objects[n] for n in names]
        else:
            targets = [o for o in context.selected_objects if o.type == 'MESH']
            if not targets:
                self.report({'ERROR'}, "select the mesh objects whose wiring to remove, "
                                       "or name them with objects=")
                return {'CANCELLED'}
        removed = sum(materials.unwire(o) for o in targets)
        self.report({'INFO'}, f"removed {removed} Canopy AO node(s) from {len(targets)} object(s)")
        return {'FINISHED'}

    def invoke(self, context, event):
        return self.execute(context)


classes = (CANOPY_AO_OT_bake, CANOPY_AO_OT_guess_roles, CANOPY_AO_OT_remove_wiring)

register, unregister = bpy.utils.register_classes_factory(classes)


def run_bake(context, object_names, opts):
    """Synchronous bake for scripts and the CLI. Returns (job, report); raises BakeError."""
    t0 = time.perf_counter()
    job = BakeJob(context, object_names, opts)
    job.run()
    rep = job.commit(context)
    rep["seconds"] = time.perf_counter() - t0
    return job, rep
