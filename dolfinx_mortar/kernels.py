"""Geometry and integration kernels of 2D mortar contact, batched over all pairs.

Everything here is a plain numpy function of coordinate arrays: no MPI, no
PETSc, no dolfinx. One call handles every candidate (slave facet, master facet)
pair at once and returns the pair's contributions to the mortar quantities of
Hammer's paper (sections 3-5), with their exact derivatives (:mod:`dual`):

    D_jk    = int Phi_j N_k                 slave x slave
    M_jl    = int Phi_j N^_l                slave x master
    Dn_jk   = int Phi_j N_k  n              the same with the normal inside,
    Mn_jl   = int Phi_j N^_l n              as eq. (1) and (2) of the paper need
    g_j     = int Phi_j n . (x^(2) - x^(1))  weighted gap = Mn_jl.x_l - Dn_jk.x_k

The integrals run over the slave facet (its parameter xi in [-1, 1]); n is
the chosen normal field, interpolated with the slave shape functions as in
the paper (n = sum_j N_j n_j, not renormalized).

The 12 variables of a pair are the coordinates of six nodes, in this order:
``p, a, b, q, c, d``: ``a -> b`` the slave facet, ``p`` and ``q`` the other
ends of the slave facets adjacent at ``a`` and ``b`` (they enter averaged
nodal normals), ``c -> d`` the master facet. Facets are oriented so that
``(t_y, -t_x)`` with ``t = end - start`` points out of their body.
"""

from __future__ import annotations

import dataclasses
import typing

import numpy as np

from . import dual
from .dual import Dual

NODE_ORDER = ("p", "a", "b", "q", "c", "d")
NUM_PAIR_VARIABLES = 12

NormalOption = typing.Literal["averaged", "slave", "master"]
IntegrationOption = typing.Literal["segment", "element"]
BasisOption = typing.Literal["standard", "dual"]

NORMAL_OPTIONS = ("averaged", "slave", "master")
INTEGRATION_OPTIONS = ("segment", "element")
BASIS_OPTIONS = ("standard", "dual")

_FACING_TOLERANCE = 1e-8
_PARALLEL_TOLERANCE = 1e-10


@dataclasses.dataclass
class PairQuantities:
    """Mortar contributions of a batch of pairs (arrays lead with the pair axis).

    ``D``, ``M``: (n, 2, 2) values; ``Dn``, ``Mn``: (n, 2, 2, 2) Duals
    (slave node j, node k or l, component); ``gap``: (n, 2) Dual;
    ``area``: (n, 2) Dual, int Phi_j over the overlap (= sum_k D_jk);
    ``valid``: (n,) pairs that face each other and overlap;
    ``overlap``: (n,) length of the overlap in the slave parameter (0 to 2).
    """

    D: np.ndarray
    M: np.ndarray
    Dn: Dual
    Mn: Dual
    gap: Dual
    area: Dual
    valid: np.ndarray
    overlap: np.ndarray


def gauss_legendre(num_points: int) -> tuple[np.ndarray, np.ndarray]:
    """Points and weights on [-1, 1]; exact for polynomials of degree 2 n - 1."""
    if num_points < 1:
        raise ValueError(f"number of Gauss points must be >= 1, got {num_points}")
    return np.polynomial.legendre.leggauss(num_points)


def element_normal(start, end):
    """Unit normal (t_y, -t_x)/|t| of the segment start -> end (Dual or array)."""
    tangent = end - start
    if isinstance(tangent, Dual):
        length = dual.sqrt(dual.dot(tangent, tangent))
        rotated = dual.stack([tangent[..., 1], -tangent[..., 0]], axis=-1)
        return rotated / length[..., None]
    length = np.linalg.norm(tangent, axis=-1, keepdims=True)
    return np.stack([tangent[..., 1], -tangent[..., 0]], axis=-1) / length


def _normalize(vector: Dual) -> Dual:
    return vector / dual.sqrt(dual.dot(vector, vector))[..., None]


