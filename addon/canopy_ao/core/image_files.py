"""Image files without OpenImageIO, no bpy (docs/PORTABILITY.md, 'Images'): the writer and
reader the portable module (built without OpenImageIO) leaves to Python. They store the same
codes as ``_core.write_image`` (image_formats.codes) and read what either writes, so a texel
bake's file holds the same pixels with either module:

- EXR: scanline, uncompressed on write; read uncompressed, ZIPS and ZIP (OpenImageIO's
  default); channels "Y", "R G B" or "R G B A"; 32-bit float or half; string attributes;
- PNG: 8 or 16 bits, grey / RGB / RGBA, written unfiltered; read with any filter; tEXt,
  zTXt and iTXt text as attributes;
- TGA: 8 bits, grey / BGR / BGRA, uncompressed on write (RLE read); the TGA 2.0 comment is
  the attribute "ImageDescription".

``write_image``, ``read_image`` and ``read_image_attributes`` take the arguments of the
module's functions of those names and raise ValueError (bad input) or OSError (the file)."""

import os
import struct
import zlib

import numpy as np

from .image_formats import SCALE, codes

_EXR_MAGIC = b"\x76\x2f\x31\x01"
_EXR_TYPES = {"float": (2, np.dtype("<f4")), "half": (1, np.dtype("<f2"))}
_EXR_LINES = {0: 1, 2: 1, 3: 16}  # NONE, ZIPS, ZIP: scanlines per chunk
_PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
_NAMES = {1: ["Y"], 3: ["R", "G", "B"], 4: ["R", "G", "B", "A"]}


def _ext(path):
    return os.path.splitext(os.fsdecode(path))[1].lower()


def write_image(path, pixels, dtype="auto", bottom_up=True, attributes=None):
    px = np.asarray(pixels)
    if px.dtype != np.float32:
        raise ValueError(f"pixels must be float32, got {px.dtype}")
    if px.ndim == 2:
        px = px[:, :, None]
    if px.ndim != 3 or px.shape[2] not in _NAMES or 0 in px.shape:
        raise ValueError(f"pixels must have shape (H, W) or (H, W, C) with C in 1, 3, 4, got "
                         f"{np.shape(pixels)}")
    if not np.all(np.isfinite(px)):
        raise ValueError("pixels has NaN or inf values: images must be finite")
    ext = _ext(path)
    dtype = dtype if dtype != "auto" else {".exr": "float", ".png": "uint16"}.get(ext, "uint8")
    allowed = {".exr": ("float", "half"), ".png": ("uint8", "uint16"), ".tga": ("uint8",)}
    if dtype not in allowed.get(ext, ()):
        raise ValueError(f"cannot write '{path}': {ext or 'no extension'} files hold "
                         f"{', '.join(allowed.get(ext, ())) or 'nothing this writer knows'}, "
                         f"not {dtype}")
    if dtype == "half" and np.abs(px).max() > 65504.0:
        raise ValueError("pixels has values outside half's range +-65504")
    attributes = dict(attributes or {})
    top = np.ascontiguousarray(px[::-1] if bottom_up else px)  # row 0 = top of the file
    with open(path, "wb") as f:
        if ext == ".exr":
            f.write(_exr(top, dtype, attributes))
        elif ext == ".png":
            f.write(_png(codes(top, dtype), attributes))
        else:
            f.write(_tga(codes(top, dtype), attributes.get("ImageDescription", "")))


