"""What every part of the benchmarks shares: paths, section names, goals, number formats."""

from __future__ import annotations

import json
import math
import pathlib
import sys

import numpy as np
from mpi4py import MPI

REPOSITORY = pathlib.Path(__file__).resolve().parents[2]
DEMOS = REPOSITORY / "demos"
RUN = REPOSITORY / "benchmarks" / "run.py"
"""The suite's command line, which the parallel and scaling runs start under mpirun."""
DEFAULT_OUTPUT = REPOSITORY / "benchmarks" / "results"
SECTIONS = ("work-precision", "cost", "skip")
SECTIONS_3D = ("patch3d", "hertz3d", "scaling3d")
PHASES = ("bulk assembly", "contact search", "mortar integration", "linear solve", "total")
GOALS = {
    "contact_share": 0.15,
    "far_apart_overhead": 0.05,
    "semismooth_iterations_per_step": 8,
    "mortar_slope": 1.1,
}


def log(message: str) -> None:
    if MPI.COMM_WORLD.rank == 0:
        print(message, file=sys.stderr, flush=True)


def fmt(value, digits: int = 3) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    if isinstance(value, int | np.integer):
        return str(value)
    if value == 0:
        return "0"
    if abs(value) >= 1e4 or abs(value) < 1e-3:
        return f"{value:.{digits - 1}e}"
    return f"{value:.{digits}g}"


def ms(seconds: float) -> str:
    return f"{1e3 * seconds:.0f}" if seconds >= 0.1 else f"{1e3 * seconds:.1f}"


def loglog_slope(x, y) -> float | None:
    """Least-squares slope of log y against log x over the positive pairs (None if < 2)."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    keep = (x > 0) & (y > 0)
    if keep.sum() < 2:
        return None
    return float(np.polyfit(np.log(x[keep]), np.log(y[keep]), 1)[0])


def write_json(path: pathlib.Path, data: dict) -> None:
    path.write_text(json.dumps(data, indent=1, default=lambda o: o.tolist()
                               if isinstance(o, np.ndarray) else str(o)) + "\n")

