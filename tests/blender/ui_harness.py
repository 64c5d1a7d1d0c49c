"""What the windowed checks share (ui_modal_undo.py, ui_live.py): checks that exit the Blender
they run in, the window's context, steps run from a timer, and the pytest side that starts
such a script under Xvfb."""
import os
import subprocess
import sys
import traceback


def fail(msg):
    print(f"UI-FAIL: {msg}", file=sys.stderr, flush=True)
    os._exit(1)


def check(cond, msg):
    if not cond:
        fail(msg)


def window_ctx():
    import bpy
    win = bpy.context.window_manager.windows[0]
    return dict(window=win, screen=win.screen, area=win.screen.areas[0])


def run_steps(steps):
    """Run the generator ``steps`` (each yield: seconds to wait) from a timer once the window
    is up; an exception fails the check."""
    import bpy
    it = steps()

    def tick():
        try:
            return next(it)
        except StopIteration:
            return None
        except BaseException:  # noqa: BLE001 - any failure is the check's failure
            traceback.print_exc()
            fail("exception")
    bpy.app.timers.register(tick, first_interval=1.0)


def run_in_window(script, user_scripts, timeout=300):
    """pytest side: run ``script`` in a windowed Blender under Xvfb (skipped without
    xvfb-run) and assert it printed UI-OK."""
    import shutil

    import bpy
    import pytest
    if shutil.which("xvfb-run") is None:
        pytest.skip("xvfb-run not installed: the windowed check cannot run")
    env = dict(os.environ, BLENDER_USER_SCRIPTS=user_scripts)
    r = subprocess.run(["xvfb-run", "-a", "-s", "-screen 0 1024x768x24", bpy.app.binary_path,
                        "--factory-startup", "--enable-event-simulate", "--python", script],
                       env=env, capture_output=True, text=True, timeout=timeout)
    assert r.returncode == 0 and "UI-OK" in r.stdout, (r.stdout[-1500:], r.stderr[-1500:])


def build_tree_scene():
    """Every object removed, then tests/python/tree_scene's tree as plain meshes (no roles)."""
    import bpy
    import tree_scene
    for ob in list(bpy.data.objects):
        bpy.data.objects.remove(ob)
    for name, (p, t) in tree_scene.scene(True).items():
        me = bpy.data.meshes.new(name)
        me.from_pydata(p.tolist(), [], t.tolist())
        bpy.context.scene.collection.objects.link(bpy.data.objects.new(name, me))
