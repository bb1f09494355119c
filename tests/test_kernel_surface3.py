"""The 3D mortar kernel on hand-made pairs: known areas and gaps, the dual basis, Taylor
tests, objectivity, scaling and degenerate geometry, on the package's compiled kernel and on
the numpy oracle (tests/oracle/surface3_numpy.py) alike (the dual basis's coefficients are the
oracle's own)."""

from __future__ import annotations

import numpy as np
import pytest

from dolfinx_mortar.kernels import KernelOptions, PairGeometry, Surface3Kernel

from oracle import surface3_numpy

# the slave facet faces -z (a lower surface of the upper body), the master faces +z
SLAVE_QUAD = np.array([[0, 0, 0], [0, 1, 0], [1, 1, 0], [1, 0, 0]], float)
SLAVE_TRIANGLE = np.array([[0, 0, 0], [0, 1, 0], [1, 0, 0]], float)
DOWN = np.array([0.0, 0.0, -1.0])


def compiled_pair_quantities(slave_x, master_x, slave_normals, *, crosspoint=None,
                             slave_facet=None, **options):
    """The package's kernel with the oracle's ``pair_quantities`` arguments."""
    geometry = PairGeometry(*(np.asarray(x, dtype=float)
                              for x in (slave_x, master_x, slave_normals)))
    return Surface3Kernel().evaluate(geometry, KernelOptions(**options), crosspoint=crosspoint,
                                     slave_facet=slave_facet)


IMPLEMENTATIONS = {"compiled": compiled_pair_quantities,
                   "oracle": surface3_numpy.pair_quantities}
pair_quantities = compiled_pair_quantities
"""The implementation the tests call (:func:`implementation` sets it per test)."""


@pytest.fixture(params=list(IMPLEMENTATIONS))
def implementation(request, monkeypatch):
    """The package's compiled kernel, then the numpy oracle."""
    monkeypatch.setitem(globals(), "pair_quantities", IMPLEMENTATIONS[request.param])
    return request.param


def master_square(x0, x1, y0, y1, z=-0.1):
    return np.array([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]], float)


def evaluate(slave, master, normals=None, **options):
    if normals is None:
        normals = np.tile(DOWN, (slave.shape[0], 1))
    return pair_quantities(slave[None], master[None], normals[None], **options)


def test_master_square_offset_by_half_a_facet(implementation):
    for basis in ("standard", "dual"):
        q = evaluate(SLAVE_QUAD, master_square(0.5, 1.5, 0.0, 1.0), basis=basis)
        assert q.valid[0]
        assert q.overlap[0] == pytest.approx(0.5, abs=1e-14)
        assert q.D.sum() == pytest.approx(0.5, abs=1e-13)
        assert q.M.sum() == pytest.approx(0.5, abs=1e-13)
        np.testing.assert_allclose(q.gap.value, 0.1 * q.area.value, atol=1e-15)
    standard = evaluate(SLAVE_QUAD, master_square(0.5, 1.5, 0.0, 1.0))
    # int N_j over x in [0.5, 1]: 1/16 at the nodes x = 0, 3/16 at x = 1
    np.testing.assert_allclose(standard.area.value[0], [1 / 16, 1 / 16, 3 / 16, 3 / 16],
                               atol=1e-15)


def test_tilted_master_plane(implementation):
    """Master plane z = -0.1 - 0.2 x below the unit slave square: gap 0.1 + 0.2 x."""
    master = np.array([[-1, -1, 0.1], [2, -1, -0.5], [2, 2, -0.5], [-1, 2, 0.1]], float)
    q = evaluate(SLAVE_QUAD, master)
    x = SLAVE_QUAD[:, 0]
    # int N_j (0.1 + 0.2 x): 0.1/4 + 0.2 (1/12 at x_j = 0, 1/6 at x_j = 1)
    expected = 0.025 + 0.2 * np.where(x == 0.0, 1 / 12, 1 / 6)
    np.testing.assert_allclose(q.gap.value[0], expected, atol=1e-13)
    np.testing.assert_allclose(q.area.value[0], 0.25, atol=1e-14)


