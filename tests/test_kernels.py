"""Known-answer tests of the batched 2D mortar kernels (:mod:`dolfinx_mortar.kernels`).

Every test runs twice: on the package's kernel (compiled, ``kernels.pair_quantities``) and on
the numpy oracle (``tests/oracle/line2_numpy.py``), so that both keep the properties checked
here and not only each other's values.

Geometry conventions (see the kernels' module docstring): a pair is the six nodes
``p, a, b, q, c, d``; ``a -> b`` is the slave facet, ``c -> d`` the master facet,
and a facet ``start -> end`` has the outward normal ``(t_y, -t_x) / |t|``. A
slave body below the line y = 0 therefore has its facets running from right to
left, a master body above it from left to right.

Run with ``-s`` to see the element-based integration error table and the
fitted Taylor slopes.
"""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest

from dolfinx_mortar import kernels
from dolfinx_mortar.kernels import BASIS_OPTIONS, INTEGRATION_OPTIONS, NORMAL_OPTIONS

from oracle import line2_numpy

INTERFACE_LENGTH = 2.5
DUAL_COEFFICIENTS = np.array([[2.0, -1.0], [-1.0, 2.0]])
ALL_OPTIONS = list(itertools.product(NORMAL_OPTIONS, INTEGRATION_OPTIONS, BASIS_OPTIONS))
IMPLEMENTATIONS = {"compiled": kernels.pair_quantities, "oracle": line2_numpy.pair_quantities}
pair_quantities = kernels.pair_quantities
"""The implementation the tests call (:func:`implementation` sets it per test)."""


@pytest.fixture(autouse=True, params=list(IMPLEMENTATIONS))
def implementation(request, monkeypatch):
    """Every test on the package's compiled kernel, then on the numpy oracle."""
    monkeypatch.setitem(globals(), "pair_quantities", IMPLEMENTATIONS[request.param])
    return request.param


# --------------------------------------------------------------------------------------------
# geometry helpers
# --------------------------------------------------------------------------------------------


def rotation(angle: float) -> np.ndarray:
    return np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])


