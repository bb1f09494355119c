"""dolfinx_mortar: mortar contact of deforming bodies at large deformations for FEniCSx.

Entry points, all importable from here (``from dolfinx_mortar import ContactProblem``):

* :class:`ContactProblem` — a bulk residual F(u; v) in UFL with mortar contact pairs
  (:class:`ContactPair`), solved by Newton's method in PETSc SNES; how it enforces and
  solves contact is a :class:`ContactOptions` (its fields are also keywords of the
  problem), friction a :class:`Coulomb` or :class:`Tresca` law.
* :func:`solve_load_steps` — drive a problem through a load with cut-backs
  (:class:`LoadSteppingError` when it cannot); :class:`ContactOutput` writes the fields
  for ParaView.
* :class:`Material` and :func:`internal_work` — the bulk residual of hyperelastic bodies.
* :func:`merge_meshes` — several bodies, each its own mesh, as one mesh with tags.
* :func:`reaction_force` — the total force a Dirichlet condition exerts on a tagged
  boundary, from the bulk residual.
* :class:`MortarInterface` — D, M, weighted gaps and their exact derivatives for one
  slave/master pair of facet-tagged surfaces, in PETSc layouts; :class:`MeshTying`
  ties non-matching subdomains with them.
* :mod:`dolfinx_mortar.meshes`, :mod:`dolfinx_mortar.meshes3d` — gmsh builders of the
  benchmark geometries.

Everything but :class:`ContactOptions`, :class:`Coulomb` and :class:`Tresca` loads on
first use: the kernels (:mod:`dolfinx_mortar.kernels`, compiled C through cffi, and
:mod:`dolfinx_mortar.dual`) import without dolfinx.
"""

from __future__ import annotations

import importlib

from .options import ContactOptions, Coulomb, Tresca

__version__ = "0.1.0"

# dolfinx-dependent names load on first use, so that the kernels
# (dolfinx_mortar.kernels, dolfinx_mortar.dual) import without dolfinx
_LAZY = {
    "ContactProblem": "problem",
    "ContactPair": "problem",
    "SolveReport": "solvers",
    "ContactWarning": "diagnostics",
    "solve_load_steps": "loading",
    "LoadSteppingError": "loading",
    "StepRecord": "loading",
    "ContactOutput": "loading",
    "configure_logging": "loading",
    "Material": "materials",
    "internal_work": "materials",
    "merge_meshes": "bodies",
    "reaction_force": "reactions",
    "ContactSurface": "surface",
    "SurfaceError": "surface",
    "MeshTying": "tying",
    "MortarInterface": "mortar",
    "MortarStatistics": "mortar",
}

__all__ = [
    "ContactOptions", "ContactOutput", "ContactPair", "ContactProblem", "ContactSurface",
    "ContactWarning", "Coulomb", "LoadSteppingError", "Material", "MeshTying",
    "MortarInterface", "MortarStatistics", "SolveReport", "StepRecord", "SurfaceError",
    "Tresca", "__version__", "configure_logging", "internal_work", "merge_meshes",
    "reaction_force", "solve_load_steps",
]


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
