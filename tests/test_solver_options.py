"""configure_snes leaves the global options database as it found it when the set-up
fails (an option left there would be read by the next problem with that prefix as the
user's own), and keeps only the factorization options when it succeeds."""

from __future__ import annotations

import pytest
from petsc4py import PETSc

from dolfinx_mortar import solvers

PREFIX = "test_solver_options_"


def configure(snes, petsc_options=None, before=lambda: None, after=lambda ksp: None):
    return solvers.configure_snes(snes, PREFIX, petsc_options or {}, False, 1e-10, before,
                                  after)


def test_failed_setup_leaves_no_option():
    options = PETSc.Options()
    before = dict(options.getAll())
    snes = PETSc.SNES().create(PETSc.COMM_SELF)
    with pytest.raises(PETSc.Error):
        configure(snes, {"snes_type": "no_such_type"})

    def fail():
        raise RuntimeError("before_options failed")

    with pytest.raises(RuntimeError, match="before_options failed"):
        configure(snes, before=fail)
    with pytest.raises(RuntimeError, match="after_options failed"):
        configure(snes, after=lambda ksp: (_ for _ in ()).throw(
            RuntimeError("after_options failed")))
    snes.destroy()
    assert dict(options.getAll()) == before


def test_failed_setup_restores_another_problems_factor_options():
    """A live problem's factorization option that a failed set-up overwrote comes back."""
    first = PETSc.SNES().create(PETSc.COMM_SELF)
    kept = configure(first, {"mat_mumps_icntl_14": 50})
    assert f"{PREFIX}mat_mumps_icntl_14" in kept
    second = PETSc.SNES().create(PETSc.COMM_SELF)
    with pytest.raises(PETSc.Error):
        configure(second, {"mat_mumps_icntl_14": 80, "ksp_type": "no_such_type"})
    assert PETSc.Options().getInt(f"{PREFIX}mat_mumps_icntl_14") == 50
    solvers.release_options(kept)
    assert not [name for name in PETSc.Options().getAll() if name.startswith(PREFIX)]
    first.destroy()
    second.destroy()


def test_successful_setup_keeps_only_factor_options_until_released():
    snes = PETSc.SNES().create(PETSc.COMM_SELF)
    kept = configure(snes)
    left = sorted(name for name in PETSc.Options().getAll() if name.startswith(PREFIX))
    assert left == sorted(kept)
    assert left and all(name.startswith(f"{PREFIX}mat_mumps_") for name in left)
    solvers.release_options(kept)
    assert not [name for name in PETSc.Options().getAll() if name.startswith(PREFIX)]
    snes.destroy()


def test_releasing_one_problem_keeps_the_factor_options_of_another():
    """Two problems with one prefix hold the same factorization options: the first one
    destroyed or garbage collected (at any moment, while the other still solves) must
    not take them from the other, whose next symbolic factorization reads them."""
    first, second = PETSc.SNES().create(PETSc.COMM_SELF), PETSc.SNES().create(PETSc.COMM_SELF)
    kept_first = configure(first)
    kept_second = configure(second)
    assert sorted(kept_first) == sorted(kept_second)
    solvers.release_options(kept_first)
    left = sorted(name for name in PETSc.Options().getAll() if name.startswith(PREFIX))
    assert left == sorted(kept_second)
    assert PETSc.Options().getInt(f"{PREFIX}mat_mumps_icntl_24") == 1
    solvers.release_options(kept_second)
    assert not [name for name in PETSc.Options().getAll() if name.startswith(PREFIX)]
    first.destroy()
    second.destroy()
