"""Image files a bake writes (docs/DESIGN.md, 'Ownership of what a bake writes'): names no
other output shares, a header record saying whose output each file is with its pixels'
fingerprint, the checks that refuse a file that is not the bake's own (another output's, or
another .blend file's), written in the chosen format (core/image_formats.py) and replaced
atomically (atomic_io.py)."""

import json
import os
import tempfile
import uuid
from typing import NamedTuple

import bpy
import numpy as np

from ..core.fingerprint import fingerprint, name_digest
from ..core import image_files
from ..core.image_formats import FORMATS, quantised, stored
from ..core.native import CanopyAOError, _core
from .atomic_io import keep_file, remove_file, replace_file  # noqa: F401 (re-exported)

# OpenImageIO's image files where the module has it, else core/image_files.py's (the portable
# module): the same codes either way (docs/PORTABILITY.md, 'Images').
write_image, read_image, read_image_attributes = image_files.functions(_core)

# The header attribute of every EXR and PNG file Canopy AO writes: JSON {"owner": the object's
# (or atlas's) exact name, "map": the map's suffix, "tile": the UDIM number or null, "atlas",
# "blend": the owning .blend (blend_of), "format": the FORMATS key, "pixels": the stored codes'
# fingerprint}. A TGA keeps only its comment: "canopy_ao:" and a digest of that JSON
# (docs/DESIGN.md, 'Ownership of what a bake writes').
FILE_RECORD = "canopy_ao"


# In the Image Folder: the .blend file's name without '.blend' ("untitled" before it is
# saved), so .blend files sharing a folder each get their own images.
BLEND_TOKEN = "{blend}"


class Output(NamedTuple):
    """One image file of a bake: whose (an object's exact name, or an atlas's: atlas=True, so
    an object and an atlas of one name never share a file), which map, which UDIM tile (None:
    the one file of an untiled image)."""

    owner: str
    map: str = "CanopyAO"
    tile: int | None = None
    atlas: bool = False

    def __str__(self):
        return f"'{self.map}' of {'atlas ' if self.atlas else ''}'{self.owner}'"


def file_stem(name):
    """A file name (no extension) for the exact name ``name`` that no other name shares:
    Blender's clean name (letters, digits, '_') when cleaning keeps it as it is, else the
    clean name and a digest of the exact text, so 'Tree.001', 'Tree 001' and 'Tree_001' get
    three files."""
    clean = bpy.path.clean_name(name)
    return clean if clean == name else f"{clean}_{name_digest(name)}"


# On the scene of a .blend never saved: the name of its own folder in the temporary folder.
UNSAVED_KEY = "canopy_ao_unsaved_folder"


def unsaved_folder():
    """The images' folder of a .blend never saved: one of its own in the temporary folder
    (named by a token kept on the scene), so another unsaved file's bake, in this Blender or
    another, never replaces an image this file shows (their records both say 'unsaved') --
    one this file keeps showing once saved, until baked again beside it."""
    scene = bpy.context.scene
    token = scene.get(UNSAVED_KEY) if scene is not None else None
    if not (isinstance(token, str) and token.isalnum()):
        token = uuid.uuid4().hex[:16]
        if scene is not None:
            scene[UNSAVED_KEY] = token
    return os.path.join(tempfile.gettempdir(), "canopy_ao", token)


def image_path(obj, image_dir, notes, suffix="CanopyAO", make=True, fmt="EXR"):
    """Where obj's image file of format fmt (core/image_formats.FORMATS) goes (the folder is
    made unless make=False); a note says when it is a temporary one. obj: anything with a
    name (an atlas's is its own)."""
    fname = file_stem(f"{obj.name}_{suffix}") + FORMATS[fmt].ext
    if image_dir and BLEND_TOKEN in image_dir:  # a folder of each .blend file's own
        stem = os.path.splitext(os.path.basename(bpy.data.filepath))[0] or "untitled"
        image_dir = image_dir.replace(BLEND_TOKEN, stem)
    if image_dir:
        if image_dir.startswith("//") and not bpy.data.filepath:
            d = unsaved_folder()
            notes.append(f"'{image_dir}' is relative to the .blend, which is not saved yet; "
                         f"the image went to {d} (bake again once the .blend is saved)")
        else:
            d = bpy.path.abspath(image_dir)
    elif bpy.data.filepath:
        d = os.path.dirname(bpy.data.filepath)
    else:
        d = unsaved_folder()
        notes.append(f"the .blend is not saved yet; the image went to {d} (bake again once "
                     "the .blend is saved)")
    if os.sep == "/" and "\\" in d:  # a letter here, a separator when Blender loads the image
        raise CanopyAOError(f"the image folder '{d}' holds a backslash, which Blender reads as "
                            "a folder separator, so it could not load the image written there; "
                            "choose a folder without one (nothing was changed)")
    try:
        if make:
            os.makedirs(d, exist_ok=True)
    except OSError as exc:
        raise CanopyAOError(f"Cannot create the image folder '{d}': {exc}; choose another "
                            "Image Folder") from exc
    return os.path.join(d, fname)


