"""Contact patch test: a uniform pressure must pass through a non-matching interface exactly.

Foundation 8 x 5 with a punch [4, 6] x [5, 7] on top (plane strain, both
E = 1000, nu = 0.4), pressure 10 on the whole top, bottom on rollers. The
exact solution is uniform: contact pressure 10 and sigma_yy = -10 everywhere
(benchmarks.md, section 2). Segment-based mortar integration with Lagrange
multipliers reproduces it to solver tolerance for any mesh ratio and either
slave side; element-based integration does not (its error is reported);
penalty gives a uniform pressure with a uniform penetration p / eps.

Outputs (``--output DIR``): the pressure along the interface (PNG) and the
displacement and contact pressure for ParaView (paraview/*.bp); ``--json FILE``
writes the summary.

Run:  mpirun -n 3 python3 demos/patch_test.py --ratio 3:7 --slave bottom --json patch.json
"""

from __future__ import annotations

import pathlib
import time

import dolfinx
import numpy as np
import ufl
from mpi4py import MPI

from dolfinx_mortar import cli, compat, meshes
from dolfinx_mortar.cli import problem_options, write_summary
from dolfinx_mortar.loading import ContactOutput
from dolfinx_mortar.materials import Material, internal_work
from dolfinx_mortar.problem import ContactPair, ContactProblem

E, NU, PRESSURE = 1000.0, 0.4, 10.0


