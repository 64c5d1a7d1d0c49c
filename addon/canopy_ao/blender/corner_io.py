"""A mesh's corner (split) normals: what Cycles shades each face corner with.

Cycles evaluates a face corner with that corner's own normal: the face normal on a flat face,
split at sharp edges (auto smooth), custom normals where set (docs/DESIGN.md, 'Facts measured
in Blender'). Read per loop triangle for the ray tracer's bake points (native raytrace.h,
'Origins'), only where they can differ from the vertex normals.
"""

import numpy as np

from ..core import native

# A corner normal this close to its vertex's (cosine; 0.08°) is the vertex's: Blender's own
# smooth corners, recomputed in another order on 3.4 - 4.0 with auto smooth.
SAME_COSINE = 1.0 - 1e-6


def corner_normals(mesh, n_loops):
    """float32 (n_loops, 3): every face corner's normal, in the mesh's space."""
    out = np.empty(n_loops * 3, dtype=np.float32)
    if hasattr(mesh, "corner_normals"):  # 4.1+
        mesh.corner_normals.foreach_get("vector", out)
    else:  # 3.4 - 4.0: split normals honour smooth/flat shading and custom normals
        mesh.calc_normals_split()
        mesh.loops.foreach_get("normal", out)
        mesh.free_normals_split()  # the mesh as found (an original one is the user's)
    return out.reshape(n_loops, 3)


def may_differ(mesh):
    """Whether any corner normal can differ from its vertex's, before reading them: a flat
    face, sharp edges or custom normals (4.1+: normals_domain; before: auto smooth or a face
    not smooth). A smooth mesh costs one attribute read."""
    domain = getattr(mesh, "normals_domain", None)
    if domain is not None:
        return domain != 'POINT'
    if getattr(mesh, "use_auto_smooth", False):
        return True
    smooth = np.empty(len(mesh.polygons), dtype=bool)
    mesh.polygons.foreach_get("use_smooth", smooth)
    return not smooth.all()


def triangle_corner_normals(mesh, triangles, normals, matrix):
    """float32 (F, 3, 3) world space: corner j of loop triangle i's normal, or None where every
    one is its vertex's (the ray tracer then takes the vertex normals, bit for bit as without).
    triangles int32 (F, 3) the mesh's loop triangles (calc_loop_triangles done); normals its
    world vertex normals (V, 3); matrix its world matrix. A corner within SAME_COSINE of its
    vertex's takes the vertex's own, so a smooth part bakes as without corner normals."""
    if not len(triangles) or not may_differ(mesh):
        return None
    loops = np.empty(len(triangles) * 3, dtype=np.int32)
    mesh.loop_triangles.foreach_get("loops", loops)
    world = np.ascontiguousarray(corner_normals(mesh, len(mesh.loops))[loops])
    # mesh_io's transform of its vertex normals, so an equal corner comes out equal
    native.require().to_world(np.zeros_like(world), world, np.array(matrix, dtype=np.float64))
    own = normals[triangles.reshape(-1)]
    same = np.einsum("ij,ij->i", world, own) >= SAME_COSINE
    if same.all():
        return None
    world[same] = own[same]
    return world.reshape(-1, 3, 3)
