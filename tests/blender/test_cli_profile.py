"""CANOPY_AO_PROFILE=1 (core/stage_profile.py): the command line prints every stage of a ray
bake on stderr, from Blender's start to the save, and the bake writes the same AO as without."""
import os
import subprocess

import bpy
import numpy as np

from conftest import _clear_scene, add_mesh
from canopy_ao.core.stage_profile import parse

ATTR = "CanopyAO"


def _scene(tmp_path):
    """A ground under a ball, saved."""
    _clear_scene()
    u = np.linspace(-3.0, 3.0, 41)
    x, y = np.meshgrid(u, u)
    pos = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    k = np.arange(40 * 41).reshape(40, 41)[:, :40].ravel()
    tris = np.concatenate([np.stack([k, k + 1, k + 42], 1), np.stack([k, k + 42, k + 41], 1)])
    add_mesh("Ground", pos, tris)
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=2, radius=1.0, location=(0, 0, 1.5))
    bpy.context.active_object.name = "Ball"
    blend = str(tmp_path / "scene.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend, copy=True)
    return blend


def _bake(blend, user_scripts, profile):
    env = dict(os.environ, BLENDER_USER_SCRIPTS=user_scripts)
    env.pop("CANOPY_AO_PROFILE", None)
    if profile:
        env["CANOPY_AO_PROFILE"] = "1"
    r = subprocess.run([bpy.app.binary_path, "-b", "--factory-startup", blend,
                        "--python-exit-code", "1", "--python-expr",
                        "import canopy_ao.cli; canopy_ao.cli.main()", "--", "--all",
                        "--method", "raytrace", "--samples", "16", "--save"],
                       env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    bpy.ops.wm.open_mainfile(filepath=blend)
    me = bpy.data.objects["Ground"].data
    buf = np.empty(len(me.vertices) * 4, np.float32)
    me.color_attributes[ATTR].data.foreach_get("color", buf)
    return r.stderr, buf


def test_profile_names_every_stage_and_changes_nothing(user_scripts, tmp_path):
    blend = _scene(tmp_path)
    err, plain = _bake(blend, user_scripts, profile=False)
    assert not parse(err)
    err, profiled = _bake(blend, user_scripts, profile=True)
    stages = parse(err)
    for name in ("Blender start, file load (to the script)", "add-on: module imports",
                 "bake: gather (total)", "bake: evaluate", "bake: write",
                 "native: tracer: BVH build", "native: tracer: corner tables",
                 "native: rays: tracing (CPU)", "native: rays: sampling, starts (CPU)",
                 "bake: whole (job.run_bake)", "report file, save", "process age"):
        assert name in stages, (name, err[-2000:])
        assert 0.0 <= stages[name] < 300.0, (name, stages[name])
    # The stages happen one after another within the process's life.
    assert stages["bake: evaluate"] <= stages["bake: whole (job.run_bake)"] < \
        stages["process age"]
    np.testing.assert_array_equal(plain, profiled)
    assert 0.0 < plain[::4].min() < 1.0  # the ball shades the ground: a real bake
