"""The compiled 2D kernel wired behind the contract (kernels/line2_compiled.py): every 2D option
runs it (whatever $DOLFINX_MORTAR_KERNELS says), and what it hands the stencils equals the numpy
oracle's (tests/oracle/line2_numpy.py): the values, valid pairs, overlaps and every output's
gradient of the kernel (every normal, integration and basis option, Gauss rules, crosspoints,
scalar gradients), and through the interface the assembled D, M, weighted gaps, gap Jacobian,
constraint matrix and force Jacobian (standard basis, covered dual basis, reference
configuration, crosspoints; triangles and quadrilaterals), and a frictional contact system's
residual and Jacobian, to 1e-13 of each result's largest entry."""

from __future__ import annotations

import contextlib

import numpy as np
import pytest
from mpi4py import MPI
from petsc4py import PETSc
from test_compiled_line2 import random_pairs
from test_mortar import interface, perturbed_displacement

from dolfinx_mortar import deprecation, meshes
from dolfinx_mortar.kernels import KernelOptions, Line2Kernel, PairGeometry, line2_compiled
from dolfinx_mortar.kernels.contract import KERNELS_VARIABLE

from oracle import line2_numpy, use_oracle

TOLERANCE = 1e-13
NORMALS = ("averaged", "slave", "master")
ORACLE = line2_numpy.Line2Kernel()


def assert_close(got: np.ndarray, expected: np.ndarray, tolerance: float = TOLERANCE, what=""):
    scale = np.abs(expected).max(initial=0.0)
    error = np.abs(got - expected).max(initial=0.0)
    assert error <= tolerance * scale or error == 0.0, (what, error, scale)


def geometry_of(x: np.ndarray, has_neighbour: np.ndarray) -> PairGeometry:
    """The contract's geometry of pairs x (n, 6, 2) = p, a, b, q, c, d."""
    return PairGeometry(slave_x=x[:, 1:3], master_x=x[:, 4:6], neighbour_x=x[:, [0, 3]],
                        has_neighbour=has_neighbour)


def evaluate_both(geometry, crosspoint=None, slave_facet=None, **options):
    """The numpy oracle's, then the package's quantities."""
    return [kernel.evaluate(geometry, KernelOptions(**options), crosspoint=crosspoint,
                            slave_facet=slave_facet)
            for kernel in (ORACLE, Line2Kernel())]


def assert_kernels_agree(expected, got) -> None:
    np.testing.assert_array_equal(got.valid, expected.valid)
    np.testing.assert_array_equal(got.rows, expected.rows)
    assert_close(got.overlap, expected.overlap, what="overlap")
    for name in ("D", "M"):
        assert_close(getattr(got, name), getattr(expected, name), what=name)
    for index, (a, b) in enumerate(zip(got.outputs()[:4], expected.outputs(), strict=False)):
        assert_close(a.value, b.value, what=("value", index))
        assert_close(a.grad_rows, b.grad_rows, what=("grad", index))
    # the outputs as the stencils read them: Dn, Mn, area, gap and D (20-23)
    assert_close(got.segment_gradients.outputs(0, 24),
                 expected.segment_gradients.outputs(0, 24), what="outputs 0-23")


@pytest.mark.parametrize("normals", NORMALS)
@pytest.mark.parametrize("integration", ["segment", "element"])
@pytest.mark.parametrize("basis", ["standard", "dual"])
@pytest.mark.parametrize("crosspoints", [False, True])
def test_kernel_equals_numpy(normals, integration, basis, crosspoints):
    x, has_neighbour, crosspoint = random_pairs(600, seed=41)
    expected, got = evaluate_both(geometry_of(x, has_neighbour),
                                  crosspoint if crosspoints else None, normals=normals,
                                  integration=integration, basis=basis)
    assert got.segment_gradients is not None and 150 < got.rows.size < 600
    assert isinstance(got.segment_gradients, line2_compiled.FullGradients)
    assert not isinstance(expected.segment_gradients, line2_compiled.FullGradients)
    assert_kernels_agree(expected, got)


@pytest.mark.parametrize("num_gauss_points", [1, 2, 5])
@pytest.mark.parametrize("integration", ["segment", "element"])
def test_gauss_rules(integration, num_gauss_points):
    x, has_neighbour, crosspoint = random_pairs(300, seed=42)
    expected, got = evaluate_both(geometry_of(x, has_neighbour), crosspoint,
                                  integration=integration, num_gauss_points=num_gauss_points)
    assert got.rows.size > 50
    assert_kernels_agree(expected, got)