def _exr(top, dtype, attributes):
    h, w, c = top.shape
    kind, np_type = _EXR_TYPES[dtype]
    names = _NAMES[c]
    order = sorted(range(c), key=lambda i: names[i])  # EXR stores channels by name
    chlist = b"".join(names[i].encode() + b"\0" + struct.pack("<iB3xii", kind, 0, 1, 1)
                      for i in order) + b"\0"
    box = struct.pack("<4i", 0, 0, w - 1, h - 1)

    def attr(name, type_, value):
        return name.encode() + b"\0" + type_.encode() + b"\0" + struct.pack("<i", len(value)) + value
    head = [attr("channels", "chlist", chlist), attr("compression", "compression", b"\0"),
            attr("dataWindow", "box2i", box), attr("displayWindow", "box2i", box),
            attr("lineOrder", "lineOrder", b"\0"),
            attr("pixelAspectRatio", "float", struct.pack("<f", 1.0)),
            attr("screenWindowCenter", "v2f", struct.pack("<2f", 0, 0)),
            attr("screenWindowWidth", "float", struct.pack("<f", 1.0))]
    for name, value in attributes.items():
        head.append(attr(name, "string", value.encode("utf-8")))
    header = _EXR_MAGIC + struct.pack("<i", 2) + b"".join(head) + b"\0"
    data = top[:, :, order].astype(np_type).transpose(0, 2, 1)  # (H, C, W): a line's channels
    line = 8 + data[0].nbytes
    start = len(header) + 8 * h
    offsets = np.arange(h, dtype="<u8") * line + start
    chunks = b"".join(struct.pack("<ii", y, data[y].nbytes) + data[y].tobytes() for y in range(h))
    return header + offsets.tobytes() + chunks


def _png(top_codes, attributes):
    h, w, c = top_codes.shape
    depth = 8 * top_codes.dtype.itemsize
    rows = top_codes.astype(f">u{top_codes.dtype.itemsize}").reshape(h, -1).view(np.uint8)
    raw = np.hstack([np.zeros((h, 1), np.uint8), rows]).tobytes()  # filter 0 on every row

    def chunk(kind, body):
        return struct.pack(">I", len(body)) + kind + body + struct.pack(
            ">I", zlib.crc32(kind + body) & 0xFFFFFFFF)
    out = [_PNG_MAGIC, chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, depth,
                                                  {1: 0, 3: 2, 4: 6}[c], 0, 0, 0))]
    for name, value in attributes.items():
        out.append(chunk(b"iTXt", name.encode("latin-1") + b"\0\0\0\0\0" + value.encode()))
    out += [chunk(b"IDAT", zlib.compress(raw, 6)), chunk(b"IEND", b"")]
    return b"".join(out)


def _tga(top_codes, comment):
    h, w, c = top_codes.shape
    px = top_codes[::-1]  # bottom-left origin: rows bottom first
    if c >= 3:
        px = px[:, :, [2, 1, 0, 3][:c]]  # BGR(A)
    header = struct.pack("<BBBHHBHHHHBB", 0, 0, 3 if c == 1 else 2, 0, 0, 0, 0, 0, w, h,
                         8 * c, 8 if c == 4 else 0)
    ext = bytearray(495)
    ext[0:2] = struct.pack("<H", 495)
    text = comment.encode("latin-1", "replace")[:4 * 80]
    for i in range(4):  # four lines of 80 characters and a NUL
        ext[43 + 81 * i:43 + 81 * i + 80] = text[80 * i:80 * (i + 1)].ljust(80, b"\0")
    body = header + np.ascontiguousarray(px).tobytes()
    return body + bytes(ext) + struct.pack("<II", len(body), 0) + b"TRUEVISION-XFILE.\0"


def _damaged(read):
    """A file cut short or garbled is a ValueError naming it, never another exception."""
    def checked(path, *args, **kwargs):
        try:
            return read(path, *args, **kwargs)
        except (struct.error, IndexError, KeyError, StopIteration, zlib.error, ValueError) as exc:
            if isinstance(exc, ValueError) and f"'{path}'" in str(exc):
                raise
            raise ValueError(f"'{path}' is damaged or not an image this reader knows "
                             f"({type(exc).__name__}: {exc})") from exc
    return checked


def functions(module):
    """(write_image, read_image, read_image_attributes): the native module's (OpenImageIO)
    when it has them, else this module's."""
    return tuple(getattr(module, name, globals()[name])
                 for name in ("write_image", "read_image", "read_image_attributes"))


@_damaged
def read_image(path, bottom_up=True):
    with open(path, "rb") as f:
        data = f.read()
    if data.startswith(_EXR_MAGIC):
        top, _ = _read_exr(data, path)
    elif data.startswith(_PNG_MAGIC):
        top = _read_png(data, path)
    elif _ext(path) == ".tga":
        top = _read_tga(data, path)
    else:
        raise ValueError(f"'{path}' is no EXR, PNG or TGA file")
    return np.ascontiguousarray(top[::-1] if bottom_up else top, np.float32)


