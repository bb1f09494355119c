"""3D mortar kernel: triangle and quadrilateral facets, segment- and element-based integration.

The test oracle of the compiled 3D kernel (``dolfinx_mortar/kernels/surface3.c``): the same
mortar integrals written once more in vectorized numpy, with their derivatives, kept under
``tests/oracle`` so that the tests (and the benchmarks' comparisons) check the package's one
implementation against a second one. Nothing in ``dolfinx_mortar`` imports it.

Per candidate pair (Puso and Laursen 2004; Popp, Gee and Wall 2009):

1. an auxiliary plane through the slave facet centre x0 with the unit normal
   n0 of the normal field there;
2. slave and master nodes projected onto it along n0, in plane coordinates
   (e1, e2) with e1 x e2 = n0 (slave polygon counter-clockwise);
3. the two convex polygons clipped (Sutherland-Hodgman; quadrilaterals as
   quadrilaterals); each clip vertex is labelled as a slave node, a master
   node or the intersection of a slave edge with a master edge (never of two
   edges that coincide: a vertex on a clip line, to :data:`_ON_LINE`, stays
   itself);
4. the clip polygon split into triangles around its vertex mean (the fan
   keeps every cell inside a convex polygon however its vertices are
   spaced); Gauss points of each triangle mapped back onto the slave and
   the master facet along n0 (closed form for triangles, Newton for
   bilinear quadrilaterals);
5. D, M, Dn, Mn, the nodal areas and the weighted gaps integrated with the
   cell areas in the plane as weights. For a triangle on a triangle both
   inverse maps are affine, so every integrand factor is affine on a cell and
   the Gauss sum is a fixed trilinear form in the factors' values at the
   cell corners: they are evaluated (with derivatives) only at the polygon's
   centre and vertices (:func:`_affine_integrals`), the same sum to rounding.

Element-based integration (``integration="element"``) instead takes the
Gauss points of the slave facet, projects each along the normal field onto
the master facet (closed form for triangles, Newton for quadrilaterals) and
keeps the points that land on it; each point goes to one master facet only
(the one it lands on most centrally), as in 2D. Cheaper, never exact in
the patch test.

Derivatives are exact: the clip topology (the labels) is decided on values;
then every position is recomputed from the labels in forward-mode dual
arithmetic (:mod:`dolfinx_mortar.dual`), and the inverse maps of the
quadrilaterals get their derivatives from one Newton step in dual arithmetic
at the converged point (implicit function theorem).

The variables of a pair, in this order: slave node coordinates (ns x 3),
master node coordinates (nm x 3), slave nodal normals (ns x 3). The normal
field is n(xi) = sum_j N_j(xi) n_j (not renormalized, as the paper): with
``normals="averaged"`` the n_j are the given nodal normals; with ``"slave"``
the slave facet's unit normals at its corners; with ``"master"`` minus the
master facet's unit normal at its centre, at every slave node.
"""

from __future__ import annotations

import numpy as np

from dolfinx_mortar import dual
from dolfinx_mortar.dual import Dual, RowSubsetDual
from dolfinx_mortar.kernels import compiled
from dolfinx_mortar.kernels.contract import KernelOptions, PairGeometry, PairQuantities

from .factors import AffineFactors

_FACING_TOLERANCE = 1e-8
_AREA_TOLERANCE = 1e-14
_ON_LINE = 1e-10
"""A clip vertex this close to a master edge's line, in lengths of that edge, lies on it."""
_MAX_VERTICES = 8
_CHUNK = 2048
_SCREEN_CHUNK = 16384  # candidates screened at once (values only)
_BATCH = 1024  # overlapping pairs integrated at once (their work arrays stay in cache)

# symmetric triangle rules on the reference triangle (barycentric points, weights sum to 1)
_TRIANGLE_RULES = {
    1: (np.array([[1 / 3, 1 / 3, 1 / 3]]), np.array([1.0])),
    3: (np.array([[2 / 3, 1 / 6, 1 / 6], [1 / 6, 2 / 3, 1 / 6], [1 / 6, 1 / 6, 2 / 3]]),
        np.full(3, 1 / 3)),
}
_a1, _b1 = 0.059715871789770, 0.470142064105115
_a2, _b2 = 0.797426985353087, 0.101286507323456
_TRIANGLE_RULES[7] = (
    np.array([[1 / 3, 1 / 3, 1 / 3], [_a1, _b1, _b1], [_b1, _a1, _b1], [_b1, _b1, _a1],
              [_a2, _b2, _b2], [_b2, _a2, _b2], [_b2, _b2, _a2]]),
    np.array([0.225] + [0.132394152788506] * 3 + [0.125939180544827] * 3),
)
DEFAULT_GAUSS_POINTS = 7


# -- dual helpers ------------------------------------------------------------------------


def _cross(a: Dual, b: Dual) -> Dual:
    """3D cross product over the last value axis."""
    return dual.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
                       a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                       a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], axis=-1)


def _cross2(a: Dual, b: Dual) -> Dual:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _normalize(v: Dual) -> Dual:
    return v / dual.sqrt(dual.dot(v, v))[..., None]


def _take(a: Dual, index: np.ndarray, axis: int) -> Dual:
    """Gather along a value axis with per-pair indices (take_along_axis)."""
    value = np.take_along_axis(a.value, index, axis=axis)
    grad = np.take_along_axis(a.grad, index[..., None], axis=axis)
    return Dual(value, grad)


def _expand(a: Dual, axis: int) -> Dual:
    """A new value axis (negative axes count value axes, not the derivative axis)."""
    axis = axis % (a.value.ndim + 1)
    return Dual(np.expand_dims(a.value, axis), np.expand_dims(a.grad, axis))


# -- facets ---------------------------------------------------------------------------------


def shape_functions(xi, nodes: int):
    """N_k at reference points xi (..., 2) (Dual or array): triangles (0,0), (1,0), (0,1);
    quadrilaterals (-1,-1), (1,-1), (1,1), (-1,1) (cyclic)."""
    r, s = xi[..., 0], xi[..., 1]
    if nodes == 3:
        return [1.0 - r - s, r, s]
    signs = ((-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0))
    return [(1.0 + r * a) * (1.0 + s * b) * 0.25 for a, b in signs]


def _shape_derivatives(xi: np.ndarray, nodes: int) -> np.ndarray:
    """dN_k/dxi (..., nodes, 2) (values)."""
    if nodes == 3:
        return np.broadcast_to(np.array([[-1.0, -1.0], [1.0, 0.0], [0.0, 1.0]]),
                               xi.shape[:-1] + (3, 2))
    r, s = xi[..., 0], xi[..., 1]
    signs = np.array([(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)])
    out = np.empty(xi.shape[:-1] + (4, 2))
    for k, (a, b) in enumerate(signs):
        out[..., k, 0] = a * (1.0 + s * b) * 0.25
        out[..., k, 1] = b * (1.0 + r * a) * 0.25
    return out


def _inverse_map(corners: Dual, point: Dual, nodes: int) -> Dual:
    """Reference coordinates xi (..., 2) where sum_k N_k(xi) corners_k = point (2D plane
    coordinates): closed form for triangles, Newton for bilinear quadrilaterals; the
    derivatives follow from one Newton step in dual arithmetic (exact at the root)."""
    c = corners.value  # (..., nodes, 2)
    p = point.value
    if nodes == 3:
        return _triangle_inverse_map(corners, point)
    xi = np.zeros(p.shape)
    for _ in range(20):
        N = np.stack([np.asarray(v) for v in shape_functions(xi, nodes)], axis=-1)
        residual = np.einsum("...k,...kc->...c", N, c) - p
        J = np.einsum("...kc,...kd->...cd", c, _shape_derivatives(xi, nodes))
        step = np.linalg.solve(J, residual[..., None])[..., 0]
        xi = xi - step
        if np.all(np.abs(step) < 1e-15 * (1.0 + np.abs(xi))):
            break
    # the final step in dual arithmetic: xi - J^-1 F(xi), with F's derivatives
    N = shape_functions(xi, nodes)
    mapped = corners[..., 0, :] * np.asarray(N[0])[..., None]
    for k in range(1, nodes):
        mapped = mapped + corners[..., k, :] * np.asarray(N[k])[..., None]
    F = mapped - point
    J = np.einsum("...kc,...kd->...cd", c, _shape_derivatives(xi, nodes))
    inverse = np.linalg.inv(J)
    correction = Dual(np.einsum("...cd,...d->...c", inverse, F.value),
                      np.einsum("...cd,...dv->...cv", inverse, F.grad))
    return Dual(xi, np.zeros(xi.shape + (F.grad.shape[-1],))) - correction