def main(argv=None, comm: MPI.Intracomm = MPI.COMM_WORLD) -> dict:
    parser = cli.parser(__doc__)
    parser.add_argument("--ratio", default="3:2", help="punch:foundation interface elements")
    parser.add_argument(
        "--slave", choices=("top", "bottom"), default="top", help="which surface is the slave"
    )
    parser.add_argument("--refinement", type=int, default=0, help="halves h per level")
    parser.add_argument(
        "--cell-type", choices=("triangle", "quadrilateral"), default="triangle", help="cells"
    )
    parser.add_argument(
        "--material",
        choices=("linear", "neo-hookean", "saint-venant-kirchhoff"),
        default="linear",
        help="bulk material of both bodies",
    )
    cli.add_common_arguments(parser)
    args = parser.parse_args(argv)
    ratio = tuple(int(n) for n in args.ratio.split(":"))
    start = time.perf_counter()
    tagged = meshes.patch_test(
        ratio=ratio,
        slave=args.slave,
        refinement=args.refinement,
        cell_type=args.cell_type,
        comm=comm,
    )
    mesh, markers = tagged.mesh, tagged.markers
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    u = dolfinx.fem.Function(V, name="displacement")
    v = ufl.TestFunction(V)
    material = Material(E, NU, args.material)
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=tagged.facet_tags)
    traction = dolfinx.fem.Constant(mesh, np.array([0.0, -PRESSURE]))
    F = internal_work(u, v, {0: material}) - ufl.inner(traction, v) * (
        ds(markers["punch_top"]) + ds(markers["foundation_top_free"])
    )

    # exact lateral strain of the uniform state (plane strain, sigma_xx = 0)
    strain_xx = PRESSURE * NU * (1.0 + NU) / E
    fdim = mesh.topology.dim - 1
    bottom = tagged.facet_tags.find(markers["foundation_bottom"])
    bcs = [
        dolfinx.fem.dirichletbc(
            np.float64(0.0), dolfinx.fem.locate_dofs_topological(V.sub(1), fdim, bottom), V.sub(1)
        )
    ]
    mesh.topology.create_connectivity(0, mesh.topology.dim)
    for corner in ((0.0, 0.0), (4.0, 7.0)):
        vertices = dolfinx.mesh.locate_entities(
            mesh, 0, lambda x, c=corner: np.isclose(x[0], c[0]) & np.isclose(x[1], c[1])
        )
        dofs = dolfinx.fem.locate_dofs_topological(V.sub(0), 0, vertices)
        bcs.append(dolfinx.fem.dirichletbc(np.float64(strain_xx * corner[0]), dofs, V.sub(0)))

    pair = ContactPair(
        tagged.facet_tags,
        markers["contact_slave"],
        markers["contact_master"],
        name="punch-foundation",
    )
    configuration = "reference" if args.material == "linear" else "current"
    problem = ContactProblem(
        F, u, bcs, [pair], configuration=configuration, **problem_options(args)
    )
    report = problem.solve()
    if not report.converged:
        raise RuntimeError(f"patch test did not converge (SNES reason {report.reason})")
    if args.output:
        output = ContactOutput(problem, args.output / "paraview")
        output.write(1.0)
        output.close()

    coordinates, pressure = problem.gathered_pressure()
    interior = (coordinates[:, 0] > 4.0 + 1e-9) & (coordinates[:, 0] < 6.0 - 1e-9)
    # the pressure of every slave node, ends included, must be uniform
    deviation = float(np.max(np.abs(pressure - PRESSURE)) / PRESSURE)
    deviation_interior = float(
        np.max(np.abs(pressure[interior] - PRESSURE), initial=0.0) / PRESSURE
    )
    stress = material.stress(u)
    if args.material != "linear":
        F_def = ufl.Identity(2) + ufl.grad(u)
        stress = stress * F_def.T / ufl.det(F_def)
    W = dolfinx.fem.functionspace(mesh, ("DG", 0))
    sigma_yy = dolfinx.fem.Function(W)
    sigma_yy.interpolate(dolfinx.fem.Expression(stress[1, 1], compat.interpolation_points(W)))
    num_cells = mesh.topology.index_map(mesh.topology.dim).size_local
    stress_deviation = (
        comm.allreduce(
            float(np.max(np.abs(sigma_yy.x.array[:num_cells] + PRESSURE), initial=0.0)), op=MPI.MAX
        )
        / PRESSURE
    )
    slave_force, master_force = problem.contact_forces()
    summary = {
        "ratio": list(ratio),
        "slave": args.slave,
        "refinement": args.refinement,
        "cell_type": args.cell_type,
        "material": args.material,
        **{key: value for key, value in problem_options(args).items()},
        "c_n": problem.c_n,
        "penalty_used": problem.penalty,
        "num_ranks": comm.size,
        "converged": report.converged,
        "newton_iterations": report.iterations,
        "linear_iterations": report.linear_iterations,
        "residuals": report.residuals,
        "active_nodes": report.active,
        "max_pressure_deviation_rel": deviation,
        "max_pressure_deviation_interior_rel": deviation_interior,
        "max_stress_deviation_rel": float(stress_deviation),
        "pressure_nonuniformity_rel": float((pressure.max() - pressure.min()) / np.mean(pressure)),
        "pressure_min": float(pressure.min()),
        "pressure_max": float(pressure.max()),
        "slave_force": slave_force.tolist(),
        "master_force": master_force.tolist(),
        "total_force_expected": PRESSURE * 2.0,
        "num_dofs": V.dofmap.index_map.size_global * 2,
        "wall_time_s": comm.allreduce(time.perf_counter() - start, op=MPI.MAX),
        "timings": report.timings,
    }
    if comm.rank == 0:
        print(
            f"patch test {args.ratio} slave={args.slave} {args.method}/{args.integration}: "
            f"pressure deviation {deviation:.3e} (non-uniformity "
            f"{summary['pressure_nonuniformity_rel']:.1e}), "
            f"stress deviation {stress_deviation:.3e}, "
            f"{report.iterations} Newton iterations",
            flush=True,
        )
        write_summary(args.json, summary)
        if args.output:
            plot(args.output / "patch_test_pressure.png", coordinates[:, 0], pressure, summary)
            print(f"results written to {args.output}/ (patch_test_pressure.png, paraview/*.bp)")
    problem.destroy()
    return summary


def plot(path: pathlib.Path, x, pressure, summary: dict) -> None:
    """The slave nodes' contact pressure against x, with the exact uniform value."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    ax.axhline(PRESSURE, color="k", lw=1.0, label="exact")
    label = f"mortar ({summary['method']}, {summary['integration']})"
    ax.plot(x, pressure, "o-", ms=3, label=label)
    # a fixed scale: round-off must not look like a variation
    ax.set_ylim(0.0, 1.5 * max(PRESSURE, float(pressure.max())))
    ax.set_xlabel("x")
    ax.set_ylabel("contact pressure")
    ax.set_title(
        f"patch test {summary['ratio'][0]}:{summary['ratio'][1]}, slave {summary['slave']}: "
        f"deviation {summary['max_pressure_deviation_rel']:.1e}"
    )
    ax.legend()
    ax.grid(alpha=0.3)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120, bbox_inches="tight")
    plt.close(fig)


if __name__ == "__main__":
    main()