@_damaged
def read_image_attributes(path):
    with open(path, "rb") as f:
        data = f.read()
    if data.startswith(_EXR_MAGIC):
        return _read_exr(data, path, pixels=False)[1]
    if data.startswith(_PNG_MAGIC):
        return {k.decode("latin-1"): v for k, v in _png_text(data)}
    if _ext(path) == ".tga":
        return _tga_comment(data)
    raise ValueError(f"'{path}' is no EXR, PNG or TGA file")


def _cstr(data, pos):
    end = data.index(b"\0", pos)
    return data[pos:end].decode("latin-1"), end + 1


def _read_exr(data, path, pixels=True):
    """(pixels (H, W, C) top row first, or None; {name: value} of the string attributes)."""
    if struct.unpack_from("<i", data, 4)[0] & 0x1A00:  # tiled, deep or multi-part
        raise ValueError(f"'{path}' is a tiled, deep or multi-part EXR, read only by OpenImageIO")
    pos, attrs = 8, {}
    while data[pos] != 0:
        name, pos = _cstr(data, pos)
        kind, pos = _cstr(data, pos)
        (size,) = struct.unpack_from("<i", data, pos)
        attrs[name] = (kind, data[pos + 4:pos + 4 + size])
        pos += 4 + size
    strings = {k: v.decode("utf-8", "replace") for k, (t, v) in attrs.items() if t == "string"}
    if not pixels:
        return None, strings
    channels, cpos, chlist = [], 0, attrs["channels"][1]
    while chlist[cpos] != 0:
        name, cpos = _cstr(chlist, cpos)
        channels.append((name, np.dtype(["<u4", "<f2", "<f4"][struct.unpack_from("<i", chlist, cpos)[0]])))
        cpos += 16
    compression = attrs["compression"][1][0]
    if compression not in _EXR_LINES:
        raise ValueError(f"'{path}': EXR compression {compression} is read only by OpenImageIO")
    x0, y0, x1, y1 = struct.unpack("<4i", attrs["dataWindow"][1])
    w, h, lines = x1 - x0 + 1, y1 - y0 + 1, _EXR_LINES[compression]
    out = {name: np.empty((h, w), np.float32) for name, _ in channels}
    line_bytes = sum(w * dt.itemsize for _, dt in channels)
    offsets = np.frombuffer(data, "<u8", -(-h // lines), pos + 1)
    for off in offsets.tolist():
        y, size = struct.unpack_from("<ii", data, off)
        n = min(lines, y1 + 1 - y)
        raw = data[off + 8:off + 8 + size]
        if size < n * line_bytes:
            raw = _exr_unzip(raw)
        p = 0
        for row in range(y - y0, y - y0 + n):
            for name, dt in channels:
                out[name][row] = np.frombuffer(raw, dt, w, p)
                p += w * dt.itemsize
    names = [name for name, _ in channels]
    order = next((o for o in _NAMES.values() if sorted(o) == sorted(names)), names)
    return np.stack([out[name] for name in order], -1), strings


def _exr_unzip(raw):
    """A ZIP/ZIPS chunk's bytes: inflated, the byte predictor undone, the halves interleaved."""
    t = np.frombuffer(zlib.decompress(raw), np.uint8).astype(np.int64)
    t[1:] -= 128
    d = (np.cumsum(t) & 0xFF).astype(np.uint8)
    out = np.empty_like(d)
    half = (len(d) + 1) // 2
    out[0::2], out[1::2] = d[:half], d[half:]
    return out.tobytes()


def _png_chunks(data):
    pos = 8
    while pos + 8 <= len(data):
        n, kind = struct.unpack_from(">I4s", data, pos)
        yield kind, data[pos + 8:pos + 8 + n]
        pos += 12 + n
        if kind == b"IEND":
            return


def _png_text(data):
    for kind, body in _png_chunks(data):
        key, _, rest = body.partition(b"\0")
        if kind == b"tEXt":
            yield key, rest.decode("latin-1")
        elif kind == b"zTXt":
            yield key, zlib.decompress(rest[1:]).decode("latin-1")
        elif kind == b"iTXt":
            compressed, text = rest[0], rest[2:].split(b"\0", 2)[-1]
            yield key, (zlib.decompress(text) if compressed else text).decode("utf-8", "replace")


def _read_png(data, path):
    ihdr = next(body for kind, body in _png_chunks(data) if kind == b"IHDR")
    w, h, depth, ctype, _, _, interlace = struct.unpack(">IIBBBBB", ihdr)
    c = {0: 1, 2: 3, 4: 2, 6: 4}.get(ctype)
    if c is None or depth not in (8, 16) or interlace:
        raise ValueError(f"'{path}': a PNG of colour type {ctype}, {depth} bits"
                         f"{', interlaced' if interlace else ''} is read only by OpenImageIO")
    idat = b"".join(body for kind, body in _png_chunks(data) if kind == b"IDAT")
    bpp = c * depth // 8
    rows = np.frombuffer(zlib.decompress(idat), np.uint8).reshape(h, w * bpp + 1)
    out = np.empty((h, w * bpp), np.uint8)
    prev = np.zeros(w * bpp, np.uint8)
    for y in range(h):
        f, line = rows[y, 0], rows[y, 1:]
        if f == 0:
            cur = line
        elif f == 1:  # Sub: a running sum per byte of a pixel
            cur = (np.cumsum(line.reshape(w, bpp), axis=0, dtype=np.int64) & 0xFF).astype(np.uint8).ravel()
        elif f == 2:  # Up
            cur = line + prev
        elif f in (3, 4):  # Average, Paeth: byte after byte
            cur = _unfilter(f, line.tolist(), prev.tolist(), bpp)
        else:
            raise ValueError(f"'{path}': PNG row filter {f} does not exist")
        out[y] = cur
        prev = out[y]
    px = out.view(">u2" if depth == 16 else np.uint8).reshape(h, w, c)
    return px.astype(np.float32) / np.float32(SCALE["uint16" if depth == 16 else "uint8"])


def _unfilter(f, line, prev, bpp):
    cur = [0] * len(line)
    for i, x in enumerate(line):
        a, b = (cur[i - bpp], prev[i]) if i >= bpp else (0, prev[i])
        if f == 3:
            p = (a + b) >> 1
        else:
            c = prev[i - bpp] if i >= bpp else 0
            pa, pb, pc = abs(b - c), abs(a - c), abs(a + b - 2 * c)
            p = a if pa <= pb and pa <= pc else (b if pb <= pc else c)
        cur[i] = (x + p) & 0xFF
    return np.array(cur, np.uint8)


def _read_tga(data, path):
    idlen, cmap, kind, *_, w, h, depth, desc = struct.unpack_from("<BBBHHBHHHHBB", data)
    c = depth // 8
    if cmap or kind not in (2, 3, 10, 11) or c not in (1, 3, 4):
        raise ValueError(f"'{path}': a TGA of type {kind}, {depth} bits is read only by OpenImageIO")
    pos, n = 18 + idlen, w * h * c
    if kind in (2, 3):
        px = np.frombuffer(data, np.uint8, n, pos)
    else:  # run-length packets
        out = bytearray()
        while len(out) < n:
            head, pos = data[pos], pos + 1
            count = (head & 0x7F) + 1
            step = c if head & 0x80 else count * c
            out += data[pos:pos + c] * count if head & 0x80 else data[pos:pos + step]
            pos += step
        px = np.frombuffer(bytes(out[:n]), np.uint8)
    px = px.reshape(h, w, c)
    if c >= 3:
        px = px[:, :, [2, 1, 0, 3][:c]]
    if not desc & 0x20:  # bottom-left origin
        px = px[::-1]
    if desc & 0x10:
        px = px[:, ::-1]
    return px.astype(np.float32) / np.float32(SCALE["uint8"])


def _tga_comment(data):
    """{"ImageDescription": the TGA 2.0 extension area's comment} ({} when it has none)."""
    if len(data) < 44 or data[-18:] != b"TRUEVISION-XFILE.\0":
        return {}
    (ext,) = struct.unpack_from("<I", data, len(data) - 26)
    if not ext or ext + 367 > len(data):
        return {}
    text = data[ext + 43:ext + 367].split(b"\0")[0].decode("latin-1")
    return {"ImageDescription": text} if text else {}
