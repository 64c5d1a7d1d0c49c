"""Engine packings (no bpy): each preset names the channel an engine reads the AO from, and a
bake with one writes the AO into that channel of an existing image or color attribute through
the Channel option (blender/maps_io.py), so a preset is a name for a channel, not a path of its
own (docs/DESIGN.md, 'Maps')."""

from .native import CanopyAOError

# Preset -> the channel its texture holds AO in.
CHANNEL = {
    "ORM": "R",  # glTF occlusion / Unreal ORM: occlusion R, roughness G, metallic B
    "HDRP_MASK": "G",  # Unity HDRP mask map: metallic R, occlusion G, detail mask B, smoothness A
}


def apply(opts):
    """Set opts["channel"] from opts["packing"] (in place; returns opts). A channel given as
    well must be the preset's: CanopyAOError names both."""
    packing = opts.get("packing", "NONE")
    if packing == "NONE":
        return opts
    want = CHANNEL[packing]
    if opts.get("channel", "RGBA") not in ("RGBA", want):
        raise CanopyAOError(f"Packing {packing} puts the AO in channel {want}, but Channel is "
                            f"{opts['channel']}; give one of them (nothing was changed)")
    opts["channel"] = want
    return opts
