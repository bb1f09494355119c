"""Load stepping with cut-back, one log line per step, and output for ParaView.

:func:`solve_load_steps` drives a :class:`~dolfinx_mortar.problem.ContactProblem`
through a load (or displacement) parameter t from 0 to 1. A step whose Newton
solve fails, or whose iterate inverts an element, is undone and retried with
half the increment; after ``max_cutbacks`` halvings in a row, or when the
increment would fall below ``min_increment``, it raises
:class:`LoadSteppingError` with the cause in words (inverted elements and where,
the SNES reason, a linear solver failure) and the last converged t. After
each step that converged without a cut-back the increment doubles again, up
to the nominal one, and no step jumps over a point of the nominal grid (so the
steps land on t = k (end - start) / num_steps again, where demos read their
results). The contact search is redone inside
the solves whenever surfaces moved past the search margin.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import pathlib
import time
import typing

import dolfinx
import dolfinx.io
from mpi4py import MPI

from .problem import ContactProblem
from .solvers import SolveReport

logger = logging.getLogger("dolfinx_mortar")

PREDICTORS = ("none", "extrapolate")
"""Initial guesses of a load step (see :func:`solve_load_steps`)."""


class LoadSteppingError(RuntimeError):
    """Newton failed even after the last allowed cut-back, or the increment became too small.

    Attributes:
        last_converged: t of the last accepted step (the state the problem is left in).
        failed: t of the step that failed last.
        report: the :class:`~dolfinx_mortar.solvers.SolveReport` of that failed solve.
    """

    def __init__(self, message: str, last_converged: float = math.nan,
                 failed: float = math.nan, report: SolveReport | None = None):
        super().__init__(message)
        self.last_converged = last_converged
        self.failed = failed
        self.report = report


@dataclasses.dataclass
class StepRecord:
    """One accepted load step, as :func:`solve_load_steps` returns it and logs it.

    The same on every rank (each field is a global quantity).

    Attributes:
        step: the step's number among the accepted steps, from 1 (a cut-back step that
            converged counts as a step; failed attempts do not).
        load: the load parameter t the step ended at (``apply_load(load)`` holds now).
        iterations: Newton iterations of the step's converged solve (with
            ``active_set="fixed-point"`` or augmented Lagrange: summed over the outer
            iterations).
        active: active slave nodes at the end of the step, all pairs, summed over ranks.
        residual: the last residual norm of the converged solve (NaN if none was recorded).
        wall_time: seconds the step's converged solve took (the slowest rank's), without
            the time of failed attempts before it.
        cutbacks: how many failed attempts were halved just before this step converged
            (0 if it converged at once).
        report: the solve's full :class:`~dolfinx_mortar.solvers.SolveReport` (SNES reason,
            residual history, linear iterations, timings per phase).
    """

    step: int
    load: float
    iterations: int
    active: int
    residual: float
    wall_time: float
    cutbacks: int
    report: SolveReport


class ContactOutput:
    """Displacement and contact pressure per step, as VTX (ADIOS2 BP) for ParaView.

    Writes ``directory/displacement.bp`` and ``directory/contact_pressure.bp`` (the
    fields ``contact_pressure``, the recovered pressure users read, and
    ``contact_multiplier``, the nodal multipliers z_j; see
    :meth:`ContactProblem.contact_pressure`), open either in ParaView with the ADIOS2
    VTX reader; with friction also
    ``tangential_traction.bp`` and ``friction_status.bp`` (1 slip, 2 stick). Creating, writing and
    closing are collective.
    """

    def __init__(self, problem: ContactProblem, directory: str | pathlib.Path):
        """Open the VTX writers of ``problem``'s fields (pair 0's pressure) in ``directory``.

        Nothing is written until :meth:`write` (which :func:`solve_load_steps` calls after
        every accepted step when given this output). Collective.

        Args:
            problem: the contact problem, 2D or 3D: its displacement ``problem.u`` is
                written as it is, the pressure and friction fields as P1 scalar Functions
                on the whole mesh (0 away from the slave nodes).
            directory: created (by rank 0) if missing; existing ``.bp`` files in it with
                the same names are overwritten.
        """
        self.problem = problem
        self.directory = pathlib.Path(directory)
        comm = problem.comm
        if comm.rank == 0:
            self.directory.mkdir(parents=True, exist_ok=True)
        comm.Barrier()
        self.pressure = problem.pressure_function()
        self.multiplier = problem.pressure_function(raw=True)
        self._writers = [
            dolfinx.io.VTXWriter(comm, self.directory / "displacement.bp", [problem.u]),
            dolfinx.io.VTXWriter(comm, self.directory / "contact_pressure.bp",
                                 [self.pressure, self.multiplier]),
        ]
        self.friction = None
        if problem.has_friction:
            self.friction = problem.friction_functions()
            self._writers += [
                dolfinx.io.VTXWriter(comm, self.directory / f"{f.name}.bp", [f])
                for f in self.friction]

    def write(self, t: float) -> None:
        """Write the current displacement and pressure at time t. Collective."""
        self.problem.pressure_function(0, self.pressure)
        self.problem.pressure_function(0, self.multiplier, raw=True)
        if self.friction is not None:
            self.problem.friction_functions(0, self.friction)
        for writer in self._writers:
            writer.write(t)

    def close(self) -> None:
        """Close the files. Collective."""
        for writer in self._writers:
            writer.close()


def solve_load_steps(
    problem: ContactProblem,
    apply_load: typing.Callable[[float], None],
    num_steps: int,
    *,
    max_cutbacks: int = 6,
    min_increment: float | None = None,
    output: ContactOutput | None = None,
    on_step: typing.Callable[[StepRecord], None] | None = None,
    start: float = 0.0,
    end: float = 1.0,
    check_penetration: bool = True,
    predictor: str = "none",
) -> list[StepRecord]:
    """Solve for t = start + (end - start) k / num_steps, k = 1 .. num_steps. Collective.

    Args:
        problem: the contact problem; its current state is the start.
        apply_load: sets every load and boundary value for parameter t
            (Constants, Dirichlet Functions); called before each solve.
        num_steps: nominal number of equal steps.
        max_cutbacks: halvings allowed in a row before giving up.
        min_increment: give up when a cut-back would make the increment smaller
            than this (default 1e-6 of the nominal step): a load that inverts
            elements or loses the body otherwise creeps towards the critical t
            in ever smaller steps.
        output: written after every accepted step.
        on_step: called after every accepted step (e.g. to record forces).
        check_penetration: after every accepted step, warn when nodes ended it
            deep inside the other body (:meth:`ContactProblem.check_penetration`).
        predictor: ``none`` (each solve starts from the last converged state) or
            ``extrapolate``: from the third accepted step on, each solve starts from
            the last two converged states extrapolated linearly in t
            (:meth:`ContactProblem.predict`), so that the active set starts near
            the new one when the contact zone moves or grows steadily.

    Raises:
        LoadSteppingError: Newton failed after ``max_cutbacks`` halvings in a row,
            or the increment fell below ``min_increment``; the message names the
            cause (inverted elements, the SNES reason in words, a linear solver
            failure), the last converged t and the t that failed. The problem is
            left in the last converged state.
    """
    if num_steps < 1:
        raise ValueError(f"num_steps must be >= 1, got {num_steps}")
    if predictor not in PREDICTORS:
        raise ValueError(f"predictor must be one of {PREDICTORS}, got {predictor!r}")
    nominal = (end - start) / num_steps
    steps = _Steps(problem, apply_load, start, end, nominal, max_cutbacks,
                   1e-6 * abs(nominal) if min_increment is None else min_increment)
    penetration_check = getattr(problem, "check_penetration", None) if check_penetration else None
    while steps.t < end - 1e-12 * abs(end - start):
        target = steps.next_target()
        saved = problem.save_state()
        apply_load(target)
        if predictor == "extrapolate" and steps.previous is not None:
            before, state = steps.previous
            problem.predict(state, (target - steps.t) / (steps.t - before))
        begin = time.perf_counter()
        report = problem.solve()
        elapsed = problem.comm.allreduce(time.perf_counter() - begin, op=MPI.MAX)
        if not report.converged:
            steps.cut_back(target, saved, report)
            continue
        record = steps.accept(target, saved, report, elapsed)
        if penetration_check is not None:
            penetration_check()
        if output is not None:
            output.write(steps.t)
        if on_step is not None:
            on_step(record)
        steps.grow_back()
    return steps.records


class _Steps:
    """The state of :func:`solve_load_steps`: where t is, the increment, the cut-backs in a
    row, the accepted steps and what a failure message needs."""

    def __init__(self, problem, apply_load, start: float, end: float, nominal: float,
                 max_cutbacks: int, min_increment: float):
        self.problem, self.apply_load = problem, apply_load
        self.start, self.end, self.nominal = start, end, nominal
        self.max_cutbacks, self.min_increment = max_cutbacks, min_increment
        self.t, self.increment, self.cutbacks, self.step = start, nominal, 0, 0
        self.records: list[StepRecord] = []
        self.inverting: tuple[float, object] | None = None
        """(t, Inversion) of the last attempt that inverted elements."""
        self.previous: tuple[float, dict] | None = None
        """(t, state) of the accepted state before t."""

    def next_target(self) -> float:
        """The next t: one increment on, but never over a point of the nominal grid, so
        that cut-back steps grow back onto it."""
        start, nominal = self.start, self.nominal
        next_grid = start + math.ceil((self.t - start) / nominal * (1.0 + 1e-12) + 1e-9) * nominal
        return min(self.end, self.t + self.increment, next_grid)

    def cut_back(self, target: float, saved: dict, report: SolveReport) -> None:
        """Undo the failed step to ``target`` and halve the increment, or raise
        :class:`LoadSteppingError` when no cut-back is left."""
        problem, t = self.problem, self.t
        problem.restore_state(saved)
        cause = report.cause()
        if report.inversion.count:
            self.inverting = (target, report.inversion)
        if self.cutbacks + 1 > self.max_cutbacks or 0.5 * self.increment < self.min_increment:
            self.apply_load(t)
            limit = (
                f"after {self.cutbacks} cut-backs"
                if self.cutbacks + 1 > self.max_cutbacks
                else f"with the increment down to {self.increment:.3g}: half of it would be "
                f"below min_increment = {self.min_increment:.3g}"
            )
            t_text, target_text = _distinct(t, target)
            raise LoadSteppingError(
                f"no convergence from t = {t_text} to {target_text} {limit} "
                f"(last SNES reason {cause.removeprefix('SNES reason ')}). The last "
                f"converged step ended at t = {t_text}; the step to t = {target_text} "
                f"failed after {report.iterations} Newton iterations."
                + _diagnosis(problem, report, self.inverting, t - abs(self.nominal)),
                last_converged=t,
                failed=target,
                report=report,
            )
        self.cutbacks += 1
        self.increment *= 0.5
        _log(
            problem,
            f"step {self.step + 1}: t = {target:.6g} failed: {cause}; "
            f"cut back to increment {self.increment:.4g}",
        )

    def accept(self, target: float, saved: dict, report: SolveReport,
               elapsed: float) -> StepRecord:
        """Move t to ``target``; the step's record, logged."""
        self.step += 1
        if self.step > 1:  # saved is a converged state (the first step starts from a guess)
            self.previous = (self.t, saved)
        self.t = target
        record = StepRecord(
            step=self.step,
            load=self.t,
            iterations=report.iterations,
            active=report.active,
            residual=report.residuals[-1] if report.residuals else float("nan"),
            wall_time=elapsed,
            cutbacks=self.cutbacks,
            report=report,
        )
        self.records.append(record)
        _log(
            self.problem,
            f"step {self.step:4d}  t = {self.t:.6g}  newton {report.iterations:2d}  "
            f"active {report.active:5d}  residual {record.residual:.3e}  "
            f"time {elapsed:.3f} s",
        )
        return record

    def grow_back(self) -> None:
        """After a step that converged at once, double a cut-back increment (up to the
        nominal one); reset the cut-backs in a row."""
        if self.increment < self.nominal and not self.cutbacks:
            self.increment = min(2.0 * self.increment, self.nominal)
        self.cutbacks = 0


