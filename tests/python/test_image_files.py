"""core/image_files.py, the image writer and reader of the portable module (no OpenImageIO):
every format the add-on writes holds the same codes whichever writer wrote it, each reader reads
the other's files to the same codes, and the header attributes round-trip (docs/PORTABILITY.md,
'Images')."""
import json

import numpy as np
import pytest

from canopy_ao import _core
from canopy_ao.core import image_files
from canopy_ao.core.image_formats import FORMATS, quantised, stored

oiio = pytest.mark.skipif(not hasattr(_core, "write_image"),
                          reason="this module has no OpenImageIO (the portable build)")
RECORD = json.dumps({"owner": "Tree é", "map": "CanopyAO", "pixels": "0123abcd"})


def pixels(shape, seed=0):
    """Values across [-0.1, 1.1] (clamped by the integer formats), with exact 0 and 1."""
    px = np.random.default_rng(seed).uniform(-0.1, 1.1, shape).astype(np.float32)
    px.reshape(-1)[:2] = [0.0, 1.0]
    return px


def attrs(fmt, digest="canopy_ao:" + "ab" * 16):
    return ({"canopy_ao": RECORD} if FORMATS[fmt].record == "attribute"
            else {"ImageDescription": digest})


CASES = [(fmt, c) for fmt in FORMATS for c in (1, 3, 4)]
# The add-on writes grey (AO) and RGB (bent normals). RGBA in PNG and TGA is not compared:
# OpenImageIO premultiplies those colours by alpha when it reads them.
SHARED = [(fmt, c) for fmt, c in CASES if c < 4 or FORMATS[fmt].ext == ".exr"]


@pytest.mark.parametrize("fmt,c", CASES)
def test_round_trip_keeps_codes_and_record(tmp_path, fmt, c):
    shape = (7, 5) if c == 1 else (7, 5, c)  # H != W: a transposition would show
    img = quantised(pixels(shape), fmt)
    path = str(tmp_path / ("a" + FORMATS[fmt].ext))
    image_files.write_image(path, img, dtype=FORMATS[fmt].dtype, attributes=attrs(fmt))
    back = image_files.read_image(path)
    assert back.shape == (7, 5, c) and back.dtype == np.float32
    np.testing.assert_array_equal(stored(back, fmt), stored(img.reshape(7, 5, c), fmt))
    got = image_files.read_image_attributes(path)
    for k, v in attrs(fmt).items():
        assert got[k] == v


@oiio
@pytest.mark.parametrize("fmt,c", SHARED)
def test_same_codes_as_openimageio_both_ways(tmp_path, fmt, c):
    """A file of either writer reads back, with either reader, as the same codes."""
    shape = (33, 18) if c == 1 else (33, 18, c)
    img = quantised(pixels(shape, seed=c), fmt)
    ext, dtype = FORMATS[fmt].ext, FORMATS[fmt].dtype
    ours, theirs = str(tmp_path / ("ours" + ext)), str(tmp_path / ("theirs" + ext))
    image_files.write_image(ours, img, dtype=dtype, attributes=attrs(fmt))
    _core.write_image(theirs, img, dtype=dtype, attributes=attrs(fmt))
    want = stored(img.reshape(33, 18, c), fmt)
    for path in (ours, theirs):
        for read in (image_files.read_image, _core.read_image):
            np.testing.assert_array_equal(stored(read(path), fmt), want, err_msg=f"{read} {path}")
        for read in (image_files.read_image_attributes, _core.read_image_attributes):
            got = read(path)
            assert all(got.get(k) == v for k, v in attrs(fmt).items()), (read, path, got)


@oiio
def test_reads_openimageio_png_filters_and_compressed_exr(tmp_path):
    """OpenImageIO's PNGs use every row filter and its EXRs are compressed: a smooth image with
    noise makes libpng pick Sub, Up, Average and Paeth."""
    y, x = np.mgrid[0:64, 0:96].astype(np.float32)
    img = np.stack([x / 96, y / 64, (x + y) / 160], -1) + pixels((64, 96, 3), 5) * 0.05
    for fmt in ("PNG", "PNG16", "EXR", "EXR_HALF"):
        img_q = quantised(img, fmt)
        path = str(tmp_path / f"{fmt}{FORMATS[fmt].ext}")
        _core.write_image(path, img_q, dtype=FORMATS[fmt].dtype)
        np.testing.assert_array_equal(stored(image_files.read_image(path), fmt), stored(img_q, fmt))


