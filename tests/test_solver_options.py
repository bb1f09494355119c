"""Our PETSc options are in the global options database only while a solver is set up
(configure_snes) or solves (inserted_options): after either, also when it fails, the
database is as it was, so that no option of ours is taken for the user's by the next
problem with that prefix; and the user's own options are neither overwritten nor removed."""

from __future__ import annotations

import pytest
from petsc4py import PETSc

from dolfinx_mortar import solvers

PREFIX = "test_solver_options_"


def configure(snes, petsc_options=None, before=lambda: None, after=lambda ksp: None):
    return solvers.configure_snes(snes, PREFIX, petsc_options or {}, False, 1e-10, before,
                                  after)


def ours() -> list[str]:
    return sorted(name for name in PETSc.Options().getAll() if name.startswith(PREFIX))


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


def test_successful_setup_leaves_no_option_and_returns_the_solve_options():
    """The factorization options, which PETSc reads at every symbolic factorization, come
    back for each solve instead of staying in the database."""
    snes = PETSc.SNES().create(PETSc.COMM_SELF)
    values = configure(snes, {"mat_mumps_icntl_14": 50})
    assert ours() == []
    assert values["mat_mumps_icntl_24"] == 1 and values["mat_mumps_icntl_14"] == 50
    with solvers.inserted_options(PREFIX, values):
        assert PETSc.Options().getInt(f"{PREFIX}mat_mumps_icntl_14") == 50
        assert f"{PREFIX}mat_mumps_icntl_24" in ours()
    assert ours() == []
    snes.destroy()


def test_inserted_options_keep_the_users_and_leave_after_an_exception():
    options = PETSc.Options()
    options[f"{PREFIX}mat_mumps_icntl_14"] = 80
    try:
        with pytest.raises(RuntimeError, match="solve failed"):
            with solvers.inserted_options(PREFIX, {"mat_mumps_icntl_14": 50,
                                                   "mat_mumps_icntl_24": 1}):
                assert options.getInt(f"{PREFIX}mat_mumps_icntl_14") == 80
                assert options.getInt(f"{PREFIX}mat_mumps_icntl_24") == 1
                raise RuntimeError("solve failed")
        assert ours() == [f"{PREFIX}mat_mumps_icntl_14"]
        assert options.getInt(f"{PREFIX}mat_mumps_icntl_14") == 80
    finally:
        options.delValue(f"{PREFIX}mat_mumps_icntl_14")


def test_a_users_atol_in_the_database_wins():
    options = PETSc.Options()
    options[f"{PREFIX}snes_atol"] = 1e-3
    snes = PETSc.SNES().create(PETSc.COMM_SELF)
    try:
        configure(snes)
        assert snes.getTolerances()[1] == pytest.approx(1e-3)
    finally:
        options.delValue(f"{PREFIX}snes_atol")
        snes.destroy()
    snes = PETSc.SNES().create(PETSc.COMM_SELF)
    configure(snes)
    assert snes.getTolerances()[1] == pytest.approx(1e-10)
    snes.destroy()


def test_a_residual_that_grows_1e4_fold_stops_newton():
    """f(x) = x + 1 for x >= 0 and 1e6 x + 1 below, from x = 1e-8: the first Newton step
    lands at -1, where the residual is 1e6 times the first one. The divergence test
    (1e4, stated in the defaults: PETSc >= 3.22 reads the -1 they held before as its
    default, older PETSc as "no test") stops the solve there, DIVERGED_DTOL, and the
    load stepper cuts back; with the test off Newton would go on to the root -1e-6."""
    residual_jump = []

    def residual(snes, x, f):
        value = x.getArray(readonly=True)[0]
        f.getArray()[0] = value + 1.0 if value >= 0.0 else 1e6 * value + 1.0
        residual_jump.append(abs(f.getArray()[0]))

    def jacobian(snes, x, J, P):
        J.setValue(0, 0, 1.0 if x.getArray(readonly=True)[0] >= 0.0 else 1e6)
        J.assemble()

    for options, reason, root in (({}, PETSc.SNES.ConvergedReason.DIVERGED_DTOL, None),
                                  ({"snes_divergence_tolerance": "unlimited"}, None, -1e-6)):
        snes = PETSc.SNES().create(PETSc.COMM_SELF)
        values = configure(snes, options)
        J = PETSc.Mat().createAIJ((1, 1), nnz=1, comm=PETSc.COMM_SELF)
        f, x = J.createVecs()
        snes.setFunction(residual, f)
        snes.setJacobian(jacobian, J)
        x.set(1e-8)
        with solvers.inserted_options(PREFIX, values):
            snes.solve(None, x)
        if reason is not None:
            assert snes.getDivergenceTolerance() == 1e4
            assert snes.getConvergedReason() == reason
            assert snes.getIterationNumber() == 1
        else:
            assert snes.getConvergedReason() > 0 and snes.getIterationNumber() == 2
            assert x.getArray()[0] == pytest.approx(root, rel=1e-12)
        for obj in (snes, J, f, x):
            obj.destroy()
    assert max(residual_jump) > 1e5 * residual_jump[0]


NETLIB = "/usr/lib/x86_64-linux-gnu/blas/libblas.so.3.12.0"
OPENBLAS = "/usr/lib/x86_64-linux-gnu/openblas-serial/libblas.so.3"


def _maps(tmp_path, *paths) -> str:
    lines = [f"7f0000000000-7f0000001000 r-xp 00000000 fe:01 {i} {path}"
             for i, path in enumerate(("/usr/lib/x86_64-linux-gnu/libpetsc_real.so.3.22",)
                                      + paths)]
    file = tmp_path / "maps"
    file.write_text("\n".join(lines + ["7ffd00000000-7ffd00001000 rw-p 00000000 00:00 0"]))
    return str(file)


def test_reference_blas_found_in_the_memory_map(tmp_path):
    assert solvers.reference_blas(_maps(tmp_path, NETLIB)) == NETLIB
    assert solvers.reference_blas(_maps(tmp_path, OPENBLAS)) is None
    assert solvers.reference_blas(_maps(tmp_path)) is None
    assert solvers.reference_blas(str(tmp_path / "no_such_file")) is None


def test_reference_blas_advised_once(tmp_path, monkeypatch, caplog):
    from mpi4py import MPI

    monkeypatch.setattr(solvers, "_blas_advised", False)
    with caplog.at_level("WARNING", logger="dolfinx_mortar"):
        solvers.advise_blas(MPI.COMM_SELF, _maps(tmp_path, OPENBLAS))
        assert not caplog.records
        monkeypatch.setattr(solvers, "_blas_advised", False)
        for _ in range(2):
            solvers.advise_blas(MPI.COMM_SELF, _maps(tmp_path, NETLIB))
    assert len(caplog.records) == 1 and NETLIB in caplog.records[0].getMessage()
    assert "libopenblas0-serial" in caplog.records[0].getMessage()
