"""Bent normals in Blender (docs/DESIGN.md, 'Bent normals'): the tangent frames of a UV map
per vertex and per texel, and the bent normals written as a color attribute or an RGB EXR,
encoded 0.5 + 0.5 · n (a normal map's encoding; alpha 1).

World space needs nothing but the bake. Tangent space needs the UV map's tangents (Blender's
MikkTSpace tangents, ``Mesh.calc_tangents``): without a UV map, or on a mesh with faces of more
than four corners (which calc_tangents refuses), the bake is refused before anything is written
with a message saying what to do. A vertex's tangent is the mean of its corners' tangents (its
bitangent sign the sign of their sum), a texel's the barycentric blend of its triangle's corner
tangents at the texel's centre, each made orthogonal to the receiver's normal (core/maps.py,
``to_tangent``): where a UV seam splits a vertex the frames of its two sides are averaged.
"""

import numpy as np

from . import files_io, mesh_io, texel_io
from ..core import maps
from ..core.native import CanopyAOError

BACKGROUND = {"WORLD": (0.5, 0.5, 0.5), "TANGENT": (0.5, 0.5, 1.0)}  # empty texels: 0 / +N


def _corner_tangents(obj, depsgraph, uv_map):
    """(per-corner world tangents float32 (L, 3), bitangent signs float32 (L,), corner vertex
    int32 (L,), loop-triangle corners int32 (3M,)) of obj's evaluated mesh for uv_map."""
    uv_map = texel_io.resolve_uv_map(obj, uv_map)
    ob_eval = obj.evaluated_get(depsgraph)
    mesh = ob_eval.to_mesh()
    try:
        if mesh.uv_layers.get(uv_map) is None:
            raise CanopyAOError(f"Object '{obj.name}': its modifiers drop UV map '{uv_map}'; "
                                "tangent-space bent normals need it (apply them, or bake "
                                "World bent normals)")
        try:
            mesh.calc_tangents(uvmap=uv_map)
        except RuntimeError as exc:  # faces of more than 4 corners
            raise CanopyAOError(f"Object '{obj.name}': Blender cannot compute tangents ({exc}); "
                                "triangulate its n-gons, or bake World bent normals") from None
        n_loops = len(mesh.loops)
        tan = np.empty(3 * n_loops, np.float32)
        sign = np.empty(n_loops, np.float32)
        vert = np.empty(n_loops, np.int32)
        mesh.loops.foreach_get("tangent", tan)
        mesh.loops.foreach_get("bitangent_sign", sign)
        mesh.loops.foreach_get("vertex_index", vert)
        mesh.calc_loop_triangles()
        corners = np.empty(3 * len(mesh.loop_triangles), np.int32)
        mesh.loop_triangles.foreach_get("loops", corners)
        mesh.free_tangents()
    finally:
        ob_eval.to_mesh_clear()
    m = np.array(obj.matrix_world, np.float64)[:3, :3]
    tan = (tan.reshape(-1, 3).astype(np.float64) @ m.T).astype(np.float32)  # tangents go as M
    if np.linalg.det(m) < 0:  # a mirroring transform flips N × T: keep B where it was
        sign = -sign
    return tan, sign, vert, corners


def vertex_frames(obj, depsgraph, uv_map, count):
    """(tangents float32 (V, 3) world, signs float32 (V,)) per vertex of obj (count vertices,
    as the bake read them). CanopyAOError without UVs or when the counts differ."""
    tan, sign, vert, _c = _corner_tangents(obj, depsgraph, uv_map)
    if len(vert) and int(vert.max()) >= count:
        raise CanopyAOError(f"Object '{obj.name}': its evaluated mesh has other vertices than "
                            "the bake read; apply its modifiers for tangent-space bent normals")
    t = np.zeros((count, 3), np.float64)
    s = np.zeros(count, np.float64)
    np.add.at(t, vert, tan)
    np.add.at(s, vert, sign)
    return t.astype(np.float32), np.where(s < 0, -1.0, 1.0).astype(np.float32)


