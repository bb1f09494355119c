"""What a self-contact surface far from itself adds to a solve (issue 29).

The crushed ring of ``demos/self_contact.py --case crush`` to a plate travel of 1.0 (the
inner walls 0.6 apart at the end, never touching), with the inner self-contact pair and
without it (``--no-self-contact``), interleaved in one process: per run, the wall time
and this process's CPU time spent in ``ContactProblem.solve`` summed over the load steps
(CPU time: what a loaded machine, whose other jobs take the cores away, changes least).
Prints each run, the medians and the ratios with/without. Rank 0 reports; under MPI the
CPU time is the largest over the ranks.

    tools/run python3 benchmarks/self_contact_far.py --repeats 5
    tools/run python3 benchmarks/self_contact_far.py --repeats 5 --refinement 1
"""

from __future__ import annotations

import argparse
import pathlib
import statistics
import sys
import time

from mpi4py import MPI

DEMOS = pathlib.Path(__file__).resolve().parent.parent / "demos"
sys.path.insert(0, str(DEMOS))
import self_contact as demo  # noqa: E402

from dolfinx_mortar import ContactProblem  # noqa: E402


def timed_solves(arguments: list[str], comm) -> tuple[float, float, int]:
    """(wall seconds, CPU seconds, Newton iterations) of the solves of one crush run."""
    spent = {"wall": 0.0, "cpu": 0.0}
    solve = ContactProblem.solve

    def measured(self, *args, **kwargs):
        wall, cpu = time.perf_counter(), time.process_time()
        try:
            return solve(self, *args, **kwargs)
        finally:
            spent["wall"] += time.perf_counter() - wall
            spent["cpu"] += time.process_time() - cpu

    ContactProblem.solve = measured
    try:
        summary = demo.main(arguments, comm=comm)
    finally:
        ContactProblem.solve = solve
    return (comm.allreduce(spent["wall"], op=MPI.MAX), comm.allreduce(spent["cpu"], op=MPI.MAX),
            sum(summary["newton_iterations"]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--refinement", type=int, default=0)
    parser.add_argument("--steps", type=int, default=40)
    parser.add_argument("--depth", type=float, default=1.0)
    args = parser.parse_args()
    comm = MPI.COMM_WORLD
    base = ["--case", "crush", "--depth", str(args.depth), "--steps", str(args.steps),
            "--refinement", str(args.refinement)]
    runs = {"with": [], "without": []}
    timed_solves(base + ["--no-self-contact"], comm)  # warm-up: imports, compiled forms
    for repeat in range(args.repeats):
        for name, extra in (("with", []), ("without", ["--no-self-contact"])):
            wall, cpu, iterations = timed_solves(base + extra, comm)
            runs[name].append((wall, cpu))
            if comm.rank == 0:
                print(f"run {repeat + 1} {name:8s}: solve wall {wall:.3f} s, CPU {cpu:.3f} s, "
                      f"{iterations} Newton iterations", flush=True)
    if comm.rank == 0:
        median = {name: [statistics.median(r[i] for r in values) for i in range(2)]
                  for name, values in runs.items()}
        for i, what in enumerate(("wall", "CPU")):
            ratio = median["with"][i] / median["without"][i] - 1.0
            print(f"median solve {what}: with {median['with'][i]:.3f} s, without "
                  f"{median['without'][i]:.3f} s, {100 * ratio:+.1f} %", flush=True)


if __name__ == "__main__":
    main()
