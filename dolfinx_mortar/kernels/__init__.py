"""Mortar kernels, one module per facet dimension behind one contract.

A kernel is a plain numpy function of the coordinates of a batch of
(slave facet, master facet) pairs: no MPI, no PETSc, no dolfinx. It returns
the pairs' contributions to D, M, Dn, Mn, the weighted gaps and the nodal
areas with their exact derivatives with respect to the pair's variables.

- :mod:`.line2`: 2D, two-node facets (projection and interval clipping);
  its variables are the six nodes ``p, a, b, q, c, d`` of a pair.
- :mod:`.surface3`: 3D, triangle and quadrilateral facets (auxiliary plane,
  polygon clipping, triangulated integration cells); its variables are the
  slave facet nodes, the master facet nodes and the slave nodal normals,
  whose own derivatives come from :mod:`dolfinx_mortar.normals`.

The names of :mod:`.line2` are re-exported here: ``kernels.pair_quantities``
is the 2D kernel.
"""

from .line2 import (
    BASIS_OPTIONS,
    INTEGRATION_OPTIONS,
    NODE_ORDER,
    NORMAL_OPTIONS,
    NUM_PAIR_VARIABLES,
    BasisOption,
    IntegrationOption,
    NormalOption,
    PairGradients,
    PairQuantities,
    _pair_quantities,
    dual_basis_coefficients,
    element_normal,
    gauss_legendre,
    nodal_normals,
    pair_quantities,
)

__all__ = [
    "BASIS_OPTIONS",
    "INTEGRATION_OPTIONS",
    "NODE_ORDER",
    "NORMAL_OPTIONS",
    "NUM_PAIR_VARIABLES",
    "BasisOption",
    "IntegrationOption",
    "NormalOption",
    "PairGradients",
    "PairQuantities",
    "_pair_quantities",
    "dual_basis_coefficients",
    "element_normal",
    "gauss_legendre",
    "nodal_normals",
    "pair_quantities",
]
