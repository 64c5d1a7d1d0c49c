"""Every bake option, declared once (no bpy).

Each :class:`Option` holds its type, default, range, label and help. From this one table come
the core's :class:`BakeSettings`, the scene's property group and the bake operator's properties
(blender/properties.py) and the command line's arguments (cli.py), and every interface checks
a value with :meth:`Option.check` (docs/DESIGN.md, 'One settings schema'). Adding an option is
one entry in OPTIONS.

An optional number (``none_prop``) may also be None, which has its own meaning: τ None means
"calibrate τ". Blender cannot hold None, so there the option is two properties, the number and
a switch named ``none_prop`` ("calibrate_tau"); the command line spells None as ``auto``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

from .ladder import DEFAULT_TAU
from .rungs import base as rungs, registry  # noqa: F401  (registry: fills the ladder)
from .native import LIMITS, CanopyAOError


@dataclass(frozen=True)
class Option:
    name: str
    kind: str  # "float", "int", "bool", "str" or "enum"
    default: object
    label: str
    help: str
    group: str = "bake"  # "bake": a BakeSettings field; "output": what Blender does with it
    min: float | None = None
    max: float | None = None
    min_exclusive: bool = False
    max_exclusive: bool = False
    soft_max: float | None = None  # the UI slider's end; values up to max stay valid
    items: tuple = ()  # enum: ((id, label, help[, number]), ...); number: see blender/properties
    none_prop: str = ""  # optional number: the switch that stands for None ...
    none_label: str = ""  # ... its label ...
    none_help: str = ""  # ... and help
    number_default: float | None = None  # optional number: the value when it is not None
    cli: str | None = ""  # the flag; "" = --name-with-dashes; None = not on the command line
    cli_enables: str = ""  # giving the flag also turns this bool option on (--aov NAME)
    cli_default: str = ""  # the command line's default, when it is not ``default``
    advanced: bool = False  # the panel's Advanced section
    unit: str = "NONE"  # Blender's unit ('LENGTH', 'TIME')
    subtype: str = "NONE"  # Blender's string subtype ('DIR_PATH')
    positive_min: float | None = None  # a value above 0 must be at least this (0 keeps its meaning)

    @property
    def flag(self) -> str:
        return self.cli or "--" + self.name.replace("_", "-")

    def range_text(self) -> str:
        """'in [1, 65536]', '> 0', '>= 0', '0 or in [1e-09, 1e+10]' or '' (no bound)."""
        if self.positive_min is not None:
            return f"0 or in [{self.positive_min:g}, {self.max:g}]"
        if self.min is not None and self.max is not None:
            return (f"in {'(' if self.min_exclusive else '['}{self.min:g}, {self.max:g}"
                    f"{')' if self.max_exclusive else ']'}")
        if self.min is not None:
            return f"{'>' if self.min_exclusive else '>='} {self.min:g}"
        if self.max is not None:
            return f"{'<' if self.max_exclusive else '<='} {self.max:g}"
        return ""

    def check(self, value):
        """The value, converted to the option's type; CanopyAOError names the option, the
        range and the value when it is out of range, not finite or of the wrong type."""
        if value is None and self.none_prop:
            return None
        if self.kind == "enum":
            ids = [i[0] for i in self.items]
            if value not in ids:
                raise CanopyAOError(f"{self.name} must be one of {', '.join(ids)}, got {value!r}")
            return value
        if self.kind == "bool":
            if not isinstance(value, (bool, int)):
                raise CanopyAOError(f"{self.name} must be true or false, got {value!r}")
            return bool(value)
        if self.kind == "str":
            if not isinstance(value, str):
                raise CanopyAOError(f"{self.name} must be text, got {value!r}")
            return value
        try:
            number = int(value) if self.kind == "int" else float(value)
        except (TypeError, ValueError, OverflowError):
            raise CanopyAOError(f"{self.name} must be a{'n integer' if self.kind == 'int' else ' number'}"
                                f", got {value!r}") from None
        if self.kind == "int" and number != value:
            raise CanopyAOError(f"{self.name} must be an integer, got {value!r}")
        ok = math.isfinite(number)
        if ok and self.min is not None:
            ok = number > self.min if self.min_exclusive else number >= self.min
        if ok and self.max is not None:
            ok = number < self.max if self.max_exclusive else number <= self.max
        if ok and self.positive_min is not None:
            ok = number == 0 or number >= self.positive_min
        if not ok:
            what = "an integer" if self.kind == "int" else "a finite number"
            hint = (f" (to {self.none_label.lower()}: --{self.name} auto on the command line, "
                    f"{self.none_prop} in Blender)" if self.none_prop else "")
            raise CanopyAOError(f"{self.name} must be {what} {self.range_text()}, got "
                                f"{value!r}{hint}".replace("  ", " "))
        return number

    def parse(self, text: str):
        """A command-line word as a checked value ('auto' = None for an optional number)."""
        if self.none_prop and text.strip().lower() == "auto":
            return None
        if self.kind == "enum":
            key = text.upper().replace("-", "_")  # hdrp-mask as HDRP_MASK
            return self.check(key if key in [i[0] for i in self.items] else text)
        if self.kind in ("int", "float"):
            try:
                value = int(text) if self.kind == "int" else float(text)
            except ValueError:
                what = "an integer" if self.kind == "int" else "a number"
                raise CanopyAOError(f"{self.name} must be {what}"
                                    f"{' or auto' if self.none_prop else ''}, got {text!r}") from None
            return self.check(value)
        return self.check(text)


def _enum(pairs):
    return tuple((i, label, text) for i, label, text in pairs)


class RungChoices(Sequence):
    """The method option's (id, label, help, number) items: the ladder's rungs as registered
    now (rungs/registry.py), so a rung registered later is offered too; number: Rung.number,
    what a saved .blend stores for it."""

    def _items(self):
        return [(r.name, r.label, r.help, r.number) for r in rungs.ladder()]

    def __getitem__(self, i):
        return self._items()[i]

    def __len__(self):
        return len(rungs.ladder())

    def __repr__(self):
        return f"RungChoices({rungs.names()})"


OPTIONS = (
    # --- how the AO is computed (BakeSettings) ---
    Option("method", "enum", "auto", "Method", "How the AO is computed (the method ladder)",
           items=RungChoices()),
    Option("tau", "float", None, "τ", "Optical depth of a canopy: AO at its centre is exp(-τ)",
           min=0.0, min_exclusive=True, max=LIMITS["tau"], soft_max=20.0,
           number_default=DEFAULT_TAU,
           none_prop="calibrate_tau", none_label="Calibrate τ",
           none_help="Calibrate the optical depth against ray-traced samples"),
    Option("distance", "float", 0.0, "AO Distance",
           "Ray length cut-off (as Cycles' world AO distance); 0 = unlimited. Rays, the "
           "density grid and calibration stop at it; the occluder laws (other trees, trunks, "
           "instanced forests) count only what lies within it; the in-shell models do not "
           "shorten paths inside a crown", min=0.0, max=LIMITS["max_length"],
           positive_min=LIMITS["min_length"], unit='LENGTH',
           cli_default="the World's AO distance, as Cycles uses it (10 without a World; a "
                       "World's 0, with which Cycles sees no AO, is refused)"),
    Option("samples", "int", 64, "Samples", "Rays per face corner for the ray-traced method, "
           "as Cycles' bake counts samples: the bake casts Cycles' rays (a vertex on k faces "
           "k times this many, a texel this many), spread evenly over the vertices",
           min=1, max=65536, soft_max=1024),
    Option("time_budget", "float", 2.0, "Time Budget",
           "Auto: seconds the bake may take; models predicted to take longer are not chosen; "
           "rays are weighed at every halving of the samples down to 4 (0 = no limit)",
           min=0.0, unit='TIME'),
    Option("target_rmse", "float", 0.06, "Target Error",
           "Auto: stop climbing the ladder once a rung's RMSE on the ray-traced sample is below "
           "this (0.06 is about an MAE of 0.05, an error an artist does not see)",
           min=0.0, max=1.0, cli="--target-error"),
    Option("ray_free", "bool", False, "Ray-free",
           "Auto: only rungs that trace no rays beyond the calibration sample (up to the "
           "regression rung), so the bake costs the same whatever the leaf count"),
    Option("shells", "int", 4, "Shells", "Ellipsoid shells per tree for the shells and leaf "
           "medium methods (k-means clusters)", min=1, max=64, advanced=True),
    Option("trim", "float", 0.0, "Trim", "Fraction of the canopy's points left out of the "
           "fits as outliers", min=0.0, max=0.5, max_exclusive=True, advanced=True),
    Option("calibration_points", "int", 256, "Calibration Points",
           "Receiver points traced to calibrate τ and choose a rung", min=16, max=1 << 20,
           advanced=True),
    Option("calibration_samples", "int", 128, "Calibration Samples",
           "Rays per calibration point", min=1, max=65536, advanced=True),
    Option("seed", "int", 0, "Seed", "Seed of the calibration sample, the k-means shells and "
           "the rays", min=0, max=2**31 - 1, advanced=True),
    Option("forest_epsilon", "float", 1e-2, "Forest Cut-off",
           "Instanced trees: an instance's shell is ignored where it would block less than "
           "this (Shanmugam-Arikan Eq. 5); 1e-2 keeps a ground vertex under 10,000 trees to "
           "~1000 occluders at a cost of < 0.08 AO", min=0.0, max=1.0, max_exclusive=True,
           advanced=True),
    # --- what the bake writes (Blender) ---
    Option("use_world_distance", "bool", True, "From World",
           "Use the World's AO distance (World > Ambient Occlusion > Distance), as Cycles' AO "
           "bake does, so the bake and a Cycles check agree at any scale (command line: when "
           "--distance is not given)", group="output", cli=None),
    Option("mode", "enum", "VERTEX", "Output", "A color attribute per vertex, or an image in "
           "the UV layout", group="output",
           items=(("VERTEX", "Per Vertex", "A color attribute"),
                  ("TEXEL", "Per Texel", "An image in the UV layout"))),
    Option("attribute", "str", "CanopyAO", "Attribute",
           "Color attribute (POINT, FLOAT_COLOR) to write", group="output"),
    Option("overwrite", "bool", False, "Overwrite",
           "Replace an attribute or image file of this name that Canopy AO did not make (or "
           "that was changed since it wrote it)", group="output"),
    Option("channel", "enum", "RGBA", "Channel",
           "Write the AO as grey (R, G, B, alpha 1) into an attribute or image of its own, or "
           "into one channel of an existing color attribute (Attribute) or image (Pack Image), "
           "leaving its other channels exactly as they were (choosing a channel is the ask to "
           "write into an attribute Canopy AO did not make)", group="output",
           items=(("RGBA", "Grey", "AO in R, G and B, alpha 1"),
                  ("R", "R", "AO in the red channel only"),
                  ("G", "G", "AO in the green channel only"),
                  ("B", "B", "AO in the blue channel only"),
                  ("A", "A", "AO in the alpha channel only"))),
    Option("pack_image", "str", "", "Pack Image",
           "Texel mode with a channel: the Blender image (square, Resolution texels) whose "
           "channel gets the AO; saved to its file if it has one", group="output"),
    Option("packing", "enum", "NONE", "Packing",
           "Pack the AO where an engine reads it, into one channel of an existing image (Pack "
           "Image, per texel) or color attribute (Attribute, per vertex), the other channels "
           "untouched: it sets Channel (core/packing.py)", group="output",
           items=(("NONE", "None", "Channel as set"),
                  ("ORM", "glTF / Unreal ORM", "AO in R, beside roughness (G) and metallic (B)"),
                  ("HDRP_MASK", "Unity HDRP Mask", "AO in G of a mask map (metallic R, "
                                                  "detail B, smoothness A)"))),
    Option("gltf", "bool", False, "For glTF",
           "Make Blender's glTF exporter export the AO: per texel, the image wired into a "
           "'glTF Material Output' node group's Occlusion input in each material "
           "(occlusionTexture, from the AO's channel); per vertex, the attribute made the "
           "render color attribute (COLOR_0; export with Use Vertex Color: Active, or "
           "Colors in Blender 3.x)", group="output"),
    Option("thickness", "bool", False, "Canopy Thickness",
           "Also bake how deep each point lies in its tree's canopy (0 on the fitted crown "
           "ellipsoid's surface, 1 at its centre, scale-free; τ times it is the optical depth "
           "out along its radius) into a grey attribute or image, and, with Wire "
           "Material, a render pass", group="output"),
    Option("thickness_name", "str", "CanopyThickness", "Thickness Name",
           "The thickness's attribute (per vertex), image name suffix (per texel) and AOV",
           group="output"),
    Option("bent_normals", "enum", "OFF", "Bent Normals",
           "Also bake each point's bent normal, the cosine-weighted mean unoccluded direction "
           "(ray-traced at Samples rays, whichever method lit the AO), encoded as colour "
           "0.5 + 0.5·n into an attribute or RGB image: in world space, or in the tangent space "
           "of the UV map (tangent, bitangent, normal as Blender's normal maps; needs UVs)",
           group="output",
           items=(("OFF", "Off", "No bent normals"),
                  ("WORLD", "World", "World-space bent normals"),
                  ("TANGENT", "Tangent", "Tangent-space bent normals (UV map's tangents)"))),
    Option("bent_normals_name", "str", "CanopyBentNormal", "Bent Normals Name",
           "The bent normals' attribute (per vertex) and image name suffix (per texel)",
           group="output"),
    Option("uv_map", "str", "", "UV Map", "Texel mode: UV map (empty = the active one)",
           group="output", cli="--uv"),
    Option("resolution", "int", 1024, "Resolution", "Texel mode: image size in texels",
           group="output", min=1, max=16384),
    # 2: four points stratify the footprint (Cycles' own texel bake jitters its samples over
    # it), each still with a quarter of the rays; memory and per-point setup grow as N².
    Option("texel_aa", "int", 2, "Anti-Aliasing",
           "Texel mode: each texel is the mean of N×N points spread over its footprint, its "
           "Samples rays dealt out over them (Samples per texel, rounded up to a multiple of "
           "N²; 1 = the texel centre alone)", group="output", min=1, max=8,
           cli="--anti-aliasing"),
    Option("margin", "int", 16, "Margin",
           "Texel mode: texels each UV island's colour is extended past its edge (dilation), "
           "so mip-maps and filtering do not bleed the background in; 16 as Blender's bake",
           group="output", min=0, max=1024),
    Option("udim", "bool", False, "UDIM Tiles",
           "Texel mode: bake every UDIM tile the UVs use (tile 1001 + u + 10 v), one EXR per "
           "tile with its own margin, loaded as one tiled image (<UDIM> in its file name)",
           group="output"),
    Option("atlas", "str", "", "Atlas",
           "Texel mode: bake every object into one image of this name, for objects sharing "
           "one UV atlas; texels two objects claim are reported (empty = an image per object)",
           group="output"),
    Option("image_dir", "str", "//canopy_ao", "Image Folder", "Texel mode: output folder "
           "('//' = beside the .blend; {blend} stands for the .blend file's name, a folder per "
           ".blend file when several share one)", group="output", subtype='DIR_PATH'),
    Option("image_format", "enum", "EXR", "Image Format",
           "Texel mode: the image files' format (AO, thickness, bent normals, UDIM tiles, "
           "atlas), values stored linearly (AO is data: Non-Color in Blender, no sRGB "
           "encoding)", group="output",
           items=(("EXR", "OpenEXR Float", "32-bit float EXR (exact)"),
                  ("EXR_HALF", "OpenEXR Half", "16-bit float EXR (within 1/4096)"),
                  ("PNG", "PNG 8-bit", "8-bit PNG (within 1/510)"),
                  ("PNG16", "PNG 16-bit", "16-bit PNG (within 1/131070)"),
                  ("TGA", "Targa 8-bit", "8-bit TGA (TGA's 16-bit mode is 5-5-5-1 colour, "
                   "coarser than 8-bit grey)"))),
    Option("show_proxies", "bool", True, "Show Proxies", "Show the fitted shells as empties "
           "in a 'Canopy AO Proxies' collection", group="output", cli="--no-proxies"),
    Option("wire_material", "bool", False, "Wire Material",
           "Connect the baked result into the objects' materials", group="output"),
    Option("add_aov", "bool", False, "Add AOV",
           "Add a shader AOV output and a view-layer AOV", group="output", cli=None),
    Option("aov_name", "str", "BakedAO", "AOV Name", "Name of the AOV ('AO' would collide "
           "with Cycles' own AO pass); on the command line, --aov NAME also adds it",
           group="output", cli="--aov", cli_enables="add_aov"),
    Option("check_cycles", "bool", False, "Check with Cycles",
           "Also bake Cycles AO and report the error per object (slow)", group="output"),
    Option("cycles_samples", "int", 64, "Cycles Samples", "Samples of the Cycles check",
           group="output", min=1, max=65536, soft_max=4096),
    Option("live", "bool", False, "Live (Animation)",
           "Re-evaluate the AO on every frame change (playback and renders) with the rung and "
           "τ of the first bake, the proxies refitted to the deformed leaves; analytic rungs "
           "and per-vertex output only (blender/live.py)", group="output"),
)
BY_NAME = {o.name: o for o in OPTIONS}


def defaults() -> dict:
    """Every option's default, by name."""
    return {o.name: o.default for o in OPTIONS}


BakeSettings = dataclasses.make_dataclass(
    "BakeSettings",
    [(o.name, object, dataclasses.field(default=o.default)) for o in OPTIONS
     if o.group == "bake"],
    namespace={"__module__": __name__,
               "__doc__": "How the AO is computed: one field per 'bake' option of "
                          "settings.OPTIONS (see each one's help there)."})


def validate(settings) -> None:
    """Check every field of a BakeSettings against its option; raises CanopyAOError."""
    for o in OPTIONS:
        if o.group == "bake":
            setattr(settings, o.name, o.check(getattr(settings, o.name)))
