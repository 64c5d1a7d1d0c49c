"""A texel bake through the add-on's own image files (core/image_files.py), as with the
portable module, which has no OpenImageIO (docs/PORTABILITY.md, 'Images'): in every format the
image Blender loads holds the same pixels as after a bake through OpenImageIO, and each writer's
files are the other's own (a re-bake replaces them without Overwrite)."""

import os

import bpy
import numpy as np
import pytest

from canopy_ao import _core
from canopy_ao.blender import files_io
from canopy_ao.blender.job import run_bake
from canopy_ao.core import image_files
from test_maps import opts, tree  # noqa: F401 (tree: the fixture, a plane under leaves)

NATIVE = image_files.functions(_core)
PORTABLE = (image_files.write_image, image_files.read_image, image_files.read_image_attributes)
NAMES = ("write_image", "read_image", "read_image_attributes")
if NATIVE == PORTABLE:
    pytest.skip("this module has no OpenImageIO: nothing to compare with", allow_module_level=True)


def _bake(fmt, folder, functions, monkeypatch):
    """Bake Ground's texel AO into folder with these image-file functions; the pixels Blender
    loaded and the file's path."""
    for name, f in zip(NAMES, functions):
        monkeypatch.setattr(files_io, name, f)
    _, rep = run_bake(bpy.context, ["Ground"],
                      opts(mode='TEXEL', resolution=32, image_dir=folder, image_format=fmt))
    path = rep["objects"]["Ground"]["texel"]["path"]
    img = bpy.data.images["Ground_CanopyAO"]
    assert bpy.path.abspath(img.filepath) == path
    px = np.empty(img.size[0] * img.size[1] * img.channels, np.float32)
    img.pixels.foreach_get(px)
    return px, path


@pytest.mark.parametrize("fmt", ["EXR", "EXR_HALF", "PNG", "PNG16", "TGA"])
def test_bake_without_openimageio_loads_the_same_pixels(tree, fmt, monkeypatch):
    native_dir = os.path.join(tree["image_dir"], "native")
    own_dir = os.path.join(tree["image_dir"], "own")
    want, native_path = _bake(fmt, native_dir, NATIVE, monkeypatch)
    got, own_path = _bake(fmt, own_dir, PORTABLE, monkeypatch)
    assert want.min() < want.max()  # the leaves shade the ground
    np.testing.assert_array_equal(got, want)  # tolerance 0: the same stored codes
    with open(native_path, "rb") as a, open(own_path, "rb") as b:
        assert a.read() != b.read()  # two writers, one image
    # Each writer's file is the other's own: replaced without Overwrite, same pixels.
    again, _ = _bake(fmt, native_dir, PORTABLE, monkeypatch)
    np.testing.assert_array_equal(again, want)
    again, _ = _bake(fmt, own_dir, NATIVE, monkeypatch)
    np.testing.assert_array_equal(again, want)
