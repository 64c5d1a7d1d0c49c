"""The add-on's shape: core/ imports no bpy (plain Python imports all of it) and calls the
native module only through core/native.py (docs/DESIGN.md, 'Architecture')."""
import os
import re
import subprocess
import sys

ADDON = os.path.join(os.path.dirname(__file__), "..", "..", "addon")
PACKAGE = os.path.join(ADDON, "canopy_ao")


def test_core_imports_without_blender():
    # A child process: nothing this test run imported earlier can hide a bpy import.
    code = (
        "import importlib, pkgutil, sys\n"
        "import canopy_ao.core as core\n"
        "names = [m.name for m in pkgutil.iter_modules(core.__path__, 'canopy_ao.core.')]\n"
        "for name in names: importlib.import_module(name)\n"
        "bad = sorted(m for m in sys.modules if m.split('.')[0] in ('bpy', 'mathutils', 'bmesh'))\n"
        "assert not bad, bad\n"
        "assert 'canopy_ao.blender' not in sys.modules\n"
        "print(len(names))\n")
    out = subprocess.run([sys.executable, "-c", code], cwd=ADDON, capture_output=True, text=True,
                         env=dict(os.environ, PYTHONPATH=os.path.abspath(ADDON)))
    assert out.returncode == 0, out.stderr
    assert int(out.stdout.strip()) >= 10  # native, settings, scene, proxies, lighting, ladder, ...


def test_native_module_imported_in_one_place():
    found = []
    for root, _dirs, files in os.walk(PACKAGE):
        for f in files:
            if f.endswith(".py"):
                path = os.path.join(root, f)
                with open(path, encoding="utf-8") as fh:
                    text = fh.read()
                if re.search(r"^\s*(from \.+ import _core|import canopy_ao\._core)", text, re.M):
                    found.append(os.path.relpath(path, PACKAGE))
    assert found == [os.path.join("core", "native.py")]