def test_element_based_points_shared_by_a_slave_facets_pairs():
    """Pairs of one slave facet (``slave_facet``): each Gauss point goes to one master."""
    x, has_neighbour, _ = random_pairs(400, seed=43)
    slave_facet = np.repeat(np.arange(100), 4)
    x[:, :4] = x[::4, :4].repeat(4, axis=0)  # four candidate masters per slave facet
    has_neighbour = has_neighbour[::4].repeat(4, axis=0)
    expected, got = evaluate_both(geometry_of(x, has_neighbour), slave_facet=slave_facet,
                                  integration="element")
    assert got.rows.size > 50
    assert_kernels_agree(expected, got)


def test_scalar_gradients_keep_D_and_M():
    """With ``scalar_gradients`` the compiled kernel also keeps D's and M's gradients
    (``D_dual``, ``M_dual``; the numpy 2D kernel keeps D's in its factors only), equal to
    the derivatives the numpy kernel's D and M show in a central difference."""
    x, has_neighbour, crosspoint = random_pairs(200, seed=44)
    geometry = geometry_of(x, has_neighbour)
    expected, got = evaluate_both(geometry, crosspoint, scalar_gradients=True)
    assert_kernels_agree(expected, got)
    assert got.D_dual is not None and got.M_dual is not None
    assert_close(got.D_dual.grad_rows, got.segment_gradients.outputs(20, 24).reshape(
        -1, 2, 2, 12), what="D")
    assert_close(got.D_dual.grad_rows, expected.segment_gradients.outputs(20, 24).reshape(
        -1, 2, 2, 12), what="D numpy")
    rows = got.rows[got.overlap[got.rows] > 0.3]
    direction = np.random.default_rng(45).uniform(-1.0, 1.0, x.shape)
    h = 1e-6
    moved = [ORACLE.evaluate(geometry_of(x + s * h * direction, has_neighbour),
                             KernelOptions(), crosspoint=crosspoint)
             for s in (1.0, -1.0)]
    difference = (moved[0].M - moved[1].M)[rows] / (2.0 * h)
    position = np.searchsorted(got.rows, rows)
    predicted = np.einsum("njlv,nv->njl", got.M_dual.grad_rows[position],
                          direction[rows].reshape(-1, 12))
    assert rows.size > 20
    assert_close(predicted, difference, 1e-7, what="M central difference")


def test_combine_equals_numpy():
    """The linear combinations the stencils ask for (weights per pair and numbers)."""
    x, has_neighbour, crosspoint = random_pairs(500, seed=46)
    expected, got = evaluate_both(geometry_of(x, has_neighbour), crosspoint)
    rng = np.random.default_rng(47)
    r = got.rows.size
    terms = [[(int(o), rng.standard_normal(r) if o % 2 else 0.7) for o in rng.choice(24, 5)]
             for _ in range(9)]
    assert_close(got.segment_gradients.combine(terms), expected.segment_gradients.combine(terms))
    with pytest.raises(ValueError, match="not kept"):
        got.segment_gradients.combine([[(24, 1.0)]])


def test_empty_and_not_overlapping():
    x, has_neighbour, _ = random_pairs(50, seed=48)
    x = x[:, [0, 1, 2, 3, 5, 4]]  # the masters turned over: facing the slaves' way
    for pairs in (x, x[:0]):
        expected, got = evaluate_both(geometry_of(pairs, has_neighbour[:pairs.shape[0]]))
        assert got.rows.size == 0
        assert_kernels_agree(expected, got)
        assert got.segment_gradients.combine([[(0, 1.0)]]).shape == (1, 12, 0)


def test_the_variable_no_longer_switches(monkeypatch):
    """$DOLFINX_MORTAR_KERNELS=numpy warns that it is not read, and the compiled kernel runs."""
    monkeypatch.setattr(deprecation, "_warned_variables", set())
    monkeypatch.setenv(KERNELS_VARIABLE, "numpy")
    x, has_neighbour, _ = random_pairs(20, seed=49)
    with pytest.warns(UserWarning, match="DOLFINX_MORTAR_KERNELS=numpy is no longer read"):
        q = Line2Kernel().evaluate(geometry_of(x, has_neighbour), KernelOptions())
    assert isinstance(q.segment_gradients, line2_compiled.FullGradients)
    q = ORACLE.evaluate(geometry_of(x, has_neighbour), KernelOptions())
    assert not isinstance(q.segment_gradients, line2_compiled.FullGradients)


# -- through the interface ----------------------------------------------------------------------