def _triangle_inverse_map(corners: Dual, point: Dual) -> Dual:
    """xi = A^-1 (p - c_0), A = [c_1 - c_0, c_2 - c_0], for triangles: the inverse map is
    affine, and dxi = A^-1 (dp - sum_k N_k(xi) dc_k)."""
    c = corners.value
    A = np.stack([c[..., 1, :] - c[..., 0, :], c[..., 2, :] - c[..., 0, :]], axis=-1)
    inverse = np.linalg.inv(A)
    offset = point.value - c[..., 0, :]
    xi = np.empty(np.broadcast_shapes(offset.shape, inverse.shape[:-1]))
    xi[..., 0] = inverse[..., 0, 0] * offset[..., 0] + inverse[..., 0, 1] * offset[..., 1]
    xi[..., 1] = inverse[..., 1, 0] * offset[..., 0] + inverse[..., 1, 1] * offset[..., 1]
    N = shape_functions(xi, 3)
    rhs = point.grad - sum(N[k][..., None, None] * corners.grad[..., k, :, :] for k in range(3))
    grad = np.empty(rhs.shape)
    for row in range(2):
        grad[..., row, :] = (inverse[..., row, 0, None] * rhs[..., 0, :]
                             + inverse[..., row, 1, None] * rhs[..., 1, :])
    return Dual(xi, grad)


def _dual_coefficients(slave_x: Dual, nodes: int) -> Dual:
    """A (n, ns, ns) with Phi = A N biorthogonal on the whole slave facet: A = D_e M_e^-1
    (the kernel's own ``dual`` basis; the interface builds it over the covered part of
    each slave facet instead, :mod:`dolfinx_mortar.covered`)."""
    n = slave_x.shape[0]
    nvar = slave_x.grad.shape[-1]
    if nodes == 3:
        A = np.array([[3.0, -1.0, -1.0], [-1.0, 3.0, -1.0], [-1.0, -1.0, 3.0]])
        return Dual(np.broadcast_to(A, (n, 3, 3)), np.zeros((n, 3, 3, nvar)))
    g, w = np.polynomial.legendre.leggauss(3)
    points = np.array([[a, b] for a in g for b in g])
    weights = np.array([wa * wb for wa in w for wb in w])
    dN = _shape_derivatives(points, 4)  # (q, 4, 2)
    N = np.stack(shape_functions(points, 4), axis=-1)  # (q, 4)
    # |x_xi x x_eta| at each point
    t1 = sum(_expand(slave_x[:, k, :], 1) * dN[None, :, k, 0, None] for k in range(4))
    t2 = sum(_expand(slave_x[:, k, :], 1) * dN[None, :, k, 1, None] for k in range(4))
    jacobian = dual.sqrt(dual.dot(_cross(t1, t2), _cross(t1, t2)))  # (n, q)
    jw = jacobian * weights[None, :]
    mass = Dual(np.einsum("nq,qj,qk->njk", jw.value, N, N),
                np.einsum("nqv,qj,qk->njkv", jw.grad, N, N))
    lumped = Dual(np.einsum("nq,qj->nj", jw.value, N), np.einsum("nqv,qj->njv", jw.grad, N))
    inverse = np.linalg.inv(mass.value)
    A = lumped.value[:, :, None] * inverse
    # dA = (dDe - A dMe) Me^-1
    dDe = np.einsum("njv,njk->njkv", lumped.grad, inverse)
    dMe = np.einsum("nil,nlmv,nmk->nikv", A, mass.grad, inverse)
    return Dual(A, dDe - dMe)


# -- clipping (values) --------------------------------------------------------------------


def _clip(slave2d: np.ndarray, master2d: np.ndarray):
    """Clip the slave polygons by the master polygons (both CCW), all pairs at once.

    Returns the clip vertex labels (n, V, 3): (kind, i, j) with kind 0 = slave
    node i, 1 = master node j, 2 = slave edge i x master edge j; and counts (n,).

    A vertex within :data:`_ON_LINE` of a clip line (relative to that master edge's
    length) lies on it: it is kept as itself, and no crossing is made on an edge
    from it. Edges that meet exactly, as where both bodies end on one plane, then
    give no intersection of two parallel lines, whose position rounding decides and
    whose derivative is of the order of 1 / rounding.
    """
    n, ns, _ = slave2d.shape
    nm = master2d.shape[1]
    V = _MAX_VERTICES + 2
    positions = np.zeros((n, V, 2))
    labels = np.zeros((n, V, 3), dtype=np.int64)
    edges = np.zeros((n, V, 2), dtype=np.int64)  # edge from vertex k: (0 slave / 1 master, index)
    positions[:, :ns] = slave2d
    labels[:, :ns, 1] = np.arange(ns)
    edges[:, :ns, 1] = np.arange(ns)
    count = np.full(n, ns)
    rows = np.arange(n)
    for j in range(nm):
        start, end = master2d[:, j], master2d[:, (j + 1) % nm]
        direction = end - start
        tolerance = _ON_LINE * (direction[:, 0] * direction[:, 0]
                                + direction[:, 1] * direction[:, 1])
        new_positions = np.zeros_like(positions)
        new_labels = np.zeros_like(labels)
        new_edges = np.zeros_like(edges)
        new_count = np.zeros(n, dtype=np.int64)
        side = (direction[:, None, 0] * (positions[..., 1] - start[:, None, 1])
                - direction[:, None, 1] * (positions[..., 0] - start[:, None, 0]))
        outside = side < -tolerance[:, None]
        inside = side > tolerance[:, None]  # strictly: neither is on the line

        target = (new_positions, new_labels, new_edges, new_count)

        for k in range(V):
            active = k < count
            if not active.any():
                break
            period = np.maximum(count, 1)
            following = np.where(count > 0, (k + 1) % period, 0)
            after = np.where(count > 0, (k + 2) % period, 0)
            current = positions[:, k]
            nxt = positions[rows, following]
            s_cur, s_next = side[:, k], side[rows, following]
            out_cur, out_next = outside[:, k], outside[rows, following]
            in_cur, in_next = inside[:, k], inside[rows, following]
            denominator = np.where(s_cur - s_next == 0.0, 1.0, s_cur - s_next)
            t = (s_cur / denominator)[:, None]
            crossing = current + t * (nxt - current)
            edge = edges[:, k]
            # the crossing vertex: on a slave edge -> intersection label; on master edge j'
            # -> the master node shared by edges j' and j
            on_slave = edge[:, 0] == 0
            shared = np.where((edge[:, 1] + 1) % nm == j, j, (j + 1) % nm)
            crossing_label = np.where(
                on_slave[:, None],
                np.column_stack([np.full(n, 2), edge[:, 1], np.full(n, j)]),
                np.column_stack([np.ones(n, dtype=np.int64), np.zeros(n, dtype=np.int64),
                                 shared]))
            along_clip = np.column_stack([np.ones(n, dtype=np.int64), np.full(n, j)])
            next_label = labels[rows, following]
            # a kept vertex on the line before one outside: the new edge runs along the line
            leaves = ~out_next & ~in_next & outside[rows, after]
            next_edge = np.where(leaves[:, None], along_clip, edges[rows, following])
            _emit(target, active & out_cur & in_next, crossing, crossing_label, edge)
            _emit(target, active & ~out_next, nxt, next_label, next_edge)
            _emit(target, active & in_cur & out_next, crossing, crossing_label, along_clip)
        positions, labels, edges, count = new_positions, new_labels, new_edges, new_count
    return labels[:, :_MAX_VERTICES], np.minimum(count, _MAX_VERTICES), positions[:, :_MAX_VERTICES]


