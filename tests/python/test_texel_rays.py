"""RayTracer.ao's point_group: a texel's anti-aliasing sub-samples share one set of rays,
dealt out to them in turn, so the texel casts its Samples in all (native raytrace.h,
RayTraceOptions::point_group)."""
import os
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "addon"))
_core = pytest.importorskip("canopy_ao._core")


def _scene():
    """A ground quad (triangles 0, 1) under a roof over x > 0 at height 1, with vertex
    normals, so a texel starts as Cycles' bake starts it; and a ground point under the roof's
    edge, on triangle 0."""
    v = np.float32([[-5, -5, 0], [5, -5, 0], [5, 5, 0], [-5, 5, 0],
                    [0, -5, 1], [5, -5, 1], [5, 5, 1], [0, 5, 1]])
    t = np.int32([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    up = np.tile(np.float32([0, 0, 1]), (8, 1))
    return _core.RayTracer(v, t, normals=up), np.float32([0.4, -0.3, 0.0])


def _texel(point, k):
    p = np.tile(point, (k, 1)).astype(np.float32)
    n = np.tile(np.float32([0, 0, 1]), (k, 1))
    return p, n, np.zeros(k, np.int32)


def test_a_group_of_one_point_is_the_point_ray_for_ray():
    rt, x = _scene()
    p, n, tri = _texel(x, 8)  # two texels of four sub-samples, all at one point
    one = rt.ao(p[:1], n[:1], samples=64, triangle_ids=tri[:1])
    grouped = rt.ao(p, n, samples=64, triangle_ids=tri, point_group=4)
    # 16 rays each, the first texel's set keyed as row 0 alone: the same 64 directions
    assert grouped[:4].mean() == one[0]
    assert 0.2 < one[0] < 0.8  # the roof's edge: partly open
    assert np.array_equal(grouped, rt.ao(p, n, samples=64, triangle_ids=tri, point_group=4))


def test_a_texel_casts_its_samples_in_all_at_least_one_per_sub_sample():
    rt, x = _scene()
    p, n, tri = _texel(x, 4)
    ao = rt.ao(p, n, samples=6, triangle_ids=tri, point_group=4)  # 2, 2, 1, 1 rays
    assert np.all(np.isin(ao[:2] * 2, [0, 1, 2])) and np.all(np.isin(ao[2:], [0, 1]))
    few = rt.ao(p, n, samples=2, triangle_ids=tri, point_group=4)  # fewer than 4: one each
    assert np.all(np.isin(few, [0, 1]))


def test_dealt_rays_are_stratified_over_the_group():
    """Four sub-samples at one point dealt one set of 16 are one 16-ray lattice estimate;
    four points with their own sets of 4 are not: measured over many texels the dealt mean
    errs less."""
    rt, x = _scene()
    k = 256
    p, n, tri = _texel(x, 4 * k)
    truth = rt.ao(p[:1], n[:1], samples=65536, triangle_ids=tri[:1])[0]
    dealt = rt.ao(p, n, samples=16, triangle_ids=tri, point_group=4).reshape(k, 4).mean(1)
    alone = rt.ao(p, n, samples=4, triangle_ids=tri).reshape(k, 4).mean(1)
    assert np.abs(dealt - truth).mean() < 0.8 * np.abs(alone - truth).mean()


def test_point_group_is_checked():
    rt, x = _scene()
    p, n, tri = _texel(x, 4)
    with pytest.raises(ValueError, match="point_group must be at least 1"):
        rt.ao(p, n, triangle_ids=tri, point_group=0)
