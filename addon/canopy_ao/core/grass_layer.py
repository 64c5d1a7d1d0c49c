"""Grass as an occluder of the ground under it: the blade field as a horizontal layer of
randomly placed leaves (no bpy; docs/DESIGN.md, 'How each role is lit').

Hegeman's Eq. 9 lights the blades themselves and says nothing about the ground between them
(its value at the roots is 0 for any density). The ground under a field sees the sky through
the layer: with leaf area index L (one-sided blade area per unit ground area) and the blades'
projection function G(ω) (mean |n·ω| over the blade area: Ross 1981, the G-function), a ray
leaving the ground at cos θ = μ crosses optical depth L G(ω)/μ (Monsi–Saeki, Beer's law), so
the cosine-weighted visibility of an upward-facing ground point is
    V = 2 ∫₀¹ exp(−L Ḡ(μ)/μ) μ dμ,     Ḡ(μ) the azimuthal mean of G,
evaluated with 24-point Gauss–Legendre in μ and 16 azimuths, G from the blades' own triangles.
L and G are measured from the mesh, nothing is tuned: denser or flatter grass darkens more.
Ground points within a blade height of the field's ground level get 1 − f (1 − V), f the share
of the disc of radius one blade height around them that the field's footprint covers (the xy
cells its blades stand in, cells as in trees.py): V inside, about half-way at its edge, 1 away.
That per-point part is the core's (grass_cover.h), so the scene plan lights a ground point in
one call; L, G and V are measured here once per field.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .native import _core
from .roles import connected_components
from .trees import _Cells


@dataclass
class GrassLayer:
    name: str
    ground: float         # ground level (z of the blade roots)
    blade: float          # blade height
    lai: float            # one-sided blade area per unit footprint area
    visibility: float     # V of an upward-facing ground point under the layer
    cells: object         # _Cells of the blade roots (the footprint)
    _native: object = field(default=None, init=False, repr=False, compare=False)

    @property
    def native(self):
        """The layer as the core's data (_core.GrassCover, grass_cover.h): what the scene plan
        multiplies a ground point by, with the disc share of the module docstring."""
        if self._native is None:
            c = self.cells
            self._native = _core.GrassCover(
                self.ground, self.blade, self.visibility, float(c.h),
                (float(c.origin[0]), float(c.origin[1])), int(c.width),
                np.ascontiguousarray(c.keys, np.int64))
        return self._native

    def ground_visibility(self, p: np.ndarray) -> np.ndarray:
        """float32 (N,): V for ground points p (N, 3) under the footprint, else 1."""
        return self.native.ground_visibility(
            np.ascontiguousarray(p, dtype=np.float32).reshape(-1, 3))


def projection_mean(normals_area: np.ndarray, mu: np.ndarray, azimuths: int = 16):
    """Ḡ(μ) for each μ: mean over azimuths of Σ |cr·ω| / Σ |cr| (cr: triangle area × normal)."""
    a = np.linalg.norm(normals_area, axis=1)
    total = a.sum()
    if not total > 0:
        return np.zeros(len(mu))
    phi = (np.arange(azimuths) + 0.5) * (2 * math.pi / azimuths)
    s = np.sqrt(np.clip(1 - mu ** 2, 0, 1))
    out = np.empty(len(mu))
    for i, (m, si) in enumerate(zip(mu, s)):
        w = np.stack([si * np.cos(phi), si * np.sin(phi), np.full(azimuths, m)], 1)  # (A, 3)
        out[i] = np.abs(normals_area @ w.T).sum() / (total * azimuths)
    return out


def layer_visibility(lai: float, normals_area: np.ndarray) -> float:
    """V = 2 ∫₀¹ exp(−L Ḡ(μ)/μ) μ dμ (see the module docstring)."""
    x, w = np.polynomial.legendre.leggauss(24)
    mu, w = 0.5 * (x + 1), 0.5 * w
    g = projection_mean(normals_area, mu)
    return float(np.clip(2 * np.sum(w * mu * np.exp(-lai * g / mu)), 0.0, 1.0))


def grass_layer(name, positions, triangles, ground, blade, max_triangles=20000):
    """The GrassLayer of one grass mesh (world space), or None without blades."""
    p = np.asarray(positions, np.float64).reshape(-1, 3)
    t = np.asarray(triangles, np.int64).reshape(-1, 3)
    if not len(t) or not len(p):
        return None
    lab = connected_components(len(p), t)
    k = int(lab.max()) + 1
    order = np.lexsort((p[:, 2], lab))
    roots = p[order[np.searchsorted(lab[order], np.arange(k))], :2]  # lowest point per blade
    ext = np.ptp(roots, axis=0)
    if k < 2 or not ext.min() > 0:
        return None
    h = 2.0 * math.sqrt(ext[0] * ext[1] / k)
    cells = _Cells(roots, h)
    footprint = len(cells.keys) * h * h
    cr = 0.5 * np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]])
    lai = float(np.linalg.norm(cr, axis=1).sum() / footprint)
    sub = cr[:: max(1, len(cr) // max_triangles)]
    return GrassLayer(name, float(ground), float(blade), lai, layer_visibility(lai, sub), cells)