def _separated(slave2d: np.ndarray, master2d: np.ndarray) -> np.ndarray:
    """(n,) the two polygons lie on either side of one of their edges' lines with a gap of
    1e-8 of their size: their clip polygon is empty (Sutherland-Hodgman moves no vertex by
    more than rounding). Either orientation; degenerate polygons are never separated."""
    points = np.concatenate([slave2d, master2d], axis=1)
    size = np.abs(points).max(axis=(1, 2))
    separated = np.zeros(slave2d.shape[0], dtype=bool)
    for polygon, other in ((slave2d, master2d), (master2d, slave2d)):
        k = polygon.shape[1]
        orientation = np.sign(_polygon_area(polygon))
        for i in range(k):
            start, end = polygon[:, i], polygon[:, (i + 1) % k]
            direction = (end - start) * orientation[:, None]
            side = (direction[:, None, 0] * (other[..., 1] - start[:, None, 1])
                    - direction[:, None, 1] * (other[..., 0] - start[:, None, 0]))
            gap = 1e-8 * size * np.hypot(direction[:, 0], direction[:, 1])
            separated |= side.max(axis=1) < -gap
    return separated


def _emit(target, mask, position, label, edge) -> None:
    """Append a vertex to the polygons of the pairs in ``mask``."""
    positions, labels, edges, count = target
    rows = np.flatnonzero(mask)
    index = count[rows]
    keep = index < positions.shape[1]
    rows, index = rows[keep], index[keep]
    positions[rows, index] = position[rows]
    labels[rows, index] = label[rows]
    edges[rows, index] = edge[rows]
    count[rows] += 1


# -- the kernel -----------------------------------------------------------------------------


def pair_quantities(
    slave_x: np.ndarray,
    master_x: np.ndarray,
    slave_normals: np.ndarray,
    *,
    normals: str = "averaged",
    integration: str = "segment",
    basis: str = "standard",
    num_gauss_points: int | None = None,
    crosspoint: np.ndarray | None = None,
    slave_facet: np.ndarray | None = None,
    scalar_gradients: bool = False,
    factorized: bool = True,
) -> PairQuantities:
    """Mortar contributions of every pair, with derivatives (see the module docstring).

    Args:
        slave_x: (n, ns, 3) slave facet nodes (cyclic, counter-clockwise seen from
            outside the slave body).
        master_x: (n, nm, 3) master facet nodes (the same rule for the master body).
        slave_normals: (n, ns, 3) unit nodal normals at the slave nodes (used with
            ``normals="averaged"``).
        normals, basis: as in 2D.
        integration: ``segment`` or ``element`` (module docstring).
        num_gauss_points: points of the triangle rule per integration cell (segment)
            or per slave triangle (element): 1, 3 or 7; a slave quadrilateral
            (element) takes 1, 4 or 9 (3 and 7 are read as 4 and 9).
        crosspoint: (n, ns) slave nodes without a multiplier: their basis
            function is shared equally by the facet's other nodes. A facet whose
            nodes are all crosspoints (prescribed everywhere) has no multiplier
            and contributes nothing.
        slave_facet: (n,) the slave facet of each pair: element-based integration
            gives each of its Gauss points to one master facet (default: every
            pair a facet of its own). Unused by segment-based integration.
        factorized: triangle pairs with averaged normals and the standard basis keep the
            gradients of Dn, Mn and the areas factorized (:class:`~.factors.AffineFactors`),
            expanded when the result's ``Dn``, ``Mn`` and ``area`` are first asked for them.
    """
    KernelOptions(normals=normals, integration=integration, basis=basis)  # (checks them)
    rule = num_gauss_points or DEFAULT_GAUSS_POINTS
    if integration == "segment" and rule not in _TRIANGLE_RULES:
        raise ValueError(f"3D segments take 1, 3 or 7 Gauss points per cell, got {rule}")
    slave_x = np.asarray(slave_x, dtype=np.float64)
    master_x = np.asarray(master_x, dtype=np.float64)
    slave_normals = np.asarray(slave_normals, dtype=np.float64)
    n, ns, _ = slave_x.shape
    nm = master_x.shape[1]
    nvar = 3 * (2 * ns + nm)
    if crosspoint is None:
        crosspoint = np.zeros((n, ns), dtype=bool)
    crosspoint = np.asarray(crosspoint, dtype=bool).reshape(n, ns)
    values = {
        "D": np.zeros((n, ns, ns)), "M": np.zeros((n, ns, nm)),
        "Dn": np.zeros((n, ns, ns, 3)), "Mn": np.zeros((n, ns, nm, 3)),
        "gap": np.zeros((n, ns)), "area": np.zeros((n, ns)),
    }
    names = ("Dn", "Mn", "gap", "area") + (("D", "M") if scalar_gradients else ())
    valid = np.zeros(n, dtype=bool)
    overlap = np.zeros(n)
    factors = None
    if integration == "segment":
        rows, fraction, batches = _screen_segments(slave_x, master_x, slave_normals, normals)
        valid[rows], overlap[rows] = True, fraction
        if (factorized and ns == 3 and nm == 3 and normals == "averaged"
                and not scalar_gradients and basis == "standard"):
            factors = AffineFactors(rows.size, ns, nm, nvar)
            names = ("gap",)
        grads = {name: np.empty((rows.size,) + values[name].shape[1:] + (nvar,))
                 for name in names}
        for batch, labels, count, master_node, master_edge_start in batches:
            quantities = _polygon_integrals(
                slave_x[batch], master_x[batch], slave_normals[batch], crosspoint[batch],
                normals, basis, rule, labels, count, master_node, master_edge_start,
                scalar_gradients=scalar_gradients, factorized=factors is not None)
            position = np.searchsorted(rows, batch)
            for name in values:
                values[name][batch] = quantities[name].value
            for name in names:
                grads[name][position] = quantities[name].grad
            if factors is not None:
                factors.put(position, quantities["factors"])
    else:
        rows, grads = _element_parts(slave_x, master_x, slave_normals, crosspoint, normals,
                                     basis, rule, slave_facet, values, valid, overlap, names)

    def subset(name: str) -> RowSubsetDual:
        if factors is not None and name in ("Dn", "Mn", "area"):
            return RowSubsetDual.of_full(values[name], rows,
                                         lambda: factors.expanded(name))
        return RowSubsetDual.of_full(values[name], rows, grads[name])

    return PairQuantities(
        D_rows=values["D"][rows], M_rows=values["M"][rows], Dn=subset("Dn"), Mn=subset("Mn"),
        gap=subset("gap"), area=subset("area"), valid=valid, overlap=overlap, num_variables=nvar,
        D_dual=subset("D") if scalar_gradients else None,
        M_dual=subset("M") if scalar_gradients else None)


class Surface3Kernel:
    """The numpy 3D kernel behind the contract (:class:`~dolfinx_mortar.kernels.contract.
    MortarKernel`), as the package's :class:`~dolfinx_mortar.kernels.Surface3Kernel` takes
    it: the slave nodal normals of the geometry are variables (zeros will do for the
    ``slave`` and ``master`` normal options); no neighbours."""

    gdim = 3
    default_gauss_points = {"segment": DEFAULT_GAUSS_POINTS, "element": DEFAULT_GAUSS_POINTS}
    factorized = True
    """Passed to :func:`pair_quantities` (False: every gradient expanded at evaluation)."""

    def evaluate(self, geometry: PairGeometry, options: KernelOptions, *,
                 crosspoint: np.ndarray | None = None,
                 slave_facet: np.ndarray | None = None) -> PairQuantities:
        slave_normals = geometry.slave_normals
        if slave_normals is None:
            slave_normals = np.zeros_like(geometry.slave_x)
        return pair_quantities(
            geometry.slave_x, geometry.master_x, slave_normals, normals=options.normals,
            integration=options.integration, basis=options.basis,
            num_gauss_points=options.num_gauss_points, crosspoint=crosspoint,
            slave_facet=slave_facet, scalar_gradients=options.scalar_gradients,
            factorized=self.factorized)