def tile_path(path, number):
    """The file of UDIM tile ``number`` of the image whose untiled file is path (name.exr →
    name.<number>.exr, Blender's <UDIM> pattern)."""
    stem, ext = os.path.splitext(path)
    return f"{stem}.{number}{ext}"


def format_of(path):
    """The FORMATS key a file's record is read by, from its extension (EXR and PNG: the
    record names the exact one), or None when no format writes that extension."""
    ext = os.path.splitext(path)[1].lower()
    return next((k for k, f in FORMATS.items() if f.ext == ext), None)


def blend_of(path):
    """The .blend that owns an image file written now at path: its path relative to the
    image's folder, links resolved ('/'-separated, so moving the project folder as a whole
    keeps it; absolute when no relative path exists, e.g. another drive), '' when the .blend
    is not saved."""
    blend = bpy.data.filepath
    if not blend:
        return ""
    try:
        rel = os.path.relpath(os.path.realpath(blend), os.path.dirname(os.path.realpath(path)))
    except ValueError:
        rel = os.path.realpath(blend)
    return os.path.normcase(rel).replace(os.sep, "/")


def _identity(path, output, fmt):
    """What a file's record says: whose output, which .blend's, which format."""
    return dict(output._asdict(), blend=blend_of(path), format=fmt)


def _digest(record):
    return "canopy_ao:" + name_digest(json.dumps(record, sort_keys=True), 32)


def write_file(path, img, output=None, fmt="EXR"):
    """Write a float image (H, W) (grey) or (H, W, C), row 0 = bottom, as format fmt (a
    FORMATS key): the writer flips rows so the file shows v = 1 on top, quantises to the
    format, and replaces path atomically (replace_file). output (an Output): the header
    records it, the .blend's and the pixels' fingerprint (FILE_RECORD), so a later bake knows
    the file as Canopy AO's."""
    img = quantised(np.ascontiguousarray(img, dtype=np.float32), fmt)
    f = FORMATS[fmt]
    attributes = None
    if output is not None:
        rec = dict(_identity(path, output, fmt), pixels=fingerprint(stored(img, fmt), "pixels"))
        attributes = ({FILE_RECORD: json.dumps(rec)} if f.record == "attribute"
                      else {"ImageDescription": _digest(rec)})

    def write(tmp):
        write_image(tmp, img, dtype=f.dtype, bottom_up=True, attributes=attributes)
    try:
        replace_file(path, write)
    except (OSError, RuntimeError) as exc:
        raise CanopyAOError(f"Could not write '{path}': {exc}") from exc


# Verdicts of file_record, keyed by the file's identity and state: a re-check of an unchanged
# file (the bake checks before it writes, and again when it writes) reads nothing.
_RECORDS = {}