def texel_frames(obj, depsgraph, rx):
    """(tangents float32 (T, 3) world, signs float32 (T,)) per texel receiver of rx
    (texel_io.TexelReceivers of obj's 0–1 tile): each texel's triangle's corner tangents
    blended by the texel centre's barycentric coordinates in UV (clamped to the triangle:
    a texel the conservative raster added outside it takes the nearest edge's blend)."""
    tan, sign, _v, corners = _corner_tangents(obj, depsgraph, rx.uv_map)
    uvs = rx.uvs  # the corner UVs receivers() read: the mesh is not read again for them
    if uvs is None:
        uvs, _p, _n = texel_io.gather_corner_triangles(obj, depsgraph, rx.uv_map)
    tri = np.asarray(rx.triangles if rx.triangles is not None else [], np.int64)
    if rx.triangles is None or len(corners) != len(uvs) or (len(tri) and
                                                             tri.max() * 3 >= len(corners)):
        raise CanopyAOError(f"Object '{obj.name}': its texels' triangles are unknown; bake "
                            "World bent normals")
    res = rx.resolution
    px = np.asarray(rx.pixels, np.int64)
    uv = np.stack([(px % res + 0.5) / res, (px // res + 0.5) / res], axis=1)
    a, b, c = (uvs[3 * tri + k].astype(np.float64) for k in range(3))
    e1, e2, q = b - a, c - a, uv - a
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    safe = np.where(np.abs(det) > 1e-30, det, 1.0)
    w1 = (q[:, 0] * e2[:, 1] - q[:, 1] * e2[:, 0]) / safe
    w2 = (e1[:, 0] * q[:, 1] - e1[:, 1] * q[:, 0]) / safe
    w = np.clip(np.stack([1.0 - w1 - w2, w1, w2], axis=1), 0.0, 1.0)
    w[np.abs(det) <= 1e-30] = 1.0 / 3.0  # a triangle of no UV area: its corners' mean
    w /= w.sum(axis=1, keepdims=True)
    ct = corners.astype(np.int64)
    t = sum(w[:, k:k + 1] * tan[ct[3 * tri + k]] for k in range(3))
    s = sum(w[:, k] * sign[ct[3 * tri + k]] for k in range(3))
    return t.astype(np.float32), np.where(s < 0, -1.0, 1.0).astype(np.float32)


def in_space(bent, normals, space, frames=None):
    """The world-space bent normals for output: as they are ('WORLD') or in the tangent
    frames (tangents, signs) given ('TANGENT')."""
    if space == "TANGENT":
        return maps.to_tangent(bent, normals, *frames)
    return np.asarray(bent, np.float32)


def write_attribute(obj, name, bent, overwrite=False):
    """Write bent normals float (V, 3) as the POINT FLOAT_COLOR attribute ``name``:
    (0.5 + 0.5 · b, 1), under mesh_io's ownership rules."""
    rgb = maps.encode(bent)
    attr, _ = mesh_io._point_attribute(obj, name, rgb[:, 0], 'FLOAT_COLOR', overwrite)
    rgba = np.ones((len(rgb), 4), np.float32)
    rgba[:, :3] = rgb
    attr.data.foreach_set("color", rgba.reshape(-1))
    obj.data.update_tag()
    mesh_io.mark_owned(obj, name, rgba.reshape(-1))
    return attr


def write_image(obj, rx, bent, space, image_dir, txn, suffix, overwrite=False, fmt="EXR"):
    """Splat the encoded bent normals per texel (each channel with rx's margin; empty texels
    BACKGROUND[space]) into an RGB image file of format fmt, loaded as obj's image of map ``suffix`` (Non-Color),
    under the files' ownership rules (files_io.write_own_file). Returns (image, path)."""
    rgb = maps.encode(bent)
    res = rx.resolution
    planes = [texel_io.splat(rx.pixels, rgb[:, k], res, res, rx.margin, BACKGROUND[space][k])[0]
              for k in range(3)]
    notes = []
    path = texel_io.image_path(obj, image_dir, notes, suffix, fmt=fmt)
    files_io.write_own_file(path, np.stack(planes, axis=2), txn,
                            files_io.Output(obj.name, suffix), overwrite, fmt)
    image, undo = texel_io.load_image(obj, path, suffix)
    txn.add(undo)
    return image, path, notes


def check_request(opts):
    """Refuse, before any work, bent normals the bake cannot give as asked."""
    name = opts["bent_normals_name"]
    if name in ("", opts["attribute"], opts["aov_name"]) or (
            opts["thickness"] and name == opts["thickness_name"]):
        raise CanopyAOError(f"the bent normals' name '{name}' is empty or also the AO's or the "
                            "thickness's attribute or AOV; give it a name of its own")
    if opts["live"]:
        raise CanopyAOError("bent normals are baked once, not re-evaluated live; turn off "
                            "Live or Bent Normals")


def summary(t, space):
    """The report's bent-normal figures of target t: space and the mean angle between the
    bent normal and the receiver's normal (degrees), over receivers with a normal."""
    b = t.bent.astype(np.float64)
    cos = b[:, 2] if space == "TANGENT" else np.einsum("ij,ij->i", b, t.normals)
    ok = np.einsum("ij,ij->i", b, b) > 0.5
    tilt = np.degrees(np.arccos(np.clip(cos[ok], -1.0, 1.0)))
    return {"space": space.lower(), "mean_tilt_degrees": float(tilt.mean()) if ok.any()
            else None}