def _normal_field(xs: Dual, xm: Dual, nodal: Dual, normals: str, ns: int, nm: int) -> Dual:
    """The slave nodal normals n_j (n, ns, 3) of the chosen normal field."""
    if normals == "averaged":
        return nodal
    if normals == "slave":
        corners = []
        for i in range(ns):
            a = xs[:, (i + 1) % ns] - xs[:, i]
            b = xs[:, (i - 1) % ns] - xs[:, i]
            corners.append(_normalize(_cross(a, b)))
        return dual.stack(corners, axis=1)
    if nm == 4:
        v = _cross(xm[:, 2] - xm[:, 0], xm[:, 3] - xm[:, 1])
    else:
        v = _cross(xm[:, 1] - xm[:, 0], xm[:, 2] - xm[:, 0])
    master_normal = -_normalize(v)
    return dual.stack([master_normal] * ns, axis=1)


def _pair_variables(slave_x, master_x, slave_normals, with_derivatives: bool = True):
    """(xs, xm, nodal) as Duals over the pair's variables (none: values only)."""
    n, ns, _ = slave_x.shape
    nm = master_x.shape[1]
    if not with_derivatives:
        return tuple(Dual(a, np.zeros(a.shape + (0,))) for a in (slave_x, master_x,
                                                                 slave_normals))
    nvar = 3 * (2 * ns + nm)
    variables = Dual.variables(
        np.concatenate([slave_x.reshape(n, -1), master_x.reshape(n, -1),
                        slave_normals.reshape(n, -1)], axis=1))
    xs = Dual(variables.value[:, :3 * ns].reshape(n, ns, 3),
              variables.grad[:, :3 * ns].reshape(n, ns, 3, nvar))
    xm = Dual(variables.value[:, 3 * ns:3 * (ns + nm)].reshape(n, nm, 3),
              variables.grad[:, 3 * ns:3 * (ns + nm)].reshape(n, nm, 3, nvar))
    nodal = Dual(variables.value[:, 3 * (ns + nm):].reshape(n, ns, 3),
                 variables.grad[:, 3 * (ns + nm):].reshape(n, ns, 3, nvar))
    return xs, xm, nodal


def _auxiliary_plane(xs: Dual, xm: Dual, nodal: Dual, normals: str):
    """The normal field's nodal normals, the plane's centre x0, normal n0, basis (e1, e2)
    and the slave and master nodes in plane coordinates (S, Mp)."""
    ns, nm = xs.shape[1], xm.shape[1]
    node_normals = _normal_field(xs, xm, nodal, normals, ns, nm)
    x0 = dual.sum_(xs, axis=1) * (1.0 / ns)
    n0 = _normalize(dual.sum_(node_normals, axis=1) * (1.0 / ns))
    edge = xs[:, 1] - xs[:, 0]
    e1 = _normalize(edge - n0 * dual.dot(edge, n0)[:, None])
    e2 = _cross(n0, e1)

    def plane(points: Dual) -> Dual:  # (n, k, 3) -> (n, k, 2)
        offset = points - _expand(x0, 1)
        return dual.stack([dual.dot(offset, _expand(e1, 1)), dual.dot(offset, _expand(e2, 1))],
                          axis=-1)

    return node_normals, x0, n0, e1, e2, plane(xs), plane(xm)


def _element_parts(slave_x, master_x, slave_normals, crosspoint, normals, basis, rule,
                   slave_facet, values, valid, overlap, names):
    """Element-based integration in chunks: fills ``values``, ``valid`` and ``overlap``;
    returns the contributing rows and the gradients of the outputs ``names``."""
    n, ns, _ = slave_x.shape
    nvar = 3 * (2 * ns + master_x.shape[1])
    points, point_weights = _facet_rule(ns, rule)
    on_master = _element_points_on_master(
        slave_x, master_x, slave_normals, normals, points,
        np.arange(n) if slave_facet is None else np.asarray(slave_facet).reshape(-1))
    gradients: dict[str, list] = {name: [] for name in names}
    all_rows = []
    for start in range(0, n, _CHUNK):
        stop = min(n, start + _CHUNK)
        part = _integrate_element(slave_x[start:stop], master_x[start:stop],
                                  slave_normals[start:stop], crosspoint[start:stop],
                                  normals, basis, points, point_weights,
                                  on_master[start:stop])
        if part is None:
            continue
        rows, quantities, fraction = part
        rows = rows + start
        all_rows.append(rows)
        valid[rows] = True
        overlap[rows] = fraction
        for name in values:
            values[name][rows] = quantities[name].value
        for name in names:
            gradients[name].append(quantities[name].grad)
    rows = np.concatenate(all_rows) if all_rows else np.zeros(0, dtype=np.int64)
    grads = {name: np.concatenate(gradients[name]) if gradients[name]
             else np.zeros((0,) + values[name].shape[1:] + (nvar,)) for name in names}
    return rows, grads


def _screen_segments(slave_x, master_x, slave_normals, normals):
    """The clip topology of every pair on values, in chunks: (rows, fraction, batches).

    ``rows`` (sorted) are the pairs that face and overlap, ``fraction`` their clipped
    area over the slave facet area; ``batches`` splits them by the vertex count of their
    clip polygons (no padded cells) into batches of at most ``_BATCH`` pairs:
    (rows, labels, count, master_node, master_edge_start).
    """
    n, _, _ = slave_x.shape
    nm = master_x.shape[1]
    near = []  # pairs that face and are not separated: clipped together afterwards
    for start in range(0, n, _SCREEN_CHUNK):
        stop = min(n, start + _SCREEN_CHUNK)
        _, _, n0, _, _, S, Mp = _auxiliary_plane(
            *_pair_variables(slave_x[start:stop], master_x[start:stop],
                             slave_normals[start:stop], False), normals)
        facing = np.einsum("ij,ij->i", n0.value,
                           _master_normal(master_x[start:stop])) < -_FACING_TOLERANCE
        local = np.flatnonzero(facing & ~_separated(S.value, Mp.value))
        near.append((local + start, S.value[local], Mp.value[local]))
    if not near:
        return np.zeros(0, dtype=np.int64), np.zeros(0), []
    near_rows = np.concatenate([part[0] for part in near])
    near_slave = np.concatenate([part[1] for part in near])
    near_master = np.concatenate([part[2] for part in near])
    kept = []
    for start in range(0, near_rows.size, _CHUNK):
        part = slice(start, start + _CHUNK)
        slave_area = np.abs(_polygon_area(near_slave[part]))
        labels, count, positions = _clip(near_slave[part], near_master[part, ::-1])
        clip_area = _padded_area(positions, count)
        contributing = (count >= 3) & (clip_area > _AREA_TOLERANCE * slave_area)
        kept.append((near_rows[part][contributing], labels[contributing], count[contributing],
                     clip_area[contributing] / slave_area[contributing]))
    if not kept:
        return np.zeros(0, dtype=np.int64), np.zeros(0), []
    rows = np.concatenate([part[0] for part in kept])
    labels = np.concatenate([part[1] for part in kept])
    count = np.concatenate([part[2] for part in kept])
    fraction = np.concatenate([part[3] for part in kept])
    # the master polygon was reversed to be counter-clockwise: map labels back
    master_node = (nm - 1 - labels[..., 2]) % nm
    master_edge_start = (nm - 2 - labels[..., 2]) % nm  # reversed edge j = (nm-1-j) -> (nm-2-j)
    batches = []
    for vertices in np.unique(count):
        group = np.flatnonzero(count == vertices)
        for start in range(0, group.size, _BATCH):
            index = group[start:start + _BATCH]
            batches.append((rows[index], labels[index, :vertices], count[index],
                            master_node[index, :vertices], master_edge_start[index, :vertices]))
    return rows, fraction, batches