def _matrices(mortar, z) -> dict:
    D, M = mortar.mortar_matrices()
    arrays = {"D": D, "M": M, "G": mortar.gap_jacobian(), "B": mortar.constraint_matrix(),
              "K": mortar.force_jacobian(z)}
    result = {name: matrix.convert("dense").getDenseArray().copy()
              for name, matrix in arrays.items()}
    result["gap"] = mortar.weighted_gap().getArray().copy()
    return result


def _slave_end_blocks(mortar, V) -> np.ndarray:
    """The global blocks of the slave surface's two end nodes (x = 0 and x = 1)."""
    x = V.tabulate_dof_coordinates()
    index_map = V.dofmap.index_map
    local = np.flatnonzero(np.isclose(x[:, 1], 0.5) & (np.isclose(x[:, 0], 0.0)
                                                       | np.isclose(x[:, 0], 1.0)))
    blocks = index_map.local_to_global(local.astype(np.int32))
    return np.intersect1d(blocks, mortar.owned_multiplier_blocks)


CONFIGURATIONS = [
    dict(),
    dict(basis="dual"),
    dict(normals="slave"),
    dict(normals="master", basis="dual"),
    dict(integration="element"),
    dict(integration="element", basis="dual", normals="slave"),
    dict(integration="element", num_gauss_points=2),
    dict(num_gauss_points=5),
    dict(configuration="reference"),
    dict(configuration="reference", basis="dual"),
    dict(crosspoints=True),
    dict(crosspoints=True, basis="dual"),
    dict(scalar_gradients=True),
]


@pytest.mark.parametrize("cell_type", ["triangle", "quadrilateral"])
@pytest.mark.parametrize("configuration", CONFIGURATIONS, ids=lambda c: "-".join(
    f"{k}={v}" for k, v in c.items()) or "default")
def test_interface_equals_numpy(cell_type, configuration):
    """D, M, gaps, gap Jacobian, B and the force Jacobian of a bent, non-matching interface."""
    options = dict(configuration)
    crosspoints = options.pop("crosspoints", False)
    scalar_gradients = options.pop("scalar_gradients", False)
    tagged = meshes.tied_blocks(ratio=(3, 7), refinement=1, cell_type=cell_type,
                                comm=MPI.COMM_SELF)
    u = perturbed_displacement(tagged)
    results = {}
    for kernels in ("numpy", "compiled"):
        with use_oracle() if kernels == "numpy" else contextlib.nullcontext():
            mortar = interface(tagged, None, **options)
            mortar.scalar_gradients = scalar_gradients
            if crosspoints:
                ends = _slave_end_blocks(mortar, u.function_space)
                assert ends.size == 2
                mortar.set_crosspoints(ends)
            mortar.update(u)
            z = mortar.create_multiplier_vector()
            z.getArray()[:] = np.random.default_rng(5).uniform(0.5, 1.5, z.getLocalSize())
            z.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
            results[kernels] = _matrices(mortar, z)
            q = mortar.quantities
            standard = getattr(q, "standard", q)
            is_compiled = isinstance(standard.segment_gradients, line2_compiled.FullGradients)
            if options.get("configuration") != "reference":
                assert is_compiled == (kernels == "compiled")
            z.destroy()
            mortar.destroy()
    for name, expected in results["numpy"].items():
        # (frozen reference integrals: the force does not change with u)
        frozen = (name, options.get("configuration")) == ("K", "reference")
        assert np.abs(expected).max() > 0.0 or frozen, name
        assert_close(results["compiled"][name], expected, what=name)


@pytest.mark.parametrize("method", ["lagrange", "penalty"])
def test_frictional_system_equals_numpy(method):
    """The residual and Jacobian of a 2D frictional contact system (the tangential terms read
    Dn, Mn, the gaps and the areas) at a state with random multipliers."""
    from test_friction import frictional_blocks

    results = {}
    for kernels in ("numpy", "compiled"):
        with use_oracle() if kernels == "numpy" else contextlib.nullcontext():
            problem = frictional_blocks(0.5, method)
            residual = problem.b.duplicate()
            problem.equations.residual(problem.snes, problem.x, residual)
            assert problem.num_active() > 0
            J = problem.equations.assemble_system()
            results[kernels] = (residual.getArray().copy(),
                                J.convert("dense").getDenseArray().copy())
            q = problem.interfaces[0].quantities
            q = getattr(q, "standard", q)  # (the covered dual basis, the problem's default)
            assert isinstance(q.segment_gradients, line2_compiled.FullGradients) == (
                kernels == "compiled")
    assert_close(results["compiled"][0], results["numpy"][0], what="residual")
    assert_close(results["compiled"][1], results["numpy"][1], what="jacobian")
