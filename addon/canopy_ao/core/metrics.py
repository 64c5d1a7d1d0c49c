"""Error metrics between our AO and a reference (Cycles or Embree), DESIGN 8.

Pure numpy, no bpy: plain pytest tests it and the add-on, the CLI and the charts share it.
"""
import numpy as np

__all__ = ["compare"]


def compare(ours, ref, mask=None):
    """Compare two AO arrays of the same shape (per vertex (N,) or per texel (H, W)).

    mask: optional bool array of the same shape; only True entries are compared (e.g. texels a
    bake covered, or vertices that are not buried inside a branch).
    Non-finite entries in either array are left out and counted in ``n_nonfinite``.

    Returns a dict of plain floats, all finite:
      mae   mean |ours - ref|
      rmse  sqrt(mean (ours - ref)^2)
      p95   95th percentile of |ours - ref|
      corr  Pearson correlation; when either side is constant (no variance to correlate) it is
            1.0 if the two agree to within 1e-6 everywhere and 0.0 otherwise
      bias  mean (ours - ref): > 0 means ours is brighter
      n     number of entries compared (0 gives zeros for every metric and corr 0.0)
    """
    a = np.asarray(ours, dtype=np.float64)
    b = np.asarray(ref, dtype=np.float64)
    if a.shape != b.shape:
        raise ValueError(f"compare: ours has shape {a.shape} but ref has shape {b.shape}; "
                         "they must describe the same vertices/texels")
    keep = np.isfinite(a) & np.isfinite(b)
    n_nonfinite = int(keep.size - np.count_nonzero(keep))
    if mask is not None:
        m = np.asarray(mask, dtype=bool)
        if m.shape != a.shape:
            raise ValueError(f"compare: mask has shape {m.shape}, expected {a.shape}")
        keep &= m
    a = a[keep]
    b = b[keep]
    n = int(a.size)
    if n == 0:
        return {"mae": 0.0, "rmse": 0.0, "p95": 0.0, "corr": 0.0, "bias": 0.0, "n": 0,
                "n_nonfinite": n_nonfinite}
    err = a - b
    abs_err = np.abs(err)
    sa = a.std()
    sb = b.std()
    if sa > 1e-12 and sb > 1e-12:
        corr = float(np.mean((a - a.mean()) * (b - b.mean())) / (sa * sb))
        corr = float(np.clip(corr, -1.0, 1.0))  # rounding can step just past +-1
    else:
        corr = 1.0 if float(abs_err.max()) <= 1e-6 else 0.0
    return {
        "mae": float(abs_err.mean()),
        "rmse": float(np.sqrt(np.mean(err * err))),
        "p95": float(np.percentile(abs_err, 95.0)),
        "corr": corr,
        "bias": float(err.mean()),
        "n": n,
        "n_nonfinite": n_nonfinite,
    }
