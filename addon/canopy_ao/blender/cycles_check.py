"""Check our AO against Cycles' own AO bake (docs/DESIGN.md, 'How we check ourselves').

Every setting a bake touches (engine, samples, denoising, adaptive sampling, device, AO distance,
bake settings, active colour attribute / UV map / image node, selection, active object) is
snapshotted first and restored in a ``finally``, also when the bake fails.

Facts this relies on (docs/DESIGN.md, 'Facts measured in Blender'):
- Cycles' AO bake is cosine-weighted, 1 = open sky, and ``world.light_settings.distance`` is a
  hard cut-off on ray length, used even with the world's AO checkbox off.
- Denoising (no OpenImageDenoise in Debian's build: the bake writes zeros) and adaptive sampling
  (stops vertex bakes early) must be off.
- A POINT-domain target gets the mean of the vertex's corners, each evaluated with that corner's
  normal: on flat-shaded meshes a vertex mixes several hemispheres.
"""
import contextlib
import time

import bpy
import numpy as np

from ..core import metrics
from . import materials, mesh_io

__all__ = ["bake_cycles_vertex_ao", "bake_cycles_texel_ao", "write_error_attribute",
           "check_objects", "check_texel", "render_settings_snapshot"]

_TMP_ATTR = "_CanopyAO_CyclesBake"
_TMP_IMAGE = "_CanopyAO_CyclesBake"
_TMP_MATERIAL = "_CanopyAO_CyclesBakeMat"
_TMP_WORLD = "_CanopyAO_CyclesBakeWorld"

_CYCLES_KEYS = ("samples", "use_denoising", "use_adaptive_sampling", "device", "seed")
_BAKE_KEYS = ("target", "margin", "margin_type", "use_clear", "use_selected_to_active",
              "use_cage", "max_ray_distance")


def render_settings_snapshot(scene):
    """The render settings a Cycles check touches, as a plain dict (tests compare two)."""
    snap = {"engine": scene.render.engine,
            "world": scene.world.name if scene.world else None,
            "distance": scene.world.light_settings.distance if scene.world else None}
    for k in _CYCLES_KEYS:
        snap["cycles." + k] = getattr(scene.cycles, k)
    for k in _BAKE_KEYS:
        snap["bake." + k] = getattr(scene.render.bake, k)
    return snap


@contextlib.contextmanager
def _cycles_bake_settings(context, objects, distance, samples, seed=None):
    """Switch the scene to a Cycles AO bake of `objects`, restore everything afterwards.
    seed: Cycles' sampling seed (None: the scene's)."""
    if not float(distance) > 0:  # Cycles' 0 is no occlusion, not the add-on's unlimited
        raise ValueError(f"AO distance {distance}: Cycles would read 1.0 everywhere; give a "
                         "length (for an unlimited bake: gather.cycles_distance)")
    scene = context.scene
    view_layer = context.view_layer
    saved = render_settings_snapshot(scene)
    saved_world = scene.world
    saved_selection = [o for o in view_layer.objects if o.select_get()]
    saved_active = view_layer.objects.active
    tmp_world = None
    try:
        if scene.world is None:
            tmp_world = bpy.data.worlds.new(_TMP_WORLD)
            scene.world = tmp_world
        scene.render.engine = "CYCLES"
        scene.cycles.samples = int(samples)
        scene.cycles.use_denoising = False
        scene.cycles.use_adaptive_sampling = False
        scene.cycles.device = "CPU"
        if seed is not None:
            scene.cycles.seed = int(seed)
        scene.world.light_settings.distance = float(distance)
        for o in saved_selection:
            o.select_set(False)
        for o in objects:
            o.select_set(True)
        view_layer.objects.active = objects[0]
        yield
    finally:
        scene.render.engine = saved["engine"]
        for k in _CYCLES_KEYS:
            setattr(scene.cycles, k, saved["cycles." + k])
        for k in _BAKE_KEYS:
            setattr(scene.render.bake, k, saved["bake." + k])
        if tmp_world is not None:
            scene.world = saved_world
            bpy.data.worlds.remove(tmp_world)
        elif scene.world is not None:
            scene.world.light_settings.distance = saved["distance"]
        for o in view_layer.objects:
            o.select_set(False)
        for o in saved_selection:
            o.select_set(True)
        view_layer.objects.active = saved_active