def unit_normal(start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """Outward normal (t_y, -t_x)/|t| of the segment start -> end."""
    tangent = end - start
    return np.array([tangent[1], -tangent[0]]) / np.linalg.norm(tangent)


def interval_nodes(num_facets: int, length: float, rng: np.random.Generator | None) -> np.ndarray:
    """Increasing node positions on [0, length]: uniform, or random spacings (ratio up to 3)."""
    if rng is None:
        return np.linspace(0.0, length, num_facets + 1)
    spacings = rng.uniform(0.5, 1.5, num_facets)
    positions = np.concatenate([[0.0], np.cumsum(spacings)]) * (length / spacings.sum())
    positions[-1] = length
    return positions


def on_line(positions: np.ndarray, height: float = 0.0) -> np.ndarray:
    return np.stack([positions, np.full_like(positions, height)], axis=-1)


def rigid_motion(points: np.ndarray, angle: float, shift) -> np.ndarray:
    return points @ rotation(angle).T + np.asarray(shift)


@dataclasses.dataclass
class SurfacePairs:
    """Every (slave facet, master facet) pair of two polylines, in the kernels' layout."""

    x: np.ndarray  # (n, 6, 2)
    has_neighbour: np.ndarray  # (n, 2)
    slave_facet: np.ndarray  # (n,) facet i joins slave nodes i and i + 1
    master_facet: np.ndarray  # (n,) facet m joins master nodes m and m + 1
    slave_nodes: np.ndarray
    master_nodes: np.ndarray


def surface_pairs(slave_nodes: np.ndarray, master_nodes: np.ndarray) -> SurfacePairs:
    """All pairs of two polylines given in their facet orientation (facet i: node i -> i + 1).

    ``p`` and ``q`` are the far ends of the slave facets before and after the
    slave facet; a missing neighbour is flagged in ``has_neighbour`` and its
    coordinates are set to NaN, so that any use of them would show.
    """
    num_slave_facets = len(slave_nodes) - 1
    num_master_facets = len(master_nodes) - 1
    slave_facet, master_facet = (
        index.ravel()
        for index in np.meshgrid(
            np.arange(num_slave_facets), np.arange(num_master_facets), indexing="ij"
        )
    )
    padded = np.concatenate([[np.full(2, np.nan)], slave_nodes, [np.full(2, np.nan)]])
    x = np.stack(
        [
            padded[slave_facet],  # p: slave node i - 1
            slave_nodes[slave_facet],
            slave_nodes[slave_facet + 1],
            padded[slave_facet + 3],  # q: slave node i + 2
            master_nodes[master_facet],
            master_nodes[master_facet + 1],
        ],
        axis=1,
    )
    has_neighbour = np.stack([slave_facet > 0, slave_facet + 1 < num_slave_facets], axis=1)
    return SurfacePairs(x, has_neighbour, slave_facet, master_facet, slave_nodes, master_nodes)


def assemble(pairs: SurfacePairs, quantities) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Global dense D (slave x slave), M (slave x master) and weighted gap (slave)."""
    num_slave, num_master = len(pairs.slave_nodes), len(pairs.master_nodes)
    slave_dofs = np.stack([pairs.slave_facet, pairs.slave_facet + 1], axis=1)
    master_dofs = np.stack([pairs.master_facet, pairs.master_facet + 1], axis=1)
    D = np.zeros((num_slave, num_slave))
    M = np.zeros((num_slave, num_master))
    gap = np.zeros(num_slave)
    np.add.at(D, (slave_dofs[:, :, None], slave_dofs[:, None, :]), quantities.D)
    np.add.at(M, (slave_dofs[:, :, None], master_dofs[:, None, :]), quantities.M)
    np.add.at(gap, slave_dofs, quantities.gap.value)
    return D, M, gap


def assembled(pairs: SurfacePairs, **options):
    quantities = pair_quantities(
        pairs.x, pairs.has_neighbour, slave_facet=pairs.slave_facet, **options
    )
    return assemble(pairs, quantities)


def flat_interface(
    num_slave: int,
    num_master: int,
    spacing: str,
    seed: int,
    master_span: tuple[float, float] = (0.0, INTERFACE_LENGTH),
) -> SurfacePairs:
    """Coincident slave (below) and master (above) polylines on a rotated, shifted line."""
    rng = np.random.default_rng(seed)
    spacing_rng = rng if spacing == "random" else None
    slave_x = interval_nodes(num_slave, INTERFACE_LENGTH, spacing_rng)[::-1]  # right to left
    start, end = master_span
    master_x = start + interval_nodes(num_master, end - start, spacing_rng)  # left to right
    angle, shift = rng.uniform(0.0, 2.0 * np.pi), rng.uniform(-1.0, 1.0, 2)
    return surface_pairs(
        rigid_motion(on_line(slave_x), angle, shift), rigid_motion(on_line(master_x), angle, shift)
    )


def linear_field(points: np.ndarray, alpha: float, beta: np.ndarray) -> np.ndarray:
    return alpha + points @ beta


def master_lumped_integrals(master_nodes: np.ndarray, values: np.ndarray) -> np.ndarray:
    """int lambda N^_l over the master polyline for a field lambda linear on each facet."""
    lengths = np.linalg.norm(np.diff(master_nodes, axis=0), axis=1)
    result = np.zeros(len(master_nodes))
    result[:-1] += lengths * (2.0 * values[:-1] + values[1:]) / 6.0
    result[1:] += lengths * (values[:-1] + 2.0 * values[1:]) / 6.0
    return result


# --------------------------------------------------------------------------------------------
# an independent per-pair reference: roots of the projection polynomial, dense Gauss quadrature
# --------------------------------------------------------------------------------------------


def reference_nodal_normals(x: np.ndarray, has_neighbour, normals: str):
    p, a, b, q, c, d = x
    if normals == "master":
        return -unit_normal(c, d), -unit_normal(c, d)
    normal_ab = unit_normal(a, b)
    if normals == "slave":
        return normal_ab, normal_ab
    normal_a = normal_ab + (unit_normal(p, a) if has_neighbour[0] else 0.0)
    normal_b = normal_ab + (unit_normal(b, q) if has_neighbour[1] else 0.0)
    return normal_a / np.linalg.norm(normal_a), normal_b / np.linalg.norm(normal_b)


def cross2(u: np.ndarray, v: np.ndarray) -> float:
    return u[0] * v[1] - u[1] * v[0]


def reference_projection(a, b, normal_a, normal_b, point) -> float:
    """Slave parameter whose normal line passes through ``point`` (the root nearest to 0)."""
    offset0, offset1 = (a + b) / 2.0 - point, (b - a) / 2.0
    normal0, normal1 = (normal_a + normal_b) / 2.0, (normal_b - normal_a) / 2.0
    coefficients = [
        cross2(offset1, normal1),
        cross2(offset0, normal1) + cross2(offset1, normal0),
        cross2(offset0, normal0),
    ]
    roots = np.roots(coefficients)
    real = roots[np.abs(roots.imag) <= 1e-12 * np.abs(roots).max()].real
    return real[np.argmin(np.abs(real))]


def reference_pair(x, has_neighbour, normals: str, basis: str, num_points: int = 40):
    """D, M, gap of one pair by segment-based integration, written without the kernels' code."""
    p, a, b, q, c, d = x
    normal_a, normal_b = reference_nodal_normals(x, has_neighbour, normals)
    xi_c = reference_projection(a, b, normal_a, normal_b, c)
    xi_d = reference_projection(a, b, normal_a, normal_b, d)
    low, high = max(-1.0, min(xi_c, xi_d)), min(1.0, max(xi_c, xi_d))
    D, M, gap = np.zeros((2, 2)), np.zeros((2, 2)), np.zeros(2)
    if high <= low:
        return D, M, gap
    points, weights = np.polynomial.legendre.leggauss(num_points)
    half_length = np.linalg.norm(b - a) / 2.0
    for point, weight in zip(points, weights, strict=True):
        xi = low + (high - low) * (point + 1.0) / 2.0
        weight = weight * (high - low) / 2.0 * half_length
        N = np.array([(1.0 - xi) / 2.0, (1.0 + xi) / 2.0])
        Phi = DUAL_COEFFICIENTS @ N if basis == "dual" else N
        slave_point = N[0] * a + N[1] * b
        normal = N[0] * normal_a + N[1] * normal_b
        # master point m0 + eta m1 on the normal line slave_point + t normal
        eta, _ = np.linalg.solve(
            np.column_stack([(d - c) / 2.0, -normal]), slave_point - (c + d) / 2.0
        )
        N_master = np.array([(1.0 - eta) / 2.0, (1.0 + eta) / 2.0])
        master_point = N_master[0] * c + N_master[1] * d
        D += weight * np.outer(Phi, N)
        M += weight * np.outer(Phi, N_master)
        gap += weight * Phi * (normal @ (master_point - slave_point))
    return D, M, gap


def random_curved_pair(rng: np.random.Generator) -> np.ndarray:
    """A slave facet a -> b of about unit length with both neighbours bent away from the
    master (a slightly curved slave surface); a master facet c -> d slightly penetrating,
    with c above the middle part of the slave facet and d well beyond a (partial overlap);
    then a random rigid motion."""
    a = np.array([0.5, 0.0]) + rng.uniform(-0.05, 0.05, 2) * (1.0, 0.2)
    b = np.array([-0.5, 0.0]) + rng.uniform(-0.05, 0.05, 2) * (1.0, 0.2)
    bend_p, bend_q = rng.uniform(0.05, 0.2, 2)
    p = a + rng.uniform(0.8, 1.2) * np.array([np.cos(bend_p), -np.sin(bend_p)])
    q = b + rng.uniform(0.8, 1.2) * np.array([-np.cos(bend_q), -np.sin(bend_q)])
    c = np.array([rng.uniform(-0.3, 0.3), rng.uniform(-0.05, -0.03)])
    tilt = rng.uniform(-0.02, 0.02)
    d = c + rng.uniform(1.0, 1.3) * np.array([np.cos(tilt), np.sin(tilt)])
    return rigid_motion(np.array([p, a, b, q, c, d]), rng.uniform(0, 2 * np.pi), rng.normal(size=2))


# --------------------------------------------------------------------------------------------
# 1. flat, coincident, non-matching interfaces, segment-based integration
# --------------------------------------------------------------------------------------------

RATIOS = [(1, 1), (2, 3), (3, 7), (1, 7), (7, 1), (5, 13)]


@pytest.mark.parametrize("basis", BASIS_OPTIONS)
@pytest.mark.parametrize("normals", NORMAL_OPTIONS)
@pytest.mark.parametrize("spacing", ["uniform", "random"])
@pytest.mark.parametrize("num_slave,num_master", RATIOS)
def test_flat_coincident_segment_based_is_exact(num_slave, num_master, spacing, normals, basis):
    pairs = flat_interface(num_slave, num_master, spacing, seed=10 * num_slave + num_master)
    D, M, gap = assembled(pairs, normals=normals, integration="segment", basis=basis)
    rng = np.random.default_rng(7)
    coordinate_scale = np.abs(pairs.x[np.isfinite(pairs.x)]).max()
    for _ in range(3):
        alpha, beta = rng.normal(), rng.normal(size=2)
        slave_values = linear_field(pairs.slave_nodes, alpha, beta)
        master_values = linear_field(pairs.master_nodes, alpha, beta)
        scale = np.abs(D).sum(axis=1).max() * np.abs(slave_values).max()
        np.testing.assert_allclose(M @ master_values, D @ slave_values, rtol=0, atol=1e-13 * scale)
    # first moments and the constant field: every slave node is covered
    np.testing.assert_allclose(M.sum(axis=1), D.sum(axis=1), rtol=0, atol=1e-14)
    assert np.all(D.sum(axis=1) > 0.0)
    np.testing.assert_allclose(D.sum(), INTERFACE_LENGTH, rtol=1e-14)
    np.testing.assert_allclose(M.sum(), INTERFACE_LENGTH, rtol=1e-14)
    # multipliers of the standard basis reproduce linear tractions, of the dual basis constants:
    # the master nodes then receive the consistent nodal forces int lambda N^_l
    if basis == "standard":
        alpha, beta = rng.normal(), rng.normal(size=2)
        multiplier_values = linear_field(pairs.slave_nodes, alpha, beta)
        lambda_at_master = linear_field(pairs.master_nodes, alpha, beta)
    else:
        multiplier_values = np.ones(len(pairs.slave_nodes))
        lambda_at_master = np.ones(len(pairs.master_nodes))
    expected = master_lumped_integrals(pairs.master_nodes, lambda_at_master)
    np.testing.assert_allclose(
        multiplier_values @ M, expected, rtol=0, atol=1e-13 * np.abs(expected).max()
    )
    np.testing.assert_allclose(gap, 0.0, rtol=0, atol=1e-14 * max(1.0, coordinate_scale))


def positions_along_interface(pairs: SurfacePairs, nodes: np.ndarray) -> np.ndarray:
    """Coordinates along a flat interface, from the slave end at 0 (the last slave node)."""
    direction = pairs.master_nodes[-1] - pairs.master_nodes[0]
    return (nodes - pairs.slave_nodes[-1]) @ (direction / np.linalg.norm(direction))


def covered_multiplier_integrals(slave_positions: np.ndarray, span, basis: str) -> np.ndarray:
    """int over [span] of Phi_j along a flat slave surface (Phi linear on each facet, so the
    trapezoidal rule on the covered part of each facet is exact)."""
    result = np.zeros(len(slave_positions))
    coefficients = DUAL_COEFFICIENTS if basis == "dual" else np.eye(2)
    for facet in range(len(slave_positions) - 1):
        start, end = slave_positions[facet], slave_positions[facet + 1]
        low, high = max(min(start, end), span[0]), min(max(start, end), span[1])
        if high <= low:
            continue
        N_low = np.array([end - low, low - start]) / (end - start)
        N_high = np.array([end - high, high - start]) / (end - start)
        result[facet : facet + 2] += (high - low) * coefficients @ (N_low + N_high) / 2.0
    return result


@pytest.mark.parametrize("basis", BASIS_OPTIONS)
@pytest.mark.parametrize("normals", NORMAL_OPTIONS)
@pytest.mark.parametrize("num_slave,num_master", [(3, 7), (5, 13), (7, 1), (4, 4), (13, 5)])
def test_flat_partially_covered_segment_based(num_slave, num_master, normals, basis):
    """Master shorter than the slave at both ends: only the covered part is integrated."""
    master_span = (0.3, INTERFACE_LENGTH - 0.45)
    pairs = flat_interface(num_slave, num_master, "random", seed=3, master_span=master_span)
    D, M, gap = assembled(pairs, normals=normals, integration="segment", basis=basis)
    covered_length = master_span[1] - master_span[0]
    np.testing.assert_allclose(D.sum(), covered_length, rtol=1e-14)
    # D and M are integrated over the same domain: the row sums agree with each other and
    # with the integral of Phi_j over the covered part, for every slave node (covered,
    # partly covered, or not at all)
    slave_positions = positions_along_interface(pairs, pairs.slave_nodes)
    expected = covered_multiplier_integrals(slave_positions, master_span, basis)
    np.testing.assert_allclose(D.sum(axis=1), expected, rtol=0, atol=1e-14)
    np.testing.assert_allclose(M.sum(axis=1), expected, rtol=0, atol=1e-14)
    rng = np.random.default_rng(11)
    alpha, beta = rng.normal(), rng.normal(size=2)
    slave_values = linear_field(pairs.slave_nodes, alpha, beta)
    master_values = linear_field(pairs.master_nodes, alpha, beta)
    scale = np.abs(D).sum(axis=1).max() * np.abs(slave_values).max()
    np.testing.assert_allclose(M @ master_values, D @ slave_values, rtol=0, atol=1e-13 * scale)
    # the whole master is covered by the slave: consistent master nodal forces for lambda = 1
    lumped = master_lumped_integrals(pairs.master_nodes, np.ones(len(pairs.master_nodes)))
    np.testing.assert_allclose(M.sum(axis=0), lumped, rtol=0, atol=1e-14)
    np.testing.assert_allclose(gap, 0.0, rtol=0, atol=1e-14 * 3.0)


# --------------------------------------------------------------------------------------------
# 2. element-based ("concentrated") integration
# --------------------------------------------------------------------------------------------


def element_based_errors(num_slave: int, num_master: int, num_gauss_points: int) -> dict:
    pairs = flat_interface(num_slave, num_master, "uniform", seed=5)
    D_exact, M_exact, _ = assembled(pairs, integration="segment", num_gauss_points=4)
    D, M, gap = assembled(pairs, integration="element", num_gauss_points=num_gauss_points)
    rng = np.random.default_rng(2)
    alpha, beta = rng.normal(), rng.normal(size=2)
    slave_values = linear_field(pairs.slave_nodes, alpha, beta)
    master_values = linear_field(pairs.master_nodes, alpha, beta)
    lumped = master_lumped_integrals(pairs.master_nodes, np.ones(len(pairs.master_nodes)))
    return {
        "rows": np.abs(M @ master_values - D @ slave_values).max()
        / (np.abs(D).sum(axis=1).max() * np.abs(slave_values).max()),
        "columns": np.abs(M.sum(axis=0) - lumped).max() / lumped.max(),
        "M": np.abs(M - M_exact).max() / np.abs(M_exact).max(),
        "D": np.abs(D - D_exact).max() / np.abs(D_exact).max(),
        "gap": np.abs(gap).max(),
    }


def test_element_based_error_table_3_to_7():
    """Concentrated integration on a flat, coincident 3:7 interface.

    Row-wise, sum_l M_jl f(x_l) = sum_k D_jk f(x_k) for a linear f still holds to
    rounding: D and M use the same Gauss points, each point lands on exactly one
    master facet, and sum_l N^_l(eta) f_l = f(x_slave(xi)) at each point. What is
    not exact is M itself: its integrand has kinks at the master nodes, so the
    column sums (the master nodal forces of a constant multiplier, the traction
    patch test) and the entries differ from the exact (segment-based) ones, and
    they do not vanish for any number of Gauss points.
    """
    print("\nelement-based, 3:7 flat coincident interface, relative errors")
    print(
        f"{'gauss':>5} {'rows M f=D f':>14} {'col sums M':>12} {'M entries':>12} {'D entries':>12}"
    )
    for num_gauss_points in range(1, 11):
        errors = element_based_errors(3, 7, num_gauss_points)
        print(
            f"{num_gauss_points:>5} {errors['rows']:>14.3e} {errors['columns']:>12.3e}"
            f" {errors['M']:>12.3e} {errors['D']:>12.3e}"
        )
        assert errors["rows"] <= 1e-13
        assert errors["gap"] <= 1e-14 * 4.0
        assert errors["columns"] > 1e-8
        assert errors["M"] > 1e-8
        if num_gauss_points >= 2:
            assert errors["D"] <= 1e-14  # N_j N_k is quadratic: exact with 2 points


@pytest.mark.parametrize("spacing", ["uniform", "random"])
@pytest.mark.parametrize("basis", BASIS_OPTIONS)
@pytest.mark.parametrize("num_gauss_points", [2, 3, 6])
def test_element_based_exact_on_matching_meshes(num_gauss_points, basis, spacing):
    slave_positions = interval_nodes(
        5, INTERFACE_LENGTH, np.random.default_rng(4) if spacing == "random" else None
    )
    slave_nodes = rigid_motion(on_line(slave_positions[::-1]), 0.4, (0.2, -0.3))
    master_nodes = rigid_motion(on_line(slave_positions), 0.4, (0.2, -0.3))
    pairs = surface_pairs(slave_nodes, master_nodes)
    options = dict(basis=basis, num_gauss_points=num_gauss_points)
    D_exact, M_exact, _ = assembled(pairs, integration="segment", **options)
    D, M, gap = assembled(pairs, integration="element", **options)
    np.testing.assert_allclose(D, D_exact, rtol=0, atol=1e-14)
    np.testing.assert_allclose(M, M_exact, rtol=0, atol=1e-14)
    np.testing.assert_allclose(M, D[:, ::-1], rtol=0, atol=1e-14)  # master nodes in reverse
    np.testing.assert_allclose(gap, 0.0, rtol=0, atol=1e-14)


@pytest.mark.parametrize("basis", BASIS_OPTIONS)
@pytest.mark.parametrize("master_start_offset", [1e-9, -1e-9])
def test_element_based_keeps_exactly_the_gauss_points_on_the_master(master_start_offset, basis):
    """Slave (1, 0) -> (-1, 0), 2 Gauss points at x = -xi = -+1/sqrt(3); the master, at
    height 0.2, starts 1e-9 right (point excluded) or left (included) of x = -1/sqrt(3)."""
    height = 0.2
    master_start = -1.0 / np.sqrt(3.0) + master_start_offset
    x = single_pair((1.0, 0.0), (-1.0, 0.0), (master_start, height), (3.0, height))
    quantities = pair_quantities(
        x, NO_NEIGHBOURS, integration="element", basis=basis, num_gauss_points=2
    )
    points, weights = np.polynomial.legendre.leggauss(2)
    counted = -points >= master_start
    assert counted.sum() == (1 if master_start_offset > 0 else 2)
    N = np.stack([(1.0 - points) / 2.0, (1.0 + points) / 2.0], axis=1)[counted]
    Phi = N @ DUAL_COEFFICIENTS.T if basis == "dual" else N
    eta = 2.0 * (-points[counted] - master_start) / (3.0 - master_start) - 1.0
    N_master = np.stack([(1.0 - eta) / 2.0, (1.0 + eta) / 2.0], axis=1)
    w = weights[counted]
    np.testing.assert_allclose(
        quantities.D[0], np.einsum("g,gj,gk->jk", w, Phi, N), rtol=0, atol=1e-15
    )
    np.testing.assert_allclose(
        quantities.M[0], np.einsum("g,gj,gl->jl", w, Phi, N_master), rtol=0, atol=1e-15
    )
    np.testing.assert_allclose(quantities.gap.value[0], height * w @ Phi, rtol=0, atol=1e-15)
    np.testing.assert_allclose(quantities.overlap[0], w.sum(), rtol=1e-15)


@pytest.mark.parametrize("num_gauss_points", [1, 3])
@pytest.mark.parametrize("angle", [0.0, 0.3])
def test_element_based_gauss_point_on_a_master_node_is_counted_once(angle, num_gauss_points):
    """Slave facets twice as long as the master facets: the middle Gauss point of every slave
    facet (odd counts) lies on a master node. sum D must still be the interface length."""
    slave_nodes = rigid_motion(
        on_line(np.linspace(0.0, INTERFACE_LENGTH, 3)[::-1]), angle, (0.0, 0.0)
    )
    master_nodes = rigid_motion(on_line(np.linspace(0.0, INTERFACE_LENGTH, 5)), angle, (0.0, 0.0))
    D, _, _ = assembled(
        surface_pairs(slave_nodes, master_nodes),
        integration="element",
        num_gauss_points=num_gauss_points,
    )
    np.testing.assert_allclose(D.sum(), INTERFACE_LENGTH, rtol=1e-14)


# --------------------------------------------------------------------------------------------
# 3. weighted gaps of separated and penetrating configurations, computed by hand
# --------------------------------------------------------------------------------------------


def single_pair(slave_a, slave_b, master_c, master_d) -> np.ndarray:
    nodes = np.array([slave_a, slave_a, slave_b, slave_b, master_c, master_d], dtype=float)
    return nodes[None]


NO_NEIGHBOURS = np.zeros((1, 2), dtype=bool)


def pair_gap(x, **options) -> np.ndarray:
    return pair_quantities(x, NO_NEIGHBOURS, **options).gap.value[0]


@pytest.mark.parametrize("integration", INTEGRATION_OPTIONS)
@pytest.mark.parametrize("basis", BASIS_OPTIONS)
@pytest.mark.parametrize("normals", NORMAL_OPTIONS)
@pytest.mark.parametrize("gap", [0.3, -0.1])
def test_gap_parallel_master_full_cover(gap, normals, basis, integration):
    """Slave facet from (1, 0) to (-1, 0) (normal +y), master at y = gap covering it."""
    x = single_pair((1.0, 0.0), (-1.0, 0.0), (-1.5, gap), (1.7, gap))
    quantities = pair_quantities(
        x, NO_NEIGHBOURS, normals=normals, integration=integration, basis=basis
    )
    # int Phi_j = int N_j = L/2 = 1 for both bases
    np.testing.assert_allclose(quantities.gap.value[0], [gap, gap], rtol=1e-14)
    assert quantities.valid[0]
    np.testing.assert_allclose(quantities.overlap[0], 2.0, rtol=1e-14)
    np.testing.assert_allclose(quantities.Dn.value[0, :, :, 0], 0.0, atol=1e-16)
    np.testing.assert_allclose(quantities.Dn.value[0, :, :, 1], quantities.D[0], rtol=1e-14)


@pytest.mark.parametrize(
    "basis,expected_per_gap", [("standard", (0.75, 0.25)), ("dual", (1.25, -0.25))]
)
@pytest.mark.parametrize("normals", NORMAL_OPTIONS)
@pytest.mark.parametrize("gap", [0.3, -0.1])
def test_gap_parallel_master_half_cover(gap, normals, basis, expected_per_gap):
    """Master over x in [0, 3] covers the half of the slave facet next to a = (1, 0), i.e.
    xi in [-1, 0]: int N_a = 3/4, int N_b = 1/4; int Phi_a = 5/4, int Phi_b = -1/4."""
    x = single_pair((1.0, 0.0), (-1.0, 0.0), (0.0, gap), (3.0, gap))
    np.testing.assert_allclose(
        pair_gap(x, normals=normals, basis=basis), gap * np.array(expected_per_gap), rtol=1e-14
    )


@pytest.mark.parametrize("basis", BASIS_OPTIONS)
@pytest.mark.parametrize("normals", NORMAL_OPTIONS)
@pytest.mark.parametrize("offset,slope", [(0.3, 0.1), (-0.05, 0.04), (0.1, -0.2)])
def test_gap_tilted_master(offset, slope, normals, basis):
    """Master line y = offset + slope x over x in [-3, 3], flat slave facet (1, 0) -> (-1, 0).

    Along the slave normal (+y, normals ``slave`` and ``averaged`` without neighbours) the
    gap is the vertical distance offset + slope x; along the master normal it is the
    distance to the line, (offset + slope x)/sqrt(1 + slope^2). With N_a = (1 + x)/2,
    Phi_a = (1 + 3 x)/2 over x in [-1, 1]: int N_a (offset + slope x) = offset + slope/3,
    int Phi_a (offset + slope x) = offset + slope; the b terms have -slope.
    """
    x = single_pair(
        (1.0, 0.0), (-1.0, 0.0), (-3.0, offset - 3.0 * slope), (3.0, offset + 3.0 * slope)
    )
    first_moment = slope / 3.0 if basis == "standard" else slope
    expected = np.array([offset + first_moment, offset - first_moment])
    if normals == "master":
        expected /= np.sqrt(1.0 + slope**2)
    np.testing.assert_allclose(
        pair_gap(x, normals=normals, basis=basis, num_gauss_points=2), expected, rtol=1e-13
    )


@pytest.mark.parametrize("basis", BASIS_OPTIONS)
@pytest.mark.parametrize("normals", NORMAL_OPTIONS)
def test_curved_pairs_match_independent_reference(normals, basis):
    """Curved slave (averaged normals vary along the facet), tilted, penetrating master:
    segment-based D, M, gap with 12 Gauss points against the per-pair reference (40 points
    on the overlap found from the roots of the projection polynomial)."""
    rng = np.random.default_rng(123)
    x = np.array([random_curved_pair(rng) for _ in range(10)])
    has_neighbour = np.ones((len(x), 2), dtype=bool)
    has_neighbour[0] = (False, True)
    has_neighbour[1] = (True, False)
    quantities = pair_quantities(
        x, has_neighbour, normals=normals, basis=basis, integration="segment", num_gauss_points=12
    )
    assert quantities.valid.all()
    for pair in range(len(x)):
        D, M, gap = reference_pair(x[pair], has_neighbour[pair], normals, basis)
        np.testing.assert_allclose(quantities.D[pair], D, rtol=0, atol=1e-13)
        np.testing.assert_allclose(quantities.M[pair], M, rtol=0, atol=1e-13)
        np.testing.assert_allclose(quantities.gap.value[pair], gap, rtol=0, atol=1e-13)
        assert np.all(gap < 0.0) or basis == "dual"  # penetrating


def test_absent_neighbours_are_ignored():
    """The coordinates given for a missing p or q change nothing, and have zero derivatives."""
    rng = np.random.default_rng(8)
    x = np.array([random_curved_pair(rng) for _ in range(4)])
    has_neighbour = np.array([(False, False), (False, True), (True, False), (True, True)])
    other = x.copy()
    other[~has_neighbour[:, 0], 0] += 10.0
    other[~has_neighbour[:, 1], 3] -= 7.0
    first = pair_quantities(x, has_neighbour)
    second = pair_quantities(other, has_neighbour)
    np.testing.assert_array_equal(first.gap.value, second.gap.value)
    np.testing.assert_array_equal(first.Dn.grad, second.Dn.grad)
    p_grad = first.gap.grad[..., 0:2]
    q_grad = first.gap.grad[..., 6:8]
    assert np.all(p_grad[~has_neighbour[:, 0]] == 0.0) and np.all(p_grad[has_neighbour[:, 0]] != 0)
    assert np.all(q_grad[~has_neighbour[:, 1]] == 0.0) and np.all(q_grad[has_neighbour[:, 1]] != 0)


@pytest.mark.parametrize("basis", BASIS_OPTIONS)
@pytest.mark.parametrize("normals", ["averaged", "slave"])
@pytest.mark.parametrize("steepness", [1e-3, 1e-7])
def test_grazing_master(steepness, normals, basis):
    """A master facet almost edge-on, from (0.2, 0.1) to (0.2 + s, 1.1): facing = -s (to first
    order), beyond the tolerance -1e-8, so it counts. It covers x in [0.2, 0.2 + s] of the
    slave (1, 0) -> (-1, 0), where the vertical gap is 0.1 + (x - 0.2)/s; the integrands are
    quadratic, so 2 Gauss points on [0.2, 0.2 + s] give the exact answer."""
    start, height = 0.2, 0.1
    x = single_pair((1.0, 0.0), (-1.0, 0.0), (start, height), (start + steepness, height + 1.0))
    quantities = pair_quantities(x, NO_NEIGHBOURS, normals=normals, basis=basis)
    assert quantities.valid[0]
    points, weights = np.polynomial.legendre.leggauss(2)
    positions = start + steepness * (points + 1.0) / 2.0
    weights = weights * steepness / 2.0
    N = np.stack([(1.0 + positions) / 2.0, (1.0 - positions) / 2.0], axis=1)  # a at x = 1
    Phi = N @ DUAL_COEFFICIENTS.T if basis == "dual" else N
    vertical_gap = height + (positions - start) / steepness
    np.testing.assert_allclose(
        quantities.D[0], np.einsum("g,gj,gk->jk", weights, Phi, N), rtol=1e-9
    )
    np.testing.assert_allclose(
        quantities.gap.value[0], np.einsum("g,gj,g->j", weights, Phi, vertical_gap), rtol=1e-9
    )


@pytest.mark.parametrize("normals,integration,basis", ALL_OPTIONS)
@pytest.mark.parametrize(
    "name,master_start,master_end",
    [
        ("back-facing (same orientation as the slave)", (1.0, 0.1), (-1.0, 0.1)),
        ("edge-on (perpendicular)", (0.2, 0.1), (0.2, 1.1)),
        ("facing within the tolerance", (0.2, 0.1), (0.2 + 1e-9, 1.1)),
    ],
)
def test_master_not_facing_the_slave_contributes_nothing(
    name, master_start, master_end, normals, integration, basis
):
    x = single_pair((1.0, 0.0), (-1.0, 0.0), master_start, master_end)
    quantities = pair_quantities(
        x, NO_NEIGHBOURS, normals=normals, integration=integration, basis=basis
    )
    assert not quantities.valid[0]
    for values in continuity_measures(quantities).values():
        assert np.all(values == 0.0)
    for item in (quantities.Dn, quantities.Mn, quantities.gap):
        assert np.all(item.grad == 0.0)


@pytest.mark.parametrize("normals,integration,basis", ALL_OPTIONS)
def test_units_do_not_matter(normals, integration, basis):
    """Scaling all coordinates by s scales D, M, Dn, Mn by s and the weighted gap by s^2;
    the gradients by 1 and s."""
    rng = np.random.default_rng(31)
    x = np.array([random_curved_pair(rng) for _ in range(6)])
    has_neighbour = np.ones((len(x), 2), dtype=bool)
    options = dict(normals=normals, integration=integration, basis=basis)
    reference = pair_quantities(x, has_neighbour, **options)
    assert reference.valid.all()
    for scale in (1e-6, 1e-3, 1e3, 1e6):
        scaled = pair_quantities(x * scale, has_neighbour, **options)
        np.testing.assert_array_equal(scaled.valid, reference.valid)
        np.testing.assert_allclose(scaled.D / scale, reference.D, rtol=0, atol=1e-14)
        np.testing.assert_allclose(scaled.M / scale, reference.M, rtol=0, atol=1e-14)
        for name in ("Dn", "Mn"):
            ours, theirs = getattr(scaled, name), getattr(reference, name)
            np.testing.assert_allclose(ours.value / scale, theirs.value, rtol=0, atol=1e-14)
            np.testing.assert_allclose(ours.grad, theirs.grad, rtol=0, atol=1e-13)
        np.testing.assert_allclose(
            scaled.gap.value / scale**2, reference.gap.value, rtol=0, atol=1e-15
        )
        np.testing.assert_allclose(scaled.gap.grad / scale, reference.gap.grad, rtol=0, atol=1e-14)


@pytest.mark.parametrize("basis", BASIS_OPTIONS)
@pytest.mark.parametrize("normals", NORMAL_OPTIONS)
@pytest.mark.parametrize("overlap", [1e-4, 1e-8, 1e-11])
def test_tiny_overlaps_are_integrated(overlap, normals, basis):
    """Segment-based: the master covers x in [1 - overlap, 3] of the slave (1, 0) -> (-1, 0),
    i.e. xi in [-1, -1 + overlap], next to a, where N_a = 1 - O(overlap)."""
    x = single_pair((1.0, 0.0), (-1.0, 0.0), (1.0 - overlap, 0.1), (3.0, 0.1))
    quantities = pair_quantities(x, NO_NEIGHBOURS, normals=normals, basis=basis)
    assert quantities.valid[0]
    relative_rounding = 1e-15 / overlap
    np.testing.assert_allclose(quantities.overlap[0], overlap, rtol=relative_rounding)
    Phi_a = np.array([1.0, 0.0]) if basis == "standard" else np.array([2.0, -1.0])
    expected_D = overlap * np.outer(Phi_a, [1.0, 0.0])
    np.testing.assert_allclose(
        quantities.D[0], expected_D, rtol=0, atol=overlap * (overlap + relative_rounding) * 4
    )
    np.testing.assert_allclose(
        quantities.gap.value[0],
        0.1 * overlap * Phi_a,
        rtol=0,
        atol=overlap * (overlap + relative_rounding),
    )


# --------------------------------------------------------------------------------------------
# 4. dual basis
# --------------------------------------------------------------------------------------------


def test_dual_basis_coefficients_of_a_linear_facet():
    np.testing.assert_allclose(kernels.dual_basis_coefficients(), DUAL_COEFFICIENTS, rtol=1e-14)
    for num_gauss_points in (2, 3, 5):
        np.testing.assert_allclose(
            kernels.dual_basis_coefficients(np.full(num_gauss_points, 3.7), num_gauss_points),
            DUAL_COEFFICIENTS,
            rtol=1e-13,
        )


@pytest.mark.parametrize("jacobian_slope", [0.5, -0.8, 0.95])
def test_dual_basis_coefficients_with_varying_jacobian(jacobian_slope):
    """J(xi) = 1 + s xi at 3 Gauss points (exact for J N N); biorthogonality checked with a
    20-point rule: int Phi_j N_k J = delta_jk int N_k J."""
    points3, _ = np.polynomial.legendre.leggauss(3)
    coefficients = kernels.dual_basis_coefficients(1.0 + jacobian_slope * points3, 3)
    assert not np.allclose(coefficients, DUAL_COEFFICIENTS)
    points, weights = np.polynomial.legendre.leggauss(20)
    N = np.stack([(1.0 - points) / 2.0, (1.0 + points) / 2.0])
    Phi = coefficients @ N
    weights = weights * (1.0 + jacobian_slope * points)
    biorthogonal = np.einsum("g,jg,kg->jk", weights, Phi, N)
    np.testing.assert_allclose(biorthogonal, np.diag(N @ weights), rtol=0, atol=1e-14)
    np.testing.assert_allclose(Phi.sum(axis=0), 1.0, rtol=1e-14)  # partition of unity


@pytest.mark.parametrize("normals", NORMAL_OPTIONS)
@pytest.mark.parametrize("integration", INTEGRATION_OPTIONS)
def test_dual_basis_biorthogonal_on_distorted_facets(normals, integration):
    """Single slave facets of random length and orientation, covered by a longer, parallel
    master: D = diag(L/2) with the dual basis, L/6 [[2, 1], [1, 2]] with the standard basis."""
    rng = np.random.default_rng(21)
    lengths = rng.uniform(0.01, 5.0, 30)
    x = []
    for length in lengths:
        slave = on_line(np.array([length, 0.0]))
        master = on_line(np.array([-0.3 * length, 1.4 * length]), rng.uniform(-0.1, 0.1) * length)
        shift = rng.normal(size=2) * 3.0
        nodes = rigid_motion(
            np.concatenate([slave[[0, 0, 1, 1]], master]), rng.uniform(0, 2 * np.pi), shift
        )
        x.append(nodes)
    x = np.array(x)
    has_neighbour = np.zeros((len(x), 2), dtype=bool)
    dual = pair_quantities(
        x, has_neighbour, normals=normals, integration=integration, basis="dual"
    )
    standard = pair_quantities(x, has_neighbour, normals=normals, integration=integration)
    expected_dual = lengths[:, None, None] / 2.0 * np.eye(2)
    expected_standard = lengths[:, None, None] / 6.0 * np.array([[2.0, 1.0], [1.0, 2.0]])
    tolerance = 1e-14 * lengths[:, None, None]
    assert np.all(np.abs(dual.D - expected_dual) <= tolerance)
    assert np.all(np.abs(standard.D - expected_standard) <= tolerance)


@pytest.mark.parametrize("normals", NORMAL_OPTIONS)
def test_dual_basis_global_D_diagonal_on_curved_surface(normals):
    """A curved slave polyline with random facet lengths against the same polyline as master
    (coincident nodes): with the dual basis the assembled D is diagonal, D_jj = (L_j-1 + L_j)/2."""
    rng = np.random.default_rng(5)
    num_facets = 9
    angles = np.cumsum(rng.uniform(0.05, 0.2, num_facets))
    steps = rng.uniform(0.2, 1.0, num_facets)[:, None] * np.stack(
        [-np.cos(angles), -np.sin(angles)], axis=1
    )
    slave_nodes = np.concatenate([[[0.0, 0.0]], np.cumsum(steps, axis=0)])
    pairs = surface_pairs(slave_nodes, slave_nodes[::-1].copy())
    D, M, gap = assembled(pairs, normals=normals, basis="dual")
    lengths = np.linalg.norm(steps, axis=1)
    expected = (np.concatenate([[0.0], lengths]) + np.concatenate([lengths, [0.0]])) / 2.0
    np.testing.assert_allclose(D, np.diag(expected), rtol=0, atol=1e-13)
    np.testing.assert_allclose(M, D[:, ::-1], rtol=0, atol=1e-13)
    np.testing.assert_allclose(gap, 0.0, rtol=0, atol=1e-13)


# --------------------------------------------------------------------------------------------
# 5. derivatives: Taylor tests and finite differences
# --------------------------------------------------------------------------------------------

NUM_DERIVATIVE_CASES = 24
TAYLOR_STEPS = 1e-2 * 2.0 ** -np.arange(7)


def flat_outputs(quantities) -> tuple[np.ndarray, np.ndarray]:
    """Dn, Mn, gap of each pair as one vector (n, 18), and its Jacobian (n, 18, 12)."""
    num_pairs = quantities.gap.value.shape[0]
    values = np.concatenate(
        [
            item.value.reshape(num_pairs, -1)
            for item in (quantities.Dn, quantities.Mn, quantities.gap)
        ],
        axis=1,
    )
    grads = np.concatenate(
        [
            item.grad.reshape(num_pairs, -1, 12)
            for item in (quantities.Dn, quantities.Mn, quantities.gap)
        ],
        axis=1,
    )
    return values, grads


def gauss_points_clear_of_master_ends(x: np.ndarray, normals: str, num_gauss_points: int) -> bool:
    normal_a, normal_b = reference_nodal_normals(x, (True, True), normals)
    points, _ = np.polynomial.legendre.leggauss(num_gauss_points)
    ends = [reference_projection(x[1], x[2], normal_a, normal_b, node) for node in x[4:]]
    return all(np.abs(points - end).min() > 0.1 for end in ends)


def derivative_cases(normals: str, integration: str, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    cases = []
    while len(cases) < NUM_DERIVATIVE_CASES:
        x = random_curved_pair(rng)
        if integration == "element" and not gauss_points_clear_of_master_ends(x, normals, 3):
            continue
        cases.append(x)
    return np.array(cases)


@pytest.mark.parametrize("basis", BASIS_OPTIONS)
@pytest.mark.parametrize("integration", INTEGRATION_OPTIONS)
@pytest.mark.parametrize("normals", NORMAL_OPTIONS)
def test_taylor_second_order(normals, integration, basis):
    seed = 100 * NORMAL_OPTIONS.index(normals) + 10 * INTEGRATION_OPTIONS.index(integration)
    cases = derivative_cases(normals, integration, seed)
    rng = np.random.default_rng(seed + 1)
    directions = rng.normal(size=cases.shape)
    directions /= np.abs(directions).max(axis=(1, 2), keepdims=True)
    num_steps = len(TAYLOR_STEPS)
    perturbed = cases[:, None] + TAYLOR_STEPS[None, :, None, None] * directions[:, None]
    x = np.concatenate([cases[:, None], perturbed], axis=1).reshape(-1, 6, 2)
    has_neighbour = np.ones((len(x), 2), dtype=bool)
    quantities = pair_quantities(
        x, has_neighbour, normals=normals, integration=integration, basis=basis
    )
    assert quantities.valid.all()
    overlap = quantities.overlap.reshape(len(cases), num_steps + 1)
    assert np.all(overlap > 0.1)
    if integration == "element":  # the same Gauss points on the master for every step
        assert np.all(overlap == overlap[:, :1])
    values, grads = flat_outputs(quantities)
    values = values.reshape(len(cases), num_steps + 1, -1)
    grads = grads.reshape(len(cases), num_steps + 1, -1, 12)
    linear_change = np.einsum("cvi,ci->cv", grads[:, 0], directions.reshape(len(cases), 12))
    remainders = np.linalg.norm(
        values[:, 1:] - values[:, :1] - TAYLOR_STEPS[None, :, None] * linear_change[:, None],
        axis=-1,
    )
    slopes = np.array([np.polyfit(np.log(TAYLOR_STEPS), np.log(r), 1)[0] for r in remainders])
    option = f"{normals:>8} {integration:>7} {basis:>8}"
    print(f"\nTaylor slopes {option}: min {slopes.min():.4f} max {slopes.max():.4f}")
    assert np.all(np.abs(slopes - 2.0) <= 0.1), slopes
    # and without the first-order term the remainder is first order
    zeroth = np.linalg.norm(values[:, 1:] - values[:, :1], axis=-1)
    zeroth_slopes = np.array([np.polyfit(np.log(TAYLOR_STEPS), np.log(r), 1)[0] for r in zeroth])
    assert np.all(np.abs(zeroth_slopes - 1.0) <= 0.1)


@pytest.mark.parametrize("basis", BASIS_OPTIONS)
@pytest.mark.parametrize("integration", INTEGRATION_OPTIONS)
@pytest.mark.parametrize("normals", NORMAL_OPTIONS)
def test_gradients_match_central_differences(normals, integration, basis):
    seed = 100 * NORMAL_OPTIONS.index(normals) + 10 * INTEGRATION_OPTIONS.index(integration) + 5
    cases = derivative_cases(normals, integration, seed)
    step = 1e-6
    offsets = step * np.eye(12).reshape(12, 6, 2)
    x = np.concatenate(
        [cases[:, None], cases[:, None] + offsets[None], cases[:, None] - offsets[None]], axis=1
    ).reshape(-1, 6, 2)
    has_neighbour = np.ones((len(x), 2), dtype=bool)
    quantities = pair_quantities(
        x, has_neighbour, normals=normals, integration=integration, basis=basis
    )
    values, grads = flat_outputs(quantities)
    values = values.reshape(len(cases), 25, -1)
    grads = grads.reshape(len(cases), 25, -1, 12)[:, 0]
    differences = (values[:, 1:13] - values[:, 13:25]).transpose(0, 2, 1) / (2.0 * step)
    error = np.abs(differences - grads).max(axis=(1, 2)) / np.abs(grads).max(axis=(1, 2))
    assert error.max() <= 1e-7, error.max()


# --------------------------------------------------------------------------------------------
# 6. degenerate geometry: finite outputs, no exception, continuity
# --------------------------------------------------------------------------------------------


def degenerate_configurations() -> dict[str, tuple[np.ndarray, np.ndarray, bool]]:
    """Named single pairs (x (1, 6, 2), has_neighbour (1, 2), whether the overlap is positive);
    slave a = (1, 0) -> b = (-1, 0) with neighbours p, q bent down a little, master above it,
    at height 0.1 unless said."""
    p, a, b, q = (2.0, -0.1), (1.0, 0.0), (-1.0, 0.0), (-2.0, -0.15)
    flat_slave = ((2.0, 0.0), a, b, (-2.0, 0.0))
    both = np.ones((1, 2), dtype=bool)

    def pair(c, d, neighbours=both, slave=(p, a, b, q), overlapping=True):
        return np.array([[*slave, c, d]], dtype=float), neighbours, overlapping

    tiny_angle = 1e-8
    tilted = rotation(tiny_angle) @ np.array([2.4, 0.0])
    start, start_on_slave = np.array([-1.2, 0.1]), np.array([-1.2, 0.0])
    return {
        "master node above slave node a": pair((-0.5, 0.1), (1.0, 0.1)),
        "master nodes above both slave nodes": pair((-1.0, 0.1), (1.0, 0.1)),
        "master nodes on both slave nodes": pair((-1.0, 0.0), (1.0, 0.0)),
        "master node on slave node, no neighbours": pair(
            (-1.0, 0.0), (0.3, 0.0), np.zeros((1, 2), bool)
        ),
        "overlap 1e-14 at a": pair((1.0 - 1e-14, 0.1), (2.5, 0.1)),
        "overlap 1e-14 at b": pair((-2.0, 0.1), (-1.0 + 1e-14, 0.1)),
        "touching at a (zero overlap)": pair((1.0, 0.0), (2.0, 0.0), overlapping=False),
        "touching at b (zero overlap)": pair((-2.0, 0.0), (-1.0, 0.0), overlapping=False),
        "adjacent above a (zero overlap)": pair(
            (1.0, 0.1), (2.0, 0.1), slave=flat_slave, overlapping=False
        ),
        "master 10x longer": pair((-10.0, 0.1), (10.0, 0.1)),
        "master 0.1x as long": pair((0.2, 0.1), (0.4, 0.1)),
        "master 0.1x as long, penetrating": pair((-0.33, -0.05), (-0.13, -0.05)),
        "nearly parallel, rotated 1e-8": pair(start, start + tilted),
        "nearly parallel, coincident": pair(start_on_slave, start_on_slave + tilted),
        "nearly parallel, flat slave": pair(start, start + tilted, slave=flat_slave),
    }


DEGENERATE = degenerate_configurations()


def continuity_measures(quantities) -> dict[str, np.ndarray]:
    return {
        "D": quantities.D,
        "M": quantities.M,
        "Dn": quantities.Dn.value,
        "Mn": quantities.Mn.value,
        "gap": quantities.gap.value,
    }


@pytest.mark.parametrize("normals,integration,basis", ALL_OPTIONS)
@pytest.mark.parametrize("name", list(DEGENERATE))
def test_degenerate_geometry_finite_and_continuous(name, normals, integration, basis):
    x, has_neighbour, overlapping = DEGENERATE[name]
    rng = np.random.default_rng(list(DEGENERATE).index(name))
    options = dict(normals=normals, integration=integration, basis=basis)
    perturbations = rng.normal(size=(8,) + x.shape[1:])
    perturbations *= 1e-12 / np.linalg.norm(perturbations, axis=-1, keepdims=True)
    batch = np.concatenate([x, x + perturbations])
    neighbours = np.repeat(has_neighbour, len(batch), axis=0)
    quantities = pair_quantities(batch, neighbours, **options)
    for item in (quantities.Dn, quantities.Mn, quantities.gap):
        assert np.all(np.isfinite(item.value)) and np.all(np.isfinite(item.grad))
    assert np.all(np.isfinite(quantities.D)) and np.all(np.isfinite(quantities.M))
    assert np.all(np.isfinite(quantities.overlap))
    if integration == "segment":
        assert quantities.valid[0] == overlapping
        assert (quantities.overlap[0] > 0.0) == overlapping
    for label, values in continuity_measures(quantities).items():
        change = np.abs(values[1:] - values[:1]).max()
        assert change <= 1e-10 * max(1.0, np.abs(values).max()), (label, change)
    # and the same pair alone gives the same result as inside a batch
    alone = pair_quantities(x, has_neighbour, **options)
    np.testing.assert_array_equal(alone.gap.value, quantities.gap.value[:1])