def nodal_normals(x: Dual, has_neighbour: np.ndarray, normals: NormalOption) -> tuple[Dual, Dual]:
    """Normals of the slave normal field at the slave nodes a and b of each pair.

    ``averaged``: the normalized arithmetic mean of the unit normals of the
    two slave facets meeting at the node (paper, section 3); a node at the end
    of the surface keeps its one facet's normal. ``slave``: the slave facet's
    normal at both nodes. ``master``: minus the master facet's normal.
    """
    xp, xa, xb, xq, xc, xd = (x[:, 2 * i : 2 * i + 2] for i in range(6))
    if normals == "master":
        normal = -element_normal(xc, xd)
        return normal, normal
    normal_ab = element_normal(xa, xb)
    if normals == "slave":
        return normal_ab, normal_ab
    if normals != "averaged":
        raise ValueError(f"unknown normal option {normals!r}; expected one of {NORMAL_OPTIONS}")
    left = has_neighbour[:, 0]
    right = has_neighbour[:, 1]
    # an absent neighbour is given the coordinates of a neighbour-less facet;
    # it is multiplied by zero, and its variables get zero derivatives
    normal_pa = element_normal(dual.where(left[:, None], xp, xa - (xb - xa)), xa)
    normal_bq = element_normal(xb, dual.where(right[:, None], xq, xb + (xb - xa)))
    normal_a = _normalize(normal_ab + normal_pa * left[:, None].astype(float))
    normal_b = _normalize(normal_ab + normal_bq * right[:, None].astype(float))
    return normal_a, normal_b


