"""The rungs of the method ladder as objects (docs/DESIGN.md, 'Architecture').

base.py holds the Rung type (what a rung is: its label, help and capabilities, how it lights
receivers and the work its cost model counts) and the lookup by name; each rung is one file
beside it; registry.py lists them in the ladder's order. The rest of the add-on asks a rung
(``base.get(name).takes_tau``) instead of comparing its name.

This package's __init__ imports nothing, so a module below the rungs (lighting, cost) can
look a rung up through base.py without importing the rungs themselves.
"""