def _polygon_integrals(slave_x, master_x, slave_normals, crosspoint, normals, basis, rule,
                       labels, count, master_node, master_edge_start, pointwise=False,
                       scalar_gradients=True, factorized=False):
    """D, M, Dn, Mn, gap and area of pairs whose clip polygons (labels (m, V, 3)) have V
    vertices each, as Duals over the pair variables (a triangle on a triangle from the
    corners of the fan cells, :func:`_affine_integrals`, unless ``pointwise``; there the
    gradients of D and M are zero unless ``scalar_gradients``)."""
    m, ns, _ = slave_x.shape
    nm = master_x.shape[1]
    nvar = 3 * (2 * ns + nm)
    xs, xm, nodal = _pair_variables(slave_x, master_x, slave_normals)
    node_normals, x0, n0, e1, e2, S, Mp = _auxiliary_plane(xs, xm, nodal, normals)
    topology = (labels, count, master_node, master_edge_start)
    bary, rule_weights = _TRIANGLE_RULES[rule]
    if ns == 3 and nm == 3 and not pointwise:
        return _affine_integrals(S, Mp, topology, node_normals, xs, xm, basis, crosspoint,
                                 bary, rule_weights, scalar_gradients,
                                 normals_are_variables=normals == "averaged",
                                 factorized=factorized)
    vertex, centre, v_next, cell_area = _clip_cells(S, Mp, *topology)
    Vn = labels.shape[1]
    c = _expand(centre, 1)
    # Gauss points (m, Vn, q, 2) in the plane
    q = rule_weights.size
    P = (_expand(c, 2) * bary[None, None, :, 0, None]
         + _expand(vertex, 2) * bary[None, None, :, 1, None]
         + _expand(v_next, 2) * bary[None, None, :, 2, None])
    W = _expand(cell_area, 2) * rule_weights[None, None, :]  # (m, Vn, q)
    P = Dual(P.value.reshape(m, Vn * q, 2), P.grad.reshape(m, Vn * q, 2, nvar))
    W = Dual(W.value.reshape(m, Vn * q), W.grad.reshape(m, Vn * q, nvar))
    xi = _inverse_map(_expand(S, 1), P, ns)  # (m, g, 2)
    eta = _inverse_map(_expand(Mp, 1), P, nm)
    N = shape_functions(xi, ns)
    Nm = shape_functions(eta, nm)

    Phi = _multiplier_basis(N, xs, basis, crosspoint, W.shape)
    normal_at = sum(_expand(node_normals[:, j], 1) * _expand(N[j], -1) for j in range(ns))
    return _mortar_integrals(W, Phi, N, Nm, normal_at, xs, xm)


def _clip_cells(S: Dual, Mp: Dual, labels, count, master_node, master_edge_start):
    """The clip vertices (m, V, 2) recomputed from their labels (as Duals over whatever
    variables S and Mp carry), their mean (m, 2), each vertex's successor (m, V, 2) and the
    areas (m, V) of the fan cells (centre, v_k, v_k+1)."""
    m, ns = S.shape[:2]
    nm = Mp.shape[1]
    nvar = S.grad.shape[-1]
    kind, i_slave = labels[..., 0], labels[..., 1]
    Vn = labels.shape[1]
    slave_vertex = _take(S, np.broadcast_to(i_slave[..., None], (m, Vn, 2)), axis=1)
    master_vertex = _take(Mp, np.broadcast_to(master_node[..., None], (m, Vn, 2)), axis=1)
    a0 = slave_vertex
    a1 = _take(S, np.broadcast_to(((i_slave + 1) % ns)[..., None], (m, Vn, 2)), axis=1)
    b0 = _take(Mp, np.broadcast_to(master_edge_start[..., None], (m, Vn, 2)), axis=1)
    b1 = _take(Mp, np.broadcast_to(((master_edge_start + 1) % nm)[..., None], (m, Vn, 2)),
               axis=1)
    da, db = a1 - a0, b1 - b0
    denominator = _cross2(da, db)
    crossing = (kind == 2) & (denominator.value != 0.0)
    one = Dual(np.ones(kind.shape), np.zeros(kind.shape + (nvar,)))
    t = _cross2(b0 - a0, db) / dual.where(crossing, denominator, one)
    intersection = a0 + da * _expand(t, -1)
    vertex = dual.where((kind == 0)[..., None], slave_vertex,
                        dual.where((kind == 1)[..., None], master_vertex, intersection))
    present = np.arange(Vn)[None, :] < count[:, None]
    weights_v = present / count[:, None]
    centre = dual.sum_(vertex * weights_v[..., None], axis=1)  # (m, 2)
    following = np.where(present, (np.arange(Vn)[None, :] + 1) % np.maximum(count, 1)[:, None], 0)
    v_next = _take(vertex, np.broadcast_to(following[..., None], (m, Vn, 2)), axis=1)
    c = _expand(centre, 1)
    edge_a, edge_b = vertex - c, v_next - c
    cell_area = _cross2(edge_a, edge_b) * 0.5 * present  # (m, Vn)
    return vertex, centre, v_next, cell_area


def _multiplier_basis(N, xs: Dual, basis: str, crosspoint: np.ndarray, shape) -> list:
    """Phi_j (m, g) at the points where the slave shape functions are N (list of Duals)."""
    ns = len(N)
    if basis == "dual":
        A = _dual_coefficients(xs, ns)
        Phi = [sum(N[k] * _expand(A[:, j, k], 1) for k in range(ns)) for j in range(ns)]
    else:
        Phi = list(N)
    if crosspoint.any():
        cross = crosspoint
        others = (~cross).sum(axis=1)
        shared = sum(Phi[j] * cross[:, j, None].astype(float) for j in range(ns))
        share = np.where(others > 0, 1.0 / np.maximum(others, 1), 0.0)[:, None]
        Phi = [dual.where(np.broadcast_to(cross[:, j, None], shape), Phi[j] * 0.0,
                          Phi[j] + shared * share) for j in range(ns)]
    return Phi