def file_record(path):
    """The FILE_RECORD of an image file Canopy AO wrote and nobody changed since (its pixels
    still have the recorded fingerprint), else None: another program's file, an edited one,
    or one written before files carried a record. A TGA's is {"digest", "format", "pixels":
    the file's own codes' fingerprint}, for check_file to compare with the record it would
    write."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    key = (path, st.st_ino, st.st_size, st.st_mtime_ns)
    if key not in _RECORDS:
        if len(_RECORDS) > 4096:
            _RECORDS.clear()
        _RECORDS[key] = _read_record(path)
    return _RECORDS[key]


def _read_record(path):
    fmt = format_of(path)
    if fmt is None:
        return None
    try:
        attrs = read_image_attributes(path)
        if FORMATS[fmt].record == "digest":  # TGA: the digest; check_file compares it
            text = attrs.get("ImageDescription", "")
            if not text.startswith("canopy_ao:"):
                return None
            rec = {"digest": text.strip(), "format": fmt}
        else:
            rec = json.loads(attrs.get(FILE_RECORD, ""))
            if not isinstance(rec, dict) or not isinstance(rec.get("pixels"), str):
                return None
            rec.setdefault("format", "EXR")  # records from before formats: float EXR
            if rec["format"] not in FORMATS or FORMATS[rec["format"]].ext != FORMATS[fmt].ext:
                return None
        px = read_image(path, bottom_up=True)
    except (ValueError, RuntimeError, OSError, TypeError):  # not an image, unreadable, no record
        return None
    # (H, W, C) as read holds the codes of the (H, W) or (H, W, C) array written.
    pixels = fingerprint(stored(px, rec["format"]), "pixels")
    if "digest" in rec:
        return dict(rec, pixels=pixels)
    return rec if pixels == rec["pixels"] else None


def _edited_image(path):
    """The Blender image showing the file path with changes not saved to it (painted in
    Texture Paint, say), or None: a bake reloads its image from the file and they would go."""
    key = os.path.normcase(os.path.realpath(path))
    for img in bpy.data.images:
        if (img.source == 'FILE' and img.packed_file is None and img.is_dirty and img.filepath
                and os.path.normcase(os.path.realpath(bpy.path.abspath(
                    img.filepath, library=img.library))) == key):
            return img
    return None


def check_file(path, output, overwrite=False):
    """None when a bake may write path for output (an Output): no file there, Overwrite, or
    Canopy AO's own unchanged file of that same output written from this .blend, not edited in
    Blender since; else the reason it may not."""
    edited = None if overwrite else _edited_image(path)
    if edited is not None:
        return (f"the image '{edited.name}' shows '{path}' with changes not saved to it (painted "
                "in Blender?); tick Overwrite to replace them by the bake, or choose another "
                "Image Folder")
    if not os.path.lexists(path) or (overwrite and not os.path.isdir(path)):
        return None
    if os.path.isdir(path):
        return f"'{path}' is a folder; choose another Image Folder"
    rec = file_record(path)
    fix = (f"choose another Image Folder (e.g. '//canopy_ao/{BLEND_TOKEN}', a folder per .blend "
           "file) or tick Overwrite")
    if rec is None:
        return (f"'{path}' already exists and Canopy AO did not write it (or changed since, or "
                f"written by a Canopy AO whose files carried no record); {fix}")
    if "digest" in rec:  # a format that holds only a digest of the record (TGA)
        ours = dict(_identity(path, output, rec["format"]), pixels=rec["pixels"])
        if rec["digest"] != _digest(ours):
            return (f"'{path}' holds another Canopy AO output (another object's, map's or "
                    f".blend file's: a {rec['format']} file records only a digest); {fix}")
        return None
    theirs = Output(rec.get("owner"), rec.get("map"), rec.get("tile"), rec.get("atlas", False))
    if theirs != output:
        return f"'{path}' holds Canopy AO's {theirs}, not {output}; {fix}"
    if rec.get("blend") != blend_of(path):
        theirs = rec.get("blend")
        where = os.path.dirname(os.path.realpath(path))
        who = (f"the .blend file '{os.path.normpath(os.path.join(where, theirs))}'"
               if theirs and isinstance(theirs, str) else "an unsaved .blend file"
               if theirs == "" else
               "a .blend file it did not record (an older Canopy AO's file)")
        here = f"'{bpy.data.filepath}'" if bpy.data.filepath else "an unsaved one"
        return (f"'{path}' holds {output} baked from {who}, not from this .blend file "
                f"({here}), and that file's material may show it; {fix}")
    return None


def check_outputs(outputs, overwrite):
    """Refuse, before anything is written, a bake whose image files would collide or replace a
    file that is not its own: outputs [(path, Output)] of every target. Two outputs whose
    paths differ only in case collide too (one file on Windows and macOS)."""
    by_file = {}
    for path, output in outputs:
        key = os.path.normcase(os.path.abspath(path)).casefold()
        by_file.setdefault(key, {})[output] = path
    for claims in by_file.values():
        if len(claims) > 1:
            who = " and ".join(str(o) for o in claims)
            raise CanopyAOError(f"{who} would write the same file '{next(iter(claims.values()))}'"
                                " (a file system cannot tell their names apart, e.g. they "
                                "differ only in case); rename one (nothing was changed)")
        output, path = next(iter(claims.items()))
        why = check_file(path, output, overwrite)
        if why:
            raise CanopyAOError(why + " (nothing was changed)")


def write_own_file(path, img, txn, output, overwrite, fmt="EXR"):
    """Write img (H, W) to path as output (an Output) in format fmt, the old file's bytes
    kept in txn for a rollback; refused (CanopyAOError, nothing written) when path holds a
    file that is not this output's own and overwrite is off (check_file: the bake checked
    before it began, this is the last look)."""
    why = check_file(path, output, overwrite)
    if why:
        raise CanopyAOError(why)
    txn.add(keep_file(path))
    write_file(path, img, output, fmt)
