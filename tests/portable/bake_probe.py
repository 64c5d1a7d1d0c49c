"""Bakes a small scene with nothing but canopy_ao._core calls (no Blender, no add-on) and prints
one JSON line of the results' SHA-256 digests: ray-traced AO, proxy (fitted ellipsoid) AO, and a
texel image (rasterised, splatted, margin dilated). Run by tests/portable/test_portable.sh in a
bare root with the portable zip's module and on the host with the Debian build's: the digests
must be equal (bit-identical AO).
    python3 bake_probe.py PACKAGE_DIR [NPZ]   (the folder holding _core*.so; NPZ: the arrays too)"""
import hashlib
import json
import sys

import numpy as np

sys.path.insert(0, sys.argv[1])
import _core  # noqa: E402  (the module alone, as the bare root has no bpy)


arrays = {}


def digest(a, name=None):
    a = np.ascontiguousarray(a)
    if name:
        arrays[name] = a
    return f"{a.dtype}{a.shape}:" + hashlib.sha256(a.tobytes()).hexdigest()


rng = np.random.default_rng(40)
# A canopy of 600 leaf triangles over a ground quad.
c = rng.normal(size=(600, 3))
c *= (1.5 * rng.random(600) ** (1 / 3) / np.linalg.norm(c, axis=1))[:, None]
c[:, 2] += 3.0
leaves = (c[:, None, :] + 0.2 * rng.uniform(-1, 1, (600, 3, 3))).reshape(-1, 3)
ground = np.array([[-5, -5, 0], [5, -5, 0], [5, 5, 0], [-5, 5, 0]], float)
v = np.ascontiguousarray(np.vstack([leaves, ground]), np.float32)
t = np.vstack([np.arange(1800).reshape(-1, 3), [[1800, 1801, 1802], [1800, 1802, 1803]]])
t = np.ascontiguousarray(t, np.int32)
# Receivers: a grid on the ground, facing up.
g = np.linspace(-4, 4, 24, dtype=np.float32)
p = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
p = np.ascontiguousarray(np.c_[p, np.zeros(len(p), np.float32)], np.float32)
n = np.ascontiguousarray(np.tile(np.float32([0, 0, 1]), (len(p), 1)))

out = {"module": _core.__file__.rsplit("/", 1)[-1], "inputs": digest(np.concatenate([v.ravel(), p.ravel()]))}
out["raytraced"] = digest(_core.RayTracer(v, t).ao(p, n, samples=64, distance=6.0, seed=3), "raytraced")
ell = _core.fit_ellipsoid(np.ascontiguousarray(leaves, np.float32))
out["proxy"] = digest(_core.ao_canopy_ellipsoid(p, n, ell, 1.0), "proxy")

# The ground quad's texels: one receiver per covered texel, AO, splatted with a margin.
uv = np.float32([[0, 0], [1, 0], [1, 1], [0, 0], [1, 1], [0, 1]])
corners = v[t[-2:].ravel()]
ts = _core.rasterize_uv(uv * 0.9 + 0.05, corners, np.tile(np.float32([0, 0, 1]), (6, 1)),
                        resolution=32)
ao = _core.RayTracer(v, t).ao(np.ascontiguousarray(ts.positions), np.ascontiguousarray(ts.normals),
                              samples=32, distance=6.0)
img = _core.splat_texels(np.ascontiguousarray(ts.pixels, np.int32),
                         np.ascontiguousarray(ao, np.float32), (32, 32), margin=2)
out["texel"] = digest(img, "texel")
if len(sys.argv) > 2:
    np.savez(sys.argv[2], **arrays)
print("PROBE " + json.dumps(out, sort_keys=True))
