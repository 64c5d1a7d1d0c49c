"""The one import of the native module ``canopy_ao._core``, its status, and the error types.

Every other module takes ``_core`` from here and calls its functions by name
(``_core.fit_sphere(...)``). The add-on must load without the module (the panel then says how
to build it), so a missing or stale build is detected once, here, not at each call.
"""

from __future__ import annotations

import functools
import os
import re
import sys


class CanopyAOError(ValueError):
    """A bake that cannot be done as asked (bad input, a scene problem, a missing build), with
    a message a user can act on. A ValueError, as the native module's refusals of bad input
    are; not a RuntimeError, so catching it never hides a bug (which keeps its traceback)."""


def refusals_are_user_errors(fn):
    """Decorator for the core's entry points: a ValueError from inside (the native module's
    documented refusal of bad input, e.g. a mesh with NaN coordinates) reaches the caller as a
    CanopyAOError with the same message, the original chained. Every other exception is a bug
    and passes unchanged, with its traceback."""
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        try:
            return fn(*args, **kwargs)
        except CanopyAOError:
            raise
        except ValueError as exc:
            raise CanopyAOError(str(exc)) from exc
    return wrapper


# The native module's accepted input range (native/python/arrays.h; _core.LIMITS, and
# tests/python/test_limits.py holds these to it): known here so that options and meshes are
# checked, and refused by name, with or without the module.
LIMITS = {"coordinate": 1e9, "min_length": 1e-9, "max_length": 1e10, "tau": 1e4,
          "samples": 1 << 16, "threads": 1 << 16}


# What the add-on calls. A module built from older sources lacks some: it is then reported as
# not loaded (with "rebuild") instead of failing in the middle of a bake.
_REQUIRED = ("Ellipsoid", "fit_sphere", "fit_ellipsoid", "fit_shells", "ao_occluders",
             "ao_canopy_sphere", "ao_canopy_ellipsoid", "ao_canopy_shells", "ao_medium_shells",
             "ao_reeves_blau", "ao_grass", "RayTracer", "DensityGrid", "OccluderField",
             "rasterize_uv", "splat_texels", "ao_near_far", "OcclusionFeatures",
             "expand_features", "predict_features",
             "to_world", "gray_rgba", "ScenePlan", "ForestOccluders", "GrassCover",
             "connected_components", "patch_visibility")


def missing_functions(module) -> list[str]:
    """Names the add-on needs that ``module`` (a loaded ``_core``) does not have."""
    return [name for name in _REQUIRED if not hasattr(module, name)]


try:
    from .. import _core
    _CORE_ERROR = None
    if missing_functions(_core):
        _CORE_ERROR = (f"it was built from older sources (no {', '.join(missing_functions(_core))}"
                       "); rebuild it")
        _core = None
except Exception as exc:  # ImportError, or an undefined symbol from a stale build
    _core = None
    _CORE_ERROR = f"{type(exc).__name__}: {exc}"


# The package folder, symlinks resolved (scripts/install_addon.sh links the source tree's).
_PACKAGE = os.path.dirname(os.path.dirname(os.path.realpath(__file__)))


def core_status() -> tuple[bool, str]:
    """(available, message). The message says how to fix a missing or broken module."""
    if _core is not None:
        return True, f"native core loaded ({_core.__file__})"
    return False, load_failure(_CORE_ERROR, _PACKAGE)


def load_failure(error: str, package: str, python: tuple = sys.version_info[:2]) -> str:
    """What to tell a user whose native module did not load (error): which Python this Blender
    runs and which Python the package's module files were built for, and the fix that fits
    where the package lives. In the source tree (package = <repo>/addon/canopy_ao, beside
    CMakeLists.txt): build it with CMake. Anywhere else (an installed extension or add-on): the
    extension zip for this Python, named as scripts/build_extension.sh names it."""
    here = f"{python[0]}.{python[1]}"
    try:
        names = sorted(f for f in os.listdir(package) if re.match(r"_core\..*(so|pyd)$", f))
    except OSError:
        names = []
    built = sorted({f"{m.group(1)[0]}.{m.group(1)[1:]}" for m in
                    (re.search(r"(?:cpython-|cp)(3\d+)", f) for f in names) if m})
    repo = os.path.dirname(os.path.dirname(package))
    if os.path.isfile(os.path.join(repo, "CMakeLists.txt")) and os.path.isdir(
            os.path.join(repo, "native")):
        fix = ("run 'cmake -S . -B build-addon && cmake --build build-addon -j2' in the Canopy AO "
               "source tree (it copies _core*.so into addon/canopy_ao/), then restart Blender")
    else:
        zip_name = _zip_name(package, python)
        fix = (f"install the Canopy AO extension built for Python {here}, {zip_name} (for a "
               "blender.org build on Linux, the self-contained "
               f"{zip_name.replace('-cp', '-linux_x64-cp')}; Edit > Preferences > Get "
               "Extensions > Install from Disk; or from the source tree: "
               "scripts/build_extension.sh [--portable]), then restart Blender")
    if built and here not in built:
        why = (f"this Blender runs Python {here}, and this copy of Canopy AO carries a module "
               f"built for Python {', '.join(built)} ({', '.join(names)}), which it cannot load")
    elif not names:
        why = f"this copy of Canopy AO has no module built for this Blender's Python {here}"
    else:
        why = f"{error}; it must be built for this Blender's Python {here}"
    return f"Canopy AO's native module could not be loaded: {why}. To fix it, {fix}."


def _zip_name(package: str, python: tuple) -> str:
    """canopy_ao-<version>-cp<XY>.zip, the extension zip for Python X.Y (the version from the
    package's blender_manifest.toml)."""
    version = "<version>"
    try:
        with open(os.path.join(package, "blender_manifest.toml"), encoding="utf-8") as f:
            m = re.search(r'^version\s*=\s*"([^"]+)"', f.read(), re.M)
        version = m.group(1) if m else version
    except OSError:
        pass
    return f"canopy_ao-{version}-cp{python[0]}{python[1]}.zip"


def require():
    """The native module; raises CanopyAOError saying how to build it when it is missing."""
    if _core is None:
        raise CanopyAOError(core_status()[1])
    return _core
