"""bpy ↔ numpy: evaluated meshes in, color attributes out (docs/DESIGN.md, 'Data flow').

Only foreach_get / foreach_set on preallocated float32 / int32 buffers; no per-vertex Python loops.
float32 and FLOAT_COLOR because they are the fast paths (docs/DESIGN.md, 'Facts measured in
Blender': float64 is ~40× slower to move, BYTE_COLOR ~25×).
"""

import ctypes
import time

import bpy
import numpy as np

from ..core import native
from ..core.native import CanopyAOError
from . import corner_io
from .ownership import mark_owned, owned_attributes, ownership, set_record  # noqa: F401


class MeshIOError(CanopyAOError):
    """A mesh that cannot be read or written as asked (a user-facing error)."""


def _vertex_normals(mesh, n):
    out = np.empty((n, 3), dtype=np.float32)
    if not hasattr(mesh, "vertex_normals"):  # cached; vertices.normal is removed in 4.1
        mesh.vertices.foreach_get("normal", out.reshape(-1))
    elif not _copy_normals(mesh.vertex_normals, out):
        mesh.vertex_normals.foreach_get("vector", out.reshape(-1))
    return out


def _copy_normals(normals, out):
    """Copy the mesh's cached vertex normals (float[3] each, one array: what vertex_normals
    iterates) into out float32 (V, 3) in one memcpy; False where they do not lie so (then
    foreach_get). foreach_get on vertex_normals has no raw path and goes element by element:
    2 ms per 100k vertices against 0.1 ms (bench/probes/live_stages.py; docs/DESIGN.md,
    'Facts measured in Blender'). The cache lives as long as the mesh, which the caller holds."""
    n = len(out)
    if n < 2 or len(normals) != n:
        return False
    first, second, last = normals[0], normals[1], normals[n - 1]
    base = first.as_pointer()
    # one run of float[3] from the first element to the last, else nothing is read from it
    if base == 0 or second.as_pointer() - base != 12 or last.as_pointer() - base != 12 * (n - 1):
        return False
    view = np.ctypeslib.as_array((ctypes.c_float * (3 * n)).from_address(base))
    if not all(np.array_equal(view[3 * i:3 * i + 3], np.array(v.vector, np.float32))
               for i, v in ((0, first), (1, second), (n - 1, last))):
        return False
    out.reshape(-1)[:] = view
    return True


def evaluated_is_original(obj):
    """True when the evaluated mesh has the same geometry as obj.data, so it can be read without
    a to_mesh() copy (~35 ms per million vertices): no modifiers, no shape keys, not in edit
    mode (whose data lives in a BMesh until it is left), and no armature / lattice / curve
    parent deforming it (a "virtual" modifier, not in obj.modifiers)."""
    me = obj.data
    return (isinstance(me, bpy.types.Mesh) and not obj.modifiers and me.shape_keys is None and not me.is_editmode
            and (obj.parent is None or obj.parent_type in ('OBJECT', 'VERTEX', 'VERTEX_3',
                                                             'BONE')))


def _lap(timings, key, t0):
    """Add the seconds since t0 to timings[key]; returns now (for the next lap)."""
    t1 = time.perf_counter()
    if timings is not None:
        timings[key] = timings.get(key, 0.0) + (t1 - t0)
    return t1