def test_bad_input_is_a_clear_error(tmp_path):
    good = np.zeros((2, 2), np.float32)
    with pytest.raises(ValueError, match="float32"):
        image_files.write_image(str(tmp_path / "a.exr"), good.astype(np.float64))
    with pytest.raises(ValueError, match="finite"):
        image_files.write_image(str(tmp_path / "a.exr"), np.full((2, 2), np.nan, np.float32))
    with pytest.raises(ValueError, match="half's range"):
        image_files.write_image(str(tmp_path / "a.exr"), good + 1e5, dtype="half")
    with pytest.raises(ValueError, match="tga files hold uint8, not uint16"):
        image_files.write_image(str(tmp_path / "a.tga"), good, dtype="uint16")
    (tmp_path / "b.png").write_bytes(b"not an image")
    with pytest.raises(ValueError, match="no EXR, PNG or TGA"):
        image_files.read_image(str(tmp_path / "b.png"))


def _png_filtered(codes, filters):
    """A PNG of uint8 codes (H, W, C) whose row y uses filter filters[y % len] (the PNG
    specification's encoder, written independently of the reader)."""
    import struct
    import zlib
    h, w, c = codes.shape
    rows, prev = [], [0] * (w * c)
    for y in range(h):
        line, f = codes[y].reshape(-1).tolist(), filters[y % len(filters)]
        out = []
        for i, x in enumerate(line):
            a = line[i - c] if i >= c else 0
            b, cc = prev[i], prev[i - c] if i >= c else 0
            pa, pb, pc = abs(b - cc), abs(a - cc), abs(a + b - 2 * cc)
            pred = [0, a, b, (a + b) >> 1,
                    a if pa <= pb and pa <= pc else (b if pb <= pc else cc)][f]
            out.append((x - pred) & 0xFF)
        rows.append(bytes([f] + out))
        prev = line

    def chunk(kind, body):
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
            + chunk(b"tEXt", b"canopy_ao\0" + RECORD.encode("ascii", "replace"))
            + chunk(b"IDAT", zlib.compress(b"".join(rows))) + chunk(b"IEND", b""))


def test_reads_every_png_row_filter(tmp_path):
    codes = np.random.default_rng(9).integers(0, 256, (10, 7, 3), dtype=np.uint8)
    path = tmp_path / "f.png"
    path.write_bytes(_png_filtered(codes, [0, 1, 2, 3, 4]))
    got = image_files.read_image(str(path), bottom_up=False)
    np.testing.assert_array_equal(stored(got, "PNG"), codes)
    assert image_files.read_image_attributes(str(path))["canopy_ao"] == RECORD.encode(
        "ascii", "replace").decode("latin-1")


@pytest.mark.parametrize("fmt", ["EXR", "PNG", "TGA"])
def test_a_damaged_file_is_a_value_error_naming_it(tmp_path, fmt):
    path = str(tmp_path / ("a" + FORMATS[fmt].ext))
    image_files.write_image(path, pixels((6, 6)), dtype=FORMATS[fmt].dtype,
                            attributes=attrs(fmt))
    with open(path, "rb") as f:
        data = f.read()
    with open(path, "wb") as f:
        f.write(data[:40])  # into the header or the pixels
    with pytest.raises(ValueError, match="a" + FORMATS[fmt].ext):
        image_files.read_image(path)


def test_a_module_without_openimageio_is_complete_and_files_come_from_here():
    """The portable module lacks only the image-file functions: the add-on loads it (not
    'rebuild') and takes this module's instead."""
    from canopy_ao.core import native
    names = ("write_image", "read_image", "read_image_attributes")
    portable = type("Portable", (), {k: getattr(_core, k) for k in dir(_core)
                                     if not k.startswith("__") and k not in names})
    assert native.missing_functions(portable) == []
    assert image_files.functions(portable) == tuple(getattr(image_files, k) for k in names)
    if hasattr(_core, "write_image"):
        assert image_files.functions(_core) == tuple(getattr(_core, k) for k in names)
