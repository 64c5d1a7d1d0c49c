"""auto: calibrate τ and climb the ladder from the cheapest rung while it pays (ladder.py)."""
from .base import Proxy, Rung

RUNG = Rung(
    "auto", "Auto", "Calibrate tau and climb sphere / ellipsoid / shells / medium / grid / rays "
    "against a few hundred ray-traced points: the cheapest rung that is good enough within "
    "the time budget",
    chooses=True, takes_tau=True, proxy=Proxy.SHELLS, needs_triangles=True, uses_samples=True,
    number=0)
# The rung auto bakes with where it cannot calibrate (no ray tracer) or has nothing to climb.
FALLBACK = "ellipsoid"
