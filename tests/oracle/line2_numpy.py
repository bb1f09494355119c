"""Geometry and integration kernels of 2D mortar contact, batched over all pairs.

The test oracle of the compiled 2D kernel (``dolfinx_mortar/kernels/line2.c``): the same
mortar integrals written once more in vectorized numpy, with their derivatives, kept under
``tests/oracle`` so that the tests (and the benchmarks' comparisons) check the package's one
implementation against a second one. Nothing in ``dolfinx_mortar`` imports it.

Everything here is a plain numpy function of coordinate arrays: no MPI, no
PETSc, no dolfinx. One call handles every candidate (slave facet, master facet)
pair at once and returns the pair's contributions to the mortar quantities of
Hammer's paper (sections 3-5), with their exact derivatives (returned as
:class:`~dolfinx_mortar.dual.Dual` arrays; computed by the chain rule written
out for these formulas, see :func:`_integrate`):

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

import numpy as np

from dolfinx_mortar.dual import RowSubsetDual
from dolfinx_mortar.kernels.contract import (
    NORMAL_OPTIONS,
    BasisOption,
    IntegrationOption,
    KernelOptions,
    NormalOption,
    PairGeometry,
    PairQuantities,
)
from dolfinx_mortar.kernels.line2_rules import DEFAULT_GAUSS_POINTS, gauss_legendre
from dolfinx_mortar.kernels.line2_rules import DUAL_COEFFICIENTS as _DUAL_COEFFICIENTS
from dolfinx_mortar.kernels.line2_rules import (
    one_master_facet_per_point as _one_master_facet_per_point,
)

from .factors import FactorizedPairGradients

NUM_PAIR_VARIABLES = 12

_FACING_TOLERANCE = 1e-8
_PARALLEL_TOLERANCE = 1e-10


# -- the batched kernel --------------------------------------------------------------------
#
# pair_quantities works on the transposed coordinates X (12, n): every scalar of the
# computation is a contiguous (n,) array (Gauss-point quantities are (g, n)), so numpy loops
# run along the pairs. Values are computed with exactly the operations (and the same order)
# of the Dual formulation of the paper's formulas, so that the discrete decisions (facing,
# projection found, overlap, parallel) are the same. Derivatives are not carried through
# every operation: the integrands are differentiated by hand with respect to a few
# pair-level quantities (the segment limits, the facet Jacobian, the two nodal normals, the
# master and slave nodes), whose own gradients (12, n) are combined in one contraction at
# the end. Only pairs that contribute (they face each other, overlap, and have a Gauss
# point with a weight) are integrated; the others are exactly zero, with zero gradients.


def _unit_normal(tx, ty):
    """(t_y, -t_x)/|t| of tangents t given by components, and 1/|t|."""
    inverse = 1.0 / np.sqrt(tx * tx + ty * ty)
    return ty * inverse, -tx * inverse, inverse


def _unit_normal_jacobian(nx, ny, tx, ty, inverse):
    """d n / d t of n = (t_y, -t_x)/|t| as the entries (00, 01, 10, 11)."""
    ux, uy = tx * inverse, ty * inverse
    return ((-ux * nx) * inverse, (1.0 - uy * nx) * inverse,
            (-1.0 - ux * ny) * inverse, (-uy * ny) * inverse)


def _normalize_jacobian(nx, ny, inverse):
    """d n / d v of n = v/|v| (= (I - n n^T)/|v|) as the entries (00, 01, 10, 11)."""
    off = (-nx * ny) * inverse
    return (1.0 - nx * nx) * inverse, off, off, (1.0 - ny * ny) * inverse


def _matmul2(A, B):
    a00, a01, a10, a11 = A
    b00, b01, b10, b11 = B
    return (a00 * b00 + a01 * b10, a00 * b01 + a01 * b11,
            a10 * b00 + a11 * b10, a10 * b01 + a11 * b11)


def _add_block(grad, node: int, J, factor: float = 1.0) -> None:
    """grad (2, 12, n) += factor J on the two variables of ``node`` (0..5 = p, a, b, q, c, d)."""
    for row in range(2):
        for column in range(2):
            grad[row, 2 * node + column] += J[2 * row + column] * factor


def _normal_field(X, has_neighbour, normals, jacobians: bool):
    """Nodal normals n_a, n_b (tuples of component arrays) and their gradients (2, 12, n)."""
    px, py, ax, ay, bx, by, qx, qy, cx, cy, dx, dy = X
    num = X.shape[1]
    if normals == "master":
        tx, ty = dx - cx, dy - cy
        mx, my, inverse = _unit_normal(tx, ty)
        normal = (-mx, -my)
        if not jacobians:
            return normal, normal, None, None
        J = _unit_normal_jacobian(mx, my, tx, ty, inverse)
        grad = np.zeros((2, 12, num))
        _add_block(grad, 4, J, 1.0)  # n_a = -n(x_d - x_c)
        _add_block(grad, 5, J, -1.0)
        return normal, normal, grad, grad
    tx, ty = bx - ax, by - ay
    nx, ny, inverse_ab = _unit_normal(tx, ty)
    J_ab = _unit_normal_jacobian(nx, ny, tx, ty, inverse_ab) if jacobians else None
    if normals == "slave":
        if not jacobians:
            return (nx, ny), (nx, ny), None, None
        grad = np.zeros((2, 12, num))
        _add_block(grad, 1, J_ab, -1.0)
        _add_block(grad, 2, J_ab, 1.0)
        return (nx, ny), (nx, ny), grad, grad
    if normals != "averaged":
        raise ValueError(f"unknown normal option {normals!r}; expected one of {NORMAL_OPTIONS}")
    left, right = has_neighbour[:, 0], has_neighbour[:, 1]
    # an absent neighbour is given the coordinates of a neighbour-less facet;
    # its normal is multiplied by zero, and its variables get zero derivatives
    sx, sy = np.where(left, px, ax - (bx - ax)), np.where(left, py, ay - (by - ay))
    ex, ey = np.where(right, qx, bx + (bx - ax)), np.where(right, qy, by + (by - ay))
    tpx, tpy = ax - sx, ay - sy
    tqx, tqy = ex - bx, ey - by
    pnx, pny, inverse_pa = _unit_normal(tpx, tpy)
    qnx, qny, inverse_bq = _unit_normal(tqx, tqy)
    lf, rf = left.astype(float), right.astype(float)
    vax, vay = nx + pnx * lf, ny + pny * lf
    vbx, vby = nx + qnx * rf, ny + qny * rf
    inverse_a = 1.0 / np.sqrt(vax * vax + vay * vay)
    inverse_b = 1.0 / np.sqrt(vbx * vbx + vby * vby)
    normal_a = (vax * inverse_a, vay * inverse_a)
    normal_b = (vbx * inverse_b, vby * inverse_b)
    if not jacobians:
        return normal_a, normal_b, None, None
    J_pa = tuple(entry * lf for entry in _unit_normal_jacobian(pnx, pny, tpx, tpy, inverse_pa))
    J_bq = tuple(entry * rf for entry in _unit_normal_jacobian(qnx, qny, tqx, tqy, inverse_bq))
    J_a = _normalize_jacobian(*normal_a, inverse_a)
    J_b = _normalize_jacobian(*normal_b, inverse_b)
    grad_a = np.zeros((2, 12, num))
    # n_a = normalize(n(x_b - x_a) + left n(x_a - x_p))
    _add_block(grad_a, 0, _matmul2(J_a, J_pa), -1.0)
    _add_block(grad_a, 1, _matmul2(J_a, tuple(p - q for p, q in zip(J_pa, J_ab, strict=True))), 1.0)
    _add_block(grad_a, 2, _matmul2(J_a, J_ab), 1.0)
    grad_b = np.zeros((2, 12, num))
    # n_b = normalize(n(x_b - x_a) + right n(x_q - x_b))
    _add_block(grad_b, 1, _matmul2(J_b, J_ab), -1.0)
    _add_block(grad_b, 2, _matmul2(J_b, tuple(p - q for p, q in zip(J_ab, J_bq, strict=True))), 1.0)
    _add_block(grad_b, 3, _matmul2(J_b, J_bq), 1.0)
    return normal_a, normal_b, grad_a, grad_b


def _project(s0, s1, n0, n1, point):
    """Slave parameter xi where the normal line through x_s(xi) meets ``point``.

    Solves (s0 + xi s1 - point) x (n0 + xi n1) = 0, quadratic in xi, and takes
    the root nearest to the facet with the cancellation-free formula. Returns
    xi, whether it was found, and what its gradient needs.
    """
    offx, offy = s0[0] - point[0], s0[1] - point[1]
    c = offx * n0[1] - offy * n0[0]
    b = (offx * n1[1] - offy * n1[0]) + (s1[0] * n0[1] - s1[1] * n0[0])
    a = s1[0] * n1[1] - s1[1] * n1[0]
    discriminant = b * b - a * c * 4.0
    ok = discriminant >= 0.0
    root = np.sqrt(np.where(ok, discriminant, 0.0))
    sign = np.where(b >= 0.0, 1.0, -1.0)
    denominator = b + root * sign
    scale = np.sqrt(s1[0] * s1[0] + s1[1] * s1[1]) * np.sqrt(n0[0] * n0[0] + n0[1] * n0[1])
    ok &= np.abs(denominator) > _PARALLEL_TOLERANCE * scale
    inverse = 1.0 / np.where(ok, denominator, 1.0)
    xi = c * -2.0 * inverse
    return xi, ok, (offx, offy, a, b, c, root, sign, inverse)


def _projection_gradient(xi, aux, s1, n0, n1, grad_a, grad_b, point_node: int) -> np.ndarray:
    """(12, n) gradient of a projection xi from :func:`_project`."""
    offx, offy, a, b, c, root, sign, inverse = aux
    positive = root > 0.0
    # d sqrt(s) = ds / (2 sqrt(s)), taken as 0 at s = 0 (as dual.sqrt)
    sign_factor = np.where(positive, sign * 0.5 / np.where(positive, root, 1.0), 0.0)
    # xi = -2 c / (b + sign sqrt(b^2 - 4 a c)): d xi = alpha_c dc + alpha_b db + alpha_a da
    alpha_c = inverse * (-2.0 + 4.0 * xi * sign_factor * a)
    alpha_b = -inverse * xi * (1.0 + 2.0 * sign_factor * b)
    alpha_a = 4.0 * inverse * xi * sign_factor * c
    # c = off x n0, b = off x n1 + s1 x n0, a = s1 x n1 (off = s0 - point)
    g_off = (alpha_c * n0[1] + alpha_b * n1[1], -(alpha_c * n0[0] + alpha_b * n1[0]))
    g_s1 = (alpha_b * n0[1] + alpha_a * n1[1], -(alpha_b * n0[0] + alpha_a * n1[0]))
    g_n0 = (-(alpha_c * offy + alpha_b * s1[1]), alpha_c * offx + alpha_b * s1[0])
    g_n1 = (-(alpha_b * offy + alpha_a * s1[1]), alpha_b * offx + alpha_a * s1[0])
    # n0 = (n_a + n_b)/2, n1 = (n_b - n_a)/2
    grad = (0.5 * (g_n0[0] - g_n1[0])) * grad_a[0]
    grad += (0.5 * (g_n0[1] - g_n1[1])) * grad_a[1]
    grad += (0.5 * (g_n0[0] + g_n1[0])) * grad_b[0]
    grad += (0.5 * (g_n0[1] + g_n1[1])) * grad_b[1]
    # s0 = (x_a + x_b)/2, s1 = (x_b - x_a)/2
    for k in range(2):
        grad[2 + k] += 0.5 * (g_off[k] - g_s1[k])
        grad[4 + k] += 0.5 * (g_off[k] + g_s1[k])
        grad[2 * point_node + k] -= g_off[k]
    return grad


def _segment_limits(xi_c, xi_d):
    """low = max(-1, min(xi_c, xi_d)), high = min(1, max(xi_c, xi_d)) and the branches taken."""
    take_c_low = xi_c <= xi_d
    clip_low = -1.0 >= np.where(take_c_low, xi_c, xi_d)
    low = np.where(clip_low, -1.0, np.where(take_c_low, xi_c, xi_d))
    take_c_high = xi_c >= xi_d
    clip_high = 1.0 <= np.where(take_c_high, xi_c, xi_d)
    high = np.where(clip_high, 1.0, np.where(take_c_high, xi_c, xi_d))
    return low, high, (take_c_low, clip_low, take_c_high, clip_high)


def _gauss_geometry(xi, X, normal_a, normal_b):
    """Shape functions, normal, slave point and master parameter eta at Gauss points (g, n)."""
    ax, ay, bx, by, cx, cy, dx, dy = X[2], X[3], X[4], X[5], X[8], X[9], X[10], X[11]
    N0 = (1.0 - xi) * 0.5
    N1 = (xi + 1.0) * 0.5
    point = (N0 * ax + N1 * bx, N0 * ay + N1 * by)
    normal = (N0 * normal_a[0] + N1 * normal_b[0], N0 * normal_a[1] + N1 * normal_b[1])
    m0 = ((cx + dx) * 0.5, (cy + dy) * 0.5)
    m1 = ((dx - cx) * 0.5, (dy - cy) * 0.5)
    cross_m1 = m1[0] * normal[1] - m1[1] * normal[0]
    parallel = np.abs(cross_m1) <= _PARALLEL_TOLERANCE * np.sqrt(m1[0] * m1[0] + m1[1] * m1[1])
    inverse = 1.0 / np.where(parallel, 1.0, cross_m1)
    relative = (m0[0] - point[0], m0[1] - point[1])
    eta = -(relative[0] * normal[1] - relative[1] * normal[0]) * inverse
    return {"N0": N0, "N1": N1, "point": point, "normal": normal, "m0": m0, "m1": m1,
            "parallel": parallel, "inverse": inverse, "relative": relative, "eta": eta}


def _basis(N0, N1, basis, crosspoint):
    """Phi_a, Phi_b at the Gauss points and their (constant) derivatives in xi."""
    if basis == "dual":
        A = _DUAL_COEFFICIENTS
        phi = [N0 * A[0, 0] + N1 * A[0, 1], N0 * A[1, 0] + N1 * A[1, 1]]
        dphi = [-0.5 * A[0, 0] + 0.5 * A[0, 1], -0.5 * A[1, 0] + 0.5 * A[1, 1]]
    else:
        phi, dphi = [N0, N1], [-0.5, 0.5]
    if crosspoint is not None and crosspoint.any():
        # the basis function of a crosspoint node moves onto the facet's other node
        cross_a, cross_b = crosspoint[:, 0], crosspoint[:, 1]
        both = cross_a & cross_b
        total = phi[0] + phi[1]
        zero = total * 0.0
        phi_a = np.where(cross_a, zero, np.where(cross_b, total, phi[0]))
        phi_b = np.where(cross_b, zero, np.where(cross_a, total, phi[1]))
        phi = [np.where(both, zero, phi_a), np.where(both, zero, phi_b)]
        dtotal = dphi[0] + dphi[1]
        dphi_a = np.where(cross_a, 0.0, np.where(cross_b, dtotal, dphi[0]))
        dphi_b = np.where(cross_b, 0.0, np.where(cross_a, dtotal, dphi[1]))
        dphi = [np.where(both, 0.0, dphi_a), np.where(both, 0.0, dphi_b)]
    return phi, dphi


def _integrate(X, has_neighbour, normals, integration, basis, points, weights, crosspoint,
               on_master):
    """Mortar integrals of the contributing pairs X (12, n), with their derivatives.

    ``on_master`` (g, n): element-based, which Gauss points count. Returns
    the values D, M (n, 2, 2), Dn, Mn (n, 2, 2, 2), area, gap (n, 2); their
    derivatives in the factorized form of :class:`FactorizedPairGradients`
    (``coefficients``, ``directions``, ``direction_rows``, ``direct``); and,
    segment-based, the pairs found to have a Gauss point where the master is
    parallel to the normal (they are not valid and contribute nothing).

    The derivatives: each output is a sum over Gauss points of products of
    the weight w, Phi_j(xi), N_k(xi) or N^_l(eta), and the normal
    n(xi) = N0 n_a + N1 n_b. Its partial derivatives with respect to xi (at
    each point), to n_a, n_b, and to the master and slave nodes (through
    eta) are written out below and summed over the points; they multiply
    the gradients of a few pair-level quantities (the segment limits low and
    length, the Jacobian J = |x_b - x_a|/2, n_a and n_b).

    It stays in one piece on purpose: the hand-written chain rule reuses every
    intermediate array of the values (at each Gauss point of the batch), which
    helpers would have to pass around by the dozen.
    """
    num = X.shape[1]
    ax, ay, bx, by = X[2], X[3], X[4], X[5]
    normal_a, normal_b, grad_na, grad_nb = _normal_field(X, has_neighbour, normals, True)
    s1 = ((bx - ax) * 0.5, (by - ay) * 0.5)
    n1 = ((normal_b[0] - normal_a[0]) * 0.5, (normal_b[1] - normal_a[1]) * 0.5)
    jacobian = np.sqrt(s1[0] * s1[0] + s1[1] * s1[1])
    grad_jacobian = np.zeros((12, num))
    for k in range(2):
        grad_jacobian[2 + k] = -0.5 * s1[k] / jacobian
        grad_jacobian[4 + k] = 0.5 * s1[k] / jacobian
    W = weights[:, None]
    segment = integration == "segment"
    if segment:
        s0 = ((ax + bx) * 0.5, (ay + by) * 0.5)
        n0 = ((normal_a[0] + normal_b[0]) * 0.5, (normal_a[1] + normal_b[1]) * 0.5)
        xi_c, _, aux_c = _project(s0, s1, n0, n1, (X[8], X[9]))
        xi_d, _, aux_d = _project(s0, s1, n0, n1, (X[10], X[11]))
        low, high, (take_c_low, clip_low, take_c_high, clip_high) = _segment_limits(xi_c, xi_d)
        length = high - low
        grad_c = _projection_gradient(xi_c, aux_c, s1, n0, n1, grad_na, grad_nb, 4)
        grad_d = _projection_gradient(xi_d, aux_d, s1, n0, n1, grad_na, grad_nb, 5)
        grad_low = np.where(clip_low, 0.0, np.where(take_c_low, grad_c, grad_d))
        grad_length = np.where(clip_high, 0.0, np.where(take_c_high, grad_c, grad_d))
        grad_length -= grad_low
        del grad_c, grad_d
        half = (points + 1.0)[:, None]
        xi = low + (length * 0.5) * half
        weight = ((length * 0.5) * W) * jacobian
    else:
        xi = np.broadcast_to(points[:, None], (points.size, num))
        weight = W * jacobian
    geometry = _gauss_geometry(xi, X, normal_a, normal_b)
    if segment:
        parallel = geometry["parallel"].any(axis=0)
        on = (~parallel).astype(float)
    else:
        parallel = np.zeros(num, dtype=bool)
        on = on_master.astype(float)
    weight = weight * on
    N0, N1, normal, eta = geometry["N0"], geometry["N1"], geometry["normal"], geometry["eta"]
    Nm0 = (1.0 - eta) * 0.5
    Nm1 = (eta + 1.0) * 0.5
    N, Nm = (N0, N1), (Nm0, Nm1)
    phi, dphi = _basis(N0, N1, basis, crosspoint)
    weighted_phi = [phi[j] * weight for j in range(2)]
    # values, as sums over the Gauss points (axis 0)
    D = np.stack([np.stack([(weighted_phi[j] * N[k]).sum(axis=0) for k in range(2)], axis=-1)
                  for j in range(2)], axis=1)
    M = np.stack([np.stack([(weighted_phi[j] * Nm[k]).sum(axis=0) for k in range(2)], axis=-1)
                  for j in range(2)], axis=1)
    PN = [[weighted_phi[j] * normal[c] for c in range(2)] for j in range(2)]
    Dn = np.array([[[(PN[j][c] * N[k]).sum(axis=0) for c in range(2)] for k in range(2)]
                   for j in range(2)])  # (j, k, c, n)
    Mn = np.array([[[(PN[j][c] * Nm[k]).sum(axis=0) for c in range(2)] for k in range(2)]
                   for j in range(2)])
    area = np.array([weighted_phi[j].sum(axis=0) for j in range(2)])
    slave_x = ((ax, ay), (bx, by))
    master_x = ((X[8], X[9]), (X[10], X[11]))
    gap = np.array([
        sum(sum(Mn[j, k, c] * master_x[k][c] - Dn[j, k, c] * slave_x[k][c] for c in range(2))
            for k in range(2))
        for j in range(2)
    ])

    # -- derivatives ----------------------------------------------------------------------
    # d eta at each Gauss point, from eta = -(m0 - x_s) x n / (m1 x n)
    inverse = geometry["inverse"]
    m1, relative = geometry["m1"], geometry["relative"]
    perp = (-normal[1] * inverse, normal[0] * inverse)  # d eta / d m0
    r = (relative[0] + eta * m1[0], relative[1] + eta * m1[1])
    rperp = (r[1] * inverse, -r[0] * inverse)  # d eta / d normal
    # d eta / d (n_a, n_b, x_a, x_b, x_c, x_d): (12, g, n)
    eta_partials = np.stack([
        N0 * rperp[0], N0 * rperp[1], N1 * rperp[0], N1 * rperp[1],
        -N0 * perp[0], -N0 * perp[1], -N1 * perp[0], -N1 * perp[1],
        Nm0 * perp[0], Nm0 * perp[1], Nm1 * perp[0], Nm1 * perp[1],
    ])
    PN_array = np.array(PN)  # (j, c, g, n)
    # Z[j, c, e] = sum_g PN_jc d eta/d e; Mn_jlc gets (-1/2, +1/2)_l Z
    Z = np.einsum("jcgn,egn->jcen", PN_array, eta_partials)
    dN = (-0.5, 0.5)
    # the pair-level directions and their gradients (12, n)
    if segment:
        eta_xi = (-(perp[0] * s1[0] + perp[1] * s1[1]) + (rperp[0] * n1[0] + rperp[1] * n1[1]))
        directions = [grad_low, grad_length, grad_jacobian]
    else:
        directions = [grad_jacobian]
    directions += [grad_na[0], grad_na[1], grad_nb[0], grad_nb[1]]
    num_directions = len(directions)
    coefficients = np.zeros((24, num_directions, num))
    direct = np.empty((10, 8, num))  # d / d (x_a, x_b, x_c, x_d) of Mn (0-7) and gap (8, 9)

    # every output F is sum_g w_g f_g with w_g = length/2 W_g J on_g (segment) or W_g J on_g
    # (element): proportional to length and to J, so dF/dJ = F/J and the part of
    # dF/dlength through w is F/length; xi_g = low + length (1 + point_g)/2
    inverse_jacobian = 1.0 / jacobian
    if segment:
        inverse_length = 1.0 / length
        xi_length = 0.5 * half

        def reduce(X_xi, value):
            return [X_xi.sum(axis=0), (xi_length * X_xi).sum(axis=0) + value * inverse_length,
                    value * inverse_jacobian]
    else:

        def reduce(X_xi, value):
            return [value * inverse_jacobian]

    first_normal = num_directions - 4
    # d (w Phi_j n_c shape_k) / d n_a,c = w Phi_j N0 shape_k (and N1 for n_b): sums over g
    phi_N = [[weighted_phi[j] * N0, weighted_phi[j] * N1] for j in range(2)]
    normal_sums = [[[[(phi_N[j][m] * shape[k]).sum(axis=0) for m in range(2)] for k in range(2)]
                    for shape in (N, Nm)] for j in range(2)]  # [j][slave, master][k][a, b]
    for j in range(2):
        for c in range(2):
            # d (w Phi_j n_c) / d xi
            Q = weight * dphi[j] * normal[c] + weighted_phi[j] * n1[c] if segment else None
            for k in range(2):
                o = 4 * j + 2 * k + c
                X_xi = Q * N[k] + PN[j][c] * dN[k] if segment else None
                coefficients[o, :first_normal] = reduce(X_xi, Dn[j, k, c])
                coefficients[o, first_normal + c] = normal_sums[j][0][k][0]
                coefficients[o, first_normal + 2 + c] = normal_sums[j][0][k][1]
                o = 8 + 4 * j + 2 * k + c
                X_xi = (Q * Nm[k] + (PN[j][c] * dN[k]) * eta_xi) if segment else None
                coefficients[o, :first_normal] = reduce(X_xi, Mn[j, k, c])
                coefficients[o, first_normal:] = dN[k] * Z[j, c, 0:4]
                coefficients[o, first_normal + c] += normal_sums[j][1][k][0]
                coefficients[o, first_normal + 2 + c] += normal_sums[j][1][k][1]
                direct[o - 8] = dN[k] * Z[j, c, 4:12]
        X_xi = weight * dphi[j] if segment else None
        coefficients[16 + j, :first_normal] = reduce(X_xi, area[j])
        for k in range(2):
            # D_jk (no normal): its derivatives through the limits and the Jacobian only
            X_xi = weight * (dphi[j] * N[k] + phi[j] * dN[k]) if segment else None
            coefficients[20 + 2 * j + k, :first_normal] = reduce(X_xi, D[:, j, k])
    # gap_j = sum_lc Mn_jlc x^m_lc - sum_kc Dn_jkc x^s_kc
    xm, xs = X[8:12], X[2:6]  # (k c, n)
    master_part = coefficients[8:16].reshape(2, 4, -1, num) * xm[None, :, None, :]
    slave_part = coefficients[0:8].reshape(2, 4, -1, num) * xs[None, :, None, :]
    coefficients[18:20] = master_part.sum(axis=1) - slave_part.sum(axis=1)
    direct[8:10] = (direct[0:8].reshape(2, 4, 8, num) * xm[None, :, None, :]).sum(axis=1)
    direct[8:10, 4:8] += Mn.reshape(2, 4, num)
    direct[8:10, 0:4] -= Dn.reshape(2, 4, num)
    if normals == "averaged":
        normal_rows = [(0, 6), (0, 6), (2, 8), (2, 8)]
    elif normals == "slave":
        normal_rows = [(2, 6)] * 4
    else:
        normal_rows = [(8, 12)] * 4
    direction_rows = ([(0, 12), (0, 12), (2, 6)] if segment else [(2, 6)]) + normal_rows
    return {
        "D": D, "M": M, "Dn": Dn.transpose(3, 0, 1, 2), "Mn": Mn.transpose(3, 0, 1, 2),
        "area": area.T, "gap": gap.T, "coefficients": coefficients, "directions": directions,
        "direction_rows": direction_rows, "direct": direct, "parallel": parallel,
    }


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
    """The numpy oracle of :func:`dolfinx_mortar.kernels.line2.pair_quantities`: the same
    arguments and outputs (see there), computed by vectorized forward-mode derivatives."""
    KernelOptions(normals=normals, integration=integration, basis=basis)  # (checks them)
    x = np.asarray(x, dtype=np.float64)
    num_pairs = x.shape[0]
    X = np.ascontiguousarray(x.reshape(num_pairs, NUM_PAIR_VARIABLES).T)
    return _pair_quantities(X, has_neighbour, normals=normals, integration=integration, basis=basis,
                            num_gauss_points=num_gauss_points, crosspoint=crosspoint,
                            slave_facet=slave_facet)


class Line2Kernel:
    """The numpy 2D kernel behind the contract (:class:`~dolfinx_mortar.kernels.contract.
    MortarKernel`), as the package's :class:`~dolfinx_mortar.kernels.Line2Kernel` takes it:
    the neighbours p, q of the geometry enter the averaged normals; no ``slave_normals``.
    ``options.scalar_gradients`` is ignored (the factorized gradients always hold D's)."""

    gdim = 2
    default_gauss_points = DEFAULT_GAUSS_POINTS

    def evaluate(self, geometry: PairGeometry, options: KernelOptions, *,
                 crosspoint: np.ndarray | None = None,
                 slave_facet: np.ndarray | None = None) -> PairQuantities:
        if geometry.neighbour_x is None or geometry.has_neighbour is None:
            raise ValueError("the 2D kernel takes the slave facets' neighbours "
                             "(PairGeometry.neighbour_x, has_neighbour)")
        points = options.num_gauss_points or self.default_gauss_points[options.integration]
        slave, master, neighbour = geometry.slave_x, geometry.master_x, geometry.neighbour_x
        X = np.empty((NUM_PAIR_VARIABLES, geometry.num_pairs))
        for node, (x, i) in enumerate([(neighbour, 0), (slave, 0), (slave, 1), (neighbour, 1),
                                       (master, 0), (master, 1)]):
            X[2 * node:2 * node + 2] = x[:, i].T
        return _pair_quantities(
            X, geometry.has_neighbour, normals=options.normals,
            integration=options.integration, basis=options.basis, num_gauss_points=points,
            crosspoint=crosspoint, slave_facet=slave_facet)


def _facing(X) -> np.ndarray:
    """n_ab . n_cd of the slave and master facets' unit normals, (t_y, -t_x)/|t| each."""
    ax, ay, bx, by, cx, cy, dx, dy = X[2], X[3], X[4], X[5], X[8], X[9], X[10], X[11]
    tx, ty = bx - ax, by - ay
    length = np.sqrt(tx * tx + ty * ty)
    ux, uy = dx - cx, dy - cy
    master_length = np.sqrt(ux * ux + uy * uy)
    return (ty / length) * (uy / master_length) + (-tx / length) * (-ux / master_length)


_CHUNK = 8192
"""Pairs per batch: the work arrays of a batch stay in the processor's caches."""


def _chunks(num: int) -> list[tuple[int, int]]:
    return [(start, min(start + _CHUNK, num)) for start in range(0, num, _CHUNK)]


def _screen(X, has_neighbour, normals, integration, points):
    """Values only, for every pair: whether it faces and projects (and, element-based, has no
    parallel point), and the overlap length (segment) or the master parameter eta (g, n)."""
    normal_a, normal_b, _, _ = _normal_field(X, has_neighbour, normals, False)
    valid = _facing(X) < -_FACING_TOLERANCE
    if integration == "segment":
        ax, ay, bx, by = X[2], X[3], X[4], X[5]
        s0 = ((ax + bx) * 0.5, (ay + by) * 0.5)
        s1 = ((bx - ax) * 0.5, (by - ay) * 0.5)
        n0 = ((normal_a[0] + normal_b[0]) * 0.5, (normal_a[1] + normal_b[1]) * 0.5)
        n1 = ((normal_b[0] - normal_a[0]) * 0.5, (normal_b[1] - normal_a[1]) * 0.5)
        xi_c, ok_c, _ = _project(s0, s1, n0, n1, (X[8], X[9]))
        xi_d, ok_d, _ = _project(s0, s1, n0, n1, (X[10], X[11]))
        low, high, _ = _segment_limits(xi_c, xi_d)
        return valid & ok_c & ok_d, high - low
    xi = np.broadcast_to(points[:, None], (points.size, X.shape[1]))
    geometry = _gauss_geometry(xi, X, normal_a, normal_b)
    return valid & ~geometry["parallel"].any(axis=0), geometry["eta"]


def _pair_quantities(X, has_neighbour, *, normals, integration, basis, num_gauss_points,
                     crosspoint, slave_facet) -> PairQuantities:
    """:func:`pair_quantities` of the coordinates X (12, n) (variable-major)."""
    num_pairs = X.shape[1]
    has_neighbour = np.asarray(has_neighbour, dtype=bool).reshape(num_pairs, 2)
    if crosspoint is not None:
        crosspoint = np.asarray(crosspoint, dtype=bool).reshape(num_pairs, 2)
    points, weights = gauss_legendre(num_gauss_points)

    # which pairs contribute: values only, for all pairs
    valid = np.empty(num_pairs, dtype=bool)
    screened = np.empty((num_pairs,) if integration == "segment" else (points.size, num_pairs))
    for start, stop in _chunks(num_pairs):
        valid[start:stop], screened[..., start:stop] = _screen(
            X[:, start:stop], has_neighbour[start:stop], normals, integration, points)
    on_master = None
    if integration == "segment":
        length = screened
        overlapping = (length > 0.0) & valid
    else:
        if slave_facet is None:
            slave_facet = np.arange(num_pairs)
        on_master = _one_master_facet_per_point(np.ascontiguousarray(screened.T), valid,
                                                np.asarray(slave_facet).reshape(-1))
        overlapping = on_master.any(axis=1)
        overlap = np.where(on_master, weights, 0.0).sum(axis=1)
    rows = np.flatnonzero(overlapping)

    # integrals and gradients of the contributing pairs, a batch at a time
    result = {
        "D": np.zeros((num_pairs, 2, 2)), "M": np.zeros((num_pairs, 2, 2)),
        "Dn": np.zeros((num_pairs, 2, 2, 2)), "Mn": np.zeros((num_pairs, 2, 2, 2)),
        "area": np.zeros((num_pairs, 2)), "gap": np.zeros((num_pairs, 2)),
    }
    parallel = np.zeros(rows.size, dtype=bool)
    parts = []
    direction_rows = []
    for start, stop in _chunks(rows.size):
        batch = rows[start:stop]
        part = _integrate(
            X[:, batch], has_neighbour[batch], normals, integration, basis, points, weights,
            None if crosspoint is None else crosspoint[batch],
            None if on_master is None else np.ascontiguousarray(on_master[batch].T),
        )
        for name, array in result.items():
            array[batch] = part[name]
        parallel[start:stop] = part["parallel"]
        parts.append((start, stop, part["coefficients"], part["directions"], part["direct"]))
        direction_rows = part["direction_rows"]
    gradients = FactorizedPairGradients(rows.size, direction_rows, parts)
    if integration == "segment":
        parallel_rows = rows[parallel]
        valid[parallel_rows] = False
        overlapping[parallel_rows] = False
        overlap = np.where(overlapping, length, 0.0)

    def subset_dual(name: str, start: int, shape: tuple[int, ...]) -> RowSubsetDual:
        stop = start + int(np.prod(shape))

        def grad_rows():
            grads = gradients.outputs(start, stop)
            return grads.reshape((rows.size,) + shape + (NUM_PAIR_VARIABLES,))

        return RowSubsetDual.of_full(result[name], rows, grad_rows)

    return PairQuantities(
        D_rows=result["D"][rows], M_rows=result["M"][rows],
        Dn=subset_dual("Dn", FactorizedPairGradients.DN, (2, 2, 2)),
        Mn=subset_dual("Mn", FactorizedPairGradients.MN, (2, 2, 2)),
        gap=subset_dual("gap", FactorizedPairGradients.GAP, (2,)),
        area=subset_dual("area", FactorizedPairGradients.AREA, (2,)),
        valid=valid & overlapping, overlap=overlap, num_variables=NUM_PAIR_VARIABLES,
        segment_gradients=gradients,
    )
