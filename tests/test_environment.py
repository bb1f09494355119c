"""The environment itself: imports, versions, MPI, PETSc solvers, and serial = parallel assembly."""

from __future__ import annotations

import dolfinx
import dolfinx.fem.petsc
import numpy as np
import pytest
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_mortar import compat


def test_imports_and_versions():
    import gmsh  # noqa: F401
    import scipy  # noqa: F401

    import dolfinx_mortar

    assert compat.DOLFINX_VERSION >= compat.MINIMUM_DOLFINX_VERSION
    assert dolfinx_mortar.__version__
    assert dolfinx.has_petsc
    assert PETSc.ScalarType == np.float64, "dolfinx_mortar needs real PETSc"


def test_blas_is_an_optimized_one():
    """tools/debian-packages.txt installs OpenBLAS (serial): with Debian's reference BLAS,
    MUMPS's factorizations were 3 to 6 times slower (docs/benchmarks.md, "The BLAS under
    MUMPS"); a host without /proc says nothing."""
    from dolfinx_mortar import solvers

    assert solvers.reference_blas() is None


def test_petsc_has_the_direct_solvers():
    """MUMPS is the default solver; SuperLU_dist is an alternative."""
    matrix = PETSc.Mat().createAIJ((2, 2), nnz=1, comm=MPI.COMM_SELF)
    matrix.setValue(0, 0, 2.0)
    matrix.setValue(1, 1, 4.0)
    matrix.assemble()
    for solver in ("mumps", "superlu_dist"):
        ksp = PETSc.KSP().create(MPI.COMM_SELF)
        ksp.setOperators(matrix)
        ksp.setType("preonly")
        ksp.getPC().setType("lu")
        ksp.getPC().setFactorSolverType(solver)
        b, x = matrix.createVecs()
        b.set(1.0)
        ksp.solve(b, x)
        assert np.allclose(x.getArray(), [0.5, 0.25])
        ksp.destroy()


def assembled_norms(comm) -> tuple[float, float, float]:
    mesh = dolfinx.mesh.create_unit_square(comm, 7, 5, dolfinx.mesh.CellType.triangle)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    x = ufl.SpatialCoordinate(mesh)
    a = dolfinx.fem.form(ufl.inner(ufl.grad(u), ufl.grad(v)) * (1 + x[0] * x[1]) * ufl.dx)
    L = dolfinx.fem.form(ufl.inner(ufl.as_vector([x[0] ** 2, ufl.sin(x[1])]), v) * ufl.dx)
    A = dolfinx.fem.petsc.assemble_matrix(a)
    A.assemble()
    b = dolfinx.fem.petsc.assemble_vector(L)
    b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    total = dolfinx.fem.assemble_scalar(dolfinx.fem.form(x[0] * ufl.exp(x[1]) * ufl.dx))
    return A.norm(PETSc.NormType.FROBENIUS), b.norm(), comm.allreduce(total, op=MPI.SUM)


@pytest.mark.parallel
def test_assembly_is_the_same_on_any_number_of_ranks():
    serial = assembled_norms(MPI.COMM_SELF)
    parallel = assembled_norms(MPI.COMM_WORLD)
    assert np.allclose(serial, parallel, rtol=1e-13, atol=0)
    assert parallel[2] == pytest.approx(0.5 * (np.e - 1.0), rel=1e-3)


@pytest.mark.parallel
def test_mpi_ranks_see_each_other():
    comm = MPI.COMM_WORLD
    assert comm.allreduce(1, op=MPI.SUM) == comm.size
    assert comm.allgather(comm.rank) == list(range(comm.size))