def test_penetrating_master_gives_negative_gaps(implementation):
    q = evaluate(SLAVE_TRIANGLE, master_square(-1, 2, -1, 2, z=0.2))
    np.testing.assert_allclose(q.area.value[0], 0.5 / 3, atol=1e-15)
    np.testing.assert_allclose(q.gap.value[0], -0.2 * 0.5 / 3, atol=1e-15)


@pytest.mark.parametrize("slave", ["triangle", "parallelogram"])
def test_dual_mortar_matrix_is_diagonal(slave, implementation):
    """A master covering the whole flat slave facet: dual D is diagonal with
    D_jj = int N_j, and sum_j Phi_j = 1 keeps the row sums of M. (Exact where the
    integrands are polynomials in the plane: triangles and parallelograms.)"""
    if slave == "triangle":
        facet = np.array([[0, 0, 0], [0.3, 1.2, 0], [1.4, 0.1, 0]], float)
    else:
        facet = np.array([[0, 0, 0], [0.3, 1.0, 0], [1.5, 1.2, 0], [1.2, 0.2, 0]], float)
    master = master_square(-1, 3, -1, 3)
    dual_q = evaluate(facet, master, basis="dual")
    standard = evaluate(facet, master, basis="standard")
    off_diagonal = dual_q.D[0] - np.diag(np.diag(dual_q.D[0]))
    assert np.abs(off_diagonal).max() < 1e-12
    np.testing.assert_allclose(np.diag(dual_q.D[0]), standard.D[0].sum(axis=1), atol=1e-12)
    np.testing.assert_allclose(dual_q.M[0].sum(axis=1), dual_q.D[0].sum(axis=1), atol=1e-12)


@pytest.mark.parametrize("warped", [False, True])
def test_dual_basis_is_biorthogonal_on_distorted_quadrilaterals(warped):
    """int Phi_j N_k dA = delta_jk int N_k dA over the facet. In a plane the area element
    is bilinear and any exact rule (here 6 x 6 Gauss) confirms it; on a warped facet it is
    not a polynomial, and the basis is biorthogonal under the facet rule (3 x 3) that
    defines it."""
    from dolfinx_mortar.dual import Dual

    facet = np.array([[0, 0, 0], [0.2, 1.0, 0], [1.6, 1.3, 0], [1.1, -0.2, 0]], float)
    if warped:
        facet[:, 2] = [0.0, 0.1, -0.2, 0.05]
    A = surface3_numpy._dual_coefficients(Dual(facet[None], np.zeros((1, 4, 3, 1))), 4).value[0]
    g, w = np.polynomial.legendre.leggauss(3 if warped else 6)
    points = np.array([[a, b] for a in g for b in g])
    weights = np.array([wa * wb for wa in w for wb in w])
    N = np.stack(surface3_numpy.shape_functions(points, 4), axis=-1)
    dN = surface3_numpy._shape_derivatives(points, 4)
    t1, t2 = np.einsum("qk,kc->qc", dN[..., 0], facet), np.einsum("qk,kc->qc", dN[..., 1], facet)
    area_element = np.linalg.norm(np.cross(t1, t2), axis=1) * weights
    Phi = N @ A.T
    mixed = np.einsum("q,qj,qk->jk", area_element, Phi, N)
    np.testing.assert_allclose(mixed, np.diag(area_element @ N), rtol=0, atol=1e-12)


def random_pair(rng, ns, nm):
    slave = (SLAVE_QUAD if ns == 4 else SLAVE_TRIANGLE) + 0.05 * rng.uniform(-1, 1, (ns, 3))
    master = (master_square(0.3, 1.3, 0.2, 1.1) if nm == 4
              else np.array([[0.2, 0.1, -0.1], [1.2, 0.3, -0.1], [0.4, 1.0, -0.1]]))
    master = master + 0.05 * rng.uniform(-1, 1, master.shape)
    normals = DOWN + 0.1 * rng.uniform(-1, 1, (ns, 3))
    return slave, master, normals / np.linalg.norm(normals, axis=1, keepdims=True)


