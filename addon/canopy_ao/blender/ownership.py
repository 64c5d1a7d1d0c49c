"""Which attributes Canopy AO wrote: a record on the mesh of each attribute's fingerprint as
written, so it vouches for exactly that content (docs/DESIGN.md, 'Ownership of what a bake
writes'). Reading and recording only; mesh_io writes and checks names."""

import json

import numpy as np

from ..core.fingerprint import fingerprint

# Mesh custom property recording the attributes Canopy AO made: a JSON object {attribute name:
# fingerprint of its content as written} (docs/DESIGN.md, 'Ownership of what a bake writes').
# Only an attribute whose content still has that fingerprint may be replaced without the
# user's say-so.
OWNED_PROP = "canopy_ao_owned"
# Before fingerprints: a JSON list of names on the object and on its mesh. A name in it proves
# nothing (any attribute of that name, the user's included, would match), so it never lets a
# bake replace an attribute: ownership() says 'unproven' and the bake asks for Overwrite, after
# which the fingerprint record replaces it. Never written.
LEGACY_OWNED_PROP = "canopy_ao_attributes"

# foreach_get key, values per element and dtype of each attribute type that can be read whole
# (to fingerprint it, or to restore it on rollback).
LAYOUT = {'FLOAT': ("value", 1, np.float32), 'INT': ("value", 1, np.int32),
          'INT8': ("value", 1, np.int32), 'BOOLEAN': ("value", 1, bool),
          'FLOAT2': ("vector", 2, np.float32), 'FLOAT_VECTOR': ("vector", 3, np.float32),
          'FLOAT_COLOR': ("color", 4, np.float32),
          # the stored bytes / 255, no colour conversion: restored bit for bit
          'BYTE_COLOR': ("color_srgb", 4, np.float32)}


def _json(idblock, key, kind):
    """idblock[key] parsed as JSON of type kind (dict or list); empty when absent or not so."""
    raw = idblock.get(key)
    try:
        value = json.loads(raw) if isinstance(raw, str) else None
    except ValueError:
        value = None
    return value if isinstance(value, kind) else kind()


# One reused buffer for reading attributes to fingerprint them: a fresh 16 MB array per read
# (a million-vertex colour attribute) costs its page faults again, ~10 ms, on every Live AO
# frame. Kept up to _SCRATCH_MAX bytes; a larger read gets its own array.
_SCRATCH = {}
_SCRATCH_MAX = 64 << 20


def read_attribute(attr, scratch=False):
    """An attribute's values as one flat array in LAYOUT's key and dtype (None for a type
    LAYOUT does not hold). scratch: into a buffer the next scratch read reuses (for a value
    used at once, never kept)."""
    if attr.data_type not in LAYOUT:
        return None
    key, width, dtype = LAYOUT[attr.data_type]
    size = len(attr.data) * width
    if scratch and size * np.dtype(dtype).itemsize <= _SCRATCH_MAX:
        buf = _SCRATCH.get(dtype)
        if buf is None or len(buf) < size:
            buf = _SCRATCH[dtype] = np.empty(size, dtype=dtype)
        buf = buf[:size]
    else:
        buf = np.empty(size, dtype=dtype)
    attr.data.foreach_get(key, buf)
    return buf


def attribute_fingerprint(attr, values=None):
    """Fingerprint of attr's content: its type, domain and values (the flat LAYOUT array, as
    written; read from attr when not given)."""
    values = read_attribute(attr) if values is None else values
    return fingerprint(values, f"{attr.data_type} {attr.domain}")


def ownership(mesh, name):
    """'ours' when mesh's attribute ``name`` is exactly what Canopy AO wrote there, 'changed'
    when Canopy AO's record of it no longer matches (painted, edited, a record copied or typed
    by hand), 'unproven' when only a pre-fingerprint name list claims it, None when there is
    no such attribute or no record."""
    attr = mesh.attributes.get(name)
    if attr is None:
        return None
    record = _json(mesh, OWNED_PROP, dict).get(name)
    legacy = name in _json(mesh, LEGACY_OWNED_PROP, list)
    if record is None and not legacy:
        return None
    if record is None:
        return 'unproven'
    values = read_attribute(attr, scratch=True)
    ok = values is not None and record == attribute_fingerprint(attr, values)
    return 'ours' if ok else 'changed'


def recorded(mesh, name):
    """The fingerprint mesh's record holds for attribute ``name`` (None: no record): what
    tells whether anything wrote the attribute since this value was read."""
    return _json(mesh, OWNED_PROP, dict).get(name)


def owned_attributes(obj):
    """Names of the attributes on obj's mesh that are exactly as Canopy AO wrote them. The
    record is the mesh's, so objects sharing one mesh agree and a swapped mesh brings its own."""
    me = obj.data
    names = list(_json(me, OWNED_PROP, dict))
    names += [n for n in _json(me, LEGACY_OWNED_PROP, list) if n not in names]
    return [n for n in names if isinstance(n, str) and ownership(me, n) == 'ours']


def linked(idblock):
    """How ``idblock`` belongs to another .blend file, None when it is this file's own: linked
    from a library, or a library override (Blender saves neither's meshes or node trees, so a
    bake must not write to them: the result would be reported and lost on save)."""
    if idblock.library is not None:
        return f"linked from the library '{idblock.library.filepath}'"
    ov = getattr(idblock, "override_library", None)
    ref = ov.reference if ov is not None else None
    if ref is not None and ref.library is not None:
        return f"a library override of data in '{ref.library.filepath}'"
    return None


def set_record(mesh, name, fp):
    """Record (fp a fingerprint) or forget (fp None) attribute ``name`` as Canopy AO's; the
    pre-fingerprint record drops the name either way."""
    records = _json(mesh, OWNED_PROP, dict)
    if fp is None:
        records.pop(name, None)
    else:
        records[name] = fp
    if records:
        mesh[OWNED_PROP] = json.dumps(records)
    else:
        mesh.pop(OWNED_PROP, None)
    legacy = _json(mesh, LEGACY_OWNED_PROP, list)
    if name in legacy:
        legacy = [n for n in legacy if n != name]
        if legacy:
            mesh[LEGACY_OWNED_PROP] = json.dumps(legacy)
        else:
            mesh.pop(LEGACY_OWNED_PROP, None)


def mark_owned(obj, name, values=None):
    """Record obj's attribute ``name`` as Canopy AO's, with the fingerprint of its content:
    values, the flat LAYOUT array just written (read back when not given)."""
    attr = obj.data.attributes[name]
    set_record(obj.data, name, attribute_fingerprint(attr, values))


def free_name(collection, name, own=None):
    """name, or name.001, name.002 … when a datablock of collection (bpy.data.images, say)
    other than own holds it: setting a taken name takes it from its holder (Blender 3.4
    renames the user's datablock), so a bake only ever sets a free one."""
    free, i = name, 0
    while collection.get(free) not in (None, own):
        i += 1
        free = f"{name}.{i:03d}"
    return free
