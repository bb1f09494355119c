"""The 3D mortar kernel: triangle and quadrilateral facets, segment- and element-based.

Per candidate pair (Puso and Laursen 2004; Popp, Gee and Wall 2009): an auxiliary plane
through the slave facet centre with the unit normal of the normal field there; the slave and
master nodes projected onto it; the two convex polygons clipped (Sutherland-Hodgman), the clip
polygon split into triangles around its vertex mean, and D, M, Dn, Mn, the nodal areas and the
weighted gaps integrated over those cells with their exact derivatives. Element-based
integration (``integration="element"``) instead takes the Gauss points of the slave facet,
projects each along the normal field onto the master facet and keeps the points that land on
it; each point goes to one master facet only (the one it lands on most centrally).

The variables of a pair, in this order: slave node coordinates (ns x 3), master node
coordinates (nm x 3), slave nodal normals (ns x 3). The normal field is n(xi) = sum_j N_j(xi)
n_j (not renormalized, as the paper): with ``normals="averaged"`` the n_j are the given nodal
normals; with ``"slave"`` the slave facet's unit normals at its corners; with ``"master"``
minus the master facet's unit normal at its centre, at every slave node.

The computation is the compiled kernel's (``surface3.c`` through :mod:`.compiled`, glued to
the contract by :mod:`.surface3_compiled`, whose docstring says how); this module is its entry
point. A vectorized numpy version of the same integrals is the tests' oracle
(``tests/oracle/surface3_numpy.py``), not part of the package.
"""

from __future__ import annotations

import numpy as np

from . import compiled, surface3_compiled
from .contract import KernelOptions, PairGeometry, PairQuantities

DEFAULT_GAUSS_POINTS = 7
"""Points of the triangle rule per integration cell (segment) or slave triangle (element)."""


def _refuse(geometry: PairGeometry, options: KernelOptions) -> None:
    """Raise the ValueError that says why the kernel does not take these pairs or options."""
    none = geometry.part(slice(0, 0))  # the shapes, nothing gathered
    slave_x, master_x, normals = none.slave_x, none.master_x, none.slave_normals
    if (slave_x.ndim != 3 or master_x.ndim != 3 or slave_x.shape[2] != 3
            or master_x.shape[2] != 3 or slave_x.shape[1] not in (3, 4)
            or master_x.shape[1] not in (3, 4)
            or (normals is not None and normals.shape != slave_x.shape)):
        raise ValueError("the 3D kernel takes (n, 3 or 4, 3) slave and master facets "
                         "(triangles or quadrilaterals) and slave normals of the slave "
                         f"facets' shape; got (n, ...) = {slave_x.shape[1:]}, "
                         f"{master_x.shape[1:]} and "
                         f"{None if normals is None else normals.shape[1:]}")
    rule = options.num_gauss_points or DEFAULT_GAUSS_POINTS
    if options.integration == "segment":
        raise ValueError(f"3D segments take 1, 3 or 7 Gauss points per cell, got {rule}")
    compiled._facet_rule(slave_x.shape[1], rule)  # (raises: the rules a facet takes)
    raise ValueError(f"element-based integration does not take {rule} Gauss points")


class Surface3Kernel:
    """The 3D kernel behind the contract (:class:`~.contract.MortarKernel`): takes the
    slave nodal normals of :class:`~.contract.PairGeometry` as variables (zeros will do
    for the ``slave`` and ``master`` normal options); no neighbours. The pairs go to the
    compiled kernel (:mod:`.surface3_compiled`: values now, gradients on demand); pairs or a
    Gauss rule it does not take raise a ValueError that says which it takes."""

    gdim = 3
    default_gauss_points = {"segment": DEFAULT_GAUSS_POINTS, "element": DEFAULT_GAUSS_POINTS}

    def evaluate(self, geometry: PairGeometry, options: KernelOptions, *,
                 crosspoint: np.ndarray | None = None,
                 slave_facet: np.ndarray | None = None) -> PairQuantities:
        if not surface3_compiled.covers(geometry, options):
            _refuse(geometry, options)
        return surface3_compiled.evaluate(geometry, options, crosspoint, slave_facet)
