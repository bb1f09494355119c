"""Friction in the iterative path (issue 26, item 1): one run of demos/hertz_sphere.py.

Runs the demo once in this process (one case per process, so that the peak memory is
the case's own) and prints one JSON line: Newton iterations, outer (fgmres) and inner
(GMRES + BoomerAMG) Krylov iterations per Newton iteration, the solve time per Newton
iteration, and the peak resident memory of the largest rank:

    tools/run mpirun -n 2 python3 benchmarks/friction_iterative.py --mu 0.3 \\
        --linear-solver iterative -- --refinement 1 --elements-per-radius 6

Everything after ``--`` goes to the demo. Run the cases one after another (direct and
iterative with friction, the frictionless iterative run of the same mesh) and compare
them within one session of the machine.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import resource
import sys

from mpi4py import MPI

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from dolfinx_mortar import condensation  # noqa: E402

from suite.runner import demo  # noqa: E402


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--mu", type=float, default=None, help="Coulomb mu (None: frictionless)")
    parser.add_argument("--linear-solver", choices=("direct", "iterative"), default="iterative")
    parser.add_argument("demo_args", nargs="*", help="arguments of demos/hertz_sphere.py")
    args = parser.parse_args(argv)
    comm = MPI.COMM_WORLD
    inner = []
    apply = condensation.CondensedPreconditioner.apply

    def counted(self, pc, x, y):
        apply(self, pc, x, y)
        inner.append(self.inner_iterations[-1])

    condensation.CondensedPreconditioner.apply = counted
    argv = list(args.demo_args) + ["--linear-solver", args.linear_solver]
    if args.mu is not None:
        argv += ["--mu", str(args.mu)]
    summary = demo("hertz_sphere").main(argv, comm=comm)
    newton = sum(summary["newton_iterations"])
    outer = sum(summary["krylov_iterations"])
    memory = comm.allreduce(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, op=MPI.MAX)
    result = {
        "mu": args.mu,
        "linear_solver": summary["linear_solver"],
        "num_dofs": summary["num_dofs"],
        "num_ranks": comm.size,
        "newton_iterations": summary["newton_iterations"],
        "cutbacks": summary["cutbacks"],
        "outer_per_newton": outer / newton,
        "inner_per_newton": sum(inner) / newton if inner else 0.0,
        "inner_per_application": sum(inner) / len(inner) if inner else 0.0,
        "solve_time_s": summary["timings"]["total"],
        "time_per_newton_s": summary["timings"]["total"] / newton,
        "linear_solve_per_newton_s": summary["timings"]["linear solve"] / newton,
        "peak_memory_per_rank_mb": memory / 1024.0,
        "p_max": summary["p_max"],
        "total_force": summary["total_force"],
    }
    if comm.rank == 0:
        print(json.dumps(result), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
