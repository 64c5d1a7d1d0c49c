"""What a texel bake spends (no bpy): the rays its anti-aliasing sub-samples cast, and the
memory it needs, checked against what the machine has before any texel is rasterised
(docs/DESIGN.md, 'Texel anti-aliasing and memory')."""

from __future__ import annotations

import os

import numpy as np

from .native import CanopyAOError

# Bytes per covered texel while it is rasterised and kept as a receiver: the native raster's
# pixel, triangle, exact flag, barycentrics, position and normal (45) and their Python copies
# (pixel, triangle, position, normal: 32).
TEXEL_BYTES = 45 + 32
# Bytes per anti-aliasing sub-sample (N > 1): its position, normal and triangle (twice, while
# the columns are stacked), the numpy temporaries that gather them, its AO and a chunk's share.
# Measured: a 2048² plane's bake grew the process by 78 bytes a texel at 1 × 1, 347 at 2 × 2 and
# 1,019 at 4 × 4; the estimate, 102, 422 and 1,382, stays above.
SUB_BYTES = 80
# Bytes per image pixel: the splat's float image and mask (5), the EXR writer's copy (4) and
# Blender's RGBA float image it loads (16).
PIXEL_BYTES = 5 + 4 + 16


def texel_rays(samples: int, group: int) -> int:
    """Rays a texel of `group` anti-aliasing sub-samples casts at Samples: Samples rounded up to
    a multiple of the group, so each sub-sample casts as many (RayTraceOptions::point_group)."""
    g = max(1, int(group))
    return -(-int(samples) // g) * g


def covered_texels(uvs, resolution: int, tiles: int = 1) -> int:
    """An upper estimate of the texels a UV layout covers at resolution²: its triangles' UV
    area (overlaps counted twice) plus a texel's width around their perimeter (conservative
    coverage), at most every texel of its tiles. uvs: float32 (3M, 2) corner UVs."""
    t = np.asarray(uvs, np.float64).reshape(-1, 3, 2)
    if not len(t):
        return 0
    e1, e2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
    area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    area = np.where(np.isfinite(area), area, 0.0)
    edges = np.linalg.norm(t - np.roll(t, 1, axis=1), axis=2).sum(axis=1)
    edges = np.where(np.isfinite(edges), edges, 0.0)
    res = float(resolution)
    est = area.sum() * res * res + edges.sum() * res
    return int(min(est, float(tiles) * res * res))


def peak_bytes(texels: int, resolution: int, aa: int, tiles: int = 1) -> int:
    """The bake's peak memory in bytes for `texels` covered texels at aa × aa sub-samples, in
    `tiles` images of resolution² (one object, atlas or UDIM set)."""
    pixels = int(tiles) * int(resolution) ** 2
    sub = int(aa) ** 2 if aa > 1 else 0  # at 1 × 1 the texels are the receivers
    return int(texels) * (TEXEL_BYTES + sub * SUB_BYTES) + pixels * PIXEL_BYTES


def available_bytes() -> int | None:
    """Memory the bake may take: Linux's MemAvailable (/proc/meminfo), else the free physical
    pages (os.sysconf), else None (unknown: nothing is refused)."""
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, OSError, ValueError):
        return None


def _gib(n: int) -> str:
    return f"{n / 2 ** 30:.1f} GiB"


def check_memory(name: str, uvs, resolution: int, aa: int, tiles: int = 1) -> int:
    """Refuse, with the figures, a texel bake of object `name` whose buffers would not fit in
    the available memory. Returns the estimated peak bytes."""
    texels = covered_texels(uvs, resolution, tiles)
    need = peak_bytes(texels, resolution, aa, tiles)
    have = available_bytes()
    if have is not None and need > have:
        raise CanopyAOError(
            f"Object '{name}': a {resolution}×{resolution} texel bake "
            f"({tiles} image{'s' if tiles != 1 else ''}, about {texels:,} texels × {aa}×{aa} "
            f"anti-aliasing) needs about {_gib(need)} ({need:,} bytes) but only {_gib(have)} "
            f"({have:,} bytes) is available; lower the resolution or the anti-aliasing "
            "(nothing was changed)")
    return need
