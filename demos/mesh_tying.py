"""Mesh tying of two non-matching meshes with the mortar matrices D and M.

Linear elasticity on the unit square, split at y = 1/2 into two separately
meshed blocks whose interface nodes do not match (``--dim 3``: the unit cube,
split at z = 1/2 into two boxes of tetrahedra or hexahedra, ``--cell-type``).
The blocks are tied with mortar multipliers (dolfinx_mortar.MeshTying) and
the solution is compared with a manufactured one:

* ``--solution linear``: a linear displacement field and no body force, which
  P1 elements reproduce exactly; the tied solution must too (patch test).
* ``--solution smooth``: a smooth field with the matching body force; the
  errors must fall like h^2 in L2 and h in H1 over the refinements.

``--ratio`` gives the elements per unit length along the interface of the
lower and upper block at refinement 0; each refinement doubles them. In 3D h
is the lower block's edge length, 1 / n_lower.

Outputs (``--output DIR``): the errors against h (PNG and CSV, one row per
mesh) and the tied displacement of the finest mesh for ParaView
(paraview/displacement.bp); ``--json FILE`` writes the summary.

Run:  mpirun -n 2 python3 demos/mesh_tying.py --refinements 5 --json tying.json --output out
      mpirun -n 2 python3 demos/mesh_tying.py --dim 3 --cell-type hexahedron --json tying3d.json
"""

from __future__ import annotations

import csv
import pathlib
import sys
import time

import dolfinx
import dolfinx.fem.petsc
import dolfinx.io
import numpy as np
import ufl
from mpi4py import MPI

from dolfinx_mortar import MeshTying, compat, merge_meshes, meshes

DEMOS = pathlib.Path(__file__).resolve().parent
if str(DEMOS) not in sys.path:  # loaded from its path (tests, benchmarks): find demos/cli.py
    sys.path.insert(0, str(DEMOS))
import cli  # noqa: E402

E, NU = 1.0, 0.3
MU = E / (2 * (1 + NU))
LMBDA = E * NU / ((1 + NU) * (1 - 2 * NU))
CELL_TYPES = {2: ("triangle", "quadrilateral"), 3: ("tetrahedron", "hexahedron")}
# 3D: the estimated degrees (18 to 21) would dominate the run time; 8 gives the errors of
# degree 16 to 1e-12 relative on the 4764-dof meshes
QUADRATURE_DEGREE_3D = 8


def exact_displacement(x, solution: str, dim: int = 2):
    if dim == 3:
        if solution == "linear":
            return ufl.as_vector(
                [
                    0.1 + 0.2 * x[0] - 0.3 * x[1] + 0.1 * x[2],
                    0.05 * x[0] + 0.2 * x[2],
                    -0.1 + 0.3 * x[1] - 0.2 * x[2],
                ]
            )
        return ufl.as_vector(
            [
                ufl.exp(x[0] + 0.5 * x[2]) * ufl.sin(x[1]),
                ufl.sin(1.5 * x[0]) * ufl.cos(x[2]),
                ufl.cos(x[0] * x[1]) + ufl.exp(-x[2]),
            ]
        )
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
    return 2.0 * MU * eps + LMBDA * ufl.tr(eps) * ufl.Identity(len(v))


def tied_boxes(ratio: tuple[int, int], refinement: int, cell_type: str, comm: MPI.Intracomm):
    """The unit cube cut at z = 0.5 into two separately meshed boxes, merged as for
    tests/test_tying3d.py: n = ratio * 2**refinement elements along x and y,
    max(1, round(n/2)) along z. The mesh, its outer boundary facets, and the slave
    (upper bottom) and master (lower top) markers."""
    cell = getattr(dolfinx.mesh.CellType, cell_type)

    def box(z0: float, n: int):
        return dolfinx.mesh.create_box(
            comm, [[0, 0, z0], [1, 1, z0 + 0.5]], [n, n, max(1, round(0.5 * n))], cell
        )

    n_lower, n_upper = (n * 2**refinement for n in ratio)
    tagged = merge_meshes(
        {
            "lower": (box(0.0, n_lower), {"top": lambda x: np.isclose(x[2], 0.5)}),
            "upper": (box(0.5, n_upper), {"bottom": lambda x: np.isclose(x[2], 0.5)}),
        },
        comm,
    )
    mesh = tagged.mesh
    mesh.topology.create_connectivity(2, 3)
    outer = dolfinx.mesh.exterior_facet_indices(mesh.topology)
    outer = outer[~np.isclose(dolfinx.mesh.compute_midpoints(mesh, 2, outer)[:, 2], 0.5)]
    return tagged, outer, tagged.markers["upper_bottom"], tagged.markers["lower_top"]


