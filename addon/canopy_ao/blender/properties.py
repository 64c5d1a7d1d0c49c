"""Settings: scene.canopy_ao (the bake) and Object.canopy_ao (role, tree, last result)."""

import bpy
from bpy.props import (BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty,
                       StringProperty)

from ..core import ladder

METHOD_LABELS = {
    "auto": ("Auto", "Calibrate tau and pick sphere / ellipsoid / shells against a few hundred "
                     "ray-traced points: the cheapest model that is good enough"),
    "sphere": ("Sphere", "One fitted sphere per tree (Hegeman Eq. 4-6)"),
    "ellipsoid": ("Ellipsoid", "One fitted ellipsoid per tree"),
    "shells": ("Shells", "Several ellipsoid shells per tree (k-means clusters)"),
    "medium": ("Leaf medium", "The shells filled with randomly oriented leaves: exact expected "
                              "AO of a uniform medium (tabulated)"),
    "reeves_blau": ("Reeves-Blau", "Baseline exp(-tau depth) inside one ellipsoid"),
    "grid": ("Density grid", "Leaf density voxelised, rays marched through it"),
    "raytrace": ("Ray-traced", "Exact: Embree rays against every triangle (slowest)"),
}


# Blender keeps only pointers to a dynamic enum's strings: hold the list for the session.
_METHOD_ITEMS = []


def method_items(self, context):
    # Offer only what the loaded native module can run ("grid" needs DensityGrid); the numbers
    # stay fixed so a saved choice keeps its meaning.
    if not _METHOD_ITEMS:
        avail = ladder.available_methods()
        _METHOD_ITEMS.extend((m, *METHOD_LABELS[m], i) for i, m in enumerate(ladder.METHODS)
                             if m in avail or m == "auto")
    return _METHOD_ITEMS


ROLE_ITEMS = [
    ("AUTO", "Auto", "Guess from the mesh: flat and wide = ground, many upright blades on one "
                     "plane = grass, many small pieces in a blob = leaves, else trunk"),
    ("CANOPY", "Canopy", "Leaves: fit the proxies, and receive"),
    ("TRUNK", "Trunk", "Receives, and occludes the ground as a solid"),
    ("GROUND", "Ground", "Receives from every tree"),
    ("GRASS", "Grass", "Blades: Hegeman Eq. 9 times the trees' occlusion"),
    ("IGNORE", "Ignore", "Takes no part in the bake"),
]


class CanopyAOSceneSettings(bpy.types.PropertyGroup):
    method: EnumProperty(name="Method", items=method_items,
                         description="How the AO is computed")
    tau_auto: BoolProperty(name="Auto τ", default=True,
                           description="Calibrate the optical depth against ray-traced samples")
    tau: FloatProperty(name="τ", default=1.5, min=0.001, soft_max=20.0,
                       description="Optical depth of a canopy: AO at its centre is exp(-τ)")
    use_world_distance: BoolProperty(
        name="From World", default=True,
        description="Use the World's AO distance (World > Ambient Occlusion > Distance), as "
                    "Cycles' AO bake does, so the bake and a Cycles check agree at any scale")
    distance: FloatProperty(name="AO Distance", default=10.0, min=0.0, unit='LENGTH',
                            description="Ray length cut-off (as Cycles' world AO distance); "
                                        "0 = unlimited. Used by the ray-traced method and "
                                        "calibration")
    samples: IntProperty(name="Samples", default=64, min=1, soft_max=1024,
                         description="Rays per vertex for the ray-traced method")
    attribute_name: StringProperty(name="Attribute", default="CanopyAO",
                                   description="Color attribute (POINT, FLOAT_COLOR) to write")
    overwrite: BoolProperty(name="Overwrite", default=False,
                            description="Replace an attribute of this name that Canopy AO did "
                                        "not make")
    wire_material: BoolProperty(name="Wire Material", default=False,
                                description="Connect the baked attribute into the materials")
    add_aov: BoolProperty(name="Add AOV", default=False,
                          description="Add a shader AOV output and a view-layer AOV")
    aov_name: StringProperty(name="AOV Name", default="BakedAO",
                             description="Name of the AOV ('AO' would collide with Cycles' own "
                                         "AO pass)")
    mode: EnumProperty(name="Output", items=[
        ("VERTEX", "Per Vertex", "A color attribute"),
        ("TEXEL", "Per Texel", "An image in the UV layout")], default="VERTEX")
    uv_map: StringProperty(name="UV Map", default="", description="Empty = active UV map")
    resolution: IntProperty(name="Resolution", default=1024, min=16, max=16384)
    image_dir: StringProperty(name="Image Folder", default="//canopy_ao", subtype='DIR_PATH')
    show_proxies: BoolProperty(name="Show Proxies", default=True,
                               description="Show the fitted shells as empties in a "
                                           "'Canopy AO Proxies' collection")
    check_cycles: BoolProperty(name="Check with Cycles", default=False,
                               description="Also bake Cycles AO and report the error (slow)")
    cycles_samples: IntProperty(name="Cycles Samples", default=64, min=1, soft_max=4096)
    last_report: StringProperty(name="Last Bake", default="",
                                description="Summary of the last bake")


class CanopyAOObjectSettings(bpy.types.PropertyGroup):
    role: EnumProperty(name="Role", items=ROLE_ITEMS, default="AUTO")
    tree: StringProperty(name="Tree", default="",
                         description="Objects with the same tree name form one tree; empty = "
                                     "group by parent, then by collection")
    last_result: StringProperty(name="Last Result", default="")


classes = (CanopyAOSceneSettings, CanopyAOObjectSettings)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.Scene.canopy_ao = PointerProperty(type=CanopyAOSceneSettings)
    bpy.types.Object.canopy_ao = PointerProperty(type=CanopyAOObjectSettings)


def unregister():
    del bpy.types.Object.canopy_ao
    del bpy.types.Scene.canopy_ao
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
