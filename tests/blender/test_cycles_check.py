"""cycles_check.py: Cycles AO bakes, metrics, and that every touched setting is restored."""
import bpy
import numpy as np
import pytest

import helpers_materials as H
from canopy_ao.blender import cycles_check as cc


@pytest.fixture
def scene():
    return H.empty_scene()


def _receiver_under_disk(height=1.0, radius=1.0):
    """A tiny receiver plane (4 vertices, normal +Z) under a disk: the cosine-weighted AO at the
    disk's axis is 1 - sin^2(theta), theta = the smaller of atan(R/h) and acos(h/D)."""
    rec = H.add_plane(size=0.01, name="Receiver")
    bpy.ops.mesh.primitive_circle_add(vertices=128, radius=radius, fill_type="NGON",
                                      location=(0, 0, height))
    return rec, bpy.context.object


def _canopy_scene():
    ground = H.add_plane(size=4.0, subdivisions=10, name="Ground")  # 144 vertices
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=2, radius=0.7, location=(0, 0, 1.0))
    return ground, bpy.context.object


def _user_state(scene, objs):
    vl = bpy.context.view_layer
    return ([o.name for o in vl.objects if o.select_get()],
            vl.objects.active.name if vl.objects.active else None,
            {o.name: ([a.name for a in o.data.color_attributes],
                      o.data.color_attributes.active_color_name,
                      o.data.color_attributes.render_color_index) for o in objs},
            len(bpy.data.images), len(bpy.data.materials), len(bpy.data.worlds))


def _make_user_settings(scene, objs):
    """Settings unlike the ones a check uses, so restoring is visible."""
    scene.render.engine = "BLENDER_WORKBENCH"  # exists in 3.x and 4.x
    scene.cycles.samples = 77
    scene.cycles.use_denoising = True
    scene.cycles.use_adaptive_sampling = True
    scene.world = bpy.data.worlds.new("UserWorld")
    scene.world.light_settings.distance = 3.5
    for o in objs:
        o.data.color_attributes.new("UserColor", "BYTE_COLOR", "CORNER")
        o.data.color_attributes.active_color = o.data.color_attributes["UserColor"]
        o.select_set(False)
    objs[-1].select_set(True)
    bpy.context.view_layer.objects.active = objs[-1]


@pytest.mark.parametrize("distance, expected", [
    (1e6, 0.5),                          # disk of radius = height: sin^2(45 deg) blocked
    (1.2, 1.0 / 1.2 ** 2),               # hard cut-off: only rays shorter than D count
    (0.9, 1.0),                          # D < height: nothing is in reach
])
def test_distance_is_hard_cutoff(scene, distance, expected):
    rec, _disk = _receiver_under_disk()
    ao = cc.bake_cycles_vertex_ao(bpy.context, [rec], distance, 256)["Receiver"]
    assert ao.dtype == np.float32 and ao.shape == (4,)
    assert abs(float(ao.mean()) - expected) < 0.03, (ao, expected)


def test_check_objects_metrics_and_restore(scene):
    ground, sphere = _canopy_scene()
    _make_user_settings(scene, [ground, sphere])
    before = cc.render_settings_snapshot(scene)
    state = _user_state(scene, [ground, sphere])
    ours = {"Ground": np.full(len(ground.data.vertices), 0.8, dtype=np.float32),
            "Icosphere": np.full(len(sphere.data.vertices), 0.9, dtype=np.float32)}
    report = cc.check_objects(bpy.context, [ground, sphere], ours, distance=10.0, samples=16,
                              write_errors=True)
    assert set(report) == {"Ground", "Icosphere"}
    for m in report.values():
        assert all(np.isfinite(v) for v in m.values())
        assert 0.0 <= m["mae"] <= 1.0 and 0.0 <= m["rmse"] <= 1.0 and 0.0 <= m["p95"] <= 1.0
        assert -1.0 <= m["corr"] <= 1.0 and -1.0 <= m["bias"] <= 1.0
    assert report["Ground"]["n"] == 144
    assert cc.render_settings_snapshot(scene) == before
    err_attr = ground.data.color_attributes.get("CanopyAO_Error")
    assert err_attr is not None and err_attr.domain == "POINT"
    ground.data.color_attributes.remove(err_attr)
    sphere.data.color_attributes.remove(sphere.data.color_attributes["CanopyAO_Error"])
    ground.data.color_attributes.active_color = ground.data.color_attributes["UserColor"]
    sphere.data.color_attributes.active_color = sphere.data.color_attributes["UserColor"]
    assert _user_state(scene, [ground, sphere]) == state


