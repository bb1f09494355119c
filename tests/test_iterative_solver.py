"""The iterative linear solver's inner matrix: K_c's values without its stored zeros.

K_c is computed on the rows near the contact only (A elsewhere), its products keeping
the pattern of every product (zeros included) so that their symbolic parts are reused;
algebraic multigrid carried those zeros into dense coarse levels, so the inner solver
is given only the nonzeros. That matrix must be K_c of the dense formula exactly (the
same preconditioner, cheaper), with the block size and the rigid-body near-nullspace
AMG needs. In 3D BoomerAMG gets HMIS coarsening and
ext+i interpolation (solvers.BOOMERAMG_3D_OPTIONS), in 2D hypre's defaults,
and an option the user gave wins.
"""

from __future__ import annotations

import os
import re
import tempfile

import numpy as np
import pytest
from mpi4py import MPI
from petsc4py import PETSc
from stress.common import hertz
from test_contact3d import curved_punch


def gathered_dense(matrix: PETSc.Mat) -> np.ndarray:
    """The whole matrix, dense, on every rank."""
    indptr, indices, values = matrix.getValuesCSR()
    first = matrix.getOwnershipRange()[0]
    rows = first + np.repeat(np.arange(indptr.size - 1), np.diff(indptr))
    dense = np.zeros(matrix.getSize())
    for part in MPI.COMM_WORLD.allgather((rows, indices, values)):
        dense[part[0], part[1]] = part[2]
    return dense


def condensed_reference(J: np.ndarray, u: np.ndarray, z: np.ndarray,
                        node_dofs: np.ndarray) -> np.ndarray:
    """K_c of the module docstring of dolfinx_mortar.condensation, dense and whole (one
    multiplier per node): the reference the sparse, row-restricted set-up must equal."""
    A, G, C = J[np.ix_(u, u)], J[np.ix_(u, z)], J[np.ix_(z, u)]
    d = np.diagonal(J[np.ix_(z, z)])
    active = d == 0.0
    at_node = G[node_dofs, np.arange(z.size)[:, None]]
    lengths = np.linalg.norm(at_node, axis=1)
    # the rows of inactive nodes (some without any G) are zero in T
    inverse_length = np.divide(1.0, lengths, out=np.zeros_like(lengths), where=active)
    T = np.zeros((z.size, u.size))
    np.put_along_axis(T, node_dofs, np.divide(at_node, lengths[:, None], out=np.zeros_like(
        at_node), where=active[:, None]), axis=1)
    A_prime = A - G @ (np.where(active, 0.0, 1.0 / np.where(active, 1.0, d))[:, None] * C)
    B1 = A_prime - (G * inverse_length) @ (T @ A_prime)
    C_a = active[:, None] * C
    K_r = B1 - T.T @ (T @ B1 + C_a)
    E = K_r @ T.T - T.T @ (T @ K_r @ T.T)
    q = np.diagonal(T @ K_r @ T.T)
    usable = active & (q != 0.0)
    return K_r + (E * np.where(usable, 1.0 / np.where(usable, q, 1.0), 0.0)) @ C_a


@pytest.mark.parallel
@pytest.mark.timeout(300)
def test_inner_matrix_is_k_c_without_its_zeros():
    """The inner matrix, computed on the rows near the contact only and A elsewhere, is
    K_c of the dense formula, whole, to rounding; it stores no zero but the diagonal."""
    setup = hertz(refinement=0, linear_solver="iterative")
    outcome = setup.steps(2)
    assert outcome.converged
    problem = setup.problem
    condenser = problem._condenser
    assert condenser.num_active > 0
    comm = MPI.COMM_WORLD
    u = np.concatenate(comm.allgather(condenser.is_u.getIndices()))
    z = np.concatenate(comm.allgather(condenser.is_z.getIndices()))
    node_dofs = np.concatenate(comm.allgather(condenser.z_node_dofs))
    J = gathered_dense(problem.snes.getJacobian()[0])
    reference = condensed_reference(J, u, z, node_dofs)
    hypre_matrix = rebuilt_inner_matrix(problem)
    assert hypre_matrix.getType() == "hypre"  # (BoomerAMG's own: no AIJ copy beside it)
    # (read before the conversion, which sets both matrices' block size to 1)
    assert hypre_matrix.getBlockSize() == 2
    assert len(hypre_matrix.getNearNullSpace().getVecs()) == 6  # 3 modes x 2 bodies
    inner = hypre_matrix.convert("aij")
    difference = np.abs(gathered_dense(inner) - reference)
    assert difference.max() <= 1e-12 * np.abs(reference).max()
    rows = comm.allgather(condenser._rows.size)
    assert 0 < sum(rows) < u.size / 2
    indptr, indices, values = inner.getValuesCSR()
    first = inner.getOwnershipRange()[0]
    local_rows = first + np.repeat(np.arange(indptr.size - 1), np.diff(indptr))
    assert np.all((values != 0.0) | (indices == local_rows))
    inner.destroy()
    setup.destroy()


