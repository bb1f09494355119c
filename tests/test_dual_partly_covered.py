"""The dual basis over the covered part of partly covered slave facets (issue 11, item 5):
positive nodal weights and the gap's sign, exact values by hand, the patch test,
Taylor tests of every output with the coupling between the pairs of a slave facet,
slivers, and serial = 2 ranks."""

from __future__ import annotations

import dolfinx
import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_mortar import MortarInterface, covered, meshes, stencils
from dolfinx_mortar.kernels import KernelOptions

# -- pairs on a node table (no mesh) --------------------------------------------------------


def covered_stencil(node_x, slave_facets, master_facets, pairs, normals="averaged"):
    blocks = np.arange(node_x.shape[0])
    slave_facets, master_facets = np.asarray(slave_facets), np.asarray(master_facets)
    pairs = np.asarray(pairs)
    base = stencils.STENCILS[node_x.shape[1]].build(
        blocks, node_x, slave_facets, slave_facets, master_facets, pairs, normals=normals)
    return covered.CoveredStencil(base)


def evaluate(stencil, node_x, normals="averaged", crosspoint=None):
    options = KernelOptions(normals=normals, integration="segment", basis="dual",
                            num_gauss_points=3 if stencil.gdim == 2 else 7)
    return stencil.evaluate(node_x, options, crosspoint=crosspoint)


def assembled(stencil, q, node_x, z):
    """Node-table D, M, gaps, areas and contact force -B^T z (z per node)."""
    n, gdim = node_x.shape
    s, m = stencil.slave_nodes, stencil.master_nodes
    D, M = np.zeros((n, n)), np.zeros((n, n))
    np.add.at(D, (s[:, :, None], s[:, None, :]), q.D)
    np.add.at(M, (s[:, :, None], m[:, None, :]), q.M)
    gap, area = np.zeros(n), np.zeros(n)
    np.add.at(gap, s, q.gap.value)
    np.add.at(area, s, q.area.value)
    zp = z[s]
    force = np.zeros((n, gdim))
    np.add.at(force, s, -np.einsum("nj,njkc->nkc", zp, q.Dn.value))
    np.add.at(force, m, np.einsum("nj,njlc->nlc", zp, q.Mn.value))
    return {"D": D, "M": M, "gap": gap, "area": area, "force": force}


