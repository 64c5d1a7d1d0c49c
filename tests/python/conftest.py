"""Shared pytest setup: `<repo>/addon` on sys.path, so `import canopy_ao._core` finds the module
the CMake build copies there (no bpy needed), and `<repo>/examples` for the scene generators."""
import os
import sys

_ADDON = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..", "addon"))
_EXAMPLES = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..", "examples"))
for _path in (_ADDON, _EXAMPLES):  # canopy_ao._core, and the scene generators
    if _path not in sys.path:
        sys.path.insert(0, _path)
