"""The command line's progress on stderr and Ctrl-C (core/progress.py, cli.py): progress lines
come before the per-object lines scripts read, which keep their form; one SIGINT mid-bake stops
it with exit 130, the .blend and the report untouched."""
import hashlib
import os
import re
import signal
import subprocess

import bpy
import numpy as np
import pytest

from conftest import _clear_scene, add_mesh

ATTR = "CanopyAO"


def _grid_and_ball(n=300):
    """A 10 x 10 ground of (n + 1)^2 vertices under a ball: a ray bake of a few seconds."""
    _clear_scene()
    u = np.linspace(-5.0, 5.0, n + 1)
    x, y = np.meshgrid(u, u)
    pos = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    k = np.arange(n * (n + 1)).reshape(n, n + 1)[:, :n].ravel()
    tris = np.concatenate([np.stack([k, k + 1, k + n + 2], 1), np.stack([k, k + n + 2, k + n + 1], 1)])
    add_mesh("Ground", pos, tris)
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=3, radius=1.5, location=(0, 0, 2))
    bpy.context.active_object.name = "Ball"
    for ob in bpy.context.scene.objects:
        ob.select_set(False)


def _argv(blend, *args):
    return [bpy.app.binary_path, "-b", "--factory-startup", blend, "--python-exit-code", "1",
            "--python-expr", "import canopy_ao.cli; canopy_ao.cli.main()", "--", *args]


def _digest(path):
    with open(path, "rb") as f:
        return hashlib.sha256(f.read()).hexdigest()


def test_progress_lines_come_before_the_object_lines_in_a_log(user_scripts, tmp_path):
    _grid_and_ball()
    blend = str(tmp_path / "scene.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend, copy=True)
    env = dict(os.environ, BLENDER_USER_SCRIPTS=user_scripts)
    r = subprocess.run(_argv(blend, "--all", "--method", "raytrace", "--samples", "16"),
                       env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stdout[-2000:]
    lines = r.stdout.splitlines()
    progress = [i for i, l in enumerate(lines) if l.startswith("canopy_ao: progress: ")]
    ground = [i for i, l in enumerate(lines) if l.startswith("Ground: ")]
    assert len(ground) == 1 and progress and max(progress) < ground[0], r.stdout
    stages = [lines[i].split(": ", 2)[2] for i in progress]
    assert stages[:2] == ["gathering", "preparing"] and stages[-1] == "writing", stages
    # The evaluation names its object, counts the receivers and gives the time left.
    assert any(re.fullmatch(r"evaluating Ground, \d+/\d+ receivers \(\d+ %\), "
                            r"time left (unknown|\d.*)", s) for s in stages), stages
    # The lines scripts parse keep their form.
    assert re.fullmatch(r"Ground: role \w+, method raytrace, 90601 vertices, [\d.]+ s, "
                        r"mean AO [\d.]+", lines[ground[0]]), lines[ground[0]]


@pytest.mark.parametrize("stage", ["gathering", "evaluating"])
def test_one_ctrl_c_stops_the_bake_with_nothing_saved(stage, user_scripts, tmp_path):
    _grid_and_ball()
    blend = str(tmp_path / "scene.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend, copy=True)
    before = _digest(blend)
    report = tmp_path / "report.json"
    env = dict(os.environ, BLENDER_USER_SCRIPTS=user_scripts)
    p = subprocess.Popen(_argv(blend, "--all", "--method", "raytrace", "--samples", "64",
                               "--report", str(report), "--save"),
                         env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    out, sent = [], False
    try:
        for line in p.stdout:  # Ctrl-C once, as the bake reaches the stage
            out.append(line)
            if not sent and line.startswith(f"canopy_ao: progress: {stage}"):
                p.send_signal(signal.SIGINT)
                sent = True
        code = p.wait(timeout=300)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
        p.stdout.close()
    text = "".join(out)
    assert sent, text
    assert code == 130, text[-2000:]
    assert "canopy_ao: error: cancelled (Ctrl-C)" in text, text[-2000:]
    assert not re.search(r"^Ground: ", text, re.M) and "canopy_ao: saved" not in text, text
    assert _digest(blend) == before and not report.exists()


def test_a_ray_bake_steps_every_few_seconds_with_the_same_ao():
    """A blocking ray bake at 256 samples evaluates 2^14 vertices a step (so the progress and
    Ctrl-C answer every few seconds, not every 2^18 vertices), and the AO is bit for bit the
    one of a bake in other steps: a vertex's rays follow its id."""
    from canopy_ao.blender import properties
    from canopy_ao.blender.job import BakeJob, run_bake
    _grid_and_ball(n=140)  # 19,881 ground vertices
    opts = dict(properties.scene_options(bpy.context.scene), method="raytrace", samples=256,
                distance=0.0, show_proxies=False)
    seen = []
    job, _rep = run_bake(bpy.context, ["Ground"], opts, lambda *s: seen.append(s))
    steps = [s for s in seen if s[0] == "evaluating" and s[1] == "Ground"]
    assert [s[2] for s in steps] == [0, 16384], steps
    split = job.targets[0].ao.copy()
    other = BakeJob(bpy.context, ["Ground"], opts)  # modal steps: 2^16, one for the ground
    other.run()
    assert other.steps == 2
    np.testing.assert_array_equal(other.targets[0].ao, split)
