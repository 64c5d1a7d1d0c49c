"""The image file formats a texel bake writes (docs/DESIGN.md, 'Image formats'), no bpy.

Each format is an extension, the pixel type OpenImageIO stores (``_core.write_image``'s
dtype) and whether its header holds a string record. AO is data: every format stores the
values linearly (no sRGB encoding), and Blender loads the image as Non-Color.

``stored`` gives, for float pixels, the codes the file holds (float32, float16, uint16 or
uint8): quantising before writing makes the file hold exactly those codes, so the pixels'
fingerprint taken at write time matches the one taken of the file read back.
"""

from typing import NamedTuple

import numpy as np


class ImageFormat(NamedTuple):
    ext: str  # the file name's extension, with the dot
    dtype: str  # _core.write_image's dtype: "float", "half", "uint16" or "uint8"
    record: str  # how the header carries the ownership record: "attribute" or "digest"


# TGA's 16-bit mode is 5-5-5-1 colour (5 bits a channel, coarser than 8-bit grey), so TGA is
# 8-bit only. OpenImageIO's TGA writer keeps no custom attribute, only the 324-character
# comment ("ImageDescription"): it carries a digest of the record (files_io).
FORMATS = {
    "EXR": ImageFormat(".exr", "float", "attribute"),
    "EXR_HALF": ImageFormat(".exr", "half", "attribute"),
    "PNG": ImageFormat(".png", "uint8", "attribute"),
    "PNG16": ImageFormat(".png", "uint16", "attribute"),
    "TGA": ImageFormat(".tga", "uint8", "digest"),
}

_CODES = {"float": np.float32, "half": np.float16, "uint16": np.uint16, "uint8": np.uint8}
SCALE = {"uint16": 65535.0, "uint8": 255.0}


def codes(pixels, dtype):
    """The codes a file of pixel type dtype ("float", "half", "uint16", "uint8") holds for
    float pixels: float32 as given, float16 rounded to nearest, or
    round(clip(v, 0, 1) · (2^bits − 1)) as unsigned integers (values outside [0, 1] clamped)."""
    px = np.asarray(pixels, np.float32)
    if dtype in SCALE:
        return np.rint(np.clip(px, 0.0, 1.0) * SCALE[dtype]).astype(_CODES[dtype])
    return px.astype(_CODES[dtype])


def stored(pixels, fmt):
    """The codes a file of format fmt (a FORMATS key) holds for float pixels (codes)."""
    return codes(pixels, FORMATS[fmt].dtype)


def quantised(pixels, fmt):
    """float32 pixels equal to what a file of format fmt reads back as (codes scaled to
    [0, 1] for the integer formats): what write_image then stores exactly."""
    codes = stored(pixels, fmt)
    dtype = FORMATS[fmt].dtype
    out = codes.astype(np.float32)
    return out / np.float32(SCALE[dtype]) if dtype in SCALE else out
