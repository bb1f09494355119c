"""The iterative linear solver against MUMPS on the 3D Hertz sphere: same answer, cost.

Runs ``demos/hertz_sphere.py`` in this process with ``--linear-solver direct``
and ``iterative`` on each mesh (``--meshes N0:REF ...``, the demo's
``--elements-per-radius`` and ``--refinement``) and reports, as a markdown
table (and JSON with ``--json``): the largest nodal pressure difference
relative to the largest pressure, the Newton iterations of each, the linear
solve time per Newton iteration, the outer FGMRES iterations per linear solve
and the inner (condensed GMRES + BoomerAMG) iterations per application:

    tools/run python3 benchmarks/iterative_agreement.py --meshes 4:0 4:1
    tools/run mpirun -n 2 python3 benchmarks/iterative_agreement.py --meshes 4:1
"""

from __future__ import annotations

import argparse
import json
import pathlib

import numpy as np
from mpi4py import MPI

from dolfinx_mortar import condensation, problem

from suite.runner import demo


def run(module, n0: int, refinement: int, solver: str) -> dict:
    """One demo run; the nodal pressures (sorted by slave node position) and inner steps."""
    captured, inner = {}, []
    gathered = problem.ContactProblem.gathered_pressure
    destroy = condensation.CondensedPreconditioner.destroy

    def capture(self, *args, **kwargs):
        captured["result"] = gathered(self, *args, **kwargs)
        return captured["result"]

    def keep_inner(self, *args, **kwargs):
        inner.extend(self.inner_iterations)
        return destroy(self, *args, **kwargs)

    problem.ContactProblem.gathered_pressure = capture
    condensation.CondensedPreconditioner.destroy = keep_inner
    try:
        summary = module.main(["--elements-per-radius", str(n0), "--refinement", str(refinement),
                               "--linear-solver", solver])
    finally:
        problem.ContactProblem.gathered_pressure = gathered
        condensation.CondensedPreconditioner.destroy = destroy
    coordinates, pressure = captured["result"]
    order = np.lexsort(np.round(coordinates, 9).T[::-1])
    newton = sum(summary["newton_iterations"])
    return {"dofs": summary["num_dofs"], "pressure": pressure[order],
            "newton": summary["newton_iterations"], "krylov": summary["krylov_iterations"],
            "linear_per_newton_s": summary["timings"]["linear solve"] / newton,
            "inner": inner}


def main(argv=None) -> list[dict]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--meshes", nargs="+", default=["4:0", "4:1"])
    parser.add_argument("--json", type=pathlib.Path)
    args = parser.parse_args(argv)
    comm = MPI.COMM_WORLD
    module = demo("hertz_sphere")
    rows = []
    for mesh in args.meshes:
        n0, refinement = (int(v) for v in mesh.split(":"))
        direct = run(module, n0, refinement, "direct")
        iterative = run(module, n0, refinement, "iterative")
        scale = np.abs(direct["pressure"]).max()
        inner = np.array(iterative["inner"])
        rows.append({
            "mesh": mesh, "dofs": direct["dofs"], "ranks": comm.size,
            "pressure_difference_rel": float(
                np.abs(iterative["pressure"] - direct["pressure"]).max() / scale),
            "newton_direct": direct["newton"], "newton_iterative": iterative["newton"],
            "krylov_per_solve": sum(iterative["krylov"]) / sum(iterative["newton"]),
            "inner_mean": float(inner.mean()) if inner.size else 0.0,
            "inner_max": int(inner.max()) if inner.size else 0,
            "linear_per_newton_direct_s": direct["linear_per_newton_s"],
            "linear_per_newton_iterative_s": iterative["linear_per_newton_s"],
        })
    if comm.rank == 0:
        print("| n0:ref | dofs | ranks | max pressure difference / p_max | Newton direct, "
              "iterative | FGMRES per solve | inner GMRES mean / max | linear solve per "
              "Newton iteration [s] direct, iterative |")
        print("|---|---|---|---|---|---|---|---|")
        for r in rows:
            print(f"| {r['mesh']} | {r['dofs']} | {r['ranks']} | "
                  f"{r['pressure_difference_rel']:.1e} | {r['newton_direct']}, "
                  f"{r['newton_iterative']} | {r['krylov_per_solve']:.1f} | "
                  f"{r['inner_mean']:.1f} / {r['inner_max']} | "
                  f"{r['linear_per_newton_direct_s']:.2f}, "
                  f"{r['linear_per_newton_iterative_s']:.2f} |")
        if args.json:
            args.json.write_text(json.dumps(rows, indent=1))
    return rows


if __name__ == "__main__":
    main()
