"""Factorized gradients: derivatives kept in the form a kernel makes them.

Most consumers need linear combinations of a pair's output gradients (sum_j z_j Dn_j,
the gap rows, ...), not every output's gradient over every variable. A kernel may keep
its gradients in a cheaper form that combines outputs before expanding them:

- :class:`PairGradients` (2D): the interface of a 2D kernel's gradients
  (:meth:`~PairGradients.combine`, :meth:`~PairGradients.outputs`), which the compiled
  kernel's :class:`~.line2_compiled.FullGradients` implements over full gradients; this
  class itself holds the tests' numpy oracle's (``tests/oracle/line2_numpy.py``):
  coefficients on the gradients of a few pair-level quantities (segment limits, facet
  Jacobian, nodal normals).

The 3D kernel makes its gradients again on demand instead (:mod:`.surface3_compiled`).
They are the typed optional parts of :class:`~dolfinx_mortar.kernels.contract.
PairQuantities`; the stencils (:mod:`dolfinx_mortar.stencils`) read them.
"""

from __future__ import annotations

import numpy as np


class PairGradients:
    """Derivatives of the 24 outputs of each contributing pair, factorized.

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