def evaluated_arrays(obj, depsgraph, same_count=True, triangles=True, timings=None,
                     polygons=None, shared=False, corners=None):
    """World-space arrays of an object's evaluated mesh (modifiers applied).

    Returns (positions float32 (V, 3), normals float32 (V, 3) unit, triangles int32 (F, 3)).
    triangles=False skips the loop triangulation (the analytic models need none; it costs more
    than positions and normals together) and returns an empty (0, 3) array.
    With same_count, raises MeshIOError when the evaluated mesh has a different vertex count
    from the original (a per-vertex result could not be stored on the original mesh); always,
    when a vertex's world position is not finite or outside the native module's range.
    timings: a dict to which the seconds of each stage are added ("fetch", "positions",
    "normals", "triangles", "transform").
    polygons: a list to which each triangle's face index, int32 (F,), is appended (with
    triangles; the ray tracer's bake points count one corner per face). corners: likewise,
    corner_io.triangle_corner_normals (None or float32 (F, 3, 3): each corner's own normal).
    shared: read the evaluated object's own mesh, not a to_mesh() copy (live AO's read each
    frame): no copy, and its vertex normals are computed once for this evaluation, cached
    where the viewport's draw finds them (a copy computes them again: 10 ms per 100k
    vertices). Not in edit mode, whose evaluated mesh is the cage's.
    """
    t = time.perf_counter()
    # The evaluated object's matrix: a render's depsgraph animates its own copies and leaves
    # the original's matrix at the frame the viewport last showed.
    evaluated = obj.evaluated_get(depsgraph)
    matrix = np.array(evaluated.matrix_world, dtype=np.float64)
    ob_eval = None
    if evaluated_is_original(obj):
        mesh = obj.data
    elif shared and not obj.data.is_editmode and isinstance(evaluated.data, bpy.types.Mesh):
        mesh = evaluated.data
    else:
        ob_eval = evaluated
        mesh = ob_eval.to_mesh()
    try:
        n = len(mesh.vertices)
        if same_count and n != len(obj.data.vertices):
            raise MeshIOError(
                f"{obj.name}: its modifiers change the vertex count ({len(obj.data.vertices)} → "
                f"{n}), so a per-vertex result cannot be stored on the mesh; apply the "
                "modifiers or bake per texel")
        t = _lap(timings, "fetch", t)
        co = np.empty((n, 3), dtype=np.float32)
        mesh.vertices.foreach_get("co", co.reshape(-1))
        t = _lap(timings, "positions", t)
        nor = _vertex_normals(mesh, n)
        t = _lap(timings, "normals", t)
        co, nor = _to_world(co, nor, matrix)
        t = _lap(timings, "transform", t)
        if triangles:
            mesh.calc_loop_triangles()
            tris = np.empty((len(mesh.loop_triangles), 3), dtype=np.int32)
            mesh.loop_triangles.foreach_get("vertices", tris.reshape(-1))
            if polygons is not None:
                faces = np.empty(len(mesh.loop_triangles), dtype=np.int32)
                mesh.loop_triangles.foreach_get("polygon_index", faces)
                polygons.append(faces)
            if corners is not None:
                corners.append(corner_io.triangle_corner_normals(mesh, tris, nor, matrix))
        else:
            tris = np.zeros((0, 3), dtype=np.int32)
        t = _lap(timings, "triangles", t)
    finally:
        if ob_eval is not None:
            ob_eval.to_mesh_clear()
    pos = co
    limit = native.LIMITS["coordinate"]
    # Two reductions first (0.04 ms per 100k vertices; a NaN makes max() NaN, which fails the
    # test), the per-vertex count (0.9 ms) only for the message.
    ok = n == 0 or max(float(pos.max()), -float(pos.min())) <= limit
    bad = 0 if ok else n - np.count_nonzero((np.abs(pos) <= limit).all(axis=1))
    if bad:
        raise MeshIOError(f"Object '{obj.name}': {bad} of its {n} vertices have no finite "
                          f"world position within ±{limit:g} (NaN or infinite coordinates, or "
                          "a transform that makes them so); fix the mesh or its transform, or "
                          "set its role to Ignore (nothing was changed)")
    _lap(timings, "transform", t)
    return pos, nor, tris


def cornered_vertices(mesh):
    """bool (V,): the vertices a face uses. Cycles bakes face corners, so a loose vertex keeps
    0 in its vertex bake, whatever lights it: a Cycles check compares only these."""
    used = np.zeros(len(mesh.vertices), dtype=bool)
    corners = np.empty(len(mesh.loops), dtype=np.int32)
    mesh.loops.foreach_get("vertex_index", corners)
    used[corners] = True
    return used


def _to_world(co, nor, matrix_world):
    """Positions and unit normals (float32 (V, 3), modified in place) in world space: one
    native pass (mesh_arrays.h), which skips the transform for an identity matrix and keeps
    Blender's own unit normals bit for bit (a zero or NaN normal becomes +Z)."""
    co = np.ascontiguousarray(co, dtype=np.float32)
    nor = np.ascontiguousarray(nor, dtype=np.float32)
    native.require().to_world(co, nor, np.array(matrix_world, dtype=np.float64))
    return co, nor


