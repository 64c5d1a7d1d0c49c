"""Canopy AO: approximate ambient occlusion for trees, grass and ground from fitted proxies.

Importing this package does not import bpy (plain pytest imports ``canopy_ao._core`` and the
pure modules ``roles`` and ``engine``); the Blender parts load in register().
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

_MODULES = ("blender.properties", "blender.operators", "blender.panels")


def _modules():
    import importlib
    return [importlib.import_module(f"{__name__}.{name}") for name in _MODULES]


def register():
    # Registers even when the native module is missing: the panel then says why and how to
    # fix it, and the bake operator's poll explains itself (engine.core_status()).
    for mod in _modules():
        mod.register()


def unregister():
    for mod in reversed(_modules()):
        mod.unregister()