def assembled_jacobians(stencil, q, node_x, z):
    """d/d node_x of the gaps, the force, D and M, from the stencil's combined gradients
    (the cross-pair terms included), scattered onto the node table."""
    n, gdim = node_x.shape
    ns, nm = stencil.ns, stencil.nm
    rows = q.gap.rows
    cols = (stencil.nodes[rows][:, :, None] * gdim + np.arange(gdim)).reshape(rows.size, -1)
    present = np.repeat(stencil.present[rows], gdim, axis=1)
    slave, master = stencil.slave_nodes[rows], stencil.master_nodes[rows]
    zp = z[slave]

    def scatter(terms, row_index, size):
        values = stencil.combined_gradients(q, rows, terms)  # (T, width gdim, rows)
        out = np.zeros((size, n * gdim))
        for t in range(len(terms)):
            r = row_index(t)  # (rows,)
            np.add.at(out, (np.broadcast_to(r[:, None], cols.shape)[present], cols[present]),
                      values[t].T[present])
        return out

    js = range(ns)
    gap = scatter([[(stencil.GAP + j, 1.0)] for j in js], lambda t: slave[:, t], n)
    terms = [[(stencil.dn(j, k, c), -zp[:, j]) for j in js] for k in range(ns)
             for c in range(gdim)]
    terms += [[(stencil.mn(j, l, c), zp[:, j]) for j in js] for l in range(nm)
              for c in range(gdim)]

    def force_row(t):
        if t < ns * gdim:
            k, c = divmod(t, gdim)
            return slave[:, k] * gdim + c
        l, c = divmod(t - ns * gdim, gdim)
        return master[:, l] * gdim + c

    force = scatter(terms, force_row, n * gdim)
    result = {"gap": gap, "force": force}
    D = scatter([[(stencil.d(j, k), 1.0)] for j in js for k in js],
                lambda t: slave[:, t // ns] * n + slave[:, t % ns], n * n)
    result["D"] = D
    if gdim == 3:
        result["M"] = scatter([[(stencil.m(j, l), 1.0)] for j in js for l in range(nm)],
                              lambda t: slave[:, t // nm] * n + master[:, t % nm], n * n)
    return result


def taylor_slopes(stencil, node_x, normals, seed=0, crosspoint=None):
    """log2 of the remainder ratio |f(x + h v) - f(x) - h J v| for h and h/2, per output."""
    rng = np.random.default_rng(seed)
    z = rng.uniform(0.5, 1.5, node_x.shape[0])
    direction = rng.standard_normal(node_x.shape)
    q = evaluate(stencil, node_x, normals, crosspoint)
    values = assembled(stencil, q, node_x, z)
    jacobians = assembled_jacobians(stencil, q, node_x, z)
    slopes = {}
    for name, J in jacobians.items():
        base = values[name].reshape(-1)
        linear = J @ direction.reshape(-1)
        errors = []
        for h in (2e-3, 1e-3):
            moved = evaluate(stencil, node_x + h * direction, normals, crosspoint)
            change = assembled(stencil, moved, node_x + h * direction, z)[name].reshape(-1)
            errors.append(np.abs(change - base - h * linear).max())
        assert np.abs(linear).max() > 1e-3, name
        slopes[name] = np.log2(errors[0] / errors[1])
    return slopes


# 2D: slave facet (1, 0) -> (0, 0) (normal +y), master lines above or below, x >= 0.32


def issue_example_2d(gap, start=0.32):
    node_x = np.array([[1.0, 0.0], [0.0, 0.0], [start, gap], [1.6, gap]])
    return node_x, [[0, 1]], [[2, 3]], [[0, 0]]


@pytest.mark.parametrize("gap", [0.05, -0.05])
def test_issue_example_2d_weights_and_gap_sign(gap):
    """Covered part x in [0.32, 1], N_a = x, N_b = 1 - x: the nodal weights are
    int N_a = (1 - 0.32^2)/2 = 0.4488 and int N_b = 0.68 - 0.4488 = 0.2312, D is
    diag(those), and a constant gap gives g~_j / weight_j = gap at both nodes (the
    whole-facet dual basis gave -0.153 gap at node b)."""
    node_x, slave, master, pairs = issue_example_2d(gap)
    stencil = covered_stencil(node_x, slave, master, pairs)
    q = evaluate(stencil, node_x)
    weights = np.array([(1 - 0.32**2) / 2, 0.68 - (1 - 0.32**2) / 2])
    np.testing.assert_allclose(q.area.value[0], weights, rtol=1e-13)
    np.testing.assert_allclose(q.D[0], np.diag(weights), atol=1e-14)
    np.testing.assert_allclose(q.gap.value[0] / q.area.value[0], [gap, gap], rtol=1e-12)
    # the master's weights: sum_l M_jl = D_jj (constants), M x^m = D x^s (linear fields)
    np.testing.assert_allclose(q.M[0].sum(axis=1), weights, rtol=1e-13)
    np.testing.assert_allclose(q.M[0] @ node_x[2:, 0], weights * node_x[:2, 0], atol=1e-14)


def tilted_master_2d(offset, slope):
    """Master line y = offset + slope x over [0.32, 1.6], split at x = 0.8 (two pairs)."""
    x = np.array([0.32, 0.8, 1.6])
    node_x = np.vstack([[[1.0, 0.0], [0.0, 0.0]], np.column_stack([x, offset + slope * x])])
    return node_x, [[0, 1]], [[2, 3], [3, 4]], [[0, 0], [0, 1]]


def test_gap_in_the_slave_space_gives_its_nodal_values_2d():
    """The gap along the facet normal +y, g(x) = 0.03 + 0.02 x > 0, is linear:
    g~_j / int N_j is g at node j (covered part only), over two master facets; D is
    diagonal. The whole-facet dual basis gave node b a negative weighted gap."""
    offset, slope = 0.03, 0.02
    node_x, slave, master, pairs = tilted_master_2d(offset, slope)
    stencil = covered_stencil(node_x, slave, master, pairs, normals="slave")
    q = evaluate(stencil, node_x, normals="slave")
    values = assembled(stencil, q, node_x, np.ones(5))
    weights = np.array([(1 - 0.32**2) / 2, 0.68 - (1 - 0.32**2) / 2])
    np.testing.assert_allclose(np.diag(values["D"])[:2], weights, rtol=1e-13)
    assert np.abs(values["D"] - np.diag(np.diag(values["D"]))).max() < 1e-15
    np.testing.assert_allclose(values["gap"][:2] / weights, offset + slope * node_x[:2, 0],
                               rtol=1e-12)
    # the whole-facet dual basis Phi_b = 2 - 3 x gave g~_b = int_0.32^1 (2 - 3 x) g(x) < 0
    whole = stencil.base.evaluate(node_x, KernelOptions(normals="slave", basis="dual",
                                                        num_gauss_points=3))
    expected = offset * 0.0136 + slope * -(0.32**2 - 0.32**3)
    assert whole.gap.value[:, 1].sum() == pytest.approx(expected, rel=1e-12)
    assert expected < 0.0


# 3D: the slave facets of tests/test_kernel_surface3.py face -z; master below, x >= c

SLAVE_QUAD = np.array([[0, 0, 0], [0, 1, 0], [1, 1, 0], [1, 0, 0]], float)
SLAVE_TRIANGLE = np.array([[0, 0, 0], [0, 1, 0], [1, 0, 0]], float)


def master_strips(x_cuts, z, y0=-0.5, y1=1.5, tilt=0.0):
    """Master quadrilaterals over [x_i, x_i+1] x [y0, y1] at z + tilt x (normal ~ +z)."""
    nodes, facets = [], []
    for x0, x1 in zip(x_cuts[:-1], x_cuts[1:], strict=True):
        start = len(nodes)
        nodes += [[x0, y0, z + tilt * x0], [x1, y0, z + tilt * x1], [x1, y1, z + tilt * x1],
                  [x0, y1, z + tilt * x0]]
        facets.append(list(range(start, start + 4)))
    return np.array(nodes), np.array(facets)


def covered_integrals(slave, c):
    """int N_j over the slave facet's part x >= c, by hand (unit triangle or square)."""
    int_1 = (1 - c) ** 2 / 2 if slave.shape[0] == 3 else 1 - c
    if slave.shape[0] == 3:
        int_x = (0.5 - 1 / 3) - (c**2 / 2 - c**3 / 3)
        int_y = (1 - c) ** 3 / 6
        return np.array([int_1 - int_x - int_y, int_y, int_x])
    int_x = (1 - c**2) / 2
    return np.array([int_1 - int_x, int_1 - int_x, int_x, int_x]) * 0.5


def pairs_3d(slave, x_cuts, z, tilt=0.0):
    master_x, master_facets = master_strips(x_cuts, z, tilt=tilt)
    ns = slave.shape[0]
    node_x = np.vstack([slave, master_x])
    pairs = [[0, f] for f in range(master_facets.shape[0])]
    return node_x, [list(range(ns))], master_facets + ns, pairs


@pytest.mark.parametrize("slave", [SLAVE_TRIANGLE, SLAVE_QUAD], ids=["triangle", "quad"])
@pytest.mark.parametrize("gap", [0.1, -0.1])
def test_partly_covered_3d_weights_and_gap_sign(slave, gap):
    """Masters over x in [0.3, 0.7] and [0.7, 1.5] at z = -gap: the nodal weights are
    the covered integrals of N_j (positive, by hand), D is diagonal, g~_j / weight_j is
    the gap at every node, and M x = D x for linear fields."""
    node_x, slave_facets, master_facets, pairs = pairs_3d(slave, [0.3, 0.7, 1.5], -gap)
    stencil = covered_stencil(node_x, slave_facets, master_facets, pairs)
    q = evaluate(stencil, node_x)
    values = assembled(stencil, q, node_x, np.ones(node_x.shape[0]))
    ns = slave.shape[0]
    weights = covered_integrals(slave, 0.3)
    assert np.all(weights > 0.0)
    D = values["D"][:ns, :ns]
    np.testing.assert_allclose(np.diag(D), weights, rtol=1e-12)
    assert np.abs(D - np.diag(np.diag(D))).max() < 1e-14
    np.testing.assert_allclose(values["area"][:ns], weights, rtol=1e-12)
    np.testing.assert_allclose(values["gap"][:ns] / weights, gap, rtol=1e-11)
    for field in (node_x[:, 0], node_x[:, 1], 0.3 - 2 * node_x[:, 0] + node_x[:, 1]):
        np.testing.assert_allclose(values["M"][:ns] @ field, D @ field[:ns], atol=1e-13)


@pytest.mark.parametrize("slave", [SLAVE_TRIANGLE, SLAVE_QUAD], ids=["triangle", "quad"])
def test_gap_in_the_slave_space_gives_its_nodal_values_3d(slave):
    """A master plane z = -0.1 - 0.05 x with the slave normals: the gap 0.1 + 0.05 x
    along -z, linear, is in the slave space: g~_j / weight_j = 0.1 + 0.05 x_j."""
    node_x, slave_facets, master_facets, pairs = pairs_3d(slave, [0.3, 0.7, 1.5], -0.1,
                                                          tilt=-0.05)
    stencil = covered_stencil(node_x, slave_facets, master_facets, pairs, normals="slave")
    q = evaluate(stencil, node_x, normals="slave")
    values = assembled(stencil, q, node_x, np.ones(node_x.shape[0]))
    ns = slave.shape[0]
    weights = covered_integrals(slave, 0.3)
    np.testing.assert_allclose(values["gap"][:ns] / weights, 0.1 + 0.05 * slave[:, 0],
                               rtol=1e-11)


@pytest.mark.parametrize("normals", ["averaged", "slave", "master"])
@pytest.mark.parametrize("dim", [2, 3])
def test_fully_covered_facets_need_no_partner_coupling(dim, normals):
    """A facet covered by two masters: its M_e is the whole facet's mass matrix, so the
    pairs' derivatives with respect to the master nodes through A_e sum to zero. The
    stencil leaves it narrow; its Jacobians equal those of the same stencil widened
    by hand (the coupling computed and summed) to rounding, and they pass Taylor.
    With master normals the two masters, projected along their own normals, leave a
    gap at their common node or edge (2D: 5e-4 of the facet): partly covered, widened.
    Masters of two surfaces meeting under the facet (their boundaries there): widened."""
    if dim == 3:
        # two master triangles of one surface, their common edge across the facet
        master = np.array([[-0.5, -0.5, -0.1], [1.4, -0.5, -0.12], [-0.5, 1.0, -0.08],
                           [1.5, 1.5, -0.1]])
        node_x = np.vstack([SLAVE_TRIANGLE, master])
        slave_facets, master_facets, pairs = [[0, 1, 2]], [[3, 4, 5], [4, 6, 5]], [[0, 0], [0, 1]]
    else:
        node_x = np.array([[1.0, 0.0], [0.0, 0.0], [-0.2, 0.05], [0.45, 0.06], [1.3, 0.08]])
        slave_facets, master_facets, pairs = [[0, 1]], [[2, 3], [3, 4]], [[0, 0], [0, 1]]
    narrow = covered_stencil(node_x, slave_facets, master_facets, pairs)
    z = np.random.default_rng(3).uniform(0.5, 1.5, node_x.shape[0])
    q = evaluate(narrow, node_x, normals)
    partly = normals == "master"
    assert narrow.widened.tolist() == [partly] and narrow.widenings == int(partly)
    wide = covered_stencil(node_x, slave_facets, master_facets, pairs)
    wide.widen(np.arange(wide.widened.size))
    assert wide.width > narrow.width or partly
    q_wide = evaluate(wide, node_x, normals)
    expected = assembled_jacobians(wide, q_wide, node_x, z)
    for name, J in assembled_jacobians(narrow, q, node_x, z).items():
        scale = np.abs(expected[name]).max()
        assert np.abs(J - expected[name]).max() <= 1e-13 * scale, name
    slopes = taylor_slopes(narrow, node_x, normals)
    assert narrow.widened.tolist() == [partly]
    for name, slope in slopes.items():
        assert abs(slope - 2.0) < 0.1, (name, slopes)
    if dim == 3:
        node_x, slave_facets, master_facets, pairs = pairs_3d(SLAVE_TRIANGLE, [-0.5, 0.4, 1.5],
                                                              -0.1, tilt=-0.05)
        split = covered_stencil(node_x, slave_facets, master_facets, pairs)
        split.master_boundary = covered.boundary_nodes(np.asarray(master_facets)[:, [0, 1, 2]],
                                                       node_x.shape[0])
        evaluate(split, node_x, normals)
        assert split.widened.tolist() == [True]


@pytest.mark.parametrize("normals", ["averaged", "slave"])
def test_facet_uncovered_later_is_widened(normals):
    """Two master strips meeting at x = 0.4 under a slave triangle, given as one surface
    (no boundary known there): fully covered, narrow. One strip moved by 0.05 leaves the
    band 0.4 < x < 0.45 uncovered: the next evaluation widens the facet (one widening)
    and its derivatives then pass Taylor."""
    node_x, slave_facets, master_facets, pairs = pairs_3d(SLAVE_TRIANGLE, [-0.5, 0.4, 1.5],
                                                          -0.1, tilt=-0.05)
    stencil = covered_stencil(node_x, slave_facets, master_facets, pairs, normals=normals)
    evaluate(stencil, node_x, normals)
    assert stencil.widened.tolist() == [False]
    narrow_width = stencil.width
    assert stencil.widenings == 0
    moved = node_x.copy()
    moved[7:, 0] += 0.05  # the second strip's nodes
    evaluate(stencil, moved, normals)
    assert stencil.widened.tolist() == [True] and stencil.widenings == 1
    assert stencil.width > narrow_width
    evaluate(stencil, moved, normals)
    assert stencil.widenings == 1
    for name, slope in taylor_slopes(stencil, moved, normals).items():
        assert abs(slope - 2.0) < 0.1, name


def test_fully_covered_facet_keeps_the_whole_facet_dual_basis():
    """Covered everywhere (by two masters), the coefficients are the whole facet's:
    A = [[3, -1, -1], ...] for a triangle, [[2, -1], [-1, 2]] for a 2D facet."""
    node_x, slave_facets, master_facets, pairs = pairs_3d(SLAVE_TRIANGLE, [-0.5, 0.4, 1.5],
                                                          -0.1)
    q = evaluate(covered_stencil(node_x, slave_facets, master_facets, pairs), node_x)
    coefficients = q.coefficients
    np.testing.assert_allclose(coefficients.A[0], 4 * np.eye(3) - 1, atol=1e-12)
    node_x, slave, master, pairs = issue_example_2d(0.05, start=-0.2)
    q = evaluate(covered_stencil(node_x, slave, master, pairs), node_x)
    np.testing.assert_allclose(q.coefficients.A[0], [[2, -1], [-1, 2]], atol=1e-12)


# -- Taylor tests on partly covered configurations ------------------------------------------


def curved_2d(gap):
    """Three slave facets (the first covered in part by two masters, whose pairs couple)
    and a master polyline starting inside the first slave facet."""
    slave = np.array([[1.0, 0.02], [0.0, 0.0], [-1.0, 0.03], [2.0, 0.01]])
    master = np.array([[0.32, gap], [0.8, gap + 0.01], [1.6, gap - 0.02], [2.4, gap]])
    node_x = np.vstack([slave, master])
    slave_facets = [[3, 0], [0, 1], [1, 2]]
    master_facets = [[4, 5], [5, 6], [6, 7]]
    pairs = [[1, 0], [1, 1], [0, 1], [0, 2], [2, 0]]
    return node_x, slave_facets, master_facets, pairs


@pytest.mark.parametrize("normals", ["averaged", "slave", "master"])
@pytest.mark.parametrize("gap", [0.05, -0.05])
def test_taylor_2d(normals, gap):
    node_x, slave_facets, master_facets, pairs = curved_2d(gap)
    stencil = covered_stencil(node_x, slave_facets, master_facets, pairs)
    assert stencil.partners.shape[1] == 0 and stencil.width == 6  # narrow until evaluated
    slopes = taylor_slopes(stencil, node_x, normals)
    # facet [0, 1] (two masters over part of it) is widened, [1, 2] (no overlap) is not
    assert stencil.widened[1] and not stencil.widened[2]
    assert stencil.partners.shape[1] == 1 and stencil.width == 6 + 3
    for name, slope in slopes.items():
        assert abs(slope - 2.0) < 0.1, (name, slopes)


def test_crosspoint_2d():
    """Node b = (0, 0) a crosspoint: its basis function goes to node a, whose weight is
    then the whole covered length 0.68 and whose weighted gap is gap 0.68; the
    derivatives hold the merge (Taylor)."""
    node_x, slave, master, pairs = issue_example_2d(0.05)
    stencil = covered_stencil(node_x, slave, master, pairs)
    q = evaluate(stencil, node_x, crosspoint=np.array([[False, True]]))
    np.testing.assert_allclose(q.area.value[0], [0.68, 0.0], atol=1e-14)
    np.testing.assert_allclose(q.gap.value[0], [0.05 * 0.68, 0.0], atol=1e-14)
    node_x, slave_facets, master_facets, pairs = curved_2d(0.05)
    stencil = covered_stencil(node_x, slave_facets, master_facets, pairs)
    crosspoint = stencil.slave_nodes == 1
    slopes = taylor_slopes(stencil, node_x, "averaged", crosspoint=crosspoint)
    for name, slope in slopes.items():
        assert abs(slope - 2.0) < 0.1, (name, slopes)


def curved_3d(slave_kind, gap):
    """Two slave facets (bent along x = 1) under three tilted master strips; the first
    strip starts inside the first slave facet."""
    if slave_kind == "quad":
        slave = np.array([[0, 0, 0], [0, 1, 0.02], [1, 1, 0], [1, 0, 0.01],
                          [2, 1, 0.05], [2, 0, 0.04]], float)
        slave_facets = [[0, 1, 2, 3], [3, 2, 4, 5]]
    else:
        slave = np.array([[0, 0, 0], [0, 1, 0.02], [1, 0, 0.01], [1, 1, 0.03]], float)
        slave_facets = [[0, 1, 2], [2, 1, 3]]
    master_x, master_facets = master_strips([0.3, 0.75, 1.4, 2.5], -gap, y0=-0.3, y1=1.4,
                                            tilt=-0.03)
    master_x = master_x + 0.01 * np.sin(3 * master_x[:, [1, 2, 0]])
    ns = slave.shape[0]
    node_x = np.vstack([slave, master_x])
    pairs = [[s, f] for s in range(2) for f in range(3)]
    return node_x, slave_facets, master_facets + ns, pairs


@pytest.mark.parametrize("normals", ["averaged", "slave", "master"])
@pytest.mark.parametrize("slave_kind", ["triangle", "quad"])
@pytest.mark.parametrize("gap", [0.05, -0.05])
def test_taylor_3d(normals, slave_kind, gap):
    node_x, slave_facets, master_facets, pairs = curved_3d(slave_kind, gap)
    stencil = covered_stencil(node_x, slave_facets, master_facets, pairs, normals)
    q = evaluate(stencil, node_x, normals)
    assert q.gap.rows.size >= 4
    slopes = taylor_slopes(stencil, node_x, normals)
    for name, slope in slopes.items():
        assert abs(slope - 2.0) < 0.1, (name, slopes)


def test_objectivity_3d():
    """A rotated and translated partly covered configuration: the same D, M, gaps and
    areas, and Dn, Mn rotated."""
    node_x, slave_facets, master_facets, pairs = curved_3d("quad", 0.05)
    rotation, _ = np.linalg.qr(np.random.default_rng(4).standard_normal((3, 3)))
    rotation *= np.sign(np.linalg.det(rotation))
    moved = node_x @ rotation.T + np.array([3.0, -1.0, 2.0])
    results = []
    for x in (node_x, moved):
        stencil = covered_stencil(x, slave_facets, master_facets, pairs)
        results.append(evaluate(stencil, x))
    first, second = results
    for name in ("D", "M"):
        np.testing.assert_allclose(getattr(second, name), getattr(first, name), atol=1e-13)
    for name in ("gap", "area"):
        np.testing.assert_allclose(getattr(second, name).value, getattr(first, name).value,
                                   atol=1e-13)
    for name in ("Dn", "Mn"):
        np.testing.assert_allclose(getattr(second, name).value,
                                   getattr(first, name).value @ rotation.T, atol=1e-13)


# -- slivers: M_e nearly singular ------------------------------------------------------------


def sliver_check(stencil, node_x, gap, num_slave):
    """Values, Jacobians and a 1e-12 perturbation of a sliver-covered slave facet: finite,
    the gap's sign and value kept, derivatives bounded, the values continuous."""
    z = np.ones(node_x.shape[0])
    q = evaluate(stencil, node_x)
    values = assembled(stencil, q, node_x, z)
    jacobians = assembled_jacobians(stencil, q, node_x, z)
    assert all(np.isfinite(a).all() for a in list(values.values()) + list(jacobians.values()))
    area = values["area"][:num_slave]
    assert np.all(area > 0.0)
    np.testing.assert_allclose(values["gap"][:num_slave] / area, gap, rtol=1e-2)
    assert max(np.abs(J).max() for J in jacobians.values()) < 1.0
    direction = np.random.default_rng(1).standard_normal(node_x.shape)
    moved = node_x + 1e-12 * direction
    perturbed = assembled(stencil, evaluate(stencil, moved), moved, z)
    assert max(np.abs(perturbed[n] - values[n]).max() for n in values) < 2e-12
    return area


@pytest.mark.parametrize("side", ["a", "b"])
@pytest.mark.parametrize("gap", [0.05, -0.05])
def test_sliver_2d(side, gap):
    """A master covering [1 - s, 1] (node a) or [0, s] (node b) of the slave facet, s down
    to 1e-12: the weights are int N_j over the sliver (s and s^2 / 2 to first order)."""
    for s in (1e-4, 1e-8, 1e-12):
        if side == "a":
            node_x = np.array([[1.0, 0.0], [0.0, 0.0], [1.0 - s, gap], [1.6, gap]])
        else:
            node_x = np.array([[1.0, 0.0], [0.0, 0.0], [-0.6, gap], [s, gap]])
        stencil = covered_stencil(node_x, [[0, 1]], [[2, 3]], [[0, 0]])
        area = sliver_check(stencil, node_x, gap, 2)
        near, far = (area[0], area[1]) if side == "a" else (area[1], area[0])
        assert near == pytest.approx(s, rel=1e-3)
        assert far == pytest.approx(s * s / 2, rel=1e-2)


@pytest.mark.parametrize("gap", [0.1, -0.1])
def test_sliver_3d(gap):
    """A strip x >= 1 - s of the square (near-singular M_e of rank 2), a strip y <= s along
    an edge of the triangle and a corner x >= 1 - s of the triangle, s to 1e-8."""
    for s in (1e-4, 1e-8):
        for slave, box in ((SLAVE_QUAD, ([1 - s, 1.5], (-0.5, 1.5))),
                           (SLAVE_TRIANGLE, ([-0.5, 1.5], (-0.5, s))),
                           (SLAVE_TRIANGLE, ([1 - s**0.5, 1.5], (-0.5, 1.5)))):
            master_x, master_facets = master_strips(box[0], -gap, y0=box[1][0], y1=box[1][1])
            ns = slave.shape[0]
            node_x = np.vstack([slave, master_x])
            stencil = covered_stencil(node_x, [list(range(ns))], master_facets + ns, [[0, 0]])
            sliver_check(stencil, node_x, gap, ns)


# -- on a mesh: the interface's matrices, serial = 2 ranks ----------------------------------


def shifted_lower_block(tagged, shift=(0.37 / 14, -0.01)):
    """The lower (master) block moved so that its interface starts inside a slave facet
    (the upper block's facets are 1/14 long), bent a little."""
    V = dolfinx.fem.functionspace(tagged.mesh, ("Lagrange", 1, (2,)))
    u = dolfinx.fem.Function(V)
    lower = tagged.cell_tags.find(tagged.markers["lower"])
    u.interpolate(lambda x: np.vstack([shift[0] + 0.01 * np.sin(3 * x[0]),
                                       shift[1] + 0.005 * np.cos(4 * x[0])]), lower)
    u.x.scatter_forward()
    return u


@pytest.mark.parallel
def test_partly_covered_interface_serial_equals_parallel():
    """D (diagonal, positive), M, the gaps and the gap and force Jacobians of a mesh
    whose master ends inside slave facets: the same on 1 rank and on all ranks to 1e-12."""
    from test_mortar import keyed_entries, node_identity

    results = []
    for comm in (MPI.COMM_SELF, MPI.COMM_WORLD):
        tagged = meshes.tied_blocks(ratio=(3, 7), refinement=1, comm=comm)
        u = shifted_lower_block(tagged)
        mortar = MortarInterface(u.function_space, tagged.facet_tags,
                                 tagged.markers["contact_slave"],
                                 tagged.markers["contact_master"], basis="dual")
        mortar.update(u)
        q = mortar.quantities
        covered_length = np.bincount(mortar.pair_slave_facets, weights=q.overlap)
        partly = comm.allreduce(int(np.count_nonzero((covered_length > 1e-3)
                                                     & (covered_length < 2 - 1e-3))))
        assert partly == 1
        identity = node_identity(u.function_space)
        owned = mortar.multiplier_offset + np.arange(mortar.num_owned_multipliers)
        key = dict(zip(owned.tolist(), [identity[int(b)] for b in
                                        mortar.owned_multiplier_blocks], strict=True))
        key = {k: v for part in comm.allgather(key) for k, v in part.items()}
        z = mortar.create_multiplier_vector()
        z.getArray()[:] = [1.0 + 0.01 * key[int(m)] for m in owned]
        z.assemble()
        D, M = mortar.mortar_matrices()
        gap = mortar.weighted_gap()

        def dof_key(c, ids=identity):
            return (ids[int(c) // 2], int(c) % 2)

        entries = {"D": keyed_entries(D, key.get, identity.get),
                   "M": keyed_entries(M, key.get, identity.get),
                   "G": keyed_entries(mortar.gap_jacobian(), key.get, dof_key),
                   "K": keyed_entries(mortar.force_jacobian(z), dof_key, dof_key)}
        owned_gap = {key[int(m)]: v for m, v in zip(owned, gap.getArray(), strict=True)}
        entries["gap"] = {k: v for part in comm.allgather(owned_gap) for k, v in part.items()}
        results.append(entries)
    serial, parallel = results
    D = serial["D"]
    assert all(abs(v) < 1e-14 for (r, c), v in D.items() if r != c)
    assert all(v > 0.0 for (r, c), v in D.items() if r == c)
    for name in ("D", "M", "G", "K", "gap"):
        assert serial[name].keys() == parallel[name].keys(), name
        difference = max(abs(serial[name][k] - parallel[name][k]) for k in serial[name])
        assert difference < 1e-12, (name, difference)
