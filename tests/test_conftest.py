"""The conftest's checks themselves: a test that leaves a PETSc option in the global
database, or a live PETSc object, fails (at teardown); clean tests, and objects freed
only by garbage collection (a reference cycle), pass; a failing test is not also
charged with the objects its traceback holds. Run on a temporary test file with
the project's conftest, in a fresh pytest process."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

CASES = '''
import weakref

from petsc4py import PETSc

_kept = []


def test_leaves_an_option():
    PETSc.Options()["conftest_selftest_leaked_icntl_14"] = 200


def test_changes_an_option():
    # an option present before the test (set at import) with another value after it
    PETSc.Options()["conftest_selftest_present"] = 2


def test_removes_an_option():
    PETSc.Options().delValue("conftest_selftest_removed")


def test_leaves_a_live_vector():
    _kept.append(PETSc.Vec().createSeq(3, comm=PETSc.COMM_SELF))


def test_cleans_up():
    options = PETSc.Options()
    options["conftest_selftest_temporary"] = 1
    vector = PETSc.Vec().createSeq(3, comm=PETSc.COMM_SELF)
    vector.destroy()
    options.delValue("conftest_selftest_temporary")


class _Problem:
    """A user's solver whose callback refers back to it (a reference cycle: ContactProblem
    avoids it with a weakly held callback object), its options released by
    weakref.finalize when it is collected."""

    def __init__(self):
        self.snes = PETSc.SNES().create(PETSc.COMM_SELF)
        self.snes.setFunction(self._residual, PETSc.Vec().createSeq(2, comm=PETSc.COMM_SELF))
        PETSc.Options()["conftest_selftest_mat_mumps_cntl_1"] = 0.1
        weakref.finalize(self, PETSc.Options().delValue, "conftest_selftest_mat_mumps_cntl_1")

    def _residual(self, snes, x, f):
        pass


def test_garbage_collected_problem_is_clean():
    _Problem()


def test_fails_holding_a_vector():
    # its traceback keeps the vector alive: reported as the failure it is, no leak on top
    vector = PETSc.Vec().createSeq(3, comm=PETSc.COMM_SELF)
    assert vector.getSize() == 4
'''

CONFTEST = Path(__file__).with_name("conftest.py")


def test_conftest_fails_tests_that_leave_petsc_state(tmp_path):
    shutil.copy(CONFTEST, tmp_path / "conftest.py")
    (tmp_path / "test_cases.py").write_text(
        "from petsc4py import PETSc\n"
        "PETSc.Options()['conftest_selftest_present'] = 1\n"
        "PETSc.Options()['conftest_selftest_removed'] = 1\n" + CASES)
    run = subprocess.run(
        [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "--color=no", "-rA",
         "test_cases.py"],
        cwd=tmp_path, capture_output=True, text=True, timeout=300)
    output = run.stdout + run.stderr
    assert run.returncode == 1, output

    def outcome(test: str) -> set[str]:
        return set(re.findall(rf"^(PASSED|FAILED|ERROR) test_cases.py::{test}\b", output,
                              re.MULTILINE))

    # a test that leaves something passes its call and errors at teardown
    for test in ("test_leaves_an_option", "test_changes_an_option", "test_removes_an_option",
                 "test_leaves_a_live_vector"):
        assert outcome(test) == {"PASSED", "ERROR"}, (test, output)
    for test in ("test_cleans_up", "test_garbage_collected_problem_is_clean"):
        assert outcome(test) == {"PASSED"}, (test, output)
    assert outcome("test_fails_holding_a_vector") == {"FAILED"}, output
    assert re.search(r"options left in the global database: \{'conftest_selftest_leaked_"
                     r"icntl_14': '200'\}", output), output
    assert re.search(r"options left in the global database: \{'conftest_selftest_present': "
                     r"'2'\}", output), output
    assert "options removed from it: ['conftest_selftest_removed']" in output, output
    assert "1 live PETSc objects left after garbage collection" in output, output
    assert "['Vec']" in output, output
    assert re.search(r"1 failed, 6 passed, 4 errors", output), output
