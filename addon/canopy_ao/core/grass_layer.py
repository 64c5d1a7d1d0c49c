"""Grass as an occluder of the ground under it: the blade field as a horizontal layer of
randomly placed leaves (no bpy; docs/DESIGN.md, 'How each role is lit').

Hegeman's Eq. 9 lights the blades themselves and says nothing about the ground between them
(its value at the roots is 0 for any density). The ground under a field sees the sky through
the layer: with leaf area index L (one-sided blade area per unit ground area) and the blades'
projection function G(ω) (mean |n·ω| over the blade area: Ross 1981, the G-function), a ray
leaving the ground at cos θ = μ crosses optical depth L G(ω)/μ (Monsi–Saeki, Beer's law), so
the cosine-weighted visibility of an upward-facing ground point is
    V = 2 ∫₀¹ exp(−L Ḡ(μ)/μ) μ dμ,     Ḡ(μ) the azimuthal mean of G,
evaluated with 24-point Gauss–Legendre in μ and 16 azimuths, G from the blades' own triangles
(within an AO distance D, the blades a ray reaches: the blade layer below at s = 0, facing up).
L and G are measured from the mesh, nothing is tuned: denser or flatter grass darkens more.
Ground points within a blade height of the field's ground level get 1 − f (1 − V), f the share
of the disc of radius one blade height around them that the field's footprint covers (the xy
cells its blades stand in, cells as in trees.py): V inside, about half-way at its edge, 1 away.
That per-point part is the core's (grass_cover.h), so the scene plan lights a ground point in
one call; L, G and V are measured here once per field.

The blades themselves see the sky through the same layer (blade_layer): Hegeman's Eq. 9,
V = (z/2h)(1 + cos θ), knows the height but not the density, so a sparse field came out 0.14
too dark and a dense one 0.06 too bright. A blade point at relative height s = z/h with normal
n sees, along a direction at cos θ = μ to up, the blade area above it if μ > 0 and the area
below it, then the ground, if μ < 0; with A(x) the share of the blade area above height x·h
(measured from the triangles) and D the AO distance,
    T(s, μ > 0) = exp(−L Ḡ(μ)/μ · [A(s) − A(s + Dμ/h)]),
    T(s, μ < 0) = 0 if D|μ| ≥ s h (the ground), else exp(−L Ḡ(|μ|)/|μ| · [A(s − D|μ|/h) − A(s)]),
    V(s, n) = (1/π) ∫ T(s, μ) max(0, n·ω) dω,
integrated over azimuth in closed form and over μ by Gauss–Legendre, tabulated over (s, cos θ)
once per field and read bilinearly by the core (grass.h). At the tip of a lone blade it is Eq.
9's (1 + cos θ)/2; nothing is tuned.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .native import _core
from .roles import connected_components
from .scene import ray_length
from .trees import _Cells


@dataclass
class GrassLayer:
    name: str
    ground: float         # ground level (z of the blade roots)
    blade: float          # blade height
    lai: float            # one-sided blade area per unit footprint area
    visibility: float     # V of an upward-facing ground point under the layer
    cells: object         # _Cells of the blade roots (the footprint)
    # float32 (LAYER_ROWS, LAYER_COLS): a blade point's V over (s, cos θ) (blade_layer)
    layer: object = None
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


LAYER_ROWS, LAYER_COLS = 33, 33   # the blade layer's table: s = z/h in [0, 1], cos θ in [-1, 1]
AREA_BINS = 64                    # A(x), the share of the blade area above x·h, in bins of h/64


def area_above(p, t, ground, blade):
    """A(x) at x = k / AREA_BINS (k = 0..AREA_BINS): the share of the blades' area above height
    x·blade, each triangle's area spread over four interior points (the centroid and the
    (2/3, 1/6, 1/6) points), so a blade made of one triangle is spread over its height."""
    a, b, c = p[t[:, 0]], p[t[:, 1]], p[t[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    z = np.stack([(a + b + c) / 3, (4 * a + b + c) / 6, (a + 4 * b + c) / 6,
                  (a + b + 4 * c) / 6])[..., 2]
    x = np.clip((z - ground) / blade, 0.0, 1.0).ravel()
    w = np.tile(area / 4, 4)
    edges = np.linspace(0.0, 1.0, AREA_BINS + 1)
    hist = np.histogram(x, bins=edges, weights=w)[0]
    total = float(hist.sum())
    if not total > 0:
        return np.zeros(AREA_BINS + 1)
    return np.concatenate([np.cumsum(hist[::-1])[::-1], [0.0]]) / total


def blade_layer(lai, normals_area, above, distance_in_blades=math.inf):
    """float32 (LAYER_ROWS, LAYER_COLS): V(s, cos θ) of a blade point (module docstring). above:
    area_above's A; distance_in_blades: the AO distance over the blade height (inf: none)."""
    x, w = np.polynomial.legendre.leggauss(24)
    mu, w = 0.5 * (x + 1), 0.5 * w                      # (0, 1], one half of the sphere
    g = projection_mean(normals_area, mu)
    grid = np.linspace(0.0, 1.0, AREA_BINS + 1)
    s = np.linspace(0.0, 1.0, LAYER_ROWS)[:, None]      # (S, 1)
    reach = distance_in_blades * mu[None, :]            # (1, M): how high/low a ray gets in h
    A = lambda v: np.interp(np.clip(v, 0.0, 1.0), grid, above)  # noqa: E731
    depth = lai * g / mu                                # optical depth per unit of A
    up = np.exp(-depth * (A(s) - A(s + reach)))         # (S, M)
    hits_ground = reach >= s
    down = np.where(hits_ground, 0.0, np.exp(-depth * (A(s - np.minimum(reach, s)) - A(s))))
    c = np.linspace(-1.0, 1.0, LAYER_COLS)[:, None]     # (C, 1)
    sin_c = np.sqrt(np.clip(1 - c ** 2, 0, 1))
    sin_m = np.sqrt(np.clip(1 - mu ** 2, 0, 1))[None, :]

    def band(sign):
        """∫ over azimuth of max(0, n·ω) for the directions at cos = sign·μ: (C, M)."""
        a, b = c * sign * mu[None, :], sin_c * sin_m
        with np.errstate(divide="ignore", invalid="ignore"):
            phi = np.arccos(np.clip(np.where(b > 0, -a / b, 0.0), -1.0, 1.0))
        return np.where(a >= b, 2 * math.pi * a,
                        np.where(a <= -b, 0.0, 2 * (a * phi + b * np.sin(phi))))

    v = (up * w) @ band(1.0).T + (down * w) @ band(-1.0).T  # (S, C)
    return np.clip(v / math.pi, 0.0, 1.0).astype(np.float32)


def grass_layer(name, positions, triangles, ground, blade, max_triangles=20000,
                distance=math.inf):
    """The GrassLayer of one grass mesh (world space), or None without blades. distance: the AO
    distance (inf or ≤ 0: none), which the blade layer honours."""
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
    reach = ray_length(distance) / float(blade)
    layer = blade_layer(lai, sub, area_above(p, t, float(ground), float(blade)), reach)
    # An upward-facing ground point is the layer's root facing up: V = 2 ∫ exp(−L Ḡ/μ) μ dμ
    # without an AO distance, the part of the layer within reach with one.
    return GrassLayer(name, float(ground), float(blade), lai, float(layer[0, -1]), cells, layer)
