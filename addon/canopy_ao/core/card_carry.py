"""A bake's card vertices carrying the AO of their card's opaque part (core/card_ao.py says
where; docs/DESIGN.md, 'Opacity of leaf cards'). Apart from card_ao because it evaluates the
plan (bake.evaluate_receivers), and the calibration, which bake imports, reads card_ao. No bpy.
"""

from __future__ import annotations

import numpy as np

from .bake import evaluate_receivers
from .card_ao import card_vertices


def carry(plan, item, ao, vertices):
    """Set ao (float32, the AO of the item's vertices ``vertices``, a slice a:b) at its card
    vertices to the AO of their card's opaque part (above). vertices None or False (texels):
    nothing to do."""
    if not isinstance(vertices, slice):
        return
    a, b, _step = vertices.indices(len(item.positions))
    cv = card_vertices(item)
    lo, hi = np.searchsorted(cv.vertex, [a, b])
    if hi <= lo:
        return
    got = evaluate_receivers(plan, item, cv.points[lo:hi], cv.normals[lo:hi],
                             triangles=cv.triangle[lo:hi])
    v = cv.vertex[lo:hi] - a
    total = np.bincount(v, got, b - a)
    count = np.bincount(v, None, b - a)
    has = count > 0
    ao[has] = (total[has] / count[has]).astype(ao.dtype)

