"""Assembly of the gradient blocks a chunk of pairs at a time: the same matrices as all at once.

G and K are summed group by group (each pair's entries in the pair's order); what the chunk
size may change is rounding: an optimized BLAS (OpenBLAS) blocks a product of a chunk's
rows differently from one of all rows, and in parallel PETSc adds other ranks' rows in an
order of its own. A chunk that dropped or repeated pairs would change entries by ~1e-2 of
the largest; the patterns must be the same.
"""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI
from petsc4py import PETSc
from test_mortar3d import bent_displacement, interface, two_blocks

from dolfinx_mortar.dual import RowSubsetDual
from dolfinx_mortar.layout import CooMatrix
from dolfinx_mortar.stencils import _gradient_rows


def _csr(matrix):
    indptr, indices, values = matrix.getValuesCSR()
    return indptr.copy(), indices.copy(), values.copy()


def _gradient_matrices(mortar, z):
    return [_csr(mortar.gap_jacobian()), _csr(mortar.force_jacobian(z))]


@pytest.mark.parallel
@pytest.mark.parametrize("cell", ["tetrahedron", "hexahedron"])
@pytest.mark.parametrize("basis", ["standard", "dual"])
def test_chunked_gradient_blocks_equal_all_at_once(cell, basis):
    tagged = two_blocks(cell, 3, 4)
    u = bent_displacement(tagged)
    results = []
    for chunk in (10**9, 3):  # all pairs in one chunk, then 3 at a time
        mortar = interface(tagged, u, basis=basis)
        mortar.assembly_chunk = chunk
        z = mortar.create_multiplier_vector()
        with z.localForm() as local:
            local.array[:] = 1.0 + np.cos(np.arange(local.array.size))
        first = _gradient_matrices(mortar, z)
        u.x.array[:] += 1e-3 * np.sin(np.arange(u.x.array.size))  # the same pairs, new values
        mortar.update(u)
        second = _gradient_matrices(mortar, z)
        u.x.array[:] -= 1e-3 * np.sin(np.arange(u.x.array.size))
        contributing = mortar.contributing_pairs().size
        results.append((first, second, contributing))
        z.destroy()
        mortar.destroy()
    (all_first, all_second, contributing), (chunk_first, chunk_second, _) = results
    # several chunks on the busiest rank (3 ranks: 20 pairs at most on one)
    assert MPI.COMM_WORLD.allreduce(contributing, op=MPI.MAX) > 3 * 3
    for expected, got in zip(all_first + all_second, chunk_first + chunk_second, strict=True):
        for a, b in zip(expected[:2], got[:2], strict=True):
            assert np.array_equal(a, b)
        scale = np.abs(expected[2]).max(initial=0.0)
        assert np.abs(expected[2] - got[2]).max(initial=0.0) <= 1e-14 * scale
    largest = max(np.abs(a[2]).max(initial=0.0) for a in all_first)
    assert MPI.COMM_WORLD.allreduce(largest, op=MPI.MAX) > 0


def test_group_chunks_equal_one_call():
    """CooMatrix.assemble_groups with values given chunk by chunk (blocks repeated within
    and across groups) is bitwise the same with one chunk, and the sums of the array."""
    rng = np.random.default_rng(3)
    num_groups = 40
    row_blocks = rng.integers(0, 6, (num_groups, 2))
    col_blocks = rng.integers(-1, 9, (num_groups, 4))
    values = rng.standard_normal((2, 3, 4, 2, 25))
    groups = np.sort(rng.choice(num_groups, 25, replace=False))
    matrices = [CooMatrix.from_blocks(MPI.COMM_SELF, row_blocks, col_blocks, (3, 2), 18, 18)
                for _ in range(3)]
    expected, one_chunk, chunked = matrices
    a = _csr(one_chunk.assemble_groups(lambda start, stop: values[..., start:stop], groups,
                                       chunk=25))
    b = _csr(chunked.assemble_groups(lambda start, stop: values[..., start:stop], groups,
                                     chunk=4))
    for x, y in zip(a, b, strict=True):
        assert np.array_equal(x, y)
    c = _csr(expected.assemble_groups(values, groups))
    assert np.array_equal(a[1], c[1])
    assert np.abs(a[2] - c[2]).max() <= 1e-15 * np.abs(c[2]).max()
    dense = np.zeros((18, 18))
    for g, group in enumerate(groups):
        for i, r in enumerate(row_blocks[group]):
            for j, c in enumerate(col_blocks[group]):
                if c >= 0:
                    dense[3 * r:3 * r + 3, 2 * c:2 * c + 2] += values[i, :, j, :, g]
    assert np.allclose(expected.mat.getValues(range(18), range(18)), dense, rtol=0, atol=1e-13)
    for matrix in matrices:
        matrix.destroy()


