"""The numpy oracle's factorized gradients: derivatives kept in the form its kernels make them.

The oracle's kernels (:mod:`.line2_numpy`, :mod:`.surface3_numpy`) differentiate their
integrands by hand with respect to a few intermediate quantities and keep the gradients so,
expanded to the pair's variables only when asked. The package's compiled kernels keep theirs
in full (2D) or make them again on demand (3D); the stencils read the oracle's through the
same contract (:class:`~dolfinx_mortar.kernels.contract.PairQuantities`).

- :class:`AffineFactors` (3D, triangle on triangle with averaged normals): gradients over
  the 12 plane coordinates and their chain to the pair's variables; the result's ``Dn``,
  ``Mn`` and ``area`` expand them on first use (:meth:`AffineFactors.expanded`).
"""

from __future__ import annotations

import numpy as np


class AffineFactors:
    """The gradients of Dn, the areas and Mn of triangle pairs with averaged normals, kept
    as the oracle's ``_affine_integrals`` makes them: over the 12 plane coordinates of the
    slave and master nodes (``local``, (r, 57, 12): Dn (j, k, c), area (j), Mn (j, l, c)),
    the chain of the plane coordinates to the pair's 27 variables (``chain``,
    (r, 12, 27)), and what multiplies each nodal normal in Dn and Mn (``slave_weights``
    (r, j, k, i), ``master_weights`` (r, j, l, i): d Dn_jk[c] / d n_i[c]); rows are those
    of the result's ``rows`` (the pairs kept).
    """

    def __init__(self, num_rows: int, ns: int, nm: int, nvar: int):
        self.ns, self.nm, self.nvar = ns, nm, nvar
        self.local = np.empty((num_rows, ns * ns * 3 + ns + ns * nm * 3, 2 * (ns + nm)))
        self.chain = np.empty((num_rows, 2 * (ns + nm), nvar))
        self.slave_weights = np.empty((num_rows, ns, ns, ns))
        self.master_weights = np.empty((num_rows, ns, nm, ns))

    def put(self, position, factors: dict) -> None:
        """Store the factors of the kept rows ``position`` (a batch of ``_affine_integrals``)."""
        for name, array in factors.items():
            getattr(self, name)[position] = array

    @property
    def offsets(self) -> dict:
        """The first row of Dn, area and Mn in ``local``."""
        ns = self.ns
        return {"Dn": 0, "area": 3 * ns * ns, "Mn": 3 * ns * ns + ns}

    def expanded(self, name: str) -> np.ndarray:
        """The gradient of Dn, Mn or area over the pair's variables (the kernel's product and
        the normals' scatter, as the oracle's ``_affine_integrals`` applies them)."""
        ns, nm, nvar = self.ns, self.nm, self.nvar
        r = self.local.shape[0]
        k = {"Dn": 3 * ns * ns, "area": ns, "Mn": 3 * ns * nm}[name]
        start = self.offsets[name]
        # the kernel's product of all rows at once (the same bits), then the rows of name
        grad = np.ascontiguousarray((self.local @ self.chain)[:, start:start + k])
        if name == "area":
            return grad.reshape(r, ns, nvar)
        count = ns if name == "Dn" else nm
        grad = grad.reshape(r, ns, count, 3, nvar)
        weights = self.slave_weights if name == "Dn" else self.master_weights
        first = nvar - 3 * ns
        for c in range(3):
            grad[..., c, first + c::3] += weights
        return grad
