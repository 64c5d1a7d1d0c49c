"""Fingerprints of data Canopy AO wrote, so that a record of ownership vouches for exactly that
data (docs/DESIGN.md, 'Ownership of what a bake writes'). No bpy: plain pytest checks it.

A fingerprint is SHA-1 over a label (what the data is: type, domain, ...), the byte count, and
a multilinear hash of the bytes: the bytes read as 64-bit words w, cut into blocks of
``_BLOCK`` words, each block summed as Σ k_i w_i (mod 2^64) with fixed odd keys k_i. One numpy
pass at memory speed (about 1 ms per 16 MB, against ~17 ms for SHA-1 over the same bytes), so
Live AO and frame-range bakes can fingerprint every write. Any change of a single word changes
its block's sum (k_i is odd, so k_i Δ ≠ 0 mod 2^64); the keys and block sums are fixed by this
file alone (not by numpy's random streams), so a fingerprint saved in a .blend or an image
header verifies in every later session.
"""

import hashlib

import numpy as np

_BLOCK = 1024
_KEYS = (np.frombuffer(hashlib.shake_128(b"canopy_ao fingerprint keys").digest(8 * _BLOCK),
                       dtype="<u8").astype(np.uint64) | np.uint64(1))
DIGITS = 24  # hex digits kept: 96 bits


def fingerprint(values, label=""):
    """Hex digest (DIGITS long) of the exact bytes of ``values`` (any numpy array, read in C
    order) and ``label``. Equal arrays (same dtype, same bits) give equal digests; NaNs
    compare by their bits."""
    b = np.ascontiguousarray(values).reshape(-1).view(np.uint8)
    m = len(b) // (8 * _BLOCK) * (8 * _BLOCK)
    h = hashlib.sha1(f"{label}\0{len(b)}\0".encode("utf-8"))
    if m:
        words = b[:m].view(np.uint64).reshape(-1, _BLOCK)
        h.update(np.einsum("ij,j->i", words, _KEYS).astype("<u8").tobytes())
    h.update(b[m:].tobytes())
    return h.hexdigest()[:DIGITS]


def name_digest(name, digits=8):
    """A short hex digest of a name's exact text (case, dots, spaces and non-ASCII included):
    what tells apart names that a file name would make alike."""
    return hashlib.sha1(name.encode("utf-8")).hexdigest()[:digits]