def _check_bakeable(context, objects):
    if not objects:
        raise ValueError("No objects to check against Cycles")
    if context.mode != "OBJECT":
        raise ValueError("The Cycles check needs Object Mode; leave Edit Mode first")
    names = {o.name for o in context.view_layer.objects}
    for o in objects:
        if o.type != "MESH":
            raise ValueError(f"Object '{o.name}' is not a mesh; Cycles can only bake meshes")
        if o.name not in names or not o.visible_get(view_layer=context.view_layer):
            raise ValueError(f"Object '{o.name}' is hidden or not in the view layer; "
                             "Cycles bakes only visible objects")
        if o.hide_render:
            raise ValueError(f"Object '{o.name}' is disabled in renders; Cycles cannot bake it")


def _run_bake(target, use_clear=True, bake_type="AO"):
    """One Cycles bake of the selected objects (margin 0: we want only covered texels); AO
    unless bake_type names another pass (bench/probes/cycles_corner_probe.py bakes POSITION)."""
    try:
        result = bpy.ops.object.bake(type=bake_type, target=target, margin=0,
                                     use_clear=use_clear, use_selected_to_active=False,
                                     save_mode="INTERNAL")
    except RuntimeError as exc:  # the operator reports its own reason, e.g. missing image
        raise RuntimeError(f"Cycles {bake_type} bake failed: {str(exc).strip()}") from exc
    if "FINISHED" not in result:
        raise RuntimeError(f"Cycles {bake_type} bake did not finish ({result})")


def bake_cycles_vertex_ao(context, objects, distance, samples, seed=None):
    """Cycles AO per vertex of each mesh object (its *original* mesh: Cycles writes the bake into
    the original mesh's attribute). seed: Cycles' sampling seed (None: the scene's; another
    seed gives noise independent of this one's). Returns {object name: float32 (V,) in
    [0, 1]}."""
    objects = list(objects)
    _check_bakeable(context, objects)
    # Per mesh: (previous active colour name, previous render colour index, temporary attr).
    state = {}
    try:
        with _cycles_bake_settings(context, objects, distance, samples, seed):
            for o in objects:
                me = o.data
                if me in state:
                    continue
                ca = me.color_attributes
                prev = (ca.active_color_name if ca.active_color is not None else None,
                        ca.render_color_index)
                attr = ca.new(_TMP_ATTR, "FLOAT_COLOR", "POINT")
                ca.active_color = attr
                state[me] = prev
            _run_bake("VERTEX_COLORS")
            out = {}
            for o in objects:
                me = o.data
                n = len(me.vertices)
                buf = np.empty(n * 4, dtype=np.float32)
                me.color_attributes[_TMP_ATTR].data.foreach_get("color", buf)
                out[o.name] = np.ascontiguousarray(buf.reshape(n, 4)[:, 0])
            return out
    finally:
        for me, (prev_name, prev_render) in state.items():
            ca = me.color_attributes
            tmp = ca.get(_TMP_ATTR)
            if tmp is not None:
                ca.remove(tmp)
            if prev_name is not None and ca.get(prev_name) is not None:
                ca.active_color = ca[prev_name]
            if 0 <= prev_render < len(ca):
                ca.render_color_index = prev_render


