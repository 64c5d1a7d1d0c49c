"""The ladder: every rung in order, cheapest first (auto's candidates climb in this order, the
settings offer them in it). Adding a rung: its file beside this one, and its name here, in
the import and in its place in the ladder."""
from . import (auto, ellipsoid, grid, hybrid, medium, raytrace, reeves_blau, regression,
               shells, sphere)
from .base import register

for _module in (auto, sphere, ellipsoid, shells, medium, reeves_blau, grid, regression,
                hybrid, raytrace):
    register(_module.RUNG)
