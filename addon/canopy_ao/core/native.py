"""The one import of the native module ``canopy_ao._core``, its status, and the error types.

Every other module takes ``_core`` from here and calls its functions by name
(``_core.fit_sphere(...)``). The add-on must load without the module (the panel then says how
to build it), so a missing or stale build is detected once, here, not at each call.
"""

from __future__ import annotations

import functools
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


# What the add-on calls. A module built from older sources lacks some: it is then reported as
# not loaded (with "rebuild") instead of failing in the middle of a bake.
_REQUIRED = ("Ellipsoid", "fit_sphere", "fit_ellipsoid", "fit_shells", "ao_occluders",
             "ao_canopy_sphere", "ao_canopy_ellipsoid", "ao_canopy_shells", "ao_medium_shells",
             "ao_reeves_blau", "ao_grass", "RayTracer", "DensityGrid", "OccluderField",
             "rasterize_uv", "splat_texels", "ao_near_far", "OcclusionFeatures",
             "expand_features", "predict_features",
             "to_world", "gray_rgba", "ScenePlan", "ForestOccluders", "GrassCover")


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


def core_status() -> tuple[bool, str]:
    """(available, message). The message says how to fix a missing or broken module."""
    if _core is not None:
        return True, f"native core loaded ({_core.__file__})"
    return False, (
        f"Canopy AO's native module could not be loaded ({_CORE_ERROR}). It must be built for "
        f"this Blender's Python {sys.version_info.major}.{sys.version_info.minor}: run "
        "'cmake -S . -B build-addon && cmake --build build-addon -j2' in the Canopy AO source "
        "tree (it copies _core*.so into addon/canopy_ao/), then restart Blender.")


def require():
    """The native module; raises CanopyAOError saying how to build it when it is missing."""
    if _core is None:
        raise CanopyAOError(core_status()[1])
    return _core