def bake_cycles_texel_ao(context, obj, uv_map, resolution, distance, samples,
                         return_mask=False, seed=None):
    """Cycles AO baked into obj's UV layout `uv_map`, as float32 (H, W) with row 0 at v = 0
    (Blender's image order). Texels no triangle covers are 0; with return_mask=True also
    returns the bool (H, W) coverage mask (texels Cycles wrote). seed: as
    bake_cycles_vertex_ao's."""
    _check_bakeable(context, [obj])
    me = obj.data
    if uv_map is None:
        uv_map = me.uv_layers.active.name if me.uv_layers.active else None
    if uv_map is None or me.uv_layers.get(uv_map) is None:
        raise ValueError(f"Object '{obj.name}' has no UV map {uv_map!r}; add one "
                         "(UV > Smart UV Project) or check per vertex")
    res = int(resolution)
    if res < 1 or res > 16384:
        raise ValueError(f"resolution must be in [1, 16384], not {resolution}")
    image = None
    added_nodes = []     # (node tree, node)
    prev_active = []     # (node tree, previously active node)
    tmp_material = None
    prev_uv = me.uv_layers.active.name if me.uv_layers.active else None
    prev_render_uv = next((l.name for l in me.uv_layers if l.active_render), None)
    try:
        image = bpy.data.images.new(_TMP_IMAGE, res, res, alpha=True, float_buffer=True)
        image.colorspace_settings.name = "Non-Color"
        # Sentinel: Cycles overwrites only the texels it bakes (use_clear off, no margin), so
        # R < 0 afterwards marks texels no triangle covers.
        image.pixels.foreach_set(np.full(res * res * 4, -1.0, dtype=np.float32))
        mats = [s.material for s in obj.material_slots if s.material is not None]
        if not mats or len(mats) < len(obj.material_slots):
            if not obj.material_slots:
                tmp_material = bpy.data.materials.new(_TMP_MATERIAL)
                materials.enable_nodes(tmp_material)
                obj.data.materials.append(tmp_material)
                mats = [tmp_material]
            else:
                raise ValueError(f"Object '{obj.name}' has an empty material slot; assign a "
                                 "material or remove the slot before a per-texel check")
        for mat in dict.fromkeys(mats):
            if not materials.uses_nodes(mat):
                raise ValueError(f"Material '{mat.name}' does not use nodes; enable "
                                 "'Use Nodes' before a per-texel Cycles check")
            nt = mat.node_tree
            node = nt.nodes.new("ShaderNodeTexImage")
            node.image = image
            added_nodes.append((nt, node))
            prev_active.append((nt, nt.nodes.active))
            nt.nodes.active = node
        me.uv_layers.active = me.uv_layers[uv_map]
        with _cycles_bake_settings(context, [obj], distance, samples, seed):
            _run_bake("IMAGE_TEXTURES", use_clear=False)
        px = np.empty(res * res * 4, dtype=np.float32)
        image.pixels.foreach_get(px)
        px = px.reshape(res, res, 4)
        mask = px[:, :, 0] >= 0.0
        ao = np.where(mask, px[:, :, 0], 0.0).astype(np.float32)
        return (ao, mask) if return_mask else ao
    finally:
        for nt, node in added_nodes:
            nt.nodes.remove(node)
        for nt, node in prev_active:
            if node is not None:
                nt.nodes.active = node
        if tmp_material is not None:
            with bpy.context.temp_override(object=obj, active_object=obj):
                for i in reversed(range(len(obj.material_slots))):
                    if obj.material_slots[i].material == tmp_material:
                        obj.active_material_index = i
                        bpy.ops.object.material_slot_remove()
            bpy.data.materials.remove(tmp_material)
        if prev_uv is not None and me.uv_layers.get(prev_uv) is not None:
            me.uv_layers.active = me.uv_layers[prev_uv]
        if prev_render_uv is not None and me.uv_layers.get(prev_render_uv) is not None:
            me.uv_layers[prev_render_uv].active_render = True
        if image is not None:
            bpy.data.images.remove(image)


def error_colors(err, scale=None):
    """(N, 4) float32 heat map of err = ours - ref: blue (ours darker) → white (equal) → red
    (ours brighter), saturated at |err| = scale (default: the largest |err|)."""
    err = np.nan_to_num(np.asarray(err, dtype=np.float32).ravel(), nan=0.0)
    if scale is None:
        scale = float(np.abs(err).max()) if err.size else 0.0
    s = np.clip(err / max(float(scale), 1e-6), -1.0, 1.0)
    rgba = np.ones((err.size, 4), dtype=np.float32)
    pos = np.maximum(s, 0.0)
    neg = np.maximum(-s, 0.0)
    rgba[:, 0] -= neg          # darker → less red and green: blue
    rgba[:, 1] -= pos + neg
    rgba[:, 2] -= pos          # brighter → less green and blue: red
    return rgba


