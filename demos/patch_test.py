"""Contact patch test: a uniform pressure must pass through a non-matching interface exactly.

Foundation 8 x 5 with a punch [4, 6] x [5, 7] on top (plane strain, E = 1000,
nu = 0.4; ``--E-punch`` and ``--E-foundation`` set each body's), pressure 10 on the
whole top, bottom on rollers. The exact solution is uniform whatever the two moduli
(the bodies' lateral strains differ and the interface slides, frictionless): contact
pressure 10 and sigma_yy = -10 everywhere
(benchmarks.md, section 2). Segment-based mortar integration with Lagrange
multipliers reproduces it to solver tolerance for any mesh ratio and either
slave side; element-based integration does not (its error is reported);
penalty gives a uniform pressure with a uniform penetration p / eps.

``--dim 3`` (benchmarks.md, section 6): a punch [0, 1]^2 x [0.5, 1] of
hexahedra or tetrahedra (``--cell-type``) on a foundation [0, 1]^2 x [0, 0.5],
non-matching in the ratio ``--ratio``, pressure 10 on the punch top, rollers
under the foundation: contact pressure 10 and sigma_zz = -10 everywhere.

Both the pressure users read (recovered, ``problem.gathered_pressure()``) and the nodal
multipliers (``raw=True``) are checked: ``max_pressure_deviation_rel`` and
``max_multiplier_deviation_rel``.

Outputs (``--output DIR``): the pressure along the interface (PNG) and the
displacement and contact pressure for ParaView (paraview/*.bp); ``--json FILE``
writes the summary.

Run:  mpirun -n 3 python3 demos/patch_test.py --ratio 3:7 --slave bottom --json patch.json
      mpirun -n 3 python3 demos/patch_test.py --dim 3 --cell tetrahedron --ratio 3:7
"""

from __future__ import annotations

import pathlib
import sys
import time

import dolfinx
import numpy as np
import ufl
from mpi4py import MPI

from dolfinx_mortar import (
    ContactOutput,
    ContactPair,
    ContactProblem,
    Material,
    compat,
    internal_work,
    meshes,
)

DEMOS = pathlib.Path(__file__).resolve().parent
if str(DEMOS) not in sys.path:  # loaded from its path (tests, benchmarks): find demos/cli.py
    sys.path.insert(0, str(DEMOS))
import cli  # noqa: E402
from cli import option_record, problem_options, write_summary  # noqa: E402

E, NU, PRESSURE = 1000.0, 0.4, 10.0


