"""Mesh tying of two non-matching meshes with the mortar matrices D and M.

Linear elasticity on the unit square, split at y = 1/2 into two separately
meshed blocks whose interface nodes do not match. The blocks are tied with
mortar multipliers (dolfinx_mortar.MeshTying) and the solution is compared
with a manufactured one:

* ``--solution linear``: a linear displacement field and no body force, which
  P1 elements reproduce exactly; the tied solution must too (patch test).
* ``--solution smooth``: a smooth field with the matching body force; the
  errors must fall like h^2 in L2 and h in H1 over the refinements.

Outputs (``--output DIR``): the errors against h (PNG and CSV, one row per
mesh) and the tied displacement of the finest mesh for ParaView
(paraview/displacement.bp); ``--json FILE`` writes the summary.

Run:  mpirun -n 2 python3 demos/mesh_tying.py --refinements 5 --json tying.json --output out
"""

from __future__ import annotations

import csv
import pathlib
import time

import dolfinx
import dolfinx.fem.petsc
import dolfinx.io
import numpy as np
import ufl
from mpi4py import MPI

from dolfinx_mortar import cli, compat, meshes
from dolfinx_mortar.tying import MeshTying

E, NU = 1.0, 0.3
MU = E / (2 * (1 + NU))
LMBDA = E * NU / ((1 + NU) * (1 - 2 * NU))


def exact_displacement(x, solution: str):
    if solution == "linear":
        return ufl.as_vector([0.1 + 0.2 * x[0] - 0.3 * x[1], -0.05 + 0.15 * x[0] + 0.25 * x[1]])
    return ufl.as_vector(
        [
            ufl.sin(ufl.pi * x[0]) * ufl.cos(ufl.pi * x[1]),
            x[0] * x[1] * ufl.exp(x[0]) + 0.5 * ufl.sin(2.0 * x[1]),
        ]
    )


def sigma(v):
    eps = ufl.sym(ufl.grad(v))
    return 2.0 * MU * eps + LMBDA * ufl.tr(eps) * ufl.Identity(2)


def solve(
    refinement: int,
    ratio: tuple[int, int],
    solution: str,
    basis: str,
    cell_type: str,
    comm: MPI.Intracomm,
    paraview: pathlib.Path | None = None,
) -> dict:
    """Solve the tied problem on one mesh; its errors, and the solution in ``paraview``
    (a VTX .bp file) if given."""
    tagged = meshes.tied_blocks(ratio=ratio, refinement=refinement, cell_type=cell_type, comm=comm)
    mesh = tagged.mesh
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    x = ufl.SpatialCoordinate(mesh)
    u_exact = exact_displacement(x, solution)
    body_force = -ufl.div(sigma(u_exact))
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    a = ufl.inner(sigma(u), ufl.sym(ufl.grad(v))) * ufl.dx
    L = ufl.inner(body_force, v) * ufl.dx

    boundary = tagged.facet_tags.find(tagged.markers["boundary"])
    u_boundary = dolfinx.fem.Function(V)
    u_boundary.interpolate(dolfinx.fem.Expression(u_exact, compat.interpolation_points(V)))
    bc = dolfinx.fem.dirichletbc(u_boundary, dolfinx.fem.locate_dofs_topological(V, 1, boundary))

    uh = dolfinx.fem.Function(V, name="displacement")
    start = time.perf_counter()
    tying = MeshTying(
        a,
        L,
        uh,
        [bc],
        tagged.facet_tags,
        tagged.markers["contact_slave"],
        tagged.markers["contact_master"],
        basis=basis,
    )
    tying.solve()
    wall = comm.allreduce(time.perf_counter() - start, op=MPI.MAX)
    if paraview is not None:
        if comm.rank == 0:
            paraview.parent.mkdir(parents=True, exist_ok=True)
        comm.Barrier()
        writer = dolfinx.io.VTXWriter(comm, paraview, [uh])
        writer.write(0.0)
        writer.close()

    def integrate(expression) -> float:
        return comm.allreduce(dolfinx.fem.assemble_scalar(dolfinx.fem.form(expression)), op=MPI.SUM)

    error = uh - u_exact
    l2 = np.sqrt(integrate(ufl.inner(error, error) * ufl.dx))
    h1 = np.sqrt(integrate(ufl.inner(ufl.grad(error), ufl.grad(error)) * ufl.dx))
    norm_l2 = np.sqrt(integrate(ufl.inner(u_exact, u_exact) * ufl.dx))
    norm_h1 = np.sqrt(integrate(ufl.inner(ufl.grad(u_exact), ufl.grad(u_exact)) * ufl.dx))
    h = 0.5 / (ratio[0] * 2**refinement)
    return {
        "refinement": refinement,
        "h": h,
        "num_dofs": V.dofmap.index_map.size_global * 2,
        "num_multipliers": tying.interface.num_global_multipliers,
        "l2_error": l2,
        "h1_error": h1,
        "l2_error_rel": l2 / norm_l2,
        "h1_error_rel": h1 / norm_h1,
        "wall_time_s": wall,
    }


