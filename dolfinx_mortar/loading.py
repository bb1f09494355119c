"""Load stepping with cut-back, one log line per step, and output for ParaView.

:func:`solve_load_steps` drives a :class:`~dolfinx_mortar.problem.ContactProblem`
through a load (or displacement) parameter t from 0 to 1. A step whose Newton
solve fails, or whose iterate inverts an element, is undone and retried with
half the increment; after ``max_cutbacks`` halvings in a row it raises
:class:`LoadSteppingError`. After each step that converged without a cut-back
the increment doubles again, up to the nominal one, and no step jumps over a
point of the nominal grid (so the steps land on t = k (end - start) / num_steps
again, where demos read their results). The contact search is redone inside
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

from .problem import ContactProblem, SolveReport

logger = logging.getLogger("dolfinx_mortar")


class LoadSteppingError(RuntimeError):
    """Newton failed even after the last allowed cut-back."""


@dataclasses.dataclass
class StepRecord:
    """One accepted load step."""

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

    Writes ``directory/displacement.bp`` and ``directory/contact_pressure.bp``
    (open either in ParaView with the ADIOS2 VTX reader).
    """

    def __init__(self, problem: ContactProblem, directory: str | pathlib.Path):
        self.problem = problem
        self.directory = pathlib.Path(directory)
        comm = problem.comm
        if comm.rank == 0:
            self.directory.mkdir(parents=True, exist_ok=True)
        comm.Barrier()
        self.pressure = problem.pressure_function()
        self._writers = [
            dolfinx.io.VTXWriter(comm, self.directory / "displacement.bp", [problem.u]),
            dolfinx.io.VTXWriter(comm, self.directory / "contact_pressure.bp", [self.pressure]),
        ]

    def write(self, t: float) -> None:
        self.problem.pressure_function(0, self.pressure)
        for writer in self._writers:
            writer.write(t)

    def close(self) -> None:
        for writer in self._writers:
            writer.close()


def solve_load_steps(
    problem: ContactProblem,
    apply_load: typing.Callable[[float], None],
    num_steps: int,
    *,
    max_cutbacks: int = 6,
    output: ContactOutput | None = None,
    on_step: typing.Callable[[StepRecord], None] | None = None,
    start: float = 0.0,
    end: float = 1.0,
) -> list[StepRecord]:
    """Solve for t = start + (end - start) k / num_steps, k = 1 .. num_steps.

    Args:
        problem: the contact problem; its current state is the start.
        apply_load: sets every load and boundary value for parameter t
            (Constants, Dirichlet Functions); called before each solve.
        num_steps: nominal number of equal steps.
        max_cutbacks: halvings allowed in a row before giving up.
        output: written after every accepted step.
        on_step: called after every accepted step (e.g. to record forces).

    Raises:
        LoadSteppingError: Newton failed after ``max_cutbacks`` halvings.
    """
    if num_steps < 1:
        raise ValueError(f"num_steps must be >= 1, got {num_steps}")
    records: list[StepRecord] = []
    nominal = (end - start) / num_steps
    increment = nominal
    t = start
    cutbacks = 0
    step = 0
    while t < end - 1e-12 * abs(end - start):
        # never step over a point of the nominal grid, so cut-back steps grow back onto it
        next_grid = start + math.ceil((t - start) / nominal * (1.0 + 1e-12) + 1e-9) * nominal
        target = min(end, t + increment, next_grid)
        saved = problem.save_state()
        apply_load(target)
        begin = time.perf_counter()
        report = problem.solve()
        elapsed = problem.comm.allreduce(time.perf_counter() - begin, op=MPI.MAX)
        if not report.converged:
            problem.restore_state(saved)
            cutbacks += 1
            if cutbacks > max_cutbacks:
                apply_load(t)
                raise LoadSteppingError(
                    f"no convergence from t = {t:.6g} to {target:.6g} after {max_cutbacks} "
                    f"cut-backs (last SNES reason {report.reason}, {report.iterations} iterations)"
                )
            increment *= 0.5
            _log(
                problem,
                f"step {step + 1}: t = {target:.6g} failed (SNES reason {report.reason}); "
                f"cut back to increment {increment:.4g}",
            )
            continue
        step += 1
        t = target
        record = StepRecord(
            step=step,
            load=t,
            iterations=report.iterations,
            active=report.active,
            residual=report.residuals[-1] if report.residuals else float("nan"),
            wall_time=elapsed,
            cutbacks=cutbacks,
            report=report,
        )
        records.append(record)
        _log(
            problem,
            f"step {step:4d}  t = {t:.6g}  newton {report.iterations:2d}  "
            f"active {report.active:5d}  residual {record.residual:.3e}  "
            f"time {elapsed:.3f} s",
        )
        if output is not None:
            output.write(t)
        if on_step is not None:
            on_step(record)
        if increment < nominal and not cutbacks:
            increment = min(2.0 * increment, nominal)
        cutbacks = 0
    return records


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