def write_error_attribute(obj, err, name="CanopyAO_Error", scale=None, overwrite=False):
    """Write err = ours - ref (per vertex) as a FLOAT_COLOR POINT heat map attribute (see
    error_colors). Like the AO attribute, it replaces only an attribute Canopy AO made (or any,
    with overwrite). Returns the attribute."""
    from . import mesh_io

    me = obj.data
    n = len(me.vertices)
    err = np.asarray(err)
    if err.shape != (n,):
        raise ValueError(f"Error array for '{obj.name}' has shape {err.shape}; the mesh has "
                         f"{n} vertices (bake and compare the same, unmodified mesh)")
    why = mesh_io.check_attribute(obj, name, overwrite)
    if why:
        raise ValueError(why)
    attr = me.attributes.get(name)
    if attr is not None and (attr.data_type != "FLOAT_COLOR" or attr.domain != "POINT"):
        me.attributes.remove(attr)
        attr = None
    if attr is None:
        attr = me.color_attributes.new(name, "FLOAT_COLOR", "POINT")
    colors = error_colors(err, scale).ravel()
    attr.data.foreach_set("color", colors)
    me.update()
    mesh_io.mark_owned(obj, name, colors)
    return attr


def check_objects(context, objects, ours, distance, samples, write_errors=False,
                  buried_threshold=1e-3):
    """Bake Cycles AO for `objects` (one bake call) and compare with ours[name] per vertex.

    Returns {name: metrics.compare(...) dict + "time_cycles" (s, shared bake time) + "n_buried" and
    "mae_unburied"/"rmse_unburied"/"corr_unburied" (vertices Cycles sees as fully blocked, e.g.
    leaf bases inside a branch, left out; docs/DESIGN.md, 'Facts measured in Blender')}.
    """
    objects = list(objects)
    for o in objects:
        if o.name not in ours:
            raise ValueError(f"No AO of ours for object '{o.name}'; bake it first")
        n = len(o.data.vertices)
        if np.asarray(ours[o.name]).shape != (n,):
            raise ValueError(
                f"Our AO for '{o.name}' has {np.asarray(ours[o.name]).size} values but its mesh "
                f"has {n} vertices (modifiers change the vertex count?); Cycles bakes the "
                "original mesh, so apply the modifiers or check per texel")
    t0 = time.perf_counter()
    ref = bake_cycles_vertex_ao(context, objects, distance, samples)
    t_bake = time.perf_counter() - t0
    report = {}
    for o in objects:
        a = np.asarray(ours[o.name], dtype=np.float32)
        r = ref[o.name]
        used = mesh_io.cornered_vertices(o.data)
        m = metrics.compare(a, r, mask=used)
        unburied = metrics.compare(a, r, mask=used & (r > buried_threshold))
        m["time_cycles"] = t_bake
        m["n_buried"] = m["n"] - unburied["n"]
        for k in ("mae", "rmse", "corr"):
            m[k + "_unburied"] = unburied[k]
        if write_errors:
            write_error_attribute(o, np.where(used, a - r, 0.0))
        report[o.name] = m
    return report


def check_texel(context, obj, ours, uv_map, distance, samples, ours_mask=None):
    """Bake Cycles AO into obj's UV layout at our image's resolution and compare the texels
    both cover (Cycles' coverage: texel centres inside a face; ours_mask, e.g. texel.splat's
    mask == 1, leaves out our margin). ours: float32 (H, W), row 0 = bottom. Needs a square
    image (Cycles bakes a square temporary image here)."""
    ours = np.asarray(ours, dtype=np.float32)
    if ours.ndim != 2 or ours.shape[0] != ours.shape[1]:
        raise ValueError(f"Our texel AO for '{obj.name}' has shape {ours.shape}; expected a "
                         "square (H, W) image")
    t0 = time.perf_counter()
    ref, mask = bake_cycles_texel_ao(context, obj, uv_map, ours.shape[0], distance, samples,
                                     return_mask=True)
    if ours_mask is not None:
        mask &= np.asarray(ours_mask, dtype=bool)
    m = metrics.compare(ours, ref, mask=mask)
    m["time_cycles"] = time.perf_counter() - t0
    return m
