"""dolfinx_mortar: mortar contact of deforming bodies at large deformations for FEniCSx.

Public entry points:

* :class:`MortarInterface` — D, M, weighted gaps and their exact derivatives
  for one slave/master pair of facet-tagged surfaces, in PETSc layouts.
* :class:`MeshTying` — tie non-matching subdomains with D and M.
* :func:`reaction_force` — the total force a Dirichlet condition exerts on a tagged
  boundary, from the bulk residual (:mod:`dolfinx_mortar.reactions`).
* :mod:`dolfinx_mortar.meshes` — gmsh builders of the benchmark geometries.
"""

from __future__ import annotations

import importlib

__version__ = "0.1.0"

__all__ = [
    "ContactSurface",
    "MeshTying",
    "MortarInterface",
    "MortarStatistics",
    "SurfaceError",
    "__version__",
    "reaction_force",
]

# dolfinx-dependent names load on first use, so that the pure-numpy kernels
# (dolfinx_mortar.kernels, dolfinx_mortar.dual) import without dolfinx
_LAZY = {
    "ContactSurface": "surface",
    "SurfaceError": "surface",
    "MeshTying": "tying",
    "MortarInterface": "mortar",
    "MortarStatistics": "mortar",
    "reaction_force": "reactions",
}


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