def test_vertex_bake_values_in_range_despite_denoise_default(scene):
    ground, _sphere = _canopy_scene()
    scene.cycles.use_denoising = True  # would make the bake write zeros (DESIGN 9)
    ao = cc.bake_cycles_vertex_ao(bpy.context, [ground], 10.0, 16)["Ground"]
    assert ao.shape == (144,) and np.all((ao >= 0) & (ao <= 1))
    assert ao.max() > 0.9          # open ground at the rim
    assert ao.min() < ao.max()     # shadow under the sphere
    assert scene.cycles.use_denoising


def test_restored_when_bake_fails(scene, monkeypatch):
    ground, sphere = _canopy_scene()
    _make_user_settings(scene, [ground, sphere])
    before = cc.render_settings_snapshot(scene)
    state = _user_state(scene, [ground, sphere])
    seen = {}

    def boom(target, use_clear=True):
        seen["engine"] = scene.render.engine  # settings were switched before the failure
        raise RuntimeError("Cycles AO bake failed: forced by the test")

    monkeypatch.setattr(cc, "_run_bake", boom)
    with pytest.raises(RuntimeError, match="forced"):
        cc.bake_cycles_vertex_ao(bpy.context, [ground, sphere], 10.0, 16)
    assert seen["engine"] == "CYCLES"
    assert cc.render_settings_snapshot(scene) == before
    assert _user_state(scene, [ground, sphere]) == state
    with pytest.raises(RuntimeError, match="forced"):
        cc.bake_cycles_texel_ao(bpy.context, ground, "UVMap", 8, 10.0, 16)
    assert cc.render_settings_snapshot(scene) == before
    assert _user_state(scene, [ground, sphere]) == state


def test_world_created_and_removed(scene):
    rec, _disk = _receiver_under_disk()
    assert scene.world is None
    cc.bake_cycles_vertex_ao(bpy.context, [rec], 1e6, 16)
    assert scene.world is None and len(bpy.data.worlds) == 0


def test_texel_bake_coverage_and_restore(scene):
    ground, _sphere = _canopy_scene()
    # squeeze the UVs into the left half: the right half must come back uncovered
    uv = ground.data.uv_layers["UVMap"].data
    buf = np.empty(len(uv) * 2, dtype=np.float32)
    uv.foreach_get("uv", buf)
    buf[0::2] *= 0.5
    uv.foreach_set("uv", buf)
    before = cc.render_settings_snapshot(scene)
    n_img, n_mat = len(bpy.data.images), len(bpy.data.materials)
    ao, mask = cc.bake_cycles_texel_ao(bpy.context, ground, "UVMap", 16, 10.0, 16,
                                       return_mask=True)
    assert ao.shape == (16, 16) and ao.dtype == np.float32
    assert mask[:, :8].all() and not mask[:, 8:].any()
    assert np.all((ao >= 0) & (ao <= 1)) and ao[mask].min() < 0.9
    assert cc.render_settings_snapshot(scene) == before
    assert (len(bpy.data.images), len(bpy.data.materials)) == (n_img, n_mat)
    assert len(ground.material_slots) == 0


def test_error_colors():
    rgba = cc.error_colors(np.array([-0.2, 0.0, 0.1, 0.2]))
    assert np.allclose(rgba[0], (0, 0, 1, 1))      # ours darker: blue
    assert np.allclose(rgba[1], (1, 1, 1, 1))      # equal: white
    assert np.allclose(rgba[2], (1, 0.5, 0.5, 1))  # half as much brighter: pale red
    assert np.allclose(rgba[3], (1, 0, 0, 1))      # ours brighter: red


def test_error_attribute_shape_checked(scene):
    obj = H.add_plane()
    with pytest.raises(ValueError, match="4 vertices"):
        cc.write_error_attribute(obj, np.zeros(5))


def test_error_attribute_spares_user_attribute(scene):
    obj = H.add_plane()
    H.set_point_color(obj, "CanopyAO_Error", 0.5)  # the user's, not ours
    with pytest.raises(ValueError, match="did not make"):
        cc.write_error_attribute(obj, np.zeros(4))
    attr = cc.write_error_attribute(obj, np.array([0.1, -0.1, 0, 0]), name="Err")
    buf = np.empty(16, dtype=np.float32)
    attr.data.foreach_get("color", buf)
    assert np.allclose(buf.reshape(4, 4)[0], (1, 0, 0, 1))
    cc.write_error_attribute(obj, np.zeros(4), name="Err")  # ours now: replaced freely


def test_edit_mode_refused(scene):
    obj = H.add_plane()
    bpy.ops.object.mode_set(mode="EDIT")
    with pytest.raises(ValueError, match="Object Mode"):
        cc.bake_cycles_vertex_ao(bpy.context, [obj], 1.0, 16)
    bpy.ops.object.mode_set(mode="OBJECT")
