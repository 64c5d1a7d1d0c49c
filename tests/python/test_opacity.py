"""Opacity without Blender (core/opacity.py, native raytrace.h 'Opacity'): alpha expressions
evaluate as Blender's nodes do, the tracer's arguments keep an opaque scene the plain tracer,
and bad opacity arrays are refused with a message naming them."""

import numpy as np
import pytest

from canopy_ao import _core
from canopy_ao.core import card_area, lighting, opacity
from canopy_ao.core.scene import SceneItem


def _px(alpha, rgb=1.0):
    px = np.full((2, 4, 4), rgb, np.float32)
    px[..., 3] = alpha
    return px


def test_expressions_evaluate_as_blenders_nodes():
    images = {"a": _px(np.array([[0, 0.5, 1, 1], [0, 0.5, 1, 1]], np.float32))}
    assert opacity.evaluate(("const", 0.3), images) == pytest.approx(0.3)
    tex = opacity.evaluate(("image", "a", "alpha"), images)
    assert tex.shape == (2, 4) and tex[0, 1] == pytest.approx(0.5)
    inv = opacity.evaluate(("invert", ("const", 1.0), ("image", "a", "alpha")), images)
    assert inv[0].tolist() == pytest.approx([1, 0.5, 0, 0])
    mix = opacity.evaluate(("mix", ("const", 0.25), ("const", 0.0), ("const", 1.0)), images)
    assert mix == pytest.approx(0.25)
    step = opacity.evaluate(("math", "GREATER_THAN", ("image", "a", "alpha"), ("const", 0.6)),
                            images)
    assert step[0].tolist() == [0, 0, 1, 1]
    ramp = opacity.evaluate(("ramp", ("const", 0.75), [0.5, 1.0], [0.0, 1.0], "LINEAR"), images)
    assert ramp == pytest.approx(0.5)
    grey = opacity.evaluate(("image", "a", "color"), {"a": _px(1.0, rgb=0.5)})
    assert np.allclose(grey, 0.5)  # luminance weights sum to 1
    with pytest.raises(opacity.NotUnderstood, match="SINE"):
        opacity.evaluate(("math", "SINE", ("const", 0.0), ("const", 0.0)), images)


def _card_items(alpha):
    ground = SceneItem("Ground", "GROUND", "t", np.float32([[-5, -5, 0], [5, -5, 0], [5, 5, 0],
                                                            [-5, 5, 0]]),
                       np.float32([[0, 0, 1]] * 4), np.int32([[0, 1, 2], [0, 2, 3]]))
    card = SceneItem("Card", "CANOPY", "t", np.float32([[-1, -1, 1], [1, -1, 1], [1, 1, 1],
                                                        [-1, 1, 1]]),
                     np.float32([[0, 0, 1]] * 4), np.int32([[0, 1, 2], [0, 2, 3]]))
    card.opacity = opacity.ItemOpacity([opacity.MaterialAlpha("Leaf", alpha=alpha)],
                                       np.zeros(2, np.int32))
    return [ground, card]


def test_an_opaque_scene_builds_the_plain_tracer_bit_for_bit():
    items = _card_items(1.0)
    assert opacity.tracer_args(items) == {}
    tracer = lighting.build_tracer(items)
    assert not tracer.has_opacity
    items[1].opacity = None
    pts = np.float32([[0.1, 0.2, 0.0]] * 64)
    nrm = np.float32([[0, 0, 1]] * 64)
    assert np.array_equal(tracer.ao(pts, nrm, samples=64),
                          lighting.build_tracer(items).ao(pts, nrm, samples=64))


def test_a_half_transparent_card_lets_half_its_rays_through():
    pts = np.float32([[0.0, 0.0, 0.01]] * 64)
    nrm = np.float32([[0, 0, 1]] * 64)
    solid = lighting.build_tracer(_card_items(1.0)).ao(pts, nrm, samples=1024).mean()
    half = lighting.build_tracer(_card_items(0.5))
    assert half.has_opacity
    assert half.ao(pts, nrm, samples=1024).mean() == pytest.approx(1 - 0.5 * (1 - solid),
                                                                   abs=0.01)