def test_gradient_rows_of_a_subset():
    """The values and gradients of some rows of a RowSubsetDual are those of its full arrays
    (zero for rows it does not keep), read from the kept rows."""
    rng = np.random.default_rng(4)
    kept = np.array([1, 4, 5, 6, 9, 12])
    item = RowSubsetDual(rng.standard_normal((6, 3)), kept, rng.standard_normal((6, 3, 5)), 15)
    full = np.zeros((15, 3, 5))
    full[kept] = item.grad_rows
    full_value = np.zeros((15, 3))
    full_value[kept] = item.value_rows
    assert np.array_equal(item.grad, full) and np.array_equal(item.value, full_value)
    assert item.shape == (15, 3)
    for rows in (kept[1:4], kept[[0, 2, 5]], np.array([0, 4, 7, 12]), np.zeros(0, dtype=int)):
        assert np.array_equal(_gradient_rows(item, rows), full[rows])
        assert np.array_equal(item.value_of(rows), full_value[rows])
    with pytest.raises(ValueError, match="rows of values"):
        RowSubsetDual(np.zeros((5, 3)), kept, None, 15)


def test_matrices_stay_valid_after_a_new_search():
    """A new search drops the old patterns' lookups; the matrices handed out before stay
    readable and unchanged until they are assembled again."""
    tagged = two_blocks("tetrahedron", 3, 4)
    u = bent_displacement(tagged)
    mortar = interface(tagged, u)
    z = mortar.create_multiplier_vector()
    z.set(1.0)
    D, _ = mortar.mortar_matrices()
    K = mortar.force_jacobian(z)
    before = [_csr(D), _csr(K)]
    mortar.reuse.invalidate()
    mortar.update(u)
    for expected, matrix in zip(before, (D, K), strict=True):
        for a, b in zip(expected, _csr(matrix), strict=True):
            assert np.array_equal(a, b)
    assert isinstance(mortar.force_jacobian(z), PETSc.Mat)
    z.destroy()
    mortar.destroy()


@pytest.mark.parallel
def test_frictional_jacobian_of_chunked_blocks_equals_all_at_once():
    """The Newton matrix's contact blocks (system.ContactSystem._contact_blocks: the weighted
    pairs' gradients, made ``assembly_chunk`` pairs at a time as they are summed) at a
    converged frictional state: the same pattern and values as with all pairs at once."""
    from test_friction import load_demo

    from dolfinx_mortar import Coulomb

    patch = load_demo("friction_patch")
    limit = 0.2 * patch.PRESSURE
    problem = patch.sheared_blocks_3d((3, 7), "upper", Coulomb(0.2),
                                      2.0 * limit / patch.SHEAR_MODULUS, limit)
    assert problem.solve().converged
    interfaces = problem.equations.interfaces
    results = []
    for chunk in (None, 3):
        for mortar in interfaces:
            mortar.assembly_chunk = chunk
        results.append(_csr(problem.equations.assemble_system()))
    contributing = max(mortar.contributing_pairs().size for mortar in interfaces)
    assert MPI.COMM_WORLD.allreduce(contributing, op=MPI.MAX) > 3 * 3
    (indptr, indices, values), (chunk_indptr, chunk_indices, chunk_values) = results
    assert np.array_equal(indptr, chunk_indptr) and np.array_equal(indices, chunk_indices)
    scale = MPI.COMM_WORLD.allreduce(np.abs(values).max(initial=0.0), op=MPI.MAX)
    assert np.abs(values - chunk_values).max(initial=0.0) <= 1e-14 * scale
    problem.destroy()


@pytest.mark.parallel
@pytest.mark.parametrize("friction", [False, True])
def test_reference_configuration_pattern_holds_the_overlapping_pairs_only(friction):
    """On the undeformed surfaces (``configuration="reference"``) only the pairs that overlap
    there have blocks in the Newton matrix's pattern (``ContactSystem._pattern_pairs``),
    fewer than the candidates; the matrix equals, value for value, the one whose pattern
    holds every candidate pair (sheared 3D blocks, solved to a state with stick or slip)."""
    from test_friction import load_demo

    from dolfinx_mortar import Coulomb

    patch = load_demo("friction_patch")
    limit = 0.2 * patch.PRESSURE
    problem = patch.sheared_blocks_3d((3, 7), "upper", Coulomb(0.2) if friction else None,
                                      2.0 * limit / patch.SHEAR_MODULUS, limit)
    assert problem.solve().converged
    equations = problem.equations
    interfaces, system = equations.interfaces, equations.system
    assert all(mortar.configuration == "reference" for mortar in interfaces)
    counts = np.array([[mortar.contributing_pairs().size, mortar.stencil.num_pairs]
                       for mortar in interfaces]).sum(axis=0)
    contributing, candidates = MPI.COMM_WORLD.allreduce(counts, op=MPI.SUM)
    assert 0 < contributing < candidates
    blocks = sum(p.shape[0] for p in system._pattern[0])
    assert MPI.COMM_WORLD.allreduce(blocks, op=MPI.SUM) == contributing
    _assert_every_candidate_adds_only_zeros(equations)
    assert MPI.COMM_WORLD.allreduce(sum(p.shape[0] for p in system._pattern[0]),
                                    op=MPI.SUM) == candidates
    problem.destroy()


