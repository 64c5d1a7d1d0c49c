"""The bake's settings (no bpy)."""

from __future__ import annotations

from dataclasses import dataclass

DEFAULT_TAU = 1.5


@dataclass
class BakeSettings:
    """method: one of ladder.METHODS. tau: optical depth (AO at a shell's centre = exp(-tau));
    None = calibrate. distance: AO distance in scene units, 0 = unlimited (Cycles' meaning: a
    hard cut-off on ray length). Rays and the grid stop at it; the occluder laws (other trees'
    shells, trunks, instanced forests) count only what lies within it (occluders.h, 'AO
    distance'); the in-shell models do not shorten their paths, which end at the crown's
    boundary (the same unless the distance is shorter than the crown). samples: rays per point for
    "raytrace". shells: k for "shells". calibration_points: reference points traced for "auto".
    time_budget: seconds the whole bake may take; "auto" does not pick a rung predicted to take
    longer (0 = no limit). target_rmse: "auto" stops climbing once a rung's sample RMSE is
    below it; 0.06 ≈ an MAE of 0.05, an error an artist does not see. forest_epsilon: the
    cut-off ε (Shanmugam–Arikan Eq. 5) for instanced trees (attach_forest): each instance's
    shell is ignored where it would block < ε; 1e-2 keeps a ground vertex under a 10,000-tree
    forest to ~1000 occluders (bench/forest.py) at a cost of < 0.08 AO against no cut-off."""

    method: str = "auto"
    tau: float | None = None
    distance: float = 0.0
    samples: int = 64
    shells: int = 4
    trim: float = 0.0
    calibration_points: int = 256
    calibration_samples: int = 128
    time_budget: float = 2.0
    target_rmse: float = 0.06
    seed: int = 0
    forest_epsilon: float = 1e-2
