"""What the native module needs at load time (docs/PORTABILITY.md): its shared-library
dependencies (ELF DT_NEEDED) and glibc symbol versions, listed, and checked against what a
Blender process already carries, so a dependency no Blender loads cannot creep in unnoticed.

Run under the Python Blender runs (as scripts/test_suite.sh does), on a machine with `blender`
and binutils (readelf, objdump)."""
import os
import re
import shutil
import subprocess

import pytest

import canopy_ao._core as core

# Loaded by every Blender build that can run a C++ Python module: the C and C++ runtimes.
RUNTIME = {"libc.so.6", "libm.so.6", "libstdc++.so.6", "libgcc_s.so.1", "libpthread.so.0",
           "libdl.so.2", "ld-linux-x86-64.so.2", "libmvec.so.1"}


def _run(*cmd):
    return subprocess.run(cmd, check=True, capture_output=True, text=True).stdout


def _needed(path):
    return set(re.findall(r"\(NEEDED\)\s+Shared library: \[([^\]]+)\]", _run("readelf", "-d", path)))


def _glibc_versions(path):
    found = set(re.findall(r"\bGLIBC_(\d+(?:\.\d+)+)\b", _run("objdump", "-T", path)))
    return {tuple(int(x) for x in v.split(".")) for v in found}


def _blender_binary():
    exe = shutil.which("blender")
    if exe is None:
        pytest.skip("no blender on PATH")
    exe = os.path.realpath(exe)
    with open(exe, "rb") as f:
        if f.read(4) != b"\x7fELF":  # a launcher script: the binary is beside it
            exe = next((p for p in ("/usr/lib/blender/blender", "/usr/bin/blender-bin")
                        if os.path.exists(p)), None)
    if exe is None:
        pytest.skip("blender is a launcher whose binary was not found")
    return exe


def _loaded_by(binary):
    """Sonames of everything the dynamic linker loads for `binary` (its whole closure)."""
    names = set()
    for line in _run("ldd", binary).splitlines():
        m = re.match(r"\s*(\S+\.so[.\d]*)\s", line)
        if m:
            names.add(os.path.basename(m.group(1)))
    return names


@pytest.fixture(scope="module")
def module_path():
    for tool in ("readelf", "objdump", "ldd"):
        if shutil.which(tool) is None:
            pytest.skip(f"{tool} missing (binutils, libc-bin)")
    return core.__file__


def test_module_needs_only_libraries_blender_loads(module_path):
    needed = _needed(module_path)
    print("\nmodule:", os.path.basename(module_path))
    print("needed:", " ".join(sorted(needed)))
    # Sanity: the list is read (a module with no C++ runtime dependency is not this module).
    assert "libstdc++.so.6" in needed or "libc.so.6" in needed
    carried = _loaded_by(_blender_binary()) | RUNTIME
    # libpython: Debian's Blender links it; an official build embeds Python and exports its
    # symbols instead; a module must never need it by name either way (pybind11 does not).
    extra = sorted(n for n in needed if n not in carried)
    assert not [n for n in needed if n.startswith("libpython")], needed
    assert not extra, f"the module needs libraries no Blender process loads: {extra}"


def test_module_glibc_no_newer_than_blender_needs(module_path):
    mod = _glibc_versions(module_path)
    blender = _glibc_versions(_blender_binary())
    assert mod and blender
    newest = max(mod)
    print("\nmodule's newest GLIBC symbol version:", ".".join(map(str, newest)),
          "; Blender's:", ".".join(map(str, max(blender))))
    assert newest <= max(blender), "the module needs a newer glibc than Blender itself"


def test_portable_kernel_can_be_forced_and_agrees():
    import numpy as np

    rng = np.random.default_rng(3)
    p = rng.uniform(-2, 2, (1001, 3)).astype(np.float32)
    n = rng.normal(size=(1001, 3)).astype(np.float32)
    before = core.canopy_kernel()
    try:
        core.set_canopy_kernel("portable")
        assert core.canopy_kernel() == "portable"
        portable = core.ao_canopy_sphere(p, n, core.Sphere(np.zeros(3, np.float32), 1.5), 1.2)
        try:
            core.set_canopy_kernel("avx2")
        except ValueError:
            pytest.skip("CPU without AVX2/FMA: only the portable kernel runs")
        fast = core.ao_canopy_sphere(p, n, core.Sphere(np.zeros(3, np.float32), 1.5), 1.2)
    finally:
        core.set_canopy_kernel(before)
    assert np.abs(portable - fast).max() < 2e-6
    assert portable.min() < 0.5 < portable.max()
    with pytest.raises(ValueError, match="kernel must be"):
        core.set_canopy_kernel("sse")


def test_environment_forces_portable_kernel():
    env = dict(os.environ, CANOPY_AO_KERNEL="portable")
    addon = os.path.dirname(os.path.dirname(core.__file__))
    out = subprocess.run(
        [os.sys.executable, "-c", "import canopy_ao._core as c; print(c.canopy_kernel())"],
        env=dict(env, PYTHONPATH=addon), check=True, capture_output=True, text=True).stdout
    assert out.strip() == "portable"
