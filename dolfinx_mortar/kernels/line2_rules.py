"""The rules of the 2D kernel that are not C (:mod:`.line2`, :mod:`.line2_compiled`,
:mod:`.compiled`): the Gauss rules, the whole-facet dual basis and the element-based
assignment of slave Gauss points to master facets. A module of its own so that the compiled
glue, which :mod:`.line2` dispatches to, need not import it back; the tests' numpy oracle
(``tests/oracle/line2_numpy.py``) takes them from here too."""

from __future__ import annotations

import numpy as np

DEFAULT_GAUSS_POINTS = {"segment": 3, "element": 4}


def gauss_legendre(num_points: int) -> tuple[np.ndarray, np.ndarray]:
    """Points and weights on [-1, 1]; exact for polynomials of degree 2 n - 1."""
    if num_points < 1:
        raise ValueError(f"number of Gauss points must be >= 1, got {num_points}")
    return np.polynomial.legendre.leggauss(num_points)


def dual_basis_coefficients(jacobian_at_points=None, num_gauss_points: int = 2) -> np.ndarray:
    """Coefficients A with Phi = A N, biorthogonal on the whole slave facet.

    A = D_e M_e^-1 with D_e = diag(int N_k) and M_e = int N N^T over the full
    facet. For a linear facet the Jacobian is constant and cancels, so A is
    the same for every facet, long or short: [[2, -1], [-1, 2]]
    (Phi_1 = (1 - 3 xi)/2, Phi_2 = (1 + 3 xi)/2). The coefficients are taken
    on the whole facet, not on the part in contact, so they do not depend on
    the contact state; on a partly covered facet D keeps off-diagonal terms
    and a nodal weight can be <= 0 (the interface uses the covered version of
    :mod:`dolfinx_mortar.covered` instead).
    """
    points, weights = gauss_legendre(num_gauss_points)
    if jacobian_at_points is None:
        jacobian = np.ones_like(points)
    else:
        jacobian = np.asarray(jacobian_at_points)
    N = np.stack([(1.0 - points) / 2.0, (1.0 + points) / 2.0], axis=-1)
    w = weights * jacobian
    mass = np.einsum("g,gj,gk->jk", w, N, N)
    lumped = np.diag(np.einsum("g,gk->k", w, N))
    return lumped @ np.linalg.inv(mass)


DUAL_COEFFICIENTS = dual_basis_coefficients()


def one_master_facet_per_point(
    eta: np.ndarray, valid: np.ndarray, slave_facet: np.ndarray
) -> np.ndarray:
    """(n, g) mask: each Gauss point of a slave facet goes to the master facet it
    projects into most centrally (smallest |eta|, within 1e-12 of [-1, 1])."""
    num_pairs, num_points = eta.shape
    score = np.where((np.abs(eta) <= 1.0 + 1e-12) & valid[:, None], np.abs(eta), np.inf).ravel()
    key = np.repeat(slave_facet * num_points, num_points)
    key += np.tile(np.arange(num_points), num_pairs)
    order = np.lexsort((score, key))
    first = np.ones(order.size, dtype=bool)
    first[1:] = key[order][1:] != key[order][:-1]
    winner = np.zeros(order.size, dtype=bool)
    winner[order[first]] = True
    return (winner & np.isfinite(score)).reshape(num_pairs, num_points)
