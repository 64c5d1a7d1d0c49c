"""Image files a bake writes (docs/DESIGN.md, 'Ownership of what a bake writes'): names no
other output shares, a header record saying whose output each file is with its pixels'
fingerprint, the checks that refuse a file that is not the bake's own, and the moved-aside
copy that lets a failed bake put the old file back."""

import json
import os
import tempfile
from typing import NamedTuple

import bpy
import numpy as np

from ..core.fingerprint import fingerprint, name_digest
from ..core.native import CanopyAOError, _core

# The header attribute of every image file Canopy AO writes: JSON {"owner": the object's (or
# atlas's) exact name, "map": the map's suffix, "tile": the UDIM number or null, "pixels": the
# pixels' fingerprint} (docs/DESIGN.md, 'Ownership of what a bake writes').
FILE_RECORD = "canopy_ao"


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


def image_path(obj, image_dir, notes, suffix="CanopyAO", make=True):
    """Where obj's EXR goes (the folder is made unless make=False); a note says when it is a
    temporary one. obj: anything with a name (an atlas's is its own)."""
    fname = file_stem(f"{obj.name}_{suffix}") + ".exr"
    if image_dir:
        if image_dir.startswith("//") and not bpy.data.filepath:
            d = os.path.join(tempfile.gettempdir(), "canopy_ao")
            notes.append(f"'{image_dir}' is relative to the .blend, which is not saved yet; "
                         f"the image went to {d}")
        else:
            d = bpy.path.abspath(image_dir)
    elif bpy.data.filepath:
        d = os.path.dirname(bpy.data.filepath)
    else:
        d = os.path.join(tempfile.gettempdir(), "canopy_ao")
        notes.append(f"the .blend is not saved yet; the image went to {d}")
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
    return f"{path[:-len('.exr')]}.{number}.exr"


def write_exr(path, ao, output=None):
    """Write a float image (H, W) (grey) or (H, W, C), row 0 = bottom: the writer flips rows
    so the file shows v = 1 on top. output (an Output): the header records it and the pixels'
    fingerprint (FILE_RECORD), so a later bake knows the file as Canopy AO's."""
    ao = np.ascontiguousarray(ao, dtype=np.float32)
    attributes = None
    if output is not None:
        attributes = {FILE_RECORD: json.dumps(dict(output._asdict(),
                                                   pixels=fingerprint(ao, "pixels")))}
    try:
        _core.write_image(path, ao, dtype="float", bottom_up=True, attributes=attributes)
    except (OSError, RuntimeError) as exc:
        raise CanopyAOError(f"Could not write '{path}': {exc}") from exc


# Verdicts of file_record, keyed by the file's identity and state: a re-check of an unchanged
# file (the bake checks before it writes, and again when it writes) reads nothing.
_RECORDS = {}


def file_record(path):
    """The FILE_RECORD of an image file Canopy AO wrote and nobody changed since (its pixels
    still have the recorded fingerprint), else None: another program's file, an edited one,
    or one written before files carried a record."""
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
    try:
        rec = json.loads(_core.read_image_attributes(path).get(FILE_RECORD, ""))
        if not isinstance(rec, dict) or not isinstance(rec.get("pixels"), str):
            return None
        px = _core.read_image(path, bottom_up=True)
    except (ValueError, RuntimeError, OSError):  # not an image, unreadable, no record
        return None
    # (H, W, C) as read holds the bytes of the (H, W) or (H, W, C) array written.
    return rec if fingerprint(px, "pixels") == rec["pixels"] else None


def check_file(path, output, overwrite=False):
    """None when a bake may write path for output (an Output): no file there, Overwrite, or
    Canopy AO's own unchanged file of that same output; else the reason it may not."""
    if not os.path.lexists(path) or (overwrite and not os.path.isdir(path)):
        return None
    if os.path.isdir(path):
        return f"'{path}' is a folder; choose another Image Folder"
    rec = file_record(path)
    if rec is None:
        return (f"'{path}' already exists and Canopy AO did not write it (or changed since, or "
                "written by a Canopy AO whose files carried no record); choose another Image "
                "Folder or tick Overwrite")
    theirs = Output(rec.get("owner"), rec.get("map"), rec.get("tile"), rec.get("atlas", False))
    if theirs != output:
        return (f"'{path}' holds Canopy AO's {theirs}, not {output}; choose another Image "
                "Folder or tick Overwrite")
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


def write_own_file(path, img, txn, output, overwrite):
    """Write img (H, W) to path as output (an Output), the old file kept in txn; refused
    (CanopyAOError, nothing written) when path holds a file that is not this output's own and
    overwrite is off (check_file: the bake checked before it began, this is the last look)."""
    why = check_file(path, output, overwrite)
    if why:
        raise CanopyAOError(why)
    txn.add(keep_file(path))
    write_exr(path, img, output)


def keep_file(path):
    """Move an existing file at path aside; returns undo() that puts it back (or removes what
    was written there). undo.keep is the moved-aside copy's path, or None."""
    backup = None
    if os.path.exists(path):
        backup, k = path + ".canopy_ao-previous", 1
        while os.path.lexists(backup):  # never over a file that is there already
            backup, k = f"{path}.canopy_ao-previous{k}", k + 1
        os.replace(path, backup)

    def undo():
        if backup is not None:
            os.replace(backup, path)
        elif os.path.exists(path):
            os.remove(path)
    undo.keep = backup
    return undo
