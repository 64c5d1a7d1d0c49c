"""Build a canopy_scenes.Scene as Blender objects (examples/canopy_scenes.py has the geometry).

One object per MeshPart, named after it, with the custom property ``canopy_ao_role`` set to the
part's role ("canopy", "trunk", "ground", "grass") and ``canopy_ao_tree`` to its tree. Each tree
gets its own collection inside the scene's collection, and its leaves object is parented to its
trunk object (identity transforms: vertices are in world space). Smooth shading everywhere, so a
vertex has one normal (docs/DESIGN.md, 'Facts measured in Blender': a POINT-domain Cycles bake
averages the corners' normals).

Mesh data goes in through ``foreach_set`` on flat numpy buffers, never per-vertex Python loops.
"""
from __future__ import annotations

import bpy
import numpy as np


def mesh_from_arrays(name: str, vertices: np.ndarray, triangles: np.ndarray,
                     uvs: np.ndarray | None = None) -> bpy.types.Mesh:
    """A triangle mesh from float32 (V,3) vertices, int32 (M,3) triangles, per-vertex (V,2) UVs."""
    v = np.ascontiguousarray(vertices, dtype=np.float32).reshape(-1, 3)
    t = np.ascontiguousarray(triangles, dtype=np.int32).reshape(-1, 3)
    me = bpy.data.meshes.new(name)
    me.vertices.add(len(v))
    me.vertices.foreach_set("co", v.ravel())
    me.loops.add(3 * len(t))
    me.loops.foreach_set("vertex_index", t.ravel())
    me.polygons.add(len(t))
    me.polygons.foreach_set("loop_start", np.arange(0, 3 * len(t), 3, dtype=np.int32))
    try:  # writable in 3.x; derived from loop_start (read-only) in 4.x
        me.polygons.foreach_set("loop_total", np.full(len(t), 3, dtype=np.int32))
    except (AttributeError, TypeError, RuntimeError):
        pass
    me.polygons.foreach_set("use_smooth", np.ones(len(t), dtype=bool))
    me.update(calc_edges=True)
    if uvs is not None and len(t):
        uv = me.uv_layers.new(name="UVMap")
        uv.data.foreach_set("uv", np.asarray(uvs, dtype=np.float32)[t.ravel()].ravel())
    me.validate(clean_customdata=False)
    return me


_COLORS = {"canopy": (0.15, 0.45, 0.1, 1), "trunk": (0.3, 0.2, 0.1, 1),
           "ground": (0.35, 0.3, 0.2, 1), "grass": (0.3, 0.55, 0.15, 1)}


def _material(role: str) -> bpy.types.Material:
    name = f"canopy_{role}"
    mat = bpy.data.materials.get(name)
    if mat is None:
        mat = bpy.data.materials.new(name)
        mat.diffuse_color = _COLORS[role]
        mat.use_nodes = True
        bsdf = mat.node_tree.nodes.get("Principled BSDF")
        if bsdf is not None:
            bsdf.inputs[0].default_value = _COLORS[role]
    return mat


def build_blender(scene, collection_name: str | None = None, materials: bool = True):
    """Create the scene's objects in the current Blender scene; returns {part name: object}.

    ``scene`` is a canopy_scenes.Scene. Everything goes into a collection named
    ``collection_name`` (default ``canopy_<scene.name>``), one child collection per tree.
    """
    top = bpy.data.collections.new(collection_name or f"canopy_{scene.name}")
    bpy.context.scene.collection.children.link(top)
    top["canopy_ao_scene"] = scene.name
    top["canopy_ao_seed"] = int(scene.seed)
    tree_cols, objects = {}, {}
    for part in scene:
        me = mesh_from_arrays(part.name, part.vertices, part.triangles, part.uvs)
        if materials:
            me.materials.append(_material(part.role))
        ob = bpy.data.objects.new(part.name, me)
        ob["canopy_ao_role"] = part.role
        if part.tree:
            ob["canopy_ao_tree"] = part.tree
            col = tree_cols.get(part.tree)
            if col is None:
                col = tree_cols[part.tree] = bpy.data.collections.new(part.tree)
                top.children.link(col)
            col.objects.link(ob)
        else:
            top.objects.link(ob)
        objects[part.name] = ob
    # leaves follow their trunk when an artist moves the tree
    for part in scene:
        if part.role == "canopy" and part.tree:
            trunk = next((objects[p.name] for p in scene
                          if p.tree == part.tree and p.role == "trunk"), None)
            if trunk is not None:
                objects[part.name].parent = trunk
    return objects
