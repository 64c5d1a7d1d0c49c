"""What a user is told when the native module does not load (core.native.load_failure, no bpy):
which Python the Blender runs, which Python the package's module was built for, and the fix
that fits where the package lives: the extension zip for this Python in an installed copy,
CMake only in the source tree."""
import os
import shutil
import subprocess
import sys
from pathlib import Path

ADDON = Path(__file__).resolve().parents[2] / "addon"
sys.path.insert(0, str(ADDON))

from canopy_ao.core import native  # noqa: E402


def _package(tmp_path, *modules, source_tree=False):
    root = tmp_path / "repo"
    pkg = root / "addon" / "canopy_ao"
    pkg.mkdir(parents=True)
    (pkg / "blender_manifest.toml").write_text('id = "canopy_ao"\nversion = "1.2.3"\n')
    for name in modules:
        (pkg / name).write_bytes(b"")
    if source_tree:
        (root / "CMakeLists.txt").write_text("")
        (root / "native").mkdir()
    return str(pkg)


def test_an_extension_for_another_python_names_both_pythons_and_the_zip(tmp_path):
    pkg = _package(tmp_path, "_core.cpython-313-x86_64-linux-gnu.so")
    msg = native.load_failure("ImportError: No module named 'canopy_ao._core'", pkg, (3, 14))
    assert "this Blender runs Python 3.14" in msg and "built for Python 3.13" in msg, msg
    assert "canopy_ao-1.2.3-cp314.zip" in msg and "cmake" not in msg.lower(), msg
    assert "canopy_ao-1.2.3-linux_x64-cp314.zip" in msg, msg  # the portable zip's name


def test_a_windows_module_is_read_by_its_tag_too(tmp_path):
    pkg = _package(tmp_path, "_core.cp312-win_amd64.pyd")
    msg = native.load_failure("ImportError: DLL load failed", pkg, (3, 11))
    assert "built for Python 3.12" in msg and "canopy_ao-1.2.3-cp311.zip" in msg, msg


def test_an_installed_copy_without_a_module_names_the_zip(tmp_path):
    msg = native.load_failure("ImportError: x", _package(tmp_path), (3, 11))
    assert "no module built for this Blender's Python 3.11" in msg, msg
    assert "canopy_ao-1.2.3-cp311.zip" in msg and "cmake" not in msg.lower(), msg


def test_the_source_tree_says_build_with_cmake(tmp_path):
    pkg = _package(tmp_path, "_core.cpython-313-x86_64-linux-gnu.so", source_tree=True)
    msg = native.load_failure("ImportError: x", pkg, (3, 11))
    assert "this Blender runs Python 3.11" in msg and "built for Python 3.13" in msg, msg
    assert "cmake -S . -B build-addon" in msg and ".zip" not in msg, msg


def test_a_module_for_this_python_that_fails_keeps_its_error(tmp_path):
    pkg = _package(tmp_path, "_core.cpython-311-x86_64-linux-gnu.so")
    msg = native.load_failure("ImportError: undefined symbol: _ZN3foo", pkg, (3, 11))
    assert "undefined symbol: _ZN3foo" in msg and "cp311.zip" in msg, msg


def test_a_copy_with_a_wrong_abi_module_says_so_through_core_status(tmp_path):
    """The real package copied with its module renamed to another Python's ABI tag, imported by
    a plain Python: core_status(), which the panel and the CLI show, names both Pythons."""
    pkg = tmp_path / "ext" / "canopy_ao"
    shutil.copytree(ADDON / "canopy_ao", pkg, ignore=shutil.ignore_patterns("__pycache__"))
    here = f"{sys.version_info.major}{sys.version_info.minor}"
    # Only this Python's module: the test legs build the others into the same folder.
    for other in pkg.glob("_core.*"):
        if f"cpython-{here}" not in other.name:
            other.unlink()
    (so,) = pkg.glob("_core.*")
    so.rename(pkg / so.name.replace(f"cpython-{here}", "cpython-399"))
    code = ("import sys; sys.path.insert(0, sys.argv[1]); from canopy_ao import core; "
            "ok, msg = core.core_status(); print(ok); print(msg)")
    r = subprocess.run([sys.executable, "-c", code, str(pkg.parent)], capture_output=True,
                       text=True, timeout=120, env=dict(os.environ, PYTHONDONTWRITEBYTECODE="1"))
    assert r.returncode == 0, r.stderr
    ok, msg = r.stdout.split("\n", 1)
    py = f"{sys.version_info.major}.{sys.version_info.minor}"
    assert ok == "False" and f"this Blender runs Python {py}" in msg, msg
    assert "built for Python 3.99" in msg and f"-cp{here}.zip" in msg, msg