def main(argv=None, comm: MPI.Intracomm = MPI.COMM_WORLD) -> dict:
    parser = cli.parser(__doc__)
    parser.add_argument("--dim", type=int, choices=(2, 3), default=2, help="2D or 3D")
    parser.add_argument("--ratio", default="3:2", help="punch:foundation interface elements")
    parser.add_argument(
        "--slave", choices=("top", "bottom"), default="top", help="which surface is the slave"
    )
    parser.add_argument("--refinement", type=int, default=0, help="halves h per level")
    parser.add_argument(
        "--cell-type",
        "--cell",
        choices=meshes.CELL_TYPES + meshes.CELL_TYPES_3D,
        default=None,
        help="cells (default: triangle in 2D, hexahedron in 3D)",
    )
    parser.add_argument("--E-punch", type=float, default=E, help="Young's modulus, punch")
    parser.add_argument(
        "--E-foundation", type=float, default=E, help="Young's modulus, foundation"
    )
    cli.add_material_argument(parser)
    cli.add_common_arguments(parser)
    args = parser.parse_args(argv)
    for option in ("E_punch", "E_foundation"):
        if not getattr(args, option) > 0.0:
            parser.error(f"--{option.replace('_', '-')} must be positive")
    allowed = meshes.CELL_TYPES if args.dim == 2 else meshes.CELL_TYPES_3D
    if args.cell_type is None:
        args.cell_type = allowed[0] if args.dim == 2 else "hexahedron"
    if args.cell_type not in allowed:
        parser.error(f"--cell-type {args.cell_type} is not a {args.dim}D cell (one of {allowed})")
    ratio = tuple(int(n) for n in args.ratio.split(":"))
    start = time.perf_counter()
    build = meshes.patch_test if args.dim == 2 else meshes.patch_test_3d
    tagged = build(
        ratio=ratio,
        slave=args.slave,
        refinement=args.refinement,
        cell_type=args.cell_type,
        comm=comm,
    )
    mesh, markers = tagged.mesh, tagged.markers
    gdim = args.dim
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (gdim,)))
    u = dolfinx.fem.Function(V, name="displacement")
    v = ufl.TestFunction(V)
    materials = {markers["punch"]: Material(args.E_punch, NU, args.material),
                 markers["foundation"]: Material(args.E_foundation, NU, args.material)}
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=tagged.facet_tags)
    traction = dolfinx.fem.Constant(mesh, np.array([0.0] * (gdim - 1) + [-PRESSURE]))
    loaded = ds(markers["punch_top"])
    if gdim == 2:
        loaded = loaded + ds(markers["foundation_top_free"])
    F = internal_work(u, v, materials, tagged.cell_tags) - ufl.inner(traction, v) * loaded
    bcs = _supports(tagged, V, args.E_punch, args.E_foundation)

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
    low, high = (4.0, 6.0) if gdim == 2 else (0.0, 1.0)
    interior = np.all(
        (coordinates[:, : gdim - 1] > low + 1e-9) & (coordinates[:, : gdim - 1] < high - 1e-9),
        axis=1,
    )
    # the pressure of every slave node, ends included, must be uniform
    deviation = float(np.max(np.abs(pressure - PRESSURE)) / PRESSURE)
    multipliers = problem.gathered_pressure(raw=True)[1]
    multiplier_deviation = float(np.max(np.abs(multipliers - PRESSURE)) / PRESSURE)
    deviation_interior = float(
        np.max(np.abs(pressure[interior] - PRESSURE), initial=0.0) / PRESSURE
    )
    W = dolfinx.fem.functionspace(mesh, ("DG", 0))
    num_cells = mesh.topology.index_map(mesh.topology.dim).size_local
    stress_deviation = 0.0
    for marker, material in materials.items():
        stress = material.stress(u)
        if args.material != "linear":
            F_def = ufl.Identity(gdim) + ufl.grad(u)
            stress = stress * F_def.T / ufl.det(F_def)
        sigma_yy = dolfinx.fem.Function(W)
        sigma_yy.interpolate(dolfinx.fem.Expression(stress[gdim - 1, gdim - 1],
                                                    compat.interpolation_points(W)))
        cells = tagged.cell_tags.find(marker)
        cells = cells[cells < num_cells]
        values = sigma_yy.x.array[W.dofmap.list[cells, 0]]
        stress_deviation = max(stress_deviation,
                               float(np.max(np.abs(values + PRESSURE), initial=0.0)))
    stress_deviation = comm.allreduce(stress_deviation, op=MPI.MAX) / PRESSURE
    slave_force, master_force = problem.contact_forces()
    summary = {
        "dim": gdim,
        "ratio": list(ratio),
        "slave": args.slave,
        "swapped": problem.swapped[0],
        "refinement": args.refinement,
        "cell_type": args.cell_type,
        "material": args.material,
        "E_punch": args.E_punch,
        "E_foundation": args.E_foundation,
        **option_record(args),
        "c_n": problem.c_n,
        "penalty_used": problem.penalty,
        "num_ranks": comm.size,
        "converged": report.converged,
        "newton_iterations": report.iterations,
        "linear_iterations": report.linear_iterations,
        "residuals": report.residuals,
        "active_nodes": report.active,
        "max_pressure_deviation_rel": deviation,
        "max_multiplier_deviation_rel": multiplier_deviation,
        "max_pressure_deviation_interior_rel": deviation_interior,
        "max_stress_deviation_rel": float(stress_deviation),
        "pressure_nonuniformity_rel": float((pressure.max() - pressure.min()) / np.mean(pressure)),
        "pressure_min": float(pressure.min()),
        "pressure_max": float(pressure.max()),
        "slave_force": slave_force.tolist(),
        "master_force": master_force.tolist(),
        "total_force_expected": PRESSURE * (2.0 if gdim == 2 else 1.0),
        "num_dofs": V.dofmap.index_map.size_global * gdim,
        "wall_time_s": comm.allreduce(time.perf_counter() - start, op=MPI.MAX),
        "timings": report.timings,
    }
    if comm.rank == 0:
        print(
            f"patch test {gdim}D {args.cell_type} {args.ratio} slave={args.slave} "
            f"{args.method}/{args.integration}: "
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


def _supports(tagged, V, E_punch: float, E_foundation: float) -> list:
    """Rollers under the foundation; each body's lateral rigid motions fixed at two corner
    nodes by the exact uniform solution's lateral displacement eps x (eps = nu (1 + nu) p / E
    in plane strain, nu p / E in 3D, with the body's E)."""
    mesh, markers = tagged.mesh, tagged.markers
    gdim = mesh.geometry.dim
    fdim = mesh.topology.dim - 1
    top = 7.0 if gdim == 2 else 1.0

    def strain(corner) -> float:
        modulus = E_punch if np.isclose(corner[gdim - 1], top) else E_foundation
        return PRESSURE * NU * ((1.0 + NU) if gdim == 2 else 1.0) / modulus

    bottom = tagged.facet_tags.find(markers["foundation_bottom"])
    vertical = V.sub(gdim - 1)
    bcs = [
        dolfinx.fem.dirichletbc(
            np.float64(0.0), dolfinx.fem.locate_dofs_topological(vertical, fdim, bottom), vertical
        )
    ]
    if gdim == 2:
        corners = [((0.0, 0.0), (0,)), ((4.0, 7.0), (0,))]
    else:
        corners = [((0.0, 0.0, z), (0, 1)) for z in (0.0, 1.0)]
        corners += [((1.0, 0.0, z), (1,)) for z in (0.0, 1.0)]
    mesh.topology.create_connectivity(0, mesh.topology.dim)
    for corner, components in corners:
        vertices = dolfinx.mesh.locate_entities(
            mesh,
            0,
            lambda x, c=corner: np.all([np.isclose(x[i], c[i]) for i in range(gdim)], axis=0),
        )
        for i in components:
            dofs = dolfinx.fem.locate_dofs_topological(V.sub(i), 0, vertices)
            value = np.float64(strain(corner) * corner[i])
            bcs.append(dolfinx.fem.dirichletbc(value, dofs, V.sub(i)))
    return bcs


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
    cli.save_figure(fig, path)


if __name__ == "__main__":
    main()