def test_bad_opacity_arrays_are_refused_by_name():
    v = np.float32([[0, 0, 0], [1, 0, 0], [0, 1, 0]])
    t = np.int32([[0, 1, 2]])
    with pytest.raises(ValueError, match="opacity_materials"):
        _core.RayTracer(v, t, opacity_materials=np.int32([0, 0]), opacity_alphas=[0.5])
    with pytest.raises(ValueError, match="outside"):
        _core.RayTracer(v, t, opacity_materials=np.int32([3]), opacity_alphas=[0.5])
    with pytest.raises(ValueError, match="together"):
        _core.RayTracer(v, t, opacity_materials=np.int32([0]))
    with pytest.raises(ValueError, match="opacity_uvs"):
        _core.RayTracer(v, t, opacity_materials=np.int32([0]), opacity_alphas=[0.5],
                        opacity_uvs=np.zeros((1, 3), np.float32))


def test_every_ray_passes_a_clear_card_texels_and_bent_normals_too():
    """A card of alpha 0 stops nothing: a texel receiver on the ground (triangle_ids) and the
    bent normals (the same rays) see the open sky."""
    tracer = lighting.build_tracer(_card_items(0.0))
    pts = np.float32([[0.2, 0.1, 0.0]] * 8)
    nrm = np.float32([[0, 0, 1]] * 8)
    ao, bent = tracer.ao(pts, nrm, samples=64, triangle_ids=np.zeros(8, np.int32),
                         bent_normals=True)
    assert np.all(ao == 1.0)
    assert np.allclose(bent, [0, 0, 1], atol=0.05)


def test_an_8bit_srgb_mask_is_handed_over_encoded_with_its_transform():
    """A Mix Shader (Transparent, BSDF) by an sRGB mask's colour: alpha = the decoded colour,
    decoded by the tracer after interpolation (as Cycles does), not per texel here."""
    images = {"m": _px(1.0, rgb=np.array([[0, 0.5, 1, 1]] * 2, np.float32)[..., None])}
    expr = ("mix", ("clamp", ("image", "m", "color")), ("const", 0.0), ("const", 1.0))
    m = opacity.material_alpha("Mask", expr, images, encoded={"m"})
    assert m.srgb and (m.scale, m.offset) == (1.0, 0.0)
    assert m.texture[0].tolist() == pytest.approx([0, 0.5, 1, 1])
    inv = opacity.material_alpha("Mask", ("mix", ("image", "m", "color"), ("const", 1.0),
                                          ("const", 0.0)), images, encoded={"m"})
    assert (inv.scale, inv.offset) == (-1.0, 1.0)
    # anything else decodes texel by texel
    other = opacity.material_alpha("Mask", ("math", "MULTIPLY", ("image", "m", "color"),
                                            ("const", 1.0)), images, encoded={"m"})
    assert not other.srgb and other.texture[0, 1] == pytest.approx(0.21404114, abs=1e-6)


def test_a_material_many_items_share_reaches_the_tracer_once():
    leaf = opacity.MaterialAlpha("Leaf", texture=np.zeros((64, 64), np.float32))
    items = _card_items(0.5) + _card_items(0.5)[1:]
    for it in items[1:]:
        it.opacity = opacity.ItemOpacity([leaf], np.zeros(2, np.int32),
                                         np.zeros((2, 3, 2), np.float32))
    args = opacity.tracer_args(items)
    assert len(args["opacity_alphas"]) == 1
    assert args["opacity_materials"].tolist() == [-1, -1, 0, 0, 0, 0]


# === Cards as the proxies count them (card_area.counted_triangles) ========================

def _card(material, uvs=True):
    """A 2 × 1 card (x in [0, 2], y in [0, 1]) of two triangles, UVs x/2, y."""
    from canopy_ao.core.scene import SceneItem
    p = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0]], np.float32)
    t = np.array([[0, 1, 2], [0, 2, 3]], np.int32)
    it = SceneItem("Card", "CANOPY", "T", p, np.tile([0, 0, 1], (4, 1)), t)
    uv = (p[:, :2] / [2, 1])[t].astype(np.float32)
    it.opacity = opacity.ItemOpacity([material], np.zeros(2, np.int32), uv if uvs else None)
    return it


