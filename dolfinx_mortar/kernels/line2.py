"""The 2D mortar kernel: two-node facets, every pair of a batch at once.

Per candidate (slave facet, master facet) pair it computes the pair's contributions to the
mortar quantities of Hammer's paper (sections 3-5), with their exact derivatives:

    D_jk    = int Phi_j N_k                 slave x slave
    M_jl    = int Phi_j N^_l                slave x master
    Dn_jk   = int Phi_j N_k  n              the same with the normal inside,
    Mn_jl   = int Phi_j N^_l n              as eq. (1) and (2) of the paper need
    g_j     = int Phi_j n . (x^(2) - x^(1))  weighted gap = Mn_jl.x_l - Dn_jk.x_k

The integrals run over the slave facet (its parameter xi in [-1, 1]); n is the chosen normal
field, interpolated with the slave shape functions as in the paper (n = sum_j N_j n_j, not
renormalized).

The 12 variables of a pair are the coordinates of six nodes, in this order: ``p, a, b, q, c,
d``: ``a -> b`` the slave facet, ``p`` and ``q`` the other ends of the slave facets adjacent at
``a`` and ``b`` (they enter averaged nodal normals), ``c -> d`` the master facet. Facets are
oriented so that ``(t_y, -t_x)`` with ``t = end - start`` points out of their body.

The computation is the compiled kernel's (``line2.c`` through :mod:`.compiled`, glued to the
contract by :mod:`.line2_compiled`); this module is its entry point. The Gauss rules and the
dual basis are :mod:`.line2_rules`. A vectorized numpy version of the same integrals is the
tests' oracle (``tests/oracle/line2_numpy.py``), not part of the package.
"""

from __future__ import annotations

import numpy as np

from . import line2_compiled
from .contract import (
    BasisOption,
    IntegrationOption,
    KernelOptions,
    NormalOption,
    PairGeometry,
    PairQuantities,
)
from .line2_rules import DEFAULT_GAUSS_POINTS

NUM_PAIR_VARIABLES = line2_compiled.NUM_VARIABLES


def pair_quantities(
    x: np.ndarray,
    has_neighbour: np.ndarray,
    *,
    normals: NormalOption = "averaged",
    integration: IntegrationOption = "segment",
    basis: BasisOption = "standard",
    num_gauss_points: int = 3,
    crosspoint: np.ndarray | None = None,
    slave_facet: np.ndarray | None = None,
) -> PairQuantities:
    """Mortar contributions of every pair, with derivatives.

    Args:
        x: (n, 6, 2) current coordinates of the nodes ``p, a, b, q, c, d``.
        has_neighbour: (n, 2) bool, whether ``p`` and ``q`` exist.
        normals: which normal field (paper, section 3).
        integration: ``segment`` integrates over the overlap found by
            projecting the master nodes onto the slave facet ("integration by
            clipping", exact for the polynomials of the mortar integrands);
            ``element`` uses fixed Gauss points on the slave facet and keeps
            those whose projection lands on the master facet ("concentrated").
        basis: multiplier basis Phi; ``dual`` is biorthogonal to N on the
            whole slave facet (see :func:`.line2_rules.dual_basis_coefficients`), pair by pair;
            :class:`~dolfinx_mortar.mortar.MortarInterface` instead builds it over the
            covered part of each slave facet from this kernel's standard outputs
            (:mod:`dolfinx_mortar.covered`).
        num_gauss_points: Gauss points per segment (or per slave facet).
        crosspoint: (n, 2) bool, slave nodes a, b that carry no multiplier
            (their displacement is prescribed). Their basis function is added
            to the other node's on the facet, so sum_j Phi_j = 1 still holds
            (constants stay representable: the patch test passes) and the
            system stays regular (a dual Phi at a crosspoint is orthogonal to
            every linear function vanishing there and would couple to nothing).
        slave_facet: (n,) which slave facet each pair belongs to; element-based
            integration gives each slave Gauss point to one master facet only
            (a point on a shared master node would otherwise count twice, or
            not at all after rounding). Default: every pair is a facet of its
            own (no sharing decided).

    The gradients of ``Dn``, ``Mn``, ``gap`` and ``area`` are
    :class:`~dolfinx_mortar.dual.RowSubsetDual`: zero outside the pairs that
    contribute, which are kept apart (``rows``, ``grad_rows``) for assembly.
    """
    options = KernelOptions(normals=normals, integration=integration, basis=basis,
                            num_gauss_points=num_gauss_points)
    x = np.asarray(x, dtype=np.float64).reshape(-1, 6, 2)
    geometry = PairGeometry(slave_x=x[:, 1:3], master_x=x[:, 4:6], neighbour_x=x[:, [0, 3]],
                            has_neighbour=has_neighbour)
    return Line2Kernel().evaluate(geometry, options, crosspoint=crosspoint,
                                  slave_facet=slave_facet)


class Line2Kernel:
    """The 2D kernel behind the contract (:class:`~.contract.MortarKernel`): the
    neighbours p, q of :class:`~.contract.PairGeometry` (``neighbour_x``,
    ``has_neighbour``) enter the averaged normals; no ``slave_normals``. Every option runs
    the compiled kernel (:mod:`.line2_compiled`: values and gradients kept, in
    :class:`~.line2_compiled.FullGradients`)."""

    gdim = 2
    default_gauss_points = DEFAULT_GAUSS_POINTS

    def evaluate(self, geometry: PairGeometry, options: KernelOptions, *,
                 crosspoint: np.ndarray | None = None,
                 slave_facet: np.ndarray | None = None) -> PairQuantities:
        if geometry.neighbour_x is None or geometry.has_neighbour is None:
            raise ValueError("the 2D kernel takes the slave facets' neighbours "
                             "(PairGeometry.neighbour_x, has_neighbour)")
        points = options.num_gauss_points or self.default_gauss_points[options.integration]
        return line2_compiled.evaluate(geometry, options, points, crosspoint=crosspoint,
                                       slave_facet=slave_facet)
