"""core/texel_budget.py: a texel bake refused up front, with its figures, when its buffers would
not fit in memory."""
import numpy as np
import pytest

from canopy_ao.core import texel_budget as tb
from canopy_ao.core.native import CanopyAOError

# The default plane's UVs: the unit square as two triangles.
SQUARE = np.float32([[0, 0], [1, 0], [1, 1], [0, 0], [1, 1], [0, 1]])


def test_covered_texels_of_the_unit_square_is_every_texel():
    assert tb.covered_texels(SQUARE, 256) == 256 * 256
    half = SQUARE * np.float32(0.5)  # a quarter of the square, plus one texel's rim
    assert 128 * 128 <= tb.covered_texels(half, 256) <= 128 * 128 + 4 * 128 * 2
    assert tb.covered_texels(np.zeros((0, 2), np.float32), 256) == 0


def test_peak_bytes_grow_with_texels_sub_samples_and_pixels():
    one = tb.peak_bytes(1000, 64, 1)
    assert tb.peak_bytes(1000, 64, 2) - one == 1000 * 4 * tb.SUB_BYTES
    assert tb.peak_bytes(1000, 64, 3) - one == 1000 * 9 * tb.SUB_BYTES
    assert tb.peak_bytes(1000, 64, 1, tiles=2) - one == 64 * 64 * tb.PIXEL_BYTES


def test_a_bake_that_does_not_fit_is_refused_with_its_figures(monkeypatch):
    monkeypatch.setattr(tb, "available_bytes", lambda: 2 ** 30)  # 1 GiB free
    need = tb.peak_bytes(16384 ** 2, 16384, 2)
    with pytest.raises(CanopyAOError) as info:
        tb.check_memory("Plane", SQUARE, 16384, 2)
    msg = str(info.value)
    assert msg.startswith("Object 'Plane': a 16384×16384 texel bake")
    assert f"{need:,} bytes" in msg and f"{2 ** 30:,} bytes" in msg
    assert "2×2 anti-aliasing" in msg and "lower the resolution" in msg
    # the same object at 1024 px fits (about 0.4 GiB)
    assert tb.check_memory("Plane", SQUARE, 1024, 2) < 2 ** 30


def test_unknown_free_memory_refuses_nothing(monkeypatch):
    monkeypatch.setattr(tb, "available_bytes", lambda: None)
    assert tb.check_memory("Plane", SQUARE, 16384, 8) > 2 ** 40


def test_available_bytes_reads_the_machine():
    have = tb.available_bytes()
    assert have is None or have > 0
