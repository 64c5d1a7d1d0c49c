"""canopy_ao._core.to_world and gray_rgba: the bake's world-space receivers and grey colours
(mesh_arrays.h), against numpy, and their argument errors."""
import numpy as np
import pytest

from canopy_ao import _core


def rows(n, seed, unit=True):
    v = np.random.default_rng(seed).standard_normal((n, 3))
    if unit:
        v /= np.linalg.norm(v, axis=1, keepdims=True)
    return np.ascontiguousarray(v, dtype=np.float32)


def test_to_world_matches_numpy_affine_and_inverse_transpose():
    m = np.array([[2.0, 0.3, 0.0, 1.0], [0.0, 1.0, -0.4, 2.0], [0.1, 0.0, 0.5, -3.0],
                  [0.0, 0.0, 0.0, 1.0]])
    p, n = rows(50000, 0) * 4, rows(50000, 1)
    p0, n0 = p.copy(), n.copy()
    assert _core.to_world(p, n, m) is None  # in place
    np.testing.assert_allclose(p, p0 @ m[:3, :3].T + m[:3, 3], atol=2e-5)
    want = n0 @ np.linalg.inv(m[:3, :3])  # rows: (inv(M)^T n)^T
    want /= np.linalg.norm(want, axis=1, keepdims=True)
    np.testing.assert_allclose(n, want, atol=2e-6)


def test_to_world_identity_keeps_unit_normals_and_fixes_the_rest():
    p, n = rows(1000, 2), rows(1000, 3)
    n[10] = 0.0
    n[11] = (np.nan, 0.0, 0.0)
    n[12] = (0.0, 3.0, 4.0)
    p0, n0 = p.copy(), n.copy()
    _core.to_world(p, n, np.eye(4))
    _core.to_world(p, n)
    assert np.array_equal(p, p0)
    keep = np.ones(1000, bool)
    keep[10:13] = False
    assert np.array_equal(n[keep], n0[keep])  # bit for bit
    np.testing.assert_array_equal(n[10], (0, 0, 1))
    np.testing.assert_array_equal(n[11], (0, 0, 1))
    np.testing.assert_allclose(n[12], (0, 0.6, 0.8), atol=1e-7)
    _core.to_world(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.float32), np.eye(4))


@pytest.mark.parametrize("call, word", [
    (lambda p, n: _core.to_world(p.astype(np.float64), n), "float32"),
    (lambda p, n: _core.to_world(p, n[:5]), "same number of rows"),
    (lambda p, n: _core.to_world(p, n, np.eye(3)), "4x4"),
    (lambda p, n: _core.to_world(p, n, np.full((4, 4), np.nan)), "non-finite"),
    (lambda p, n: _core.to_world(p[:, :2].copy(), n), "(N, 3)"),
    (lambda p, n: _core.to_world(p[::2], n[::2]), "C-contiguous"),
])
def test_to_world_refuses_bad_arguments(call, word):
    p, n = rows(10, 4), rows(10, 5)
    with pytest.raises(ValueError, match=word.replace("(", r"\(").replace(")", r"\)")):
        call(p, n)


def test_to_world_refuses_read_only_arrays():
    p, n = rows(10, 4), rows(10, 5)
    p.flags.writeable = False
    with pytest.raises(ValueError, match="writeable"):
        _core.to_world(p, n)


def test_gray_rgba():
    v = np.linspace(0, 1, 70001, dtype=np.float32)
    c = _core.gray_rgba(v)
    assert c.dtype == np.float32 and c.shape == (70001, 4)
    assert np.array_equal(c[:, :3], np.repeat(v[:, None], 3, axis=1))
    assert np.all(c[:, 3] == 1.0)
    assert _core.gray_rgba(np.zeros(0, np.float32)).shape == (0, 4)
    with pytest.raises(ValueError, match="float32"):
        _core.gray_rgba(v.astype(np.float64))
    with pytest.raises(ValueError, match=r"\(N,\)"):
        _core.gray_rgba(np.zeros((3, 2), np.float32))