@pytest.mark.parallel
@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("friction", [False, True])
def test_reference_configuration_blocks_hold_the_facet_columns_only(dim, friction):
    """On the undeformed surfaces the pairs' blocks have the displacement columns of their
    slave and master facet nodes only (``MortarInterface.differentiated_columns``), not
    those of the averaged normals' stars: the matrix equals, value for value, the one whose
    blocks span the whole stencil, with fewer entries (sheared blocks, averaged normals,
    solved to a state with stick or slip)."""
    from test_friction import load_demo

    from dolfinx_mortar import Coulomb
    from dolfinx_mortar.mortar import MortarInterface

    patch = load_demo("friction_patch")
    limit = 0.2 * patch.PRESSURE
    make = patch.sheared_blocks_3d if dim == 3 else patch.sheared_blocks
    problem = make((3, 7), "upper", Coulomb(0.2) if friction else None,
                   2.0 * limit / patch.SHEAR_MODULUS, limit)
    assert problem.solve().converged
    equations = problem.equations
    interfaces, system = equations.interfaces, equations.system
    assert all(m.configuration == "reference" and m.normals == "averaged" for m in interfaces)
    facet_columns = (interfaces[0].stencil.ns + interfaces[0].stencil.nm) * dim
    multipliers = (dim if friction else 1) * interfaces[0].stencil.ns
    assert system._block_shape[1] == facet_columns + multipliers
    narrow = equations.assemble_system().copy()
    system._versions = ()  # (the next assembly builds its pattern again)
    wide = pytest.MonkeyPatch()
    wide.setattr(MortarInterface, "differentiated_columns", property(lambda self: None))
    try:
        whole = equations.assemble_system()
        assert system._block_shape[1] == interfaces[0].stencil.width * dim + multipliers
    finally:
        wide.undo()
    assert narrow.getInfo()["nz_used"] < whole.getInfo()["nz_used"]
    scale = whole.norm(PETSc.NormType.INFINITY)
    whole.axpy(-1.0, narrow, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    assert whole.norm(PETSc.NormType.INFINITY) <= 1e-14 * scale
    narrow.destroy()
    problem.destroy()


def _assert_every_candidate_adds_only_zeros(equations) -> None:
    """The Newton matrix as assembled equals, to rounding, the one whose pattern holds a
    block for every candidate pair, which has more entries."""
    leaner = equations.assemble_system().copy()
    system = equations.system
    system._versions = ()  # (the next assembly builds its pattern again)
    system._pattern_pairs = lambda k, grown=False: None
    every = equations.assemble_system()
    assert leaner.getInfo()["nz_used"] < every.getInfo()["nz_used"]
    scale = every.norm(PETSc.NormType.INFINITY)
    every.axpy(-1.0, leaner, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    assert every.norm(PETSc.NormType.INFINITY) <= 1e-14 * scale
    leaner.destroy()


@pytest.mark.parallel
def test_current_configuration_pattern_grows_with_the_overlapping_pairs():
    """On the current configuration the pattern holds the pairs that overlapped since the
    last search: a pair that overlaps and has no block (taken out of the pattern here, as
    a Newton iterate that slides a slave facet over another master facet leaves it) makes
    the next assembly build the pattern again with it (``ContactSystem._outgrown``), and
    the matrix equals the one whose pattern holds every candidate pair (curved punch,
    Neo-Hookean, covered dual basis)."""
    from test_contact3d import curved_punch

    from dolfinx_mortar import solve_load_steps

    problem, apply_load = curved_punch(MPI.COMM_WORLD, cell="tetrahedron", ratio=(4, 3),
                                       material="neo-hookean")
    solve_load_steps(problem, apply_load, 1)
    equations = problem.equations
    interfaces, system = equations.interfaces, equations.system
    assert all(mortar.configuration == "current" for mortar in interfaces)
    equations.assemble_system()
    assert not system._outgrown()
    k = max(range(len(interfaces)), key=lambda k: interfaces[k].contributing_pairs().size)
    dropped = interfaces[k].contributing_pairs()[-1:]
    system._pairs[k] = np.setdiff1d(system._pairs[k], dropped)
    assert system._outgrown() == (MPI.COMM_WORLD.allreduce(dropped.size, op=MPI.SUM) > 0)
    equations.assemble_system()
    assert np.all(np.isin(interfaces[k].contributing_pairs(), system._pairs[k]))
    assert not system._outgrown()
    _assert_every_candidate_adds_only_zeros(equations)
    problem.destroy()
