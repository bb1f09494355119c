"""A failing linear solve: never a step, always a reason; ``auto`` falls back to direct.

The iterative solver is made to fail on the small 3D curved punch by its options: the
inner solve of the condensed system diverges (Richardson without preconditioner, so the
condenser returns NaN and fgmres stops with DIVERGED_NANORINF), or fgmres is given one
iteration. SNES must stop before it applies the step (the state stays finite, at the
start of the step), and the report must say why and what to try. With
``linear_solver="auto"`` (made to choose the iterative solver on this small problem) the
direct solver must take over in the same load step, with one ContactWarning, and give
the direct answer.
"""

from __future__ import annotations

import numpy as np
import pytest
from contact_warnings import warns_on_rank_zero
from mpi4py import MPI
from petsc4py import PETSc
from stress.common import relative_difference
from test_contact3d import curved_punch

from dolfinx_mortar import LoadSteppingError, condensation, solve_load_steps, solvers

FAILING_OPTIONS = {
    "inner breakdown": {"condensed_ksp_type": "richardson",
                        "condensed_ksp_richardson_scale": 1e3, "condensed_pc_type": "none"},
    "outer iteration limit": {"ksp_max_it": 1},
}
FAILURE_WORDS = {
    "inner breakdown": ["DIVERGED_NANORINF", "condensed inner solve",
                        "broke down: KSP reason -4 DIVERGED_DTOL"],
    "outer iteration limit": ["DIVERGED_MAX_IT", "did not reach its tolerance in 1 iterations"],
}


def gathered(problem) -> dict:
    coordinates, pressure = problem.gathered_pressure()
    order = np.lexsort(np.round(coordinates, 9).T)
    slave, master = problem.contact_forces()
    return {"pressure": pressure[order], "force": slave, "active": problem.num_active()}


@pytest.mark.parallel
@pytest.mark.parametrize("failure", sorted(FAILING_OPTIONS))
def test_failed_iterative_solve_applies_no_step_and_says_what_to_try(failure):
    problem, apply_load = curved_punch(MPI.COMM_WORLD, linear_solver="iterative",
                                       petsc_options=FAILING_OPTIONS[failure])
    apply_load(0.5)
    start = problem.save_state()
    report = problem.solve()
    assert not report.converged and report.iterations == 0
    assert "DIVERGED_LINEAR_SOLVE" in report.cause()
    for words in FAILURE_WORDS[failure] + ["try linear_solver='direct'"]:
        assert words in report.linear_solver_failure
    assert np.isfinite(problem.u.x.array).all()
    assert np.array_equal(problem.u.x.array, start["u"])
    for z, before in zip(problem.multipliers, start["z"], strict=True):
        assert np.array_equal(z.getArray(readonly=True), before)
    # the load stepping cuts back, then names the failure and what to try
    problem.restore_state(start)
    with pytest.raises(LoadSteppingError) as error:
        solve_load_steps(problem, apply_load, 1, max_cutbacks=1)
    message = str(error.value)
    assert "try linear_solver='direct'" in message and "cut-backs" in message
    assert "singular system usually" not in message
    assert problem.linear_solver == "iterative"
    problem.destroy()


@pytest.mark.parallel
@pytest.mark.timeout(300)
@pytest.mark.parametrize("failure", sorted(FAILING_OPTIONS))
def test_auto_falls_back_to_direct_where_the_iterative_solve_fails(failure, monkeypatch):
    problem, apply_load = curved_punch(MPI.COMM_WORLD, linear_solver="direct")
    direct_records = solve_load_steps(problem, apply_load, 2)
    direct = gathered(problem)
    problem.destroy()

    monkeypatch.setattr(solvers, "AUTO_ITERATIVE_MIN_DOFS", 1)
    problem, apply_load = curved_punch(MPI.COMM_WORLD, petsc_options=FAILING_OPTIONS[failure])
    assert problem.linear_solver == "iterative"
    with warns_on_rank_zero("linear_solver='auto' chose the iterative solver") as shown:
        records = solve_load_steps(problem, apply_load, 2)
    assert len(shown) == (1 if MPI.COMM_WORLD.rank == 0 else 0)
    if shown:
        for words in FAILURE_WORDS[failure] + ["MUMPS LU", "every later one"]:
            assert words in str(shown[0].message)
    assert problem.linear_solver == "direct" and problem._condenser is None
    # the same step was solved again: no cut-back, the direct Newton iterations and answer
    assert [r.cutbacks for r in records] == [0, 0]
    assert [r.iterations for r in records] == [r.iterations for r in direct_records]
    result = gathered(problem)
    assert result["active"] == direct["active"] > 0
    assert relative_difference(result["pressure"], direct["pressure"]) <= 1e-8
    assert relative_difference(result["force"], direct["force"]) <= 1e-8
    problem.destroy()


