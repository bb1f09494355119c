"""The numpy oracle's factorized gradients: derivatives kept in the form its kernels make them.

The oracle's kernels (:mod:`.line2_numpy`, :mod:`.surface3_numpy`) differentiate their
integrands by hand with respect to a few intermediate quantities and keep the gradients so,
expanded to the pair's variables only when asked. The package's compiled kernels keep theirs
in full (2D) or make them again on demand (3D); the stencils read the oracle's through the
same contract (:class:`~dolfinx_mortar.kernels.contract.PairQuantities`).

- :class:`FactorizedPairGradients` (2D): coefficients on the gradients of a few pair-level
  quantities (segment limits, facet Jacobian, nodal normals), combined before they are
  expanded (:meth:`FactorizedPairGradients.combine`), the result's ``segment_gradients``.
- :class:`AffineFactors` (3D, triangle on triangle with averaged normals): gradients over
  the 12 plane coordinates and their chain to the pair's variables; the result's ``Dn``,
  ``Mn`` and ``area`` expand them on first use (:meth:`AffineFactors.expanded`).
"""

from __future__ import annotations

import numpy as np


class FactorizedPairGradients:
    """Derivatives of the 24 outputs of each contributing pair, factorized
    (:class:`~dolfinx_mortar.kernels.PairGradients`, as the 2D oracle's ``_integrate`` makes
    them).

    Outputs: ``Dn`` (0-7, index 4 j + 2 k + c), ``Mn`` (8-15, 8 + 4 j + 2 l + c),
    ``area`` (16, 17), ``gap`` (18, 19), ``D`` (20-23, 20 + 2 j + k: the covered dual
    basis of :mod:`dolfinx_mortar.covered` needs it). The derivative of output o with
    respect to the 12 pair variables is

        sum_k coefficients[o, k] directions[k] + direct[o] on (x_a, x_b, x_c, x_d)

    where the directions are the gradients (12, n) of a few pair-level
    quantities (segment limits, facet Jacobian, nodal normals), each nonzero
    only on the variable rows ``direction_rows[k]``; only ``Mn`` and ``gap``
    have direct terms. :meth:`combine` forms any linear combination of
    outputs before expanding it to 12 variables, so a consumer that needs,
    say, sum_j z_j Dn_j pays for 8 gradients, not 16. The pairs come in the
    batches they were integrated in: ``parts`` is a list of (start, stop,
    coefficients (24, directions, batch), directions (list of (12, batch)),
    direct (10, 8, batch): Mn then gap).
    """

    DN, MN, AREA, GAP = 0, 8, 16, 18

    def __init__(self, num_pairs: int, direction_rows, parts):
        self.num_pairs = num_pairs
        self.direction_rows = direction_rows
        self.parts = parts

    @staticmethod
    def _direct_row(o: int) -> int | None:
        if 8 <= o < 16:
            return o - 8
        return o - 10 if 18 <= o < 20 else None

    def combine(self, terms) -> np.ndarray:
        """(len(terms), 12, n): row p sums weight * d output / dx over (output, weight) in terms[p].

        A weight is a number or an (n,) array.
        """
        result = np.empty((len(terms), 12, self.num_pairs))
        for start, stop, coefficients, directions, direct in self.parts:
            scratch = np.empty((12, stop - start))
            for p, row in enumerate(terms):
                weights = [w if np.ndim(w) == 0 else w[start:stop] for _, w in row]
                outputs = [o for o, _ in row]
                pairs = list(zip(outputs, weights, strict=True))
                coefficient = sum(coefficients[o] * w for o, w in pairs)
                out = result[p, :, start:stop]
                out[...] = 0.0
                for k, (lo, hi) in enumerate(self.direction_rows):
                    part = scratch[lo:hi]
                    np.multiply(directions[k][lo:hi], coefficient[k], out=part)
                    out[lo:hi] += part
                for o, w in pairs:
                    d = self._direct_row(o)
                    if d is not None:
                        out[2:6] += direct[d, 0:4] * w
                        out[8:12] += direct[d, 4:8] * w
        return result

    def outputs(self, start: int, stop: int) -> np.ndarray:
        """(n, stop - start, 12): the gradients of outputs start .. stop - 1."""
        rows = self.combine([[(o, 1.0)] for o in range(start, stop)])
        return np.ascontiguousarray(rows.transpose(2, 0, 1))


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