def _area(p, t):
    a, b, c = (p[t[:, i]].astype(np.float64) for i in range(3))
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)


def test_counted_card_by_its_opaque_area_and_where():
    """A card opaque on its left half counts half its area, centred on that half; a constant
    alpha scales the area about each triangle's centre; an opaque card is itself."""
    tex = np.zeros((16, 16), np.float32)
    tex[:, :8] = 1.0  # u < 0.5: opaque
    for nearest in (True, False):
        it = _card(opacity.MaterialAlpha("Half", texture=tex, nearest=nearest))
        p, t = card_area.counted_triangles(it)
        assert abs(_area(p, t).sum() - 1.0) < 0.03, nearest
        centre = (p[t].mean(1) * _area(p, t)[:, None]).sum(0) / _area(p, t).sum()
        assert abs(centre[0] - 0.5) < 0.03 and abs(centre[1] - 0.5) < 0.1, centre
    it = _card(opacity.MaterialAlpha("Const", alpha=0.3), uvs=False)
    p, t = card_area.counted_triangles(it)
    np.testing.assert_allclose(_area(p, t), 0.3, rtol=1e-5)
    np.testing.assert_allclose(p[t].mean(1), it.positions[it.triangles].mean(1), atol=1e-6)
    clear = _card(opacity.MaterialAlpha("Clear", alpha=0.0), uvs=False)
    assert len(card_area.counted_triangles(clear)[1]) == 0
    solid = _card(opacity.MaterialAlpha("Solid"))
    assert card_area.counted_item(solid) is solid
    assert card_area.counted_points(solid) is solid.positions


def test_texture_alpha_reads_as_the_tracer():
    """Bilinear between texel centres with wrap, or the texel the UV falls in; sRGB masks
    decoded before offset and scale."""
    tex = np.array([[0.0, 1.0]], np.float32)  # one row, two texels
    lin = opacity.MaterialAlpha("L", texture=tex)
    got = card_area.texture_alpha(lin, [[0.25, 0.5], [0.5, 0.5], [1.0, 0.5]])
    np.testing.assert_allclose(got, [0.0, 0.5, 0.5])
    near = opacity.MaterialAlpha("N", texture=tex, nearest=True)
    np.testing.assert_allclose(card_area.texture_alpha(near, [[0.49, 0.5], [0.51, 0.5]]), [0, 1])
    s = opacity.MaterialAlpha("S", texture=np.full((2, 2), 0.5, np.float32), srgb=True,
                              scale=-1.0, offset=1.0)
    np.testing.assert_allclose(card_area.texture_alpha(s, [[0.3, 0.3]]),
                               1.0 - opacity.srgb_decode(0.5), rtol=1e-6)


def test_tiled_copies_carry_their_materials_and_mirror_their_uvs():
    """A realised field's opacity: each item's triangles copied in turn, a mirrored copy's UVs
    in reversed corner order (forest.realize winds its triangles back), an item without
    opacity opaque."""
    tex = np.ones((2, 2), np.float32) * 0.5
    card = SceneItem("Card", "CANOPY", "T", np.eye(3, dtype=np.float32),
                     np.tile([0, 0, 1], (3, 1)), np.array([[0, 1, 2]], np.int32))
    uv = np.array([[[0, 0], [1, 0], [0, 1]]], np.float32)
    card.opacity = opacity.ItemOpacity([opacity.MaterialAlpha("Leaf", texture=tex)],
                                       np.zeros(1, np.int32), uv)
    twig = SceneItem("Twig", "TRUNK", "T", np.eye(3, dtype=np.float32),
                     np.tile([0, 0, 1], (3, 1)), np.array([[0, 1, 2]], np.int32))
    op = opacity.tiled([(card, np.array([False, True])), (twig, np.array([False]))])
    assert [m.name for m in op.materials] == ["Leaf", "Twig"] and op.materials[1].opaque
    assert op.triangle_material.tolist() == [0, 0, 1]
    np.testing.assert_array_equal(op.uvs[0], uv[0])
    np.testing.assert_array_equal(op.uvs[1], uv[0][::-1])
    assert opacity.tiled([(twig, np.array([False]))]) is None