@pytest.mark.parallel
@pytest.mark.timeout(300)
def test_a_second_solve_with_the_same_matrix_makes_k_c_again():
    """The condenser frees K_c after each linear solve; a solve with the same Newton matrix
    (PETSc then skips the preconditioner's set-up) makes it again and gives the first
    solve's answer, bit for bit."""
    setup = hertz(refinement=0, linear_solver="iterative")
    assert setup.steps(1).converged
    problem = setup.problem
    condenser = problem._condenser
    assert "K_inner" not in condenser._matrices
    ksp = problem.snes.getKSP()
    rhs = problem.b.duplicate()
    rhs.setRandom(PETSc.Random().create(MPI.COMM_WORLD))
    answers = []
    for _ in range(2):
        x = rhs.duplicate()
        before = len(condenser.inner_iterations)
        ksp.solve(rhs, x)
        assert ksp.getConvergedReason() > 0
        assert len(condenser.inner_iterations) > before
        assert "K_inner" not in condenser._matrices
        answers.append(x.getArray().copy())
    assert np.array_equal(answers[0], answers[1])
    setup.destroy()


def rebuilt_inner_matrix(problem) -> PETSc.Mat:
    """K_c of the last Newton matrix, made again: the condenser frees it (and the inner
    preconditioner's data) after each linear solve."""
    condenser = problem._condenser
    assert "K_inner" not in condenser._matrices
    condenser.setUp(problem.snes.getKSP().getPC())
    return condenser.ksp.getOperators()[0]


def inner_preconditioner_view(problem) -> str:
    """What the inner PC's view prints (BoomerAMG's options are set before its set-up)."""
    comm = problem.comm
    name = comm.bcast(tempfile.mkstemp(suffix=".txt")[1] if comm.rank == 0 else None)
    viewer = PETSc.Viewer().createASCII(name, comm=comm)
    problem._condenser.ksp.getPC().view(viewer)
    viewer.destroy()
    comm.barrier()
    with open(name) as file:
        text = file.read()
    comm.barrier()
    if comm.rank == 0:
        os.remove(name)
    return text


@pytest.mark.parallel
@pytest.mark.parametrize(("dim", "cell", "petsc_options", "coarsening", "interpolation",
                          "p_max", "threshold", "aggressive"), [
    (3, "hexahedron", {}, "HMIS", "ext\\+i", 4, "0.7", 1),
    (3, "tetrahedron", {}, "HMIS", "ext\\+i", 4, "0.25", 1),
    (3, "hexahedron", {"condensed_pc_hypre_boomeramg_coarsen_type": "PMIS",
                       "condensed_pc_hypre_boomeramg_strong_threshold": 0.5,
                       "condensed_pc_hypre_boomeramg_agg_nl": 0},
     "PMIS", "ext\\+i", 4, "0.5", 0),
    # PETSc 3.25 (sid) prints "not yet set" where it leaves hypre its own default
    (2, "triangle", {}, "(Falgout|not yet set)", "(classical|not yet set)", 0, "0.25", 0),
])
def test_boomeramg_options_follow_the_dimension(dim, cell, petsc_options, coarsening,
                                                interpolation, p_max, threshold, aggressive):
    """HMIS, ext+i, P_max 4 and one level of aggressive coarsening in 3D; the strong
    threshold 0.7 on hexahedra only (issue 26); the user's options win; hypre's defaults
    in 2D (no aggressive level: PETSc prints its count only when there is one)."""
    if dim == 3:
        problem, _ = curved_punch(MPI.COMM_WORLD, cell=cell, linear_solver="iterative",
                                  petsc_options=petsc_options)
    else:
        problem = hertz(refinement=0, linear_solver="iterative",
                        petsc_options=petsc_options).problem
    text = inner_preconditioner_view(problem)
    assert re.search(f"Coarsen type +{coarsening}\\n", text), text
    assert re.search(f"Interpolation type +{interpolation}\\n", text), text
    assert re.search(f"max elements per row {p_max}\\n", text), text
    assert re.search(f"Threshold for strong coupling {threshold}\\n", text), text
    levels = re.search(r"Number of levels of aggressive coarsening (\d+)\n", text)
    assert (int(levels.group(1)) if levels else 0) == aggressive, text
    names = [name for name in PETSc.Options().getAll() if "boomeramg" in name]
    assert names == []
    problem.destroy()


def test_automatic_choice_follows_dimension_size_and_support():
    """``auto``: iterative only where it was measured faster and is supported (3D, at
    least AUTO_ITERATIVE_MIN_DOFS, dual multipliers, with or without friction); direct
    elsewhere."""
    from dolfinx_mortar.solvers import AUTO_ITERATIVE_MIN_DOFS, automatic_linear_solver

    large = AUTO_ITERATIVE_MIN_DOFS
    assert automatic_linear_solver(3, large, "dual", False) == "iterative"
    assert automatic_linear_solver(3, large - 1, "dual", False) == "direct"
    assert automatic_linear_solver(2, 100 * large, "dual", False) == "direct"
    assert automatic_linear_solver(3, large, "standard", False) == "direct"
    assert automatic_linear_solver(3, large, "dual", True) == "iterative"  # friction too


@pytest.mark.parallel
def test_default_linear_solver_is_resolved_by_the_problem(monkeypatch):
    """The default ``auto`` becomes ``direct`` on a small 3D problem and ``iterative`` (with
    its condensation) once the threshold is below the problem's size."""
    from dolfinx_mortar import solvers

    problem, _ = curved_punch(MPI.COMM_WORLD)
    assert problem.linear_solver == "direct" and problem._condenser is None
    problem.destroy()
    monkeypatch.setattr(solvers, "AUTO_ITERATIVE_MIN_DOFS", 1)
    problem, _ = curved_punch(MPI.COMM_WORLD)
    assert problem.linear_solver == "iterative" and problem.condensation
    problem.destroy()