def outputs(q):
    return np.concatenate([q.Dn.value.ravel(), q.Mn.value.ravel(), q.gap.value.ravel(),
                           q.area.value.ravel()])


@pytest.mark.parametrize("shapes", [(3, 3), (4, 4), (3, 4), (4, 3)])
@pytest.mark.parametrize("normals", ["averaged", "slave", "master"])
@pytest.mark.parametrize("basis", ["standard", "dual"])
@pytest.mark.parametrize("integration", ["segment", "element"])
def test_taylor(shapes, normals, basis, integration, implementation):
    """Element-based pairs on a master that covers the slave facet whole: no Gauss point
    leaves it within the steps."""
    ns, nm = shapes
    if integration == "segment":
        rng = np.random.default_rng(ns * 10 + nm)
        slave, master, nodal = random_pair(rng, ns, nm)
    else:
        rng = np.random.default_rng(ns * 10 + nm + 1)
        slave, master, nodal = covering_pair(rng, ns, nm)
    x = np.concatenate([slave.ravel(), master.ravel(), nodal.ravel()])
    direction = rng.uniform(-1, 1, x.size)

    def quantities(values):
        return pair_quantities(
            values[:3 * ns].reshape(1, ns, 3), values[3 * ns:3 * (ns + nm)].reshape(1, nm, 3),
            values[3 * (ns + nm):].reshape(1, ns, 3), normals=normals, basis=basis,
            integration=integration)

    base = quantities(x)
    if integration == "element":
        assert base.overlap[0] == 1.0
    gradient = np.concatenate([item.grad.reshape(-1, x.size)
                               for item in (base.Dn, base.Mn, base.gap, base.area)])
    predicted = gradient @ direction
    assert np.abs(predicted).max() > 1e-3
    steps = np.array([1e-2, 5e-3, 2.5e-3, 1.25e-3])
    remainders = [np.abs(outputs(quantities(x + h * direction)) - outputs(base)
                         - h * predicted).max() for h in steps]
    slopes = np.diff(np.log(remainders)) / np.diff(np.log(steps))
    assert np.all(np.abs(slopes - 2.0) < 0.1), slopes


def covering_pair(rng, ns, nm):
    """A perturbed slave facet and a tilted, perturbed master facet that covers it whole."""
    slave, _, normals = random_pair(rng, ns, nm)
    master = (master_square(-0.5, 1.5, -0.5, 1.5) if nm == 4
              else np.array([[-0.5, -0.5, -0.1], [2.5, -0.5, -0.1], [-0.5, 2.5, -0.1]]))
    master = master + 0.05 * rng.uniform(-1, 1, master.shape)
    return slave, master, normals


@pytest.mark.parametrize("shapes", [(3, 3), (4, 4), (3, 4)])
def test_objectivity_and_scaling(shapes, implementation):
    ns, nm = shapes
    rng = np.random.default_rng(3)
    slave, master, nodal = random_pair(rng, ns, nm)
    R, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    R *= np.sign(np.linalg.det(R))
    shift = np.array([2.0, -1.0, 0.5])
    base = evaluate(slave, master, nodal, basis="dual")
    moved = evaluate(slave @ R.T + shift, master @ R.T + shift, nodal @ R.T, basis="dual")
    for name in ("D", "M"):
        a, b = getattr(base, name), getattr(moved, name)
        assert np.abs(a - b).max() <= 1e-12 * np.abs(a).max()
    assert np.abs(base.gap.value - moved.gap.value).max() <= 1e-12 * np.abs(base.gap.value).max()
    scaled = evaluate(1e3 * slave, 1e3 * master, nodal, basis="dual")
    np.testing.assert_allclose(scaled.D, 1e6 * base.D, rtol=1e-12, atol=1e-12 * 1e6)
    np.testing.assert_allclose(scaled.M, 1e6 * base.M, rtol=1e-12, atol=1e-12 * 1e6)
    np.testing.assert_allclose(scaled.gap.value, 1e9 * base.gap.value, rtol=1e-11,
                               atol=1e-12 * 1e9)


@pytest.mark.parametrize("case", ["coincident", "edges_on_edges", "tiny_corner", "inside",
                                  "around", "nearly_tangent"])
