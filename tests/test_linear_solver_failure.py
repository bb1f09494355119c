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
from stress.common import relative_difference
from test_contact3d import curved_punch

from dolfinx_mortar import LoadSteppingError, solve_load_steps, solvers

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
