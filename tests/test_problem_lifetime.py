"""A contact problem leaves nothing behind: no option in PETSc's global options database
after destroy() or garbage collection (2D and 3D, direct and iterative linear solver, with
and without friction), no reference cycle that would keep it alive, and a with-block frees
its PETSc objects on every rank, also when the block raises."""

from __future__ import annotations

import gc
import weakref

import dolfinx
import numpy as np
import pytest
import ufl
from mpi4py import MPI
from petsc4py import PETSc
from test_contact3d import curved_punch

from dolfinx_mortar import (
    ContactPair,
    ContactProblem,
    Coulomb,
    Material,
    internal_work,
    meshes,
    solve_load_steps,
)

CASES = [
    (2, {"linear_solver": "direct"}),
    (2, {"linear_solver": "iterative"}),
    (2, {"linear_solver": "direct", "friction": Coulomb(0.3)}),
    (3, {"linear_solver": "direct"}),
    (3, {"linear_solver": "iterative"}),
    (3, {"linear_solver": "direct", "friction": Coulomb(0.3)}),
]


def pressed_punch(gdim: int, comm=MPI.COMM_WORLD, **options):
    """The patch test's punch pressed onto its foundation: (problem, apply_load)."""
    if gdim == 3:
        return curved_punch(comm, ratio=(3, 2), **options)
    tagged = meshes.patch_test(ratio=(2, 3), comm=comm)
    mesh, markers = tagged.mesh, tagged.markers
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    u = dolfinx.fem.Function(V)
    F = internal_work(u, ufl.TestFunction(V), {0: Material(1000.0, 0.3, "linear")})
    drive = dolfinx.fem.Function(V)
    top = tagged.facet_tags.find(markers["punch_top"])
    bottom = tagged.facet_tags.find(markers["foundation_bottom"])
    bcs = [
        dolfinx.fem.dirichletbc(drive, dolfinx.fem.locate_dofs_topological(V, 1, top)),
        dolfinx.fem.dirichletbc(np.zeros(2), dolfinx.fem.locate_dofs_topological(V, 1, bottom), V),
    ]
    pair = ContactPair(tagged.facet_tags, markers["contact_slave"], markers["contact_master"])
    problem = ContactProblem(F, u, bcs, [pair], **options)

    def apply_load(t):
        drive.x.array.reshape(-1, 2)[:, 0] = 0.005 * t
        drive.x.array.reshape(-1, 2)[:, 1] = -0.02 * t

    return problem, apply_load


def free_parallel_garbage(comm) -> None:
    """Free the PETSc objects of collected wrappers on ``comm`` (the mesh's), on every
    rank. petsc4py only marks a parallel object for destruction when its wrapper is
    collected (destroying is collective, collection is not), so the SNES, and the
    equations whose callbacks it holds, live on until this collective clean-up."""
    gc.collect()
    PETSc.garbage_cleanup(comm)


def database() -> dict:
    return dict(PETSc.Options().getAll())


@pytest.mark.parallel
@pytest.mark.parametrize("gdim, options", CASES)
def test_no_option_is_left_after_destroy_or_garbage_collection(gdim, options):
    before = database()
    problem, apply_load = pressed_punch(gdim, **options)
    assert database() == before  # nothing between set-up and solve
    records = solve_load_steps(problem, apply_load, 1)
    assert records[-1].report.converged and problem.linear_solver == options["linear_solver"]
    assert database() == before
    problem.destroy()
    problem.destroy()  # a second call does nothing
    assert database() == before

    problem, apply_load = pressed_punch(gdim, **options)
    solve_load_steps(problem, apply_load, 1)
    collected, comm = weakref.ref(problem), problem.comm
    del problem
    gc.collect()
    assert collected() is None
    assert database() == before
    free_parallel_garbage(comm)


@pytest.mark.parallel
@pytest.mark.parametrize("gdim", [2, 3])
def test_a_dropped_problem_is_freed_at_once(gdim):
    """No reference cycle (the SNES holds the equations' methods, not the problem's): the
    last reference gone, the problem is freed without waiting for the cycle collector."""
    problem, apply_load = pressed_punch(gdim)
    solve_load_steps(problem, apply_load, 1)
    collected, comm = weakref.ref(problem), problem.comm
    gc.disable()
    try:
        del problem, apply_load
        assert collected() is None
    finally:
        gc.enable()
    free_parallel_garbage(comm)


@pytest.mark.parallel
def test_a_with_block_destroys_the_problem_also_after_an_exception():
    before = database()
    problem, apply_load = pressed_punch(2)
    with problem:
        x, snes = problem.x, problem.snes
        assert x and snes
    assert not x and not snes and not problem.equations.b_u
    problem, apply_load = pressed_punch(2)
    with pytest.raises(RuntimeError, match="inside the block"):
        with problem:
            solve_load_steps(problem, apply_load, 1)
            x, snes, K = problem.x, problem.snes, problem.system.mat
            raise RuntimeError("inside the block")
    assert not x and not snes and not K
    assert problem.solver.snes is None
    assert database() == before


@pytest.mark.parallel
def test_a_failed_set_up_leaves_no_option():
    """An unknown solver type fails the SNES set-up: the problem's objects are freed and
    its options are gone."""
    before = database()
    with pytest.raises(PETSc.Error):
        pressed_punch(2, petsc_options={"ksp_type": "no_such_type"})
    assert database() == before