# Blender keeps layer names in 64-byte buffers (MAX_CUSTOMDATA_LAYER_NAME, with the NUL).
MAX_ATTRIBUTE_NAME_BYTES = 63
# Attributes Blender itself owns on a mesh (3.4 to 5.x): never ours to replace, not even with
# Overwrite (their type and domain are fixed; "." names are internal).
BUILTIN_ATTRIBUTES = frozenset((
    "position", "normal", "radius", "id", "material_index", "sharp_face", "sharp_edge",
    "crease", "crease_vert", "crease_edge", "bevel_weight_vert", "bevel_weight_edge",
    "shade_smooth", "edge_crease", "vertex_crease", "custom_normal"))


def check_attribute(obj, name, overwrite):
    """None if ``name`` may be written on obj, else the reason it may not (nothing changed)."""
    if not name:
        return "the attribute name is empty"
    if len(name.encode("utf-8")) > MAX_ATTRIBUTE_NAME_BYTES:
        return (f"the attribute name '{name[:20]}…' is longer than Blender's limit of "
                f"{MAX_ATTRIBUTE_NAME_BYTES} bytes (Blender would shorten it)")
    if name.startswith(".") or name in BUILTIN_ATTRIBUTES or name in obj.data.uv_layers:
        return (f"{obj.name}: '{name}' names one of Blender's own layers (a built-in "
                "attribute or a UV map); choose another attribute name")
    if name in obj.vertex_groups:  # Blender makes no attribute beside it (new() gives None)
        return (f"{obj.name}: '{name}' names one of its vertex groups; choose another "
                "attribute name or rename the vertex group")
    if overwrite or obj.data.attributes.get(name) is None:
        return None
    state = ownership(obj.data, name)
    if state == 'ours':
        return None
    if state == 'unproven':
        return (f"{obj.name}: its attribute '{name}' is claimed only by the record of a Canopy "
                "AO without fingerprints, which cannot tell it from an attribute of yours; "
                "check it and tick Overwrite (--overwrite) to replace it, once")
    if state == 'changed':
        return (f"{obj.name}: its attribute '{name}' is no longer what Canopy AO wrote (painted "
                "or edited since, or the mesh changed); choose another name or tick Overwrite")
    return (f"{obj.name}: it already has an attribute '{name}' that Canopy AO did not make; "
            "choose another name or tick Overwrite")


def _point_attribute(obj, name, values, data_type, overwrite, checked=False):
    """(the POINT attribute ``name`` of type data_type to fill, values float32 (V,)): checked
    against the ownership rules (unless the caller just did: checked) and the vertex count, an
    attribute of another type replaced."""
    why = None if checked else check_attribute(obj, name, overwrite)
    if why:
        raise MeshIOError(why)
    mesh = obj.data
    n = len(mesh.vertices)
    values = np.ascontiguousarray(values, dtype=np.float32).reshape(-1)
    if len(values) != n:
        raise MeshIOError(f"{obj.name}: {len(values)} AO values for {n} vertices")
    attr = mesh.attributes.get(name)
    if attr is not None and (attr.data_type != data_type or attr.domain != 'POINT'):
        mesh.attributes.remove(attr)
        attr = None
    if attr is None:
        attr = (mesh.color_attributes.new(name=name, type=data_type, domain='POINT')
                if data_type == 'FLOAT_COLOR' else mesh.attributes.new(name, data_type, 'POINT'))
    return attr, values


def gray_rgba(ao):
    """The colours (ao, ao, ao, 1) of AO float (V,), flat float32 (4V,), as the writes store
    them."""
    return native.require().gray_rgba(np.ascontiguousarray(ao, dtype=np.float32)).reshape(-1)


def write_ao_attribute(obj, name, ao, overwrite=False, checked=False, tag=True):
    """Write AO (float (V,)) as a POINT-domain FLOAT_COLOR attribute (ao, ao, ao, 1).

    Replaces an attribute exactly as Canopy AO wrote it (or any, with overwrite); refuses
    otherwise. checked: the caller ran check_attribute on it just before (Live AO checks every
    target before it writes any), so its content is not read and fingerprinted twice.
    tag=False: no depsgraph tag, so nothing is evaluated again (live AO's Session.flush: the
    evaluated copy drawn already holds this AO).
    """
    attr, ao = _point_attribute(obj, name, ao, 'FLOAT_COLOR', overwrite, checked)
    mesh = obj.data
    rgba = gray_rgba(ao)
    attr.data.foreach_set("color", rgba)
    # Only the depsgraph tag: mesh.update() also marks the normals dirty, and the next bake
    # would pay their recomputation (~50 ms per million vertices).
    if tag:
        mesh.update_tag()
    mark_owned(obj, name, rgba)
    return attr