def fitted_rate(h, error) -> float:
    """Least-squares slope of log(error) against log(h)."""
    return float(np.polyfit(np.log(h), np.log(error), 1)[0])


def main(argv=None, comm: MPI.Intracomm = MPI.COMM_WORLD) -> dict:
    parser = cli.parser(__doc__)
    parser.add_argument(
        "--refinements", type=int, default=5, help="number of meshes (each halves h)"
    )
    parser.add_argument(
        "--ratio", default="3:4", help="interface elements lower:upper, e.g. 3:4 or 1:7"
    )
    parser.add_argument(
        "--solution",
        choices=("smooth", "linear"),
        default="smooth",
        help="manufactured solution (linear: P1 reproduces it exactly)",
    )
    parser.add_argument(
        "--basis", choices=("standard", "dual"), default="standard", help="multiplier basis"
    )
    parser.add_argument(
        "--cell-type", choices=("triangle", "quadrilateral"), default="triangle", help="cells"
    )
    args = parser.parse_args(argv)
    if args.refinements < 1:
        parser.error(f"--refinements must be at least 1, got {args.refinements}")
    ratio = tuple(int(n) for n in args.ratio.split(":"))
    runs = []
    for refinement in range(args.refinements):
        last = refinement == args.refinements - 1
        paraview = args.output / "paraview" / "displacement.bp" if args.output and last else None
        run = solve(
            refinement, ratio, args.solution, args.basis, args.cell_type, comm, paraview=paraview
        )
        runs.append(run)
        if comm.rank == 0:
            print(
                f"refinement {refinement}: dofs {run['num_dofs']:7d}  L2 {run['l2_error']:.3e}  "
                f"H1 {run['h1_error']:.3e}  {run['wall_time_s']:.2f} s",
                flush=True,
            )
    h = np.array([r["h"] for r in runs])
    summary = {
        "solution": args.solution,
        "ratio": list(ratio),
        "basis": args.basis,
        "cell_type": args.cell_type,
        "num_ranks": comm.size,
        "runs": runs,
        "max_l2_error": max(r["l2_error"] for r in runs),
        "max_h1_error": max(r["h1_error"] for r in runs),
    }
    if len(runs) >= 2:
        summary["l2_rate"] = fitted_rate(h, [r["l2_error"] for r in runs])
        summary["h1_rate"] = fitted_rate(h, [r["h1_error"] for r in runs])
        finest = slice(max(0, len(runs) - 4), len(runs))
        summary["l2_rate_finest"] = fitted_rate(h[finest], [r["l2_error"] for r in runs][finest])
        summary["h1_rate_finest"] = fitted_rate(h[finest], [r["h1_error"] for r in runs][finest])
    if comm.rank == 0:
        if "l2_rate" in summary:
            print(
                f"fitted rates: L2 {summary['l2_rate']:.3f}, H1 {summary['h1_rate']:.3f} "
                f"(finest 4 meshes: L2 {summary['l2_rate_finest']:.3f}, "
                f"H1 {summary['h1_rate_finest']:.3f})"
            )
        cli.write_summary(args.json, summary)
        if args.output:
            write_csv(args.output / "mesh_tying_errors.csv", runs)
            if len(runs) >= 2:
                plot(args.output / "mesh_tying_convergence.png", h, runs, summary, args)
            print(f"results written to {args.output}/", flush=True)
    return summary


def write_csv(path: pathlib.Path, runs: list[dict]) -> None:
    """One row per mesh: h, sizes and errors."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as stream:
        writer = csv.DictWriter(stream, fieldnames=list(runs[0]))
        writer.writeheader()
        writer.writerows(runs)


def plot(path: pathlib.Path, h, runs: list[dict], summary: dict, args) -> None:
    """L2 and H1 errors against h, log-log, with the fitted rates."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5, 4))
    ax.loglog(h, [r["l2_error"] for r in runs], "o-", label=f"L2 (rate {summary['l2_rate']:.2f})")
    ax.loglog(h, [r["h1_error"] for r in runs], "s-", label=f"H1 (rate {summary['h1_rate']:.2f})")
    ax.set_xlabel("h (lower block)")
    ax.set_ylabel("error")
    ax.set_title(f"mortar mesh tying, ratio {args.ratio}, {args.basis} basis")
    ax.legend()
    ax.grid(True, which="both", alpha=0.3)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120, bbox_inches="tight")
    plt.close(fig)


if __name__ == "__main__":
    main()
