"""core/fingerprint.py: the record of what Canopy AO wrote vouches for exactly those bytes
(docs/DESIGN.md, 'Ownership of what a bake writes')."""
import numpy as np
import pytest

from canopy_ao.core.fingerprint import DIGITS, fingerprint, name_digest


def test_a_fingerprint_is_fixed_across_sessions_and_numpy_versions():
    # Saved in .blend files and image headers: the same bytes must always give this digest.
    assert fingerprint(np.arange(5000, dtype=np.float32), "FLOAT POINT") == \
        "c32fdedd4d439b413b298895"
    assert len(fingerprint(np.zeros(0, np.float32))) == DIGITS


@pytest.mark.parametrize("n", [1, 1023, 8 * 1024, 8 * 1024 + 3, 300_001])
def test_any_one_changed_value_changes_the_fingerprint(n):
    rng = np.random.default_rng(n)
    a = rng.random(n).astype(np.float32)
    base = fingerprint(a, "x")
    assert fingerprint(a.copy(), "x") == base
    for i in {0, n // 2, n - 1}:  # in a block and in the tail
        b = a.copy()
        b[i] = np.nextafter(b[i], np.float32(2))  # one ulp
        assert fingerprint(b, "x") != base, i
    assert fingerprint(a, "y") != base  # the label (type, domain) counts
    assert fingerprint(a.view(np.int32), "x") == base  # bytes, not values: same bits, same
    assert fingerprint(a[:-1], "x") != base  # the length counts


def test_two_swapped_words_change_the_fingerprint():
    a = np.arange(4096, dtype=np.float64)
    b = a.copy()
    b[[10, 20]] = b[[20, 10]]
    assert fingerprint(a) != fingerprint(b)


def test_name_digests_tell_apart_names_a_file_name_makes_alike():
    names = ["Tree.001", "Tree 001", "Tree/001", "Tree_001", "tree_001", "Baum_ä", "Baum_ö"]
    assert len({name_digest(n) for n in names}) == len(names)
    # Names reach file names on disk: the digest of a name must never change.
    assert name_digest("Tree.001") == "174e7cdf" and len(name_digest("x")) == 8
