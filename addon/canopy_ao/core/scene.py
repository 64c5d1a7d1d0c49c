"""The bake's data: scene items (world-space arrays), the plan prepare() makes, results."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import roles as _roles
from .native import CanopyAOError

RECEIVER_ROLES = ("CANOPY", "TRUNK", "GROUND", "GRASS")


@dataclass
class SceneItem:
    """One mesh object in world space: positions, normals float32 (N, 3); triangles int32 (M, 3)."""

    name: str
    role: str
    tree: str
    positions: np.ndarray
    normals: np.ndarray
    triangles: np.ndarray

    def __post_init__(self):
        self.positions = np.ascontiguousarray(self.positions, dtype=np.float32).reshape(-1, 3)
        self.normals = np.ascontiguousarray(self.normals, dtype=np.float32).reshape(-1, 3)
        self.triangles = np.ascontiguousarray(self.triangles, dtype=np.int32).reshape(-1, 3)
        if self.role not in _roles.ROLES:
            raise CanopyAOError(f"{self.name}: unknown role {self.role!r} (one of {_roles.ROLES})")
        if len(self.positions) != len(self.normals):
            raise CanopyAOError(f"{self.name}: {len(self.positions)} positions but "
                                f"{len(self.normals)} normals")


@dataclass
class Plan:
    """What prepare() decided: proxies per tree, method, τ, and the shared state for the bake."""

    settings: object  # settings.BakeSettings
    method: str
    tau: float
    fits: dict = field(default_factory=dict)  # tree -> (Sphere, Ellipsoid, [Ellipsoid] shells)
    proxies: dict = field(default_factory=dict)  # tree -> [Ellipsoid] the chosen method's shells
    trunks: dict = field(default_factory=dict)  # tree -> list of _core.Ellipsoid (solid)
    grass: dict = field(default_factory=dict)  # item name -> (ground_height, blade_height)
    tracer: object = None
    grid: object = None
    regression: object = None  # regression.RegressionRung, method "regression"
    calibration: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    forest: object = None  # forest.Forest: instanced trees occluding every receiver (attach_forest)


@dataclass
class ItemResult:
    name: str
    role: str
    tree: str
    method: str
    ao: np.ndarray
    seconds: float

    @property
    def vertices(self) -> int:
        return int(len(self.ao))
