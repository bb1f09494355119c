"""Mortar kernels, one module per facet dimension behind one contract.

A kernel is a computation over the coordinates of a batch of (slave facet, master facet)
pairs: numpy arrays in and out, no MPI, no PETSc, no dolfinx. It returns the pairs'
contributions to D, M, Dn, Mn, the weighted gaps and the nodal areas with their exact
derivatives with respect to the pair's variables.

- :mod:`.contract`: what every kernel takes and returns
  (:class:`MortarKernel`, :class:`PairGeometry`, :class:`KernelOptions`,
  :class:`PairQuantities`, and the forms a result's gradients come in:
  :class:`PairGradients` in 2D, ``GradientsOnDemand`` in 3D).
- :mod:`.line2` (:class:`Line2Kernel`): 2D, two-node facets (projection and
  interval clipping); its variables are the six nodes ``p, a, b, q, c, d`` of a pair.
- :mod:`.surface3` (:class:`Surface3Kernel`): 3D, triangle and quadrilateral
  facets (auxiliary plane, polygon clipping, triangulated integration cells);
  its variables are the slave facet nodes, the master facet nodes and the slave
  nodal normals, whose own derivatives come from :mod:`dolfinx_mortar.normals`.

Each has one implementation, C compiled at first use through cffi and cached
(:mod:`.compiled`; ``line2.c``, ``surface3.c``; glued to the contract by
:mod:`.line2_compiled` and :mod:`.surface3_compiled`), as dolfinx compiles its form kernels:
it needs a C compiler and cffi, which dolfinx's form compilation needs anyway. The vectorized
numpy kernels that came first are the tests' oracle (``tests/oracle``), outside the package:
kept in it behind an option, they were a second implementation to keep right that no run
used.

``pair_quantities`` here is the 2D kernel's function of one coordinate array per
pair (:func:`.line2.pair_quantities`), kept for the tests and scripts that call it so.
"""

from . import line2, surface3
from .contract import (
    BASIS_OPTIONS,
    INTEGRATION_OPTIONS,
    NORMAL_OPTIONS,
    BasisOption,
    IntegrationOption,
    KernelOptions,
    MortarKernel,
    NormalOption,
    PairGeometry,
    PairGradients,
    PairQuantities,
)
from .line2 import NUM_PAIR_VARIABLES, Line2Kernel, pair_quantities
from .line2_rules import dual_basis_coefficients, gauss_legendre
from .surface3 import Surface3Kernel

__all__ = [
    "BASIS_OPTIONS",
    "INTEGRATION_OPTIONS",
    "NORMAL_OPTIONS",
    "NUM_PAIR_VARIABLES",
    "BasisOption",
    "IntegrationOption",
    "KernelOptions",
    "Line2Kernel",
    "MortarKernel",
    "NormalOption",
    "PairGeometry",
    "PairGradients",
    "PairQuantities",
    "Surface3Kernel",
    "dual_basis_coefficients",
    "gauss_legendre",
    "line2",
    "pair_quantities",
    "surface3",
]