def _affine_integrals(S: Dual, Mp: Dual, topology: tuple, node_normals: Dual, xs: Dual,
                      xm: Dual, basis: str, crosspoint: np.ndarray, bary: np.ndarray,
                      rule_weights: np.ndarray, scalar_gradients: bool = True,
                      normals_are_variables: bool = False, factorized: bool = False) -> dict:
    """The integrals of :func:`_mortar_integrals` for a triangle on a triangle.

    Both inverse maps are affine, so every point quantity (Phi_j, N_k, N_l, the normal
    field) is affine on a fan cell: the Gauss rule's sum over a cell is a fixed
    multilinear form in the quantities' values at the cell's three corners. These are
    evaluated (with derivatives) at the V + 1 points centre and vertices only, instead of
    at every Gauss point; the result is the same quadrature sum, to rounding.

    Everything in the plane (clip vertices, cell areas, both inverse maps, N_k, N_l and
    Phi_j) depends on the pair's variables only through the 12 plane coordinates S, Mp of
    the slave and master nodes, so it is differentiated with respect to those, and the
    sums are chained to the pair's variables once; the normal field's own dependence on
    the nodal normals is added from what multiplies it, summed at each point
    (:func:`_cell_sum`; a plain scatter if the nodal normals are the pair's last variables,
    ``normals_are_variables``). Only the gradients read are chained (those of D and M only
    with ``scalar_gradients``). A multiplier basis with derivatives of its own keeps the
    pair's variables throughout.

    It stays in one piece on purpose: the corner values, their plane derivatives and the
    chain share one batch's intermediate arrays, which stay in cache only while they are
    not passed on.
    """
    m, ns = S.shape[:2]
    nm = Mp.shape[1]
    nvar = xs.grad.shape[-1]
    if basis == "standard" or not _dual_coefficients(xs, ns).grad.any():
        plane = Dual.variables(np.concatenate([S.value.reshape(m, -1), Mp.value.reshape(m, -1)],
                                              axis=1))
        local = plane.grad.shape[-1]
        chain = np.concatenate([S.grad.reshape(m, 2 * ns, nvar),
                                Mp.grad.reshape(m, 2 * nm, nvar)], axis=1)  # (m, 12, nvar)
        S = Dual(S.value, plane.grad[:, :2 * ns].reshape(m, ns, 2, local))
        Mp = Dual(Mp.value, plane.grad[:, 2 * ns:].reshape(m, nm, 2, local))
        basis_x = Dual(xs.value, np.zeros(xs.shape + (local,)))
    else:
        chain, basis_x = None, xs
    vertex, centre, _, cell_area = _clip_cells(S, Mp, *topology)
    points = Dual(np.concatenate([centre.value[:, None], vertex.value], axis=1),
                  np.concatenate([centre.grad[:, None], vertex.grad], axis=1))  # (m, V+1, 2)
    xi = _inverse_map(_expand(S, 1), points, ns)
    eta = _inverse_map(_expand(Mp, 1), points, nm)
    N = shape_functions(xi, ns)
    Nm = shape_functions(eta, nm)
    Phi = _multiplier_basis(N, basis_x, basis, crosspoint, points.shape[:2])
    N_stacked = dual.stack(N, axis=-1)  # (m, V+1, ns)
    if chain is None:
        normal_at = sum(_expand(node_normals[:, j], 1) * _expand(N[j], -1) for j in range(ns))
        direct = None
    else:
        # n(p) = sum_j N_j(p) n_j: through N_j over the plane coordinates here, through
        # the n_j over the pair's variables after the chain
        nodal = node_normals.value  # (m, ns, 3)
        normal_at = Dual(N_stacked.value @ nodal,
                         (N_stacked.grad.transpose(0, 1, 3, 2) @ nodal[:, None])
                         .transpose(0, 1, 3, 2))
        direct = N_stacked.value
    # with a constant 1 after N_k, N_l and the normal field, one sum gives D, Dn and the
    # areas (the barycentric weights of a point sum to 1) and one M and Mn
    phi = dual.stack(Phi, axis=-1)
    factors = [(phi.value, phi.grad)]
    for stacked in (N_stacked, dual.stack(Nm, axis=-1), normal_at):
        factors.append((np.concatenate([stacked.value, np.ones(stacked.shape[:-1] + (1,))],
                                       axis=-1), stacked.grad))
    T = np.einsum("g,ga,gb,gd->abd", rule_weights, bary, bary, bary)
    slave, slave_weights = _cell_sum(cell_area, [factors[0], factors[1], factors[3]], T,
                                     direct)  # (m, ns, ns+1, 4)
    master, master_weights = _cell_sum(cell_area, [factors[0], factors[2], factors[3]], T,
                                       direct)  # (m, ns, nm+1, 4)
    if chain is None:
        D, Dn, area = slave[:, :, :ns, 3], slave[:, :, :ns, :3], slave[:, :, ns, 3]
        M, Mn = master[:, :, :nm, 3], master[:, :, :nm, :3]
    else:
        # chained: the gradients read (Dn, the areas, Mn; D and M if asked), in one product
        read = [slave.grad[:, :, :ns, :3], slave.grad[:, :, ns, 3], master.grad[:, :, :nm, :3]]
        if scalar_gradients:
            read += [slave.grad[:, :, :ns, 3], master.grad[:, :, :nm, 3]]
        sizes = [part[0].size // local for part in read]
        local_gradients = np.concatenate([part.reshape(m, -1, local) for part in read], axis=1)
        product = local_gradients @ chain
        parts = np.split(product, np.cumsum(sizes)[:-1], axis=1)
        Dn_grad = parts[0].reshape(m, ns, ns, 3, nvar)
        Mn_grad = parts[2].reshape(m, ns, nm, 3, nvar)
        # the normal field's dependence on the nodal normals: sum_j (weight of n(p) at the
        # points, times N_j(p)) dn_j
        for grad, weights, k in ((Dn_grad, slave_weights, ns), (Mn_grad, master_weights, nm)):
            weights = weights[:, :, :k]  # (m, ns, k, ns): of n(p)_c's gradient, N_j
            if normals_are_variables:
                first = nvar - 3 * ns
                for c in range(3):
                    grad[..., c, first + c::3] += weights
            else:
                grad += (weights.reshape(m, ns * k, ns)
                         @ node_normals.grad.reshape(m, ns, 3 * nvar)).reshape(grad.shape)
        if scalar_gradients:
            D_grad = parts[3].reshape(m, ns, ns, nvar)
            M_grad = parts[4].reshape(m, ns, nm, nvar)
        else:
            D_grad = np.broadcast_to(0.0, (m, ns, ns, nvar))
            M_grad = np.broadcast_to(0.0, (m, ns, nm, nvar))
        D, M = Dual(slave.value[:, :, :ns, 3], D_grad), Dual(master.value[:, :, :nm, 3], M_grad)
        Dn = Dual(slave.value[:, :, :ns, :3], Dn_grad)
        Mn = Dual(master.value[:, :, :nm, :3], Mn_grad)
        area = Dual(slave.value[:, :, ns, 3], parts[1])
        if _identity_variables(xs, xm):
            # gap_j = sum_lc Mn_jlc xm_lc - sum_kc Dn_jkc xs_kc, the coordinates being variables
            gap_value = ((Mn.value * xm.value[:, None]).sum(axis=(-1, -2))
                         - (Dn.value * xs.value[:, None]).sum(axis=(-1, -2)))
            gap_grad = (np.einsum("mjkv,mk->mjv", Mn_grad.reshape(m, ns, 3 * nm, nvar),
                                  xm.value.reshape(m, -1))
                        - np.einsum("mjkv,mk->mjv", Dn_grad.reshape(m, ns, 3 * ns, nvar),
                                    xs.value.reshape(m, -1)))
            gap_grad[:, :, :3 * ns] -= Dn.value.reshape(m, ns, 3 * ns)
            gap_grad[:, :, 3 * ns:3 * (ns + nm)] += Mn.value.reshape(m, ns, 3 * nm)
            result = {"D": D, "M": M, "Dn": Dn, "Mn": Mn, "gap": Dual(gap_value, gap_grad),
                      "area": area}
            if factorized and normals_are_variables and not scalar_gradients:
                result["factors"] = {
                    "local": local_gradients, "chain": chain,
                    "slave_weights": slave_weights[:, :, :ns],
                    "master_weights": master_weights[:, :, :nm]}
            return result
    gap = (dual.sum_(dual.sum_(Mn * _expand(xm, 1), axis=-1), axis=-1)
           - dual.sum_(dual.sum_(Dn * _expand(xs, 1), axis=-1), axis=-1))
    return {"D": D, "M": M, "Dn": Dn, "Mn": Mn, "gap": gap, "area": area}


def _identity_variables(xs: Dual, xm: Dual) -> bool:
    """Whether the slave and master coordinates are the first 3 (ns + nm) variables, in
    order (as :func:`_pair_variables` makes them)."""
    ns, nm = xs.shape[1], xm.shape[1]
    first = np.eye(3 * (ns + nm), xs.grad.shape[-1])
    return (np.array_equal(xs.grad[0].reshape(3 * ns, -1), first[:3 * ns])
            and np.array_equal(xm.grad[0].reshape(3 * nm, -1), first[3 * ns:])
            and bool((xs.grad == xs.grad[:1]).all()) and bool((xm.grad == xm.grad[:1]).all()))


def _cell_sum(W: Dual, factors: list, T: np.ndarray,
              last_weights: np.ndarray | None = None) -> tuple[Dual, np.ndarray | None]:
    """sum_c W_c sum_abd T_abd F_1[a] F_2[b] F_3[d] (m, k_1, k_2, k_3), F_i[a] at corner a
    of cell c.

    ``factors`` are (value (m, V+1, k_i), grad (m, V+1, g_i, nv)) at the fan's centre (0)
    and vertices (1..V), the columns from g_i on constant; cell c has the corners
    (centre, vertex c, vertex c+1). Each gradient is contracted once at the V + 1 points,
    with what multiplies it summed over the cells at each point. With ``last_weights`` L
    (m, V+1, r), also returns sum_p (what multiplies the last factor's gradient at p) L_r(p)
    (m, k_1, k_2, r): the last factor's gradient over other variables, sum_r L_r C_r, then
    contributes that times C_r.
    """
    m, V = W.shape
    cells = np.arange(V)
    corner = np.stack([np.zeros(V, dtype=np.int64), 1 + cells, 1 + (cells + 1) % V], axis=1)
    values = [value[:, corner] for value, _ in factors]  # (m, V, 3, k_i)
    sizes = [value.shape[-1] for value, _ in factors]
    nv = W.grad.shape[-1]
    k1, k2, k3 = sizes
    # T is symmetric (a sum of w_g b_a b_b b_d): contracted one factor at a time by matmuls
    F1t, F2t = values[0].transpose(0, 1, 3, 2), values[1].transpose(0, 1, 3, 2)
    U3 = (T.reshape(9, 3) @ values[2]).reshape(m, V, 3, 3, k3)  # sum_d T_abd F3_dk
    U2 = (T.reshape(9, 3) @ values[1]).reshape(m, V, 3, 3, k2)  # sum_b T_adb F2_bj
    X = F2t[:, :, None] @ U3  # (m, V, a, j, k): sum_bd T_abd F2_bj F3_dk
    product = (F1t @ X.reshape(m, V, 3, k2 * k3)).reshape(m, V, k1 * k2 * k3)
    value = np.einsum("mc,mcp->mp", W.value, product).reshape(m, *sizes)
    w = W.value[:, :, None, None, None]
    R = (w * X,  # (m, V, a, j, k)
         w * (F1t @ U3.reshape(m, V, 3, 3 * k3)).reshape(m, V, k1, 3, k3).transpose(0, 1, 3, 2, 4),
         w * (F1t @ U2.reshape(m, V, 3, 3 * k2)).reshape(m, V, k1, 3, k2).transpose(0, 1, 3, 2, 4))
    grad = (product.transpose(0, 2, 1) @ W.grad).reshape(m, *sizes, nv)
    weights = None
    for i, (_, dF) in enumerate(factors):
        others = [j for j in range(3) if j != i]
        Ri = R[i].reshape(m, V, 3, -1)  # (m, V, corner, the other two factors' columns)
        # summed onto the points: centre from every cell, vertex c from cells c and c-1
        Rp = np.empty((m, V + 1, Ri.shape[-1]))
        Rp[:, 0] = Ri[:, :, 0].sum(axis=1)
        Rp[:, 1:] = Ri[:, :, 1] + np.roll(Ri[:, :, 2], 1, axis=1)
        g = dF.shape[2]
        term = Rp.transpose(0, 2, 1) @ dF.reshape(m, V + 1, g * nv)
        term = term.reshape(m, *[sizes[j] for j in others], g, nv)
        grad[(slice(None),) * (1 + i) + (slice(0, g),)] += np.moveaxis(term, -2, 1 + i)
        if i == 2 and last_weights is not None:
            weights = (Rp.transpose(0, 2, 1) @ last_weights).reshape(m, k1, k2, -1)
    return Dual(value, grad), weights


def _stacked(items, nvar: int) -> tuple[np.ndarray, np.ndarray]:
    """Values (m, k, g) and gradients (m, k, g, V) of k Duals (or constant arrays) (m, g)."""
    value = np.stack([item.value if isinstance(item, Dual) else np.asarray(item)
                      for item in items], axis=1)
    if not all(isinstance(item, Dual) for item in items):
        return value, np.zeros(value.shape + (nvar,))
    return value, np.stack([item.grad for item in items], axis=1)


def _mortar_integrals(W: Dual, Phi, N, Nm, normal_at: Dual, xs: Dual, xm: Dual) -> dict:
    """D_jk = sum_g W Phi_j N_k, M_jl (with the master N_l), Dn and Mn (times the normal
    field), area_j = sum_g W Phi_j and the weighted gaps, from the point values (m, g)
    and their gradients, contracted over the points without forming the products."""
    nvar = W.grad.shape[-1]
    Pv, Pg = _stacked(Phi, nvar)
    Nv, Ng = _stacked(N, nvar)
    Mv, Mg = _stacked(Nm, nvar)
    nv, ng = normal_at.value, normal_at.grad  # (m, g, 3), (m, g, 3, V)
    Qv = W.value[:, None] * Pv  # W Phi_j
    Qg = W.grad[:, None] * Pv[..., None] + W.value[:, None, :, None] * Pg

    m, ns, g = Qv.shape
    V = Qg.shape[-1]
    Qg_rows = Qg.transpose(0, 1, 3, 2).reshape(m, ns * V, g)  # (m, j v, g)
    Qn = (Qv[..., None] * nv[:, None]).reshape(m, ns, g * 3)  # (m, j, g c)

    def weighted(Sv, Sg):
        k = Sv.shape[1]
        value = Qv @ Sv.transpose(0, 2, 1)  # (m, j, k)
        grad = ((Qg_rows @ Sv.transpose(0, 2, 1)).reshape(m, ns, V, k).transpose(0, 1, 3, 2)
                + (Qv @ Sg.transpose(0, 2, 1, 3).reshape(m, g, k * V)).reshape(m, ns, k, V))
        Sn = Sv[..., None] * nv[:, None]  # (m, k, g, 3)
        normal_value = Qv @ Sn.transpose(0, 2, 1, 3).reshape(m, g, k * 3)
        products = Qv[:, :, None, :] * Sv[:, None, :, :]  # (m, j, k, g)
        normal_grad = (
            (Qg_rows @ Sn.transpose(0, 2, 1, 3).reshape(m, g, k * 3))
            .reshape(m, ns, V, k, 3).transpose(0, 1, 3, 4, 2)
            + (Sg.transpose(0, 1, 3, 2).reshape(m, k * V, g)
               @ Qn.reshape(m, ns, g, 3).transpose(0, 2, 1, 3).reshape(m, g, ns * 3))
            .reshape(m, k, V, ns, 3).transpose(0, 3, 1, 4, 2)
            + (products.reshape(m, ns * k, g) @ ng.reshape(m, g, 3 * V))
            .reshape(m, ns, k, 3, V))
        return Dual(value, grad), Dual(normal_value.reshape(m, ns, k, 3), normal_grad)

    D, Dn = weighted(Nv, Ng)
    M, Mn = weighted(Mv, Mg)
    area = Dual(Qv.sum(axis=2), Qg.sum(axis=2))
    gap = (dual.sum_(dual.sum_(Mn * _expand(xm, 1), axis=-1), axis=-1)
           - dual.sum_(dual.sum_(Dn * _expand(xs, 1), axis=-1), axis=-1))
    return {"D": D, "M": M, "Dn": Dn, "Mn": Mn, "gap": gap, "area": area}


# -- element-based integration ------------------------------------------------------------


def _facet_rule(nodes: int, rule: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss points (q, 2) and weights of the slave reference facet (triangle: the
    symmetric rules of 1, 3 or 7 points, weights summing to its area 1/2;
    quadrilateral: 1, 2 x 2 or 3 x 3 Gauss-Legendre, weights summing to 4)."""
    if nodes == 3:
        if rule not in _TRIANGLE_RULES:
            raise ValueError(f"element-based triangles take 1, 3 or 7 Gauss points, got {rule}")
        bary, weights = _TRIANGLE_RULES[rule]
        return bary[:, 1:].copy(), 0.5 * weights
    per_direction = {1: 1, 3: 2, 4: 2, 7: 3, 9: 3}.get(rule)
    if per_direction is None:
        raise ValueError(f"element-based quadrilaterals take 1, 4 or 9 Gauss points, got {rule}")
    g, w = np.polynomial.legendre.leggauss(per_direction)
    return (np.array([[a, b] for a in g for b in g]),
            np.array([wa * wb for wa in w for wb in w]))


def _interpolate(corners: Dual, N) -> Dual:
    """sum_k N_k corners_k for corners (n, k, 3) and N_k (n, q) or (q,) -> (n, q, 3)."""
    total = None
    for k, Nk in enumerate(N):
        Nk = np.asarray(Nk) if not isinstance(Nk, Dual) else Nk
        term = _expand(corners[:, k], 1) * (Nk[..., None] if not isinstance(Nk, Dual)
                                            else _expand(Nk, -1))
        total = term if total is None else total + term
    return total


def _project_onto_master(point: Dual, direction: Dual, xm: Dual, nm: int):
    """(eta (n, q, 2), alpha (n, q)) with sum_l Nm_l(eta) xm_l = point + alpha direction:
    Newton on values (one step for triangles, whose map is linear), then one step in
    dual arithmetic at the root for the derivatives (implicit function theorem)."""
    c = xm.value  # (n, nm, 3)
    p, d = point.value, direction.value
    eta = np.zeros(p.shape[:-1] + (2,)) + (1.0 / 3.0 if nm == 3 else 0.0)
    alpha = np.zeros(p.shape[:-1])

    def jacobian(eta):
        dN = _shape_derivatives(eta, nm)  # (n, q, nm, 2)
        tangents = np.einsum("nqkd,nkc->nqcd", dN, c)
        return np.concatenate([tangents, -d[..., None]], axis=-1)  # (n, q, 3, 3)

    for _ in range(1 if nm == 3 else 30):
        N = np.stack([np.asarray(v) for v in shape_functions(eta, nm)], axis=-1)
        residual = np.einsum("nqk,nkc->nqc", N, c) - p - alpha[..., None] * d
        J = jacobian(eta)
        singular = np.abs(np.linalg.det(J)) <= 1e-300
        J[singular] = np.eye(3)
        step = np.linalg.solve(J, residual[..., None])[..., 0]
        eta = eta - step[..., :2]
        alpha = alpha - step[..., 2]
        if np.all(np.abs(step) < 1e-15 * (1.0 + np.abs(np.concatenate(
                [eta, alpha[..., None]], axis=-1)))):
            break
    N = shape_functions(eta, nm)
    F = _interpolate(xm, N) - point - direction * _expand(
        Dual(alpha, np.zeros(alpha.shape + (point.grad.shape[-1],))), -1)
    J = jacobian(eta)
    J[np.abs(np.linalg.det(J)) <= 1e-300] = np.eye(3)
    inverse = np.linalg.inv(J)
    correction = Dual(np.einsum("...cd,...d->...c", inverse, F.value),
                      np.einsum("...cd,...dv->...cv", inverse, F.grad))
    unknowns = Dual(np.concatenate([eta, alpha[..., None]], axis=-1),
                    np.zeros(eta.shape[:-1] + (3, point.grad.shape[-1])))
    solution = unknowns - correction
    return solution[..., :2], solution[..., 2]


def _element_geometry(slave_x, master_x, slave_normals, normals, points):
    """Values only: (eta (n, q, 2), facing (n,)) of every pair's slave Gauss points."""
    n, ns, _ = slave_x.shape
    nm = master_x.shape[1]
    xs, xm, nodal = _pair_variables(slave_x, master_x, slave_normals, False)
    node_normals = _normal_field(xs, xm, nodal, normals, ns, nm)
    N = [np.broadcast_to(v, (n, points.shape[0])) for v in shape_functions(points, ns)]
    point = _interpolate(xs, N)
    direction = _interpolate(node_normals, N)
    eta, _ = _project_onto_master(point, direction, xm, nm)
    n0 = node_normals.value.sum(axis=1)
    master_normal = _master_normal(master_x)
    facing = np.einsum("ij,ij->i", n0, master_normal) < -_FACING_TOLERANCE * np.linalg.norm(
        n0, axis=1)
    return eta.value, facing


def _master_normal(master_x: np.ndarray) -> np.ndarray:
    if master_x.shape[1] == 4:
        v = np.cross(master_x[:, 2] - master_x[:, 0], master_x[:, 3] - master_x[:, 1])
    else:
        v = np.cross(master_x[:, 1] - master_x[:, 0], master_x[:, 2] - master_x[:, 0])
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _outside(eta: np.ndarray, nodes: int) -> np.ndarray:
    """How far reference points lie outside the facet (<= 0 inside; smaller = more central)."""
    if nodes == 3:
        return np.max(np.stack([-eta[..., 0], -eta[..., 1], eta[..., 0] + eta[..., 1] - 1.0]),
                      axis=0)
    return np.max(np.abs(eta), axis=-1) - 1.0


def _element_points_on_master(slave_x, master_x, slave_normals, normals, points, slave_facet):
    """(n, q) mask: each Gauss point of a slave facet goes to the facing master facet it
    lands on most centrally (within 1e-12 of its edges)."""
    n, q = slave_x.shape[0], points.shape[0]
    eta = np.zeros((n, q, 2))
    facing = np.zeros(n, dtype=bool)
    for start in range(0, n, _CHUNK):
        stop = min(n, start + _CHUNK)
        eta[start:stop], facing[start:stop] = _element_geometry(
            slave_x[start:stop], master_x[start:stop], slave_normals[start:stop], normals,
            points)
    outside = _outside(eta, master_x.shape[1])
    finite = np.all(np.isfinite(eta), axis=-1)
    score = np.where((outside <= 1e-12) & finite & facing[:, None], outside, np.inf)
    return compiled.points_on_master(score.reshape(n, q), slave_facet)


def _integrate_element(slave_x, master_x, slave_normals, crosspoint, normals, basis, points,
                       point_weights, on_master):
    rows = np.flatnonzero(on_master.any(axis=1))
    if rows.size == 0:
        return None
    slave_x, master_x, slave_normals = slave_x[rows], master_x[rows], slave_normals[rows]
    crosspoint, on_master = crosspoint[rows], on_master[rows]
    m, ns, _ = slave_x.shape
    nm = master_x.shape[1]
    nvar = 3 * (2 * ns + nm)
    xs, xm, nodal = _pair_variables(slave_x, master_x, slave_normals)
    node_normals = _normal_field(xs, xm, nodal, normals, ns, nm)
    q = points.shape[0]
    N = [np.broadcast_to(v, (m, q)) for v in shape_functions(points, ns)]
    dN = _shape_derivatives(points, ns)  # (q, ns, 2)
    point = _interpolate(xs, N)
    normal_at = _interpolate(node_normals, N)
    eta, _ = _project_onto_master(point, normal_at, xm, nm)
    Nm = shape_functions(eta, nm)
    t1 = _interpolate(xs, [np.broadcast_to(dN[:, k, 0], (m, q)) for k in range(ns)])
    t2 = _interpolate(xs, [np.broadcast_to(dN[:, k, 1], (m, q)) for k in range(ns)])
    jacobian = dual.sqrt(dual.dot(_cross(t1, t2), _cross(t1, t2)))  # (m, q)
    W = jacobian * (point_weights[None, :] * on_master)

    if basis == "dual":
        A = _dual_coefficients(xs, ns)
        Phi = [sum(_expand(A[:, j, k], 1) * N[k] for k in range(ns)) for j in range(ns)]
    else:
        Phi = [Dual(np.array(Nk), np.zeros(Nk.shape + (nvar,))) for Nk in N]
    if crosspoint.any():
        others = (~crosspoint).sum(axis=1)
        shared = sum(Phi[j] * crosspoint[:, j, None].astype(float) for j in range(ns))
        share = np.where(others > 0, 1.0 / np.maximum(others, 1), 0.0)[:, None]
        Phi = [dual.where(np.broadcast_to(crosspoint[:, j, None], W.shape), Phi[j] * 0.0,
                          Phi[j] + shared * share) for j in range(ns)]
    quantities = _mortar_integrals(W, Phi, N, Nm, normal_at, xs, xm)
    fraction = (jacobian.value * point_weights * on_master).sum(axis=1) / (
        jacobian.value * point_weights).sum(axis=1)
    return rows, quantities, fraction


def _polygon_area(points: np.ndarray) -> np.ndarray:
    """Signed area of polygons (n, k, 2) (shoelace)."""
    x, y = points[..., 0], points[..., 1]
    return 0.5 * (x * np.roll(y, -1, axis=-1) - np.roll(x, -1, axis=-1) * y).sum(axis=-1)


def _padded_area(positions: np.ndarray, count: np.ndarray) -> np.ndarray:
    """Areas of the clip polygons (n, V, 2) with ``count`` vertices each."""
    n, V, _ = positions.shape
    k = np.arange(V)[None, :]
    following = np.where(k < count[:, None], (k + 1) % np.maximum(count, 1)[:, None], 0)
    nxt = np.take_along_axis(positions, following[..., None], axis=1)
    term = positions[..., 0] * nxt[..., 1] - nxt[..., 0] * positions[..., 1]
    return 0.5 * np.where(k < count[:, None], term, 0.0).sum(axis=1)
