"""A texel never reads occluded by the surface it lies on (issue #35, item 1): a plane, a cube
and a UV sphere, each alone under open sky, bake to >= 0.99 on every texel of the image (the
UV islands, their margin and the untouched background alike) under every rung the bake offers,
through bpy.ops.canopy_ao.bake. Before the tracer applied Cycles' self-intersection offset the
plane's diagonal read 0.0 under rays (256 texels at 256 px); before a texel within rounding
of its triangle's edge moved inside, the UV sphere's conservative texels at its poles read
0.8-0.94 under rays (3 texels at 64 px, 35 at 256)."""
import bpy
import numpy as np
import pytest

import helpers_materials as H
from canopy_ao.blender import texel_io
from canopy_ao.core.ladder import METHODS

OPEN = 0.99  # AO under open sky is 1; a few rays' noise on nothing cannot lower it


def _mesh(kind):
    H.empty_scene()
    if kind == "plane":
        bpy.ops.mesh.primitive_plane_add(size=2.0)
    elif kind == "cube":
        bpy.ops.mesh.primitive_cube_add(size=2.0)
    else:
        bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0, segments=16, ring_count=8)
    obj = bpy.context.object
    obj.name = kind.capitalize()
    return obj


def _bake(obj, method, res, tmp_path, **kw):
    r = bpy.ops.canopy_ao.bake(objects=obj.name, mode='TEXEL', method=method, resolution=res,
                               samples=8, tau=1.5, distance=0.0, show_proxies=False,
                               image_dir=str(tmp_path), **kw)
    assert r == {'FINISHED'}, f"{obj.name} {method} {res}"
    img = texel_io.find_image(texel_io.OBJ_KEY, obj.name)
    w, h = img.size
    assert (w, h) == (res, res)
    px = np.empty(w * h * 4, np.float32)
    img.pixels.foreach_get(px)
    return px.reshape(h, w, 4)[:, :, 0]


# The density grid voxelises a lone trunk's own surface as leaf-like density, so a receiver on
# it reads its own voxels (per vertex too: a UV sphere 0.82 at worst, 0.77 per texel); the
# hybrid's far part is that grid. A model matter, not the texel's start: tested apart below.
GRID_RUNGS = ("grid", "hybrid")


def _rungs(kind):
    """(method, anti-aliasing) to bake: every rung at the texel centre alone (a texel exactly
    on an edge or vertex), and the rays also anti-aliased (sub-samples across edges)."""
    for method in METHODS:
        if kind != "plane" and method in GRID_RUNGS:
            continue
        yield method, 1
        if method == "raytrace":
            yield method, 2
            yield method, 3


@pytest.mark.parametrize("kind", ["plane", "cube", "sphere"])
@pytest.mark.parametrize("res", [64, 256])
def test_lone_mesh_bakes_open_sky_on_every_texel_under_every_rung(kind, res, tmp_path):
    obj = _mesh(kind)
    bad = []
    for method, aa in _rungs(kind):
        if method == "regression" and kind == "plane":  # a lone ground: no tree to fit on
            with pytest.raises(RuntimeError, match="'regression' needs a CANOPY"):
                _bake(obj, method, res, tmp_path / method)
            continue
        ao = _bake(obj, method, res, tmp_path / f"{method}{aa}", texel_aa=aa)
        dark = np.argwhere(ao < OPEN)
        if len(dark):
            bad.append(f"{method} AA {aa}: {len(dark)} texels below {OPEN} (min "
                       f"{ao.min():.3f}, first at row/col {dark[:3].tolist()})")
    assert not bad, f"{kind} at {res} px: " + "; ".join(bad)


@pytest.mark.xfail(reason="the density grid counts a lone trunk's own surface as density "
                          "(per vertex as per texel); a model matter left open")
@pytest.mark.parametrize("method", GRID_RUNGS)
def test_density_grid_rungs_on_a_lone_trunk(method, tmp_path):
    obj = _mesh("sphere")
    assert _bake(obj, method, 64, tmp_path, texel_aa=1).min() >= OPEN


@pytest.mark.parametrize("kind", ["plane", "sphere"])
def test_at_1024_px_by_rays_no_texel_reads_its_own_surface(kind, tmp_path):
    obj = _mesh(kind)
    ao = _bake(obj, "raytrace", 1024, tmp_path, texel_aa=1)
    assert ao.min() >= OPEN, f"{np.count_nonzero(ao < OPEN)} texels below {OPEN}"
