"""Shared pytest setup: `<repo>/addon` on sys.path, so `import canopy_ao._core` finds the module
the CMake build copies there (no bpy needed)."""
import os
import sys

_ADDON = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..", "addon"))
if _ADDON not in sys.path:
    sys.path.insert(0, _ADDON)