def test_degenerate_geometry_is_finite_and_continuous(case, implementation):
    slave = SLAVE_QUAD
    masters = {
        "coincident": master_square(0, 1, 0, 1, z=0.0)[[0, 1, 2, 3]],
        "edges_on_edges": master_square(0, 1, 0.5, 1.5),
        "tiny_corner": master_square(1 - 1e-7, 2, 1 - 1e-7, 2),
        "inside": master_square(0.25, 0.75, 0.25, 0.75),
        "around": master_square(-1, 2, -1, 2),
        "nearly_tangent": np.array([[0, 0, -0.1], [1, 0, -0.1], [1, 1, -0.1 + 1e-9],
                                    [0, 1, -0.1]], float),
    }
    master = masters[case]
    rng = np.random.default_rng(9)
    for basis in ("standard", "dual"):
        q = evaluate(slave, master, basis=basis)
        for item in (q.D, q.M, q.Dn.value, q.Dn.grad, q.Mn.grad, q.gap.grad):
            assert np.all(np.isfinite(item))
        perturbed = evaluate(slave + 1e-12 * rng.uniform(-1, 1, slave.shape),
                             master + 1e-12 * rng.uniform(-1, 1, master.shape), basis=basis)
        assert np.abs(perturbed.D - q.D).max() < 1e-9
        assert np.abs(perturbed.M - q.M).max() < 1e-9



@pytest.mark.parametrize("shapes", [(3, 3), (4, 4), (3, 4), (4, 3)])
@pytest.mark.parametrize("basis", ["standard", "dual"])
def test_element_based_equals_segment_based_under_one_master_facet(shapes, basis, implementation):
    """A flat slave facet wholly inside one parallel master facet: the integrands are
    polynomials the slave rule integrates exactly, so both integrations agree."""
    ns, nm = shapes
    slave = SLAVE_QUAD if ns == 4 else SLAVE_TRIANGLE
    master = (master_square(-0.5, 1.5, -0.5, 1.5) if nm == 4
              else np.array([[-0.5, -0.5, -0.1], [2.5, -0.5, -0.1], [-0.5, 2.5, -0.1]]))
    segment = evaluate(slave, master, basis=basis)
    element = evaluate(slave, master, basis=basis, integration="element")
    for name in ("D", "M"):
        np.testing.assert_allclose(getattr(element, name), getattr(segment, name), atol=1e-14)
    for name in ("gap", "area", "Dn", "Mn"):
        np.testing.assert_allclose(getattr(element, name).value, getattr(segment, name).value,
                                   atol=1e-14)


@pytest.mark.parametrize("basis", ["standard", "dual"])
def test_element_based_gives_each_gauss_point_to_one_master_facet(basis, implementation):
    """Two master squares meeting at x = 1/2, where the middle row of the slave's 3 x 3
    Gauss points lies: summed over both pairs, D is the whole facet's (each point counted
    once) and the weighted gap is 0.1 times the area; the overlaps add up to 1."""
    left, right = master_square(-0.5, 0.5, -0.5, 1.5), master_square(0.5, 1.5, -0.5, 1.5)
    slave = np.stack([SLAVE_QUAD, SLAVE_QUAD])
    normals = np.tile(DOWN, (2, 4, 1))
    options = {"basis": basis, "integration": "element", "num_gauss_points": 9}
    both = pair_quantities(slave, np.stack([left, right]), normals,
                                    slave_facet=np.array([0, 0]), **options)
    whole = evaluate(SLAVE_QUAD, master_square(-0.5, 1.5, -0.5, 1.5), **options)
    np.testing.assert_allclose(both.D.sum(axis=0), whole.D[0], atol=1e-15)
    assert both.overlap.sum() == pytest.approx(1.0, abs=1e-15)
    np.testing.assert_allclose(both.gap.value.sum(axis=0), 0.1 * whole.area.value[0],
                               atol=1e-15)
    alone = pair_quantities(slave, np.stack([left, right]), normals, **options)
    assert alone.overlap.sum() > 1.0  # without the facet numbers the middle row counts twice
