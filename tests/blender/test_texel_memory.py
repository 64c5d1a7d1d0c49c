"""A texel bake whose buffers would not fit in the available memory is refused before anything
is read or written, with the figures (issue #35, item 6): 16384 px, the documented maximum,
ended in MemoryError: std::bad_alloc. The estimate itself: tests/python/test_texel_budget.py."""
import os
import subprocess

import bpy
import pytest

import helpers_materials as H
from canopy_ao.blender import properties
from canopy_ao.blender.job import run_bake
from canopy_ao.core import texel_budget
from canopy_ao.core.native import CanopyAOError

RES = 16384


def _plane_blend(tmp_path):
    H.empty_scene()
    H.add_plane(name="Ground")
    blend = str(tmp_path / "plane.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend, copy=True)
    return blend


def test_cli_refuses_16384_px_with_the_bytes_needed_and_available(user_scripts, tmp_path):
    need = texel_budget.peak_bytes(RES * RES, RES, 1)  # the plane covers every texel
    have = texel_budget.available_bytes()
    if have is None or have >= need:
        pytest.skip(f"this machine has {have} bytes available, a 16384 px bake fits")
    blend = _plane_blend(tmp_path)
    out = tmp_path / "images"
    env = dict(os.environ, BLENDER_USER_SCRIPTS=user_scripts)
    cmd = [bpy.app.binary_path, "-b", blend, "--factory-startup", "--addons", "canopy_ao",
           "--python-exit-code", "1", "--python-expr",
           "import canopy_ao.cli as c; c.main()", "--", "--all", "--mode", "texel",
           "--resolution", str(RES), "--anti-aliasing", "1", "--method", "sphere",
           "--image-dir", str(out)]
    r = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=120)
    assert r.returncode == 1, r.stdout[-2000:] + r.stderr[-2000:]
    assert "Object 'Ground': a 16384×16384 texel bake" in r.stderr, r.stderr[-2000:]
    assert "bytes) is available; lower the resolution" in r.stderr
    assert "MemoryError" not in r.stderr and "bad_alloc" not in r.stderr
    assert not out.exists() or not os.listdir(out)  # nothing written


def test_bake_refused_before_anything_changes(tmp_path, monkeypatch):
    H.empty_scene()
    ground = H.add_plane(name="Ground")
    ground.canopy_ao.role = 'GROUND'
    monkeypatch.setattr(texel_budget, "available_bytes", lambda: 64 * 2 ** 20)  # 64 MiB
    n_img = len(bpy.data.images)
    opts = dict(properties.scene_options(bpy.context.scene), mode='TEXEL', method="sphere",
                resolution=2048, texel_aa=2, show_proxies=False, image_dir=str(tmp_path))
    with pytest.raises(CanopyAOError, match=r"Object 'Ground': a 2048×2048 texel bake .*"
                                            r"2×2 anti-aliasing\) needs about"):
        run_bake(bpy.context, ["Ground"], opts)
    assert len(bpy.data.images) == n_img and not os.listdir(tmp_path)
    # at 1 × 1 and 512 px it fits in the same 64 MiB
    _job, rep = run_bake(bpy.context, ["Ground"], dict(opts, resolution=512, texel_aa=1))
    assert rep["objects"]["Ground"]["texel"]["texels"] == 512 * 512