def _distinct(a: float, b: float) -> tuple[str, str]:
    """a and b with 6 significant digits, or as many more as it takes to tell them apart."""
    for digits in range(6, 18):
        first, second = f"{a:.{digits}g}", f"{b:.{digits}g}"
        if first != second or a == b:
            break
    return first, second


def _diagnosis(problem, report: SolveReport, inverting, since: float) -> str:
    """What the failure points to, for the causes we can tell apart (collective)."""
    text = ""
    recent = inverting is not None and inverting[0] >= since
    if report.inversion.count:
        text += " Elements invert before the step can converge."
    elif recent:
        text += (
            f" An earlier attempt, to t = {inverting[0]:.8g}, inverted elements: "
            f"{inverting[1].describe()}."
        )
    compressed = getattr(problem, "most_compressed_cell", None)
    if compressed is not None:
        ratio, where = compressed()
        if where is not None and ratio < 0.1:
            location = ", ".join(f"{c:.4g}" for c in where)
            text += (
                f" At the last converged state the most compressed element has det F = "
                f"{ratio:.3g} (reference point ({location})): it is about to be inverted."
            )
            recent = True
    if report.inversion.count or recent:
        text += (
            " The load or prescribed displacement is too large for the mesh and material "
            "there: refine the mesh, use a material that resists compression, or check that "
            "no body is free to move as a rigid body."
        )
    if report.linear_solver_failure and getattr(problem, "linear_solver", "") != "iterative":
        text += (
            " The linear solver failed: a singular system usually means a body whose rigid-body "
            "motion no boundary condition or active contact holds."
        )
    for warning in getattr(problem, "setup_warnings", []):
        text += f" Warned when the problem was built: {warning}"
    return text


def _log(problem: ContactProblem, message: str) -> None:
    if problem.comm.rank == 0:
        logger.info(message)


def configure_logging(comm: MPI.Intracomm = MPI.COMM_WORLD, level: int = logging.INFO) -> None:
    """Show dolfinx_mortar's progress lines on rank 0 (for demos and scripts)."""
    if comm.rank == 0 and not logger.handlers:
        handler = logging.StreamHandler()
        handler.setFormatter(logging.Formatter("%(message)s"))
        logger.addHandler(handler)
        logger.setLevel(level)
