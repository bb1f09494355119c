"""Shared pytest setup: garbage collection and rank synchronisation between tests, and
no PETSc state left behind by a test.

dolfinx and petsc4py objects hold collective resources; collecting them at the
same point on every rank, and waiting for all ranks after each test, keeps a
failure on one rank from turning into a hang on another.

What exists when a test starts is frozen (``gc.freeze``): the collections and the
scan for live PETSc objects after it then walk only what the test made, not the
whole heap of dolfinx, PETSc and the test modules (about 0.2 s a test otherwise).
Each module's frozen objects are released and collected at its start and its end,
so garbage of module-scoped fixtures is still collected, at the same point on every
rank.

Every test must leave PETSc's global options database as it found it (an option a
problem leaves there is read by every later solver with that prefix: a test's
outcome would depend on the tests run before it) and must not leave live PETSc
objects behind (with a non-null handle after garbage collection). Either fails the
test at teardown, on every rank (tests/test_conftest.py checks this).
"""

from __future__ import annotations

import gc

import hypothesis
import pytest
from mpi4py import MPI
from petsc4py import PETSc


def _options() -> dict[str, str]:
    return dict(PETSc.Options().getAll())


def _live_petsc_objects() -> dict[tuple[int, int], str]:
    """petsc4py objects alive with a PETSc object behind them: (id, handle) -> type name."""
    live = {}
    for obj in gc.get_objects():
        if isinstance(obj, PETSc.Object):
            try:
                handle = obj.handle
            except Exception:  # pragma: no cover - a half-made wrapper
                continue
            if handle:
                live[(id(obj), handle)] = type(obj).__name__
    return live


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item, call):
    report = yield
    if report.when == "call":
        item.stash[_CALL_FAILED] = report.failed
    return report


_CALL_FAILED = pytest.StashKey[bool]()


@hypothesis.given(hypothesis.strategies.just(0))
def _hypothesis_started(_):
    """Run once at import: Hypothesis registers its global random generator at its first
    test, and with ``gc.get_referrers``, which does not see frozen referrers."""


_hypothesis_started()


def _collect_everything() -> None:
    gc.unfreeze()
    gc.collect()
    MPI.COMM_WORLD.Barrier()


@pytest.fixture(autouse=True, scope="module")
def _module_heap():
    _collect_everything()
    yield
    _collect_everything()


@pytest.fixture(autouse=True)
def _no_petsc_state_left(request, _module_heap):
    # set up before and torn down after _collect_and_synchronise (which requests it):
    # what is compared is what is left after the test's garbage was collected
    comm = MPI.COMM_WORLD
    gc.freeze()
    options = _options()
    live = _live_petsc_objects()
    yield
    gc.collect()
    now = _options()
    left = {name: value for name, value in now.items() if options.get(name) != value}
    removed = sorted(name for name in options if name not in now)
    # a failed test's traceback keeps its frames' objects alive: not a leak of its own
    failed = request.node.stash.get(_CALL_FAILED, False)
    objects = [] if failed else sorted(kind for key, kind in _live_petsc_objects().items()
                                       if key not in live)
    problems = []
    if left or removed:
        problems.append(f"PETSc options left in the global database: {left}"
                        + (f", options removed from it: {removed}" if removed else ""))
    if objects:
        problems.append(f"{len(objects)} live PETSc objects left after garbage collection "
                        f"(destroy() them or drop their references): {objects[:20]}")
    reports = comm.allgather("; ".join(problems))
    if any(reports):
        # restore the database for the next test, whichever rank failed
        for name in left:
            PETSc.Options().delValue(name)
        for name, value in options.items():
            PETSc.Options()[name] = value
        pytest.fail("; ".join(f"rank {rank}: {text}" for rank, text in enumerate(reports)
                              if text), pytrace=False)


@pytest.fixture(autouse=True)
def _collect_and_synchronise(_no_petsc_state_left):
    # no automatic collection inside a test: it would run at a rank-dependent moment
    # and free dolfinx objects whose destructors are collective (a hang on sid, 2 ranks)
    gc.disable()
    try:
        yield
    finally:
        gc.enable()
    gc.collect()
    MPI.COMM_WORLD.Barrier()


@pytest.fixture
def comm():
    return MPI.COMM_WORLD