def _project_onto_slave(s0: Dual, s1: Dual, n0: Dual, n1: Dual, point: Dual) -> tuple[Dual, np.ndarray]:
    """Slave parameter xi where the normal line through x_s(xi) meets ``point``.

    Solves (s0 + xi s1 - point) x (n0 + xi n1) = 0, quadratic in xi, and takes
    the root nearest to the facet with the cancellation-free formula.
    """
    offset = s0 - point
    c = dual.cross(offset, n0)
    b = dual.cross(offset, n1) + dual.cross(s1, n0)
    a = dual.cross(s1, n1)
    discriminant = b * b - a * c * 4.0
    ok = discriminant.value >= 0.0
    safe = dual.where(ok, discriminant, Dual.constant(np.zeros_like(discriminant.value), b.grad.shape[-1]))
    sign = np.where(b.value >= 0.0, 1.0, -1.0)
    denominator = b + dual.sqrt(safe) * sign
    scale = np.linalg.norm(s1.value, axis=-1) * np.linalg.norm(n0.value, axis=-1)
    ok &= np.abs(denominator.value) > _PARALLEL_TOLERANCE * scale
    denominator = dual.where(ok, denominator, Dual.constant(np.ones_like(b.value), b.grad.shape[-1]))
    return c * (-2.0) / denominator, ok


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
            whole slave facet (see :func:`dual_basis_coefficients`).
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
    """
    if integration not in INTEGRATION_OPTIONS:
        raise ValueError(f"unknown integration {integration!r}; expected one of {INTEGRATION_OPTIONS}")
    if basis not in BASIS_OPTIONS:
        raise ValueError(f"unknown multiplier basis {basis!r}; expected one of {BASIS_OPTIONS}")
    x = np.asarray(x, dtype=np.float64)
    num_pairs = x.shape[0]
    has_neighbour = np.asarray(has_neighbour, dtype=bool).reshape(num_pairs, 2)
    X = Dual.variables(x.reshape(num_pairs, NUM_PAIR_VARIABLES))
    nvars = NUM_PAIR_VARIABLES
    xa, xb, xc, xd = (X[:, 2 * i : 2 * i + 2] for i in (1, 2, 4, 5))

    normal_a, normal_b = nodal_normals(X, has_neighbour, normals)
    s0, s1 = (xa + xb) * 0.5, (xb - xa) * 0.5
    n0, n1 = (normal_a + normal_b) * 0.5, (normal_b - normal_a) * 0.5
    m0, m1 = (xc + xd) * 0.5, (xd - xc) * 0.5

    facing = np.einsum("ni,ni->n", element_normal(xa.value, xb.value), element_normal(xc.value, xd.value))
    valid = facing < -_FACING_TOLERANCE

    points, weights = gauss_legendre(num_gauss_points)
    if integration == "segment":
        xi_c, ok_c = _project_onto_slave(s0, s1, n0, n1, xc)
        xi_d, ok_d = _project_onto_slave(s0, s1, n0, n1, xd)
        valid &= ok_c & ok_d
        minus_one = Dual.constant(-np.ones(num_pairs), nvars)
        plus_one = Dual.constant(np.ones(num_pairs), nvars)
        low = dual.maximum(minus_one, dual.minimum(xi_c, xi_d))
        high = dual.minimum(plus_one, dual.maximum(xi_c, xi_d))
        length = high - low
        overlapping = (length.value > 0.0) & valid
        length = dual.where(overlapping, length, Dual.constant(np.zeros(num_pairs), nvars))
        low = dual.where(overlapping, low, minus_one)
        xi = low[:, None] + (length * 0.5)[:, None] * (points + 1.0)[None, :]
        weight = (length * 0.5)[:, None] * weights[None, :]
    else:
        xi = Dual.constant(np.broadcast_to(points, (num_pairs, num_gauss_points)), nvars)
        weight = Dual.constant(np.broadcast_to(weights, (num_pairs, num_gauss_points)), nvars)

    jacobian = dual.sqrt(dual.dot(s1, s1))
    N = dual.stack([(1.0 - xi) * 0.5, (xi + 1.0) * 0.5], axis=-1)  # (n, g, 2)
    slave_point = N[..., 0:1] * xa[:, None, :] + N[..., 1:2] * xb[:, None, :]
    normal = N[..., 0:1] * normal_a[:, None, :] + N[..., 1:2] * normal_b[:, None, :]
    cross_m1 = dual.cross(m1[:, None, :], normal)
    parallel = np.abs(cross_m1.value) <= _PARALLEL_TOLERANCE * np.linalg.norm(m1.value, axis=-1)[:, None]
    cross_m1 = dual.where(parallel, Dual.constant(np.ones_like(cross_m1.value), nvars), cross_m1)
    eta = -dual.cross(m0[:, None, :] - slave_point, normal) / cross_m1
    valid &= ~parallel.any(axis=1)

    weight = weight * jacobian[:, None]
    if integration == "element":
        if slave_facet is None:
            slave_facet = np.arange(num_pairs)
        on_master = _one_master_facet_per_point(eta.value, valid, np.asarray(slave_facet).reshape(-1))
        overlapping = on_master.any(axis=1)
        overlap = np.where(on_master, weights, 0.0).sum(axis=1)
    else:
        overlapping &= valid
        on_master = np.broadcast_to(overlapping[:, None], eta.value.shape)
        overlap = np.where(overlapping, length.value, 0.0)
    weight = weight * on_master.astype(float)
    N_master = dual.stack([(1.0 - eta) * 0.5, (eta + 1.0) * 0.5], axis=-1)
    if basis == "dual":
        Phi = _apply_dual_coefficients(N)
    else:
        Phi = N
    if crosspoint is not None:
        Phi = _merge_crosspoints(Phi, np.asarray(crosspoint, dtype=bool).reshape(num_pairs, 2))

    weighted_phi = Phi * weight[..., None]  # (n, g, 2)
    D = np.einsum("ngj,ngk->njk", weighted_phi.value, N.value)
    M = np.einsum("ngj,ngl->njl", weighted_phi.value, N_master.value)
    phi_n = weighted_phi[:, :, :, None, None] * normal[:, :, None, None, :]  # (n, g, j, 1, c)
    Dn = dual.sum_(phi_n * N[:, :, None, :, None], axis=1)
    Mn = dual.sum_(phi_n * N_master[:, :, None, :, None], axis=1)
    slave_x = dual.stack([xa, xb], axis=1)  # (n, k, c)
    master_x = dual.stack([xc, xd], axis=1)
    gap = dual.sum_(dual.sum_(Mn * master_x[:, None, :, :] - Dn * slave_x[:, None, :, :], axis=-1), axis=-1)
    area = dual.sum_(weighted_phi, axis=1)
    return PairQuantities(
        D=D, M=M, Dn=Dn, Mn=Mn, gap=gap, area=area, valid=valid & overlapping, overlap=overlap
    )


def dual_basis_coefficients(jacobian_at_points=None, num_gauss_points: int = 2) -> np.ndarray:
    """Coefficients A with Phi = A N, biorthogonal on the whole slave facet.

    A = D_e M_e^-1 with D_e = diag(int N_k) and M_e = int N N^T over the full
    facet. For a linear facet the Jacobian is constant and cancels, so A is
    the same for every facet, long or short: [[2, -1], [-1, 2]]
    (Phi_1 = (1 - 3 xi)/2, Phi_2 = (1 + 3 xi)/2). The coefficients are taken
    on the whole facet, not on the part in contact, so they do not depend on
    the contact state; on a partly covered facet D keeps off-diagonal terms,
    which keeps D and M integrated over the same domain (patch test).
    """
    points, weights = gauss_legendre(num_gauss_points)
    jacobian = np.ones_like(points) if jacobian_at_points is None else np.asarray(jacobian_at_points)
    N = np.stack([(1.0 - points) / 2.0, (1.0 + points) / 2.0], axis=-1)
    w = weights * jacobian
    mass = np.einsum("g,gj,gk->jk", w, N, N)
    lumped = np.diag(np.einsum("g,gk->k", w, N))
    return lumped @ np.linalg.inv(mass)


_DUAL_COEFFICIENTS = dual_basis_coefficients()


def _apply_dual_coefficients(N: Dual) -> Dual:
    A = _DUAL_COEFFICIENTS
    return dual.stack(
        [N[..., 0] * A[0, 0] + N[..., 1] * A[0, 1], N[..., 0] * A[1, 0] + N[..., 1] * A[1, 1]],
        axis=-1,
    )


def _merge_crosspoints(Phi: Dual, crosspoint: np.ndarray) -> Dual:
    """Move the basis function of a crosspoint node onto the facet's other node."""
    if not crosspoint.any():
        return Phi
    total = Phi[..., 0] + Phi[..., 1]
    zero = total * 0.0
    cross_a = crosspoint[:, 0][:, None]
    cross_b = crosspoint[:, 1][:, None]
    phi_a = dual.where(cross_a, zero, dual.where(cross_b, total, Phi[..., 0]))
    phi_b = dual.where(cross_b, zero, dual.where(cross_a, total, Phi[..., 1]))
    both = cross_a & cross_b
    phi_a = dual.where(both, zero, phi_a)
    phi_b = dual.where(both, zero, phi_b)
    return dual.stack([phi_a, phi_b], axis=-1)


def _one_master_facet_per_point(eta: np.ndarray, valid: np.ndarray, slave_facet: np.ndarray) -> np.ndarray:
    """(n, g) mask: each Gauss point of a slave facet goes to the master facet it
    projects into most centrally (smallest |eta|, within 1e-12 of [-1, 1])."""
    num_pairs, num_points = eta.shape
    score = np.where((np.abs(eta) <= 1.0 + 1e-12) & valid[:, None], np.abs(eta), np.inf).ravel()
    key = (slave_facet[:, None] * num_points + np.arange(num_points)).ravel()
    order = np.lexsort((score, key))
    first = np.ones(order.size, dtype=bool)
    first[1:] = key[order][1:] != key[order][:-1]
    winner = np.zeros(order.size, dtype=bool)
    winner[order[first]] = True
    return (winner & np.isfinite(score)).reshape(num_pairs, num_points)
