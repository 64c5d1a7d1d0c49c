"""Canopy AO: approximate ambient occlusion for trees, grass and ground from fitted proxies.

Two packages: ``core`` (the bake's math and data; imports no bpy, so plain pytest tests it) and
``blender`` (everything that touches bpy), which loads in register(). ``cli`` is the headless
entry point. Importing this package does not import bpy.
"""

bl_info = {
    "name": "Canopy AO",
    "author": "Canopy AO contributors",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "3D View > Sidebar (N) > Canopy AO",
    "description": "Bake approximate ambient occlusion for vegetation from fitted proxies",
    "doc_url": "",
    "category": "Render",
}

_MODULES = ("blender.properties", "blender.viewport", "blender.operators", "blender.panels",
            "blender.live", "blender.frames")


def _modules():
    import importlib
    return [importlib.import_module(f"{__name__}.{name}") for name in _MODULES]


# Seconds of the last register(): its module imports and its registrations (the command
# line's profile, core/stage_profile.py).
REGISTER_SECONDS = {}


def register():
    # Registers even when the native module is missing: the panel then says why and how to
    # fix it, and the bake operator's poll explains itself (core.native.core_status()).
    import time
    t0 = time.perf_counter()
    mods = _modules()
    t1 = time.perf_counter()
    for mod in mods:
        mod.register()
    REGISTER_SECONDS.update(imports=t1 - t0, registration=time.perf_counter() - t1)


def unregister():
    for mod in reversed(_modules()):
        mod.unregister()
