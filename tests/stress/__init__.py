"""Stress suite of dolfinx_mortar: extreme parameters, geometry and loading (docs/stress.md).

The fast cases run with the rest of the tests (``pytest tests``); the full sweep is
marked ``slow`` and runs with ``make stress`` (``--run-slow``).
"""
