"""The command line as documented, run as a pipeline would: when the add-on is not installed
the failure must reach the exit code (Blender exits 0 when a --python-expr fails unless it is
given --python-exit-code). The commands are read from README.md, docs/guide.md,
addon/README.md, scripts/run_example.sh and docs/DESIGN.md, so the test checks what the
documents say."""
import os
import re
import shlex
import subprocess

import bpy
import pytest

REPO = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))


def documented_commands(path):
    """Every `blender -b ... canopy_ao.cli ...` command in a file, continuation lines joined."""
    with open(os.path.join(REPO, path), encoding="utf-8") as f:
        text = f.read().replace("\\\n", " ")
    return [m.group(0) for m in re.finditer(r"blender -b [^\n]*canopy_ao\.cli[^\n]*", text)]


def as_argv(command, blend):
    command = command.replace('"out/$scene.blend"', "scene.blend")
    command = command.replace('"$method"', "sphere").replace("$scene", "x")
    argv = shlex.split(command)
    # The .blend a documented command opens (scene.blend, out/round_tree.blend, ...): this one.
    argv = [blend if a.endswith(".blend") and not a.startswith("-") else a for a in argv]
    argv[0] = bpy.app.binary_path
    if "--factory-startup" not in argv:
        argv.insert(2, "--factory-startup")  # never the user's own preferences
    if "--" in argv:  # the bake's own options do not matter: it fails before them
        argv = argv[:argv.index("--") + 1] + ["--all", "--method", "sphere"]
    return argv


SOURCES = ["README.md", "docs/guide.md", "addon/README.md", "scripts/run_example.sh",
           "docs/DESIGN.md"]


@pytest.mark.parametrize("source", SOURCES)
def test_the_documented_command_fails_with_a_message_without_the_addon(source, tmp_path):
    commands = documented_commands(source)
    assert commands, f"no CLI command found in {source}"
    blend = str(tmp_path / "scene.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend, copy=True)
    empty = tmp_path / "scripts"  # a user-scripts folder without the add-on
    (empty / "addons").mkdir(parents=True)
    env = dict(os.environ, BLENDER_USER_SCRIPTS=str(empty))
    for command in commands:
        argv = as_argv(command, blend)
        r = subprocess.run(argv, env=env, capture_output=True, text=True, timeout=120)
        assert r.returncode != 0, f"{source}: exit 0 without the add-on: {command}"
        # The add-on's package, or the extension's repository package above it.
        out = r.stdout + r.stderr
        assert "No module named 'canopy_ao'" in out or "No module named 'bl_ext" in out, \
            out[-1000:]
        # It stopped at the failure: Blender went on to nothing else (a command that renders
        # with -a after the bake must not render when the bake could not even start).
        assert "Fra:" not in out, f"{source}: Blender went on after the failure: {command}"


@pytest.mark.parametrize("render", [["-a"], ["-f", "1"]])
def test_render_arguments_without_live_are_refused(render, tmp_path, user_scripts):
    """-a (or -f) before '--' renders after the script only when --live hands back to Blender:
    without --live the bake would exit Blender first, 0 and nothing rendered."""
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.mesh.primitive_plane_add(size=4.0)
    blend = str(tmp_path / "scene.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend, copy=True)
    argv = [bpy.app.binary_path, "-b", blend, "--factory-startup", "--addons", "canopy_ao",
            "--python-exit-code", "1", "--python-expr", "import canopy_ao.cli as c; c.main()",
            *render, "--", "--all", "--method", "sphere", "--tau", "1.5", "--save"]
    env = dict(os.environ, BLENDER_USER_SCRIPTS=user_scripts)
    r = subprocess.run(argv, env=env, capture_output=True, text=True, timeout=120)
    out = r.stdout + r.stderr
    assert r.returncode == 2 and "with --live" in out and render[0] in out, out[-2000:]
    assert "Fra:" not in out and "canopy_ao: saved" not in out, out[-2000:]