@pytest.mark.parallel
@pytest.mark.parametrize("user_smoother", [False, True])
def test_inner_breakdown_is_retried_with_the_other_amg_smoother(user_smoother):
    """An inner solve preconditioned by BoomerAMG that breaks down is solved again, once,
    with condensation.FALLBACK_RELAXATION, which the AMG then keeps; both failures are
    reported. A smoother the user chose is never switched."""
    diverging = {"condensed_ksp_type": "richardson", "condensed_ksp_richardson_scale": 1e3}
    if user_smoother:
        diverging["condensed_pc_hypre_boomeramg_relax_type_all"] = "Jacobi"
    problem, apply_load = curved_punch(MPI.COMM_WORLD, cell="tetrahedron",
                                       linear_solver="iterative", petsc_options=diverging)
    apply_load(0.5)
    report = problem.solve()
    condenser = problem.solver.condenser
    assert not report.converged and report.iterations == 0
    assert "broke down: KSP reason -4 DIVERGED_DTOL" in report.linear_solver_failure
    retried = f"with {condensation.FALLBACK_RELAXATION} smoothing: KSP reason -4"
    if user_smoother:
        assert condenser.relaxation_switches == 0
        assert retried not in report.linear_solver_failure
        assert len(condenser.inner_iterations) == 1
    else:
        assert condenser.relaxation_switches == 1
        assert retried in report.linear_solver_failure
        assert len(condenser.inner_iterations) == 2
        assert condenser.ksp.getPC().getHYPREType() == "boomeramg"
    problem.destroy()


def _inner_view(condenser, path) -> str:
    """The inner KSP's view, as rank 0 writes it ("" on the other ranks)."""
    if MPI.COMM_WORLD.size > 1:
        return ""
    viewer = PETSc.Viewer().createASCII(str(path), comm=MPI.COMM_SELF)
    condenser.ksp.view(viewer)
    viewer.destroy()
    return path.read_text()


def _iterative_equals_direct_after(change) -> None:
    """The curved punch's second load step solved directly and iteratively, ``change``
    (condenser) made to the iterative solver after its first step: the answers equal to
    1e-8, and the iterative one made inner solves after the change."""
    answers = []
    for linear_solver in ("direct", "iterative"):
        problem, apply_load = curved_punch(MPI.COMM_WORLD, cell="tetrahedron",
                                           linear_solver=linear_solver)
        solve_load_steps(problem, apply_load, 1)
        if linear_solver == "iterative":
            condenser = problem.solver.condenser
            # (K_c, freed after each linear solve, made again from the last Newton matrix)
            condenser.setUp(problem.solver.snes.getKSP().getPC())
            change(condenser)
            before = len(condenser.inner_iterations)
        apply_load(2.0)
        assert problem.solve().converged
        answers.append(gathered(problem))
        problem.destroy()
    assert len(condenser.inner_iterations) > before
    assert answers[1]["active"] == answers[0]["active"] > 0
    assert relative_difference(answers[1]["pressure"], answers[0]["pressure"]) <= 1e-8


@pytest.mark.parallel
def test_the_switched_smoother_solves_as_before(tmp_path):
    """After a switch of the inner AMG's smoother (as after a breakdown) the Newton steps
    stay exact: the next load step's answer is the direct one to 1e-8."""
    def switch(condenser):
        views = [_inner_view(condenser, tmp_path / "started.txt")]
        assert condenser._switch_relaxation() and condenser.relaxation_switches == 1
        views.append(_inner_view(condenser, tmp_path / "switched.txt"))
        if MPI.COMM_WORLD.size == 1:
            # 3D: forward down, backward up; then the l1 form both ways
            assert "Relax down          SOR/Jacobi" in views[0]
            assert "Relax up            backward-SOR/Jacobi" in views[0]
            assert "Relax down          l1scaled-SOR/Jacobi" in views[1]
            assert "Relax up            l1scaled-SOR/Jacobi" in views[1]
            assert "Coarsen type        HMIS" in views[1]  # the 3D options stay

    _iterative_equals_direct_after(switch)


@pytest.mark.parallel
def test_a_singular_inner_matrix_gets_an_iterative_coarsest_level(tmp_path):
    """While the inner matrix has a null space, BoomerAMG relaxes its coarsest level
    (``condensation.SINGULAR_COARSE_RELAXATION``) instead of eliminating it (a singular
    coarsest matrix made the inner GMRES break down on the 3D Cattaneo-Mindlin, 3 ranks),
    and eliminates it again once there is none; the Newton steps after it stay the direct
    ones to 1e-8."""
    def singular_then_not(condenser):
        inner = condenser._matrices["K_inner"]
        assert not condenser._singular_coarse
        # a slide along x with zero multipliers: J's null space as set_null_space gives it
        slide = inner.createVecRight()
        slide.getArray()[:] = np.tile([1.0, 0.0, 0.0], condenser.num_u // 3)
        whole = PETSc.Vec().createMPI((condenser.num_u + condenser.num_z, None),
                                      comm=MPI.COMM_WORLD)
        whole.zeroEntries()
        whole.getArray()[: condenser.num_u] = slide.getArray(readonly=True)
        whole.normalize()
        condenser._null_space = PETSc.NullSpace().create(vectors=[whole], comm=MPI.COMM_WORLD)
        views = []
        for singular in (True, False):
            condenser._set_inner_null_space(inner)
            condenser.ksp.setUp()
            views.append(_inner_view(condenser, tmp_path / f"{singular}.txt"))
            assert condenser._singular_coarse == singular
            if condenser._null_space is not None:
                condenser._null_space.destroy()
                condenser._null_space = None
        for vector in (slide, whole):
            vector.destroy()
        if MPI.COMM_WORLD.size == 1:
            assert "Relax on coarse     l1scaled-SOR/Jacobi" in views[0]
            assert "Relax on coarse     Gaussian-elimination" in views[1]
            assert "Coarsen type        HMIS" in views[0]  # the 3D options stay

    _iterative_equals_direct_after(singular_then_not)