def solve(
    refinement: int,
    ratio: tuple[int, int],
    solution: str,
    basis: str,
    cell_type: str,
    comm: MPI.Intracomm,
    paraview: pathlib.Path | None = None,
    dim: int = 2,
) -> dict:
    """Solve the tied problem on one mesh; its errors, and the solution in ``paraview``
    (a VTX .bp file) if given."""
    if dim == 3:
        tagged, boundary, slave, master = tied_boxes(ratio, refinement, cell_type, comm)
        h = 1.0 / (ratio[0] * 2**refinement)
    else:
        tagged = meshes.tied_blocks(
            ratio=ratio, refinement=refinement, cell_type=cell_type, comm=comm
        )
        boundary = tagged.facet_tags.find(tagged.markers["boundary"])
        slave, master = tagged.markers["contact_slave"], tagged.markers["contact_master"]
        h = 0.5 / (ratio[0] * 2**refinement)
    mesh = tagged.mesh
    metadata = {"quadrature_degree": QUADRATURE_DEGREE_3D} if dim == 3 else {}
    dx = ufl.Measure("dx", domain=mesh, metadata=metadata)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (dim,)))
    x = ufl.SpatialCoordinate(mesh)
    u_exact = exact_displacement(x, solution, dim)
    body_force = -ufl.div(sigma(u_exact))
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    a = ufl.inner(sigma(u), ufl.sym(ufl.grad(v))) * ufl.dx
    L = ufl.inner(body_force, v) * dx

    u_boundary = dolfinx.fem.Function(V)
    u_boundary.interpolate(dolfinx.fem.Expression(u_exact, compat.interpolation_points(V)))
    dofs = dolfinx.fem.locate_dofs_topological(V, dim - 1, boundary)
    bc = dolfinx.fem.dirichletbc(u_boundary, dofs)

    uh = dolfinx.fem.Function(V, name="displacement")
    start = time.perf_counter()
    tying = MeshTying(
        a,
        L,
        uh,
        [bc],
        tagged.facet_tags,
        slave,
        master,
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
    l2 = np.sqrt(integrate(ufl.inner(error, error) * dx))
    h1 = np.sqrt(integrate(ufl.inner(ufl.grad(error), ufl.grad(error)) * dx))
    norm_l2 = np.sqrt(integrate(ufl.inner(u_exact, u_exact) * dx))
    norm_h1 = np.sqrt(integrate(ufl.inner(ufl.grad(u_exact), ufl.grad(u_exact)) * dx))
    return {
        "refinement": refinement,
        "h": h,
        "num_dofs": V.dofmap.index_map.size_global * dim,
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
    parser.add_argument("--dim", type=int, choices=(2, 3), default=2, help="space dimension")
    parser.add_argument(
        "--refinements",
        type=int,
        default=None,
        help="number of meshes, each halving h (None: 5 in 2D, 4 in 3D)",
    )
    parser.add_argument(
        "--ratio",
        default=None,
        help="interface elements lower:upper, e.g. 3:4 or 1:7 (None: 3:4 in 2D, 2:3 in 3D)",
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
        "--cell-type",
        "--cell",
        choices=CELL_TYPES[2] + CELL_TYPES[3],
        default=None,
        help="cells: triangle or quadrilateral in 2D, tetrahedron or hexahedron in 3D "
        "(None: triangle, tetrahedron)",
    )
    args = parser.parse_args(argv)
    if args.cell_type is None:
        args.cell_type = CELL_TYPES[args.dim][0]
    elif args.cell_type not in CELL_TYPES[args.dim]:
        parser.error(f"--cell-type {args.cell_type} is not a cell of dimension {args.dim}")
    if args.refinements is None:
        args.refinements = 5 if args.dim == 2 else 4
    if args.refinements < 1:
        parser.error(f"--refinements must be at least 1, got {args.refinements}")
    if args.ratio is None:
        args.ratio = "3:4" if args.dim == 2 else "2:3"
    ratio = tuple(int(n) for n in args.ratio.split(":"))
    if args.dim == 3 and (len(ratio) != 2 or min(ratio) < 1):
        parser.error(f"--ratio needs two positive element counts, got {args.ratio}")
    runs = []
    for refinement in range(args.refinements):
        last = refinement == args.refinements - 1
        paraview = args.output / "paraview" / "displacement.bp" if args.output and last else None
        run = solve(
            refinement,
            ratio,
            args.solution,
            args.basis,
            args.cell_type,
            comm,
            paraview=paraview,
            dim=args.dim,
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
        "dim": args.dim,
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
    ax.set_title(
        f"mortar mesh tying, {args.dim}D {args.cell_type}, ratio {args.ratio}, {args.basis} basis"
    )
    ax.legend()
    ax.grid(True, which="both", alpha=0.3)
    cli.save_figure(fig, path)


if __name__ == "__main__":
    main()