def evaluated_ao_attribute(obj, depsgraph, name):
    """The POINT FLOAT_COLOR attribute ``name`` of obj's mesh as the depsgraph evaluated it
    (what that depsgraph's render draws); None when the depsgraph does not hold obj (not in
    the render: evaluated_get would give the original); MeshIOError when the evaluated mesh has
    none (a modifier dropped it, or no bake wrote it)."""
    evaluated = obj.evaluated_get(depsgraph)
    if not evaluated.is_evaluated:
        return None
    mesh = evaluated.data
    attr = mesh.attributes.get(name)
    if attr is None or attr.data_type != 'FLOAT_COLOR' or attr.domain != 'POINT':
        raise MeshIOError(f"{obj.name}: its evaluated mesh has no '{name}' colour attribute per "
                          "vertex (a modifier removes it, or no bake wrote it): live AO has "
                          "nothing to write at this frame; bake again, or move the modifier")
    if len(attr.data) != len(obj.data.vertices):
        raise MeshIOError(f"{obj.name}: its modifiers change the vertex count, so live AO "
                          "cannot be written per vertex")
    return attr


def write_evaluated_ao(attr, ao):
    """Fill an attribute of an evaluated mesh (evaluated_ao_attribute) with AO: no tag, no
    ownership record (the depsgraph drops its copy at its next evaluation; nothing original)."""
    attr.data.foreach_set("color", gray_rgba(ao))


def write_float_attribute(obj, name, values, overwrite=False):
    """Write float (V,) as a POINT-domain FLOAT attribute (one frame of a frame-range bake's
    cache), under write_ao_attribute's ownership rules."""
    attr, values = _point_attribute(obj, name, values, 'FLOAT', overwrite)
    attr.data.foreach_set("value", values)
    obj.data.update_tag()
    mark_owned(obj, name, values)
    return attr


def remove_owned_attribute(obj, name):
    """Remove an attribute exactly as Canopy AO wrote it, and its record; True if one went."""
    if ownership(obj.data, name) != 'ours':
        return False
    obj.data.attributes.remove(obj.data.attributes[name])
    set_record(obj.data, name, None)
    obj.data.update_tag()
    return True


def read_ao_attribute(obj, name):
    """The red channel of a POINT color attribute as float32 (V,) (for tests and checks)."""
    attr = obj.data.attributes[name]
    buf = np.empty(len(obj.data.vertices) * 4, dtype=np.float32)
    attr.data.foreach_get("color", buf)
    return buf.reshape(-1, 4)[:, 0].copy()


# === Proxies in the viewport ================================================================

PROXY_COLLECTION = "Canopy AO Proxies"
PROXY_PROP = "canopy_ao_proxy"


def show_proxies(scene, proxies):
    """Replace the empties in the 'Canopy AO Proxies' collection with one sphere empty per shell,
    scaled and rotated to the ellipsoid. proxies: {tree: [{"center", "axes", "radii"}]}."""
    from mathutils import Matrix

    coll = bpy.data.collections.get(PROXY_COLLECTION)
    if coll is None:
        coll = bpy.data.collections.new(PROXY_COLLECTION)
    if coll.name not in scene.collection.children:
        scene.collection.children.link(coll)
    for ob in list(coll.objects):
        if ob.get(PROXY_PROP):  # ours only: leave anything the user put there
            bpy.data.objects.remove(ob, do_unlink=True)
    made = []
    for tree, shells in proxies.items():
        for i, e in enumerate(shells):
            q = np.asarray(e["axes"], dtype=np.float64) * np.asarray(e["radii"], np.float64)
            m = np.eye(4)
            m[:3, :3] = q
            m[:3, 3] = e["center"]
            ob = bpy.data.objects.new(f"CanopyAO_{tree}_{i}", None)
            ob.empty_display_type = 'SPHERE'
            ob.empty_display_size = 1.0
            ob.matrix_world = Matrix(m.tolist())
            ob[PROXY_PROP] = tree
            ob.hide_render = True
            ob.hide_select = True
            coll.objects.link(ob)
            made.append(ob)
    return made
