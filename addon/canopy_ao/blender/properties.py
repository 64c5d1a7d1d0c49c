"""Settings in Blender: scene.canopy_ao (the bake's options, generated from core/settings.py's
OPTIONS, plus the last report) and Object.canopy_ao (role, tree, last result). The bake
operator's properties come from the same generator (option_properties)."""

import bpy
from bpy.props import (BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty,
                       StringProperty)

from ..core.settings import OPTIONS
from .gather import world_ao_distance


def _number_kw(o, hard):
    """The range of o's field: hard, Blender clamps a value typed or given to it; soft, only
    the slider stops there (the bake's own check refuses a value outside, naming it)."""
    kw = {}
    if o.min is not None:
        kw["min" if hard else "soft_min"] = o.min
    if o.max is not None:
        kw["max" if hard else "soft_max"] = o.max
    if o.soft_max is not None:
        kw["soft_max"] = o.soft_max
    return kw


def _property(o, hard=True):
    """The bpy property of one option (its number, for an optional one)."""
    kw = dict(name=o.label, description=o.help)
    if o.kind == "float":
        default = o.number_default if o.none_prop else o.default
        return FloatProperty(default=default, unit=o.unit, **_number_kw(o, hard), **kw)
    if o.kind == "int":
        return IntProperty(default=o.default, **_number_kw(o, hard), **kw)
    if o.kind == "bool":
        return BoolProperty(default=o.default, **kw)
    if o.kind == "str":
        return StringProperty(default=o.default, subtype=o.subtype, **kw)
    # Fixed numbers, so a saved choice keeps its meaning when items are added: an item's own
    # (a rung's Rung.number, wherever it sits on the ladder), else its place in the list.
    items = [(i, label, text, num[0] if num else n)
             for n, (i, label, text, *num) in enumerate(o.items)]
    return EnumProperty(items=items, default=o.default, **kw)


def option_properties(hard=True):
    """{name: bpy property} for every option, and the None switch of optional numbers
    (calibrate_tau), in OPTIONS order. hard=False (the operator's arguments): numbers are not
    clamped, so one out of range reaches the bake's check and is refused, as on the command
    line, instead of baking another number (samples=0 as 1 ray)."""
    out = {}
    for o in OPTIONS:
        if o.none_prop:
            out[o.none_prop] = BoolProperty(name=o.none_label, description=o.none_help,
                                            default=o.default is None)
        out[o.name] = _property(o, hard)
    return out


def resolve(values, scene):
    """Options as a bake takes them, from raw property values: an optional number is None when
    its switch is on (calibrate_tau: τ None), and the AO distance is the World's when
    use_world_distance is on (CanopyAOError when the World's is 0, gather.world_ao_distance)."""
    opts = {o.name: values[o.name] for o in OPTIONS}
    for o in OPTIONS:
        if o.none_prop and values[o.none_prop]:
            opts[o.name] = None
    if values["use_world_distance"]:
        opts["distance"] = world_ao_distance(scene, bake=True)
    return opts


def raw_values(group):
    """Every option's (and None switch's) value as a property group or operator holds it."""
    return {name: getattr(group, name) for name in option_properties()}


def scene_options(scene):
    """The bake options as the scene's panel has them."""
    return resolve(raw_values(scene.canopy_ao), scene)


ROLE_ITEMS = [
    ("AUTO", "Auto", "Guess from the mesh: flat and wide = ground, many upright blades on one "
                     "plane = grass, many small pieces in a blob = leaves, else trunk"),
    ("CANOPY", "Canopy", "Leaves: fit the proxies, and receive"),
    ("TRUNK", "Trunk", "Receives, and occludes the ground as a solid"),
    ("GROUND", "Ground", "Receives from every tree"),
    ("GRASS", "Grass", "Blades: Hegeman Eq. 9 times the trees' occlusion"),
    ("IGNORE", "Ignore", "Takes no part in the bake"),
]

CanopyAOSceneSettings = type("CanopyAOSceneSettings", (bpy.types.PropertyGroup,), {
    "__annotations__": dict(option_properties(), last_report=StringProperty(
        name="Last Bake", default="", description="Summary of the last bake")),
    "__doc__": "The bake's options (core/settings.py) and the last bake's summary",
})


class CanopyAOObjectSettings(bpy.types.PropertyGroup):
    role: EnumProperty(name="Role", items=ROLE_ITEMS, default="AUTO")
    tree: StringProperty(name="Tree", default="",
                         description="Objects with the same tree name form one tree; empty = "
                                     "group by parent, then by collection")
    last_result: StringProperty(name="Last Result", default="")


classes = (CanopyAOSceneSettings, CanopyAOObjectSettings)


def register():
    # The options as they are now: a rung registered after this module was imported
    # (core/rungs/base.register) is in the method menu too.
    CanopyAOSceneSettings.__annotations__.update(option_properties())
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.Scene.canopy_ao = PointerProperty(type=CanopyAOSceneSettings)
    bpy.types.Object.canopy_ao = PointerProperty(type=CanopyAOObjectSettings)


def unregister():
    del bpy.types.Object.canopy_ao
    del bpy.types.Scene.canopy_ao
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
