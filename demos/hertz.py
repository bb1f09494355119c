"""Hertz contact of a cylinder on an elastic block (plane strain), against the exact solution.

Case B of benchmarks.md by default: a half-cylinder of radius 8 on a block,
both E = 200, nu = 0.3, pressed by a force P = 10 (per unit thickness) applied
as a uniform traction on the cylinder's flat top. Hertz:
a = sqrt(4 P R / (pi E*)) = 0.9628, p0 = 2 P / (pi a) = 6.612. Cases A (rigid
plate) and C (two cylinders) with ``--case``.

The slave surface is the cylinder's arc and the master the block's top, or the
other way round with ``--slave block`` (the lower body's surface as the slave; the
same mesh). Everything reported is measured on the slave side's nodes and
multipliers (p_max, the L2 error, the half-width), and the total force is the
cylinder's whichever side it is. Both bodies carry a line x = 0 on which u_x = 0
(no rigid sliding); the cylinder is held only by contact, so the first Newton
iterate starts it slightly pressed into the block.

Normals: with linear elasticity (the default, what Hertz theory assumes) the
mortar integrals live on the undeformed configuration, where the averaged
normals of the cylinder's arc tilt by x/R (0.12 rad at the edge of the zone)
away from the common normal of the linearized theory, the block's. That tilt
moves the converged pressure 1.7 % (L2) away from Hertz however fine the mesh
(benchmarks/results/hertz_convergence_R8_averaged.md), so ``--normals`` defaults to
the block's for ``--material linear`` (``master``, or ``slave`` with ``--slave
block``) and to the library's ``averaged`` for the finite-strain models, whose
integrals follow the deformed, flattened arc.

Mesh: refined (h = a/5, halved per --refinement) where the contact zone is, with
a the Hertz half-width of the --load, --radius and moduli given, and every other
length a multiple of a or R: the same dimensionless problem in other units
(lengths x s, moduli x m, load x s m) gives the same p_max / p0 and a / a_exact.

Outputs (``--output DIR``): hertz_pressure.png and hertz_pressure.csv (pressure of
the slave nodes and Hertz's at their x), paraview/displacement.bp and
paraview/contact_pressure.bp (every load step); ``--json FILE`` writes the summary.

Run:  mpirun -n 2 python3 demos/hertz.py --refinement 2 --json hertz.json --output results/hertz
"""

from __future__ import annotations

import csv
import math
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
    configure_logging,
    internal_work,
    meshes,
    solve_load_steps,
)

DEMOS = pathlib.Path(__file__).resolve().parent
if str(DEMOS) not in sys.path:  # loaded from its path (tests, benchmarks): find demos/cli.py
    sys.path.insert(0, str(DEMOS))
import cli  # noqa: E402
from cli import option_record, problem_options, write_summary  # noqa: E402

CASES = {
    # load P, E and nu of the lower body (the cylinder is always E = 200, nu = 0.3)
    "A": {"load": 3.2032, "E_block": 2e12, "nu_block": 0.3},
    "B": {"load": 10.0, "E_block": 200.0, "nu_block": 0.3},
    "C": {"load": 10.0, "E_block": 200.0, "nu_block": 0.3},
}


def hertz_solution(load, radius, E1, nu1, E2, nu2, case) -> dict:
    """Half-width a, peak pressure p0 and effective quantities of 2D Hertz contact."""
    effective_modulus = 1.0 / ((1 - nu1**2) / E1 + (1 - nu2**2) / E2)
    effective_radius = radius / 2.0 if case == "C" else radius
    a = math.sqrt(4.0 * load * effective_radius / (math.pi * effective_modulus))
    return {
        "a": a,
        "p0": 2.0 * load / (math.pi * a),
        "E_star": effective_modulus,
        "R_star": effective_radius,
    }


def hertz_pressure(x, a, p0):
    return p0 * np.sqrt(np.clip(1.0 - (x / a) ** 2, 0.0, None))


def l2_pressure_error(x_nodes, p_nodes, a, p0, samples_per_facet=64) -> tuple[float, float]:
    """Absolute and relative L2 error of the piecewise-linear pressure along x.

    Each facet is sampled finely, and split at x = +-a where the exact pressure
    has its square-root edge; the slave surface is nearly flat in the contact
    zone, so x serves as the arc length to O(a^2/R^2).
    """
    points, weights = np.polynomial.legendre.leggauss(samples_per_facet)
    error2 = norm2 = 0.0
    for x0, x1, p0_, p1_ in zip(x_nodes[:-1], x_nodes[1:], p_nodes[:-1], p_nodes[1:], strict=True):
        cuts = [x0] + [c for c in (-a, a) if x0 < c < x1] + [x1]
        for lo, hi in zip(cuts[:-1], cuts[1:], strict=True):
            x = 0.5 * (lo + hi) + 0.5 * (hi - lo) * points
            w = 0.5 * (hi - lo) * weights
            ph = p0_ + (p1_ - p0_) * (x - x0) / (x1 - x0)
            pe = hertz_pressure(x, a, p0)
            error2 += np.sum(w * (ph - pe) ** 2)
            norm2 += np.sum(w * pe**2)
    return math.sqrt(error2), math.sqrt(error2 / norm2)


def bulk_problem(tagged, u, materials):
    """(F, traction, bcs) of the Hertz meshes: internal work minus a uniform traction
    (a Constant, set per load step) on the facets "load"; the lower body's "support"
    clamped and u_x = 0 on the symmetry lines of both bodies (no rigid sliding)."""
    mesh, markers = tagged.mesh, tagged.markers
    V = u.function_space
    v = ufl.TestFunction(V)
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=tagged.facet_tags)
    traction = dolfinx.fem.Constant(mesh, np.array([0.0, 0.0]))
    F = internal_work(u, v, materials, tagged.cell_tags) - ufl.inner(traction, v) * ds(
        markers["load"]
    )
    fdim = mesh.topology.dim - 1
    support = tagged.facet_tags.find(markers["support"])
    bcs = [
        dolfinx.fem.dirichletbc(
            np.zeros(2), dolfinx.fem.locate_dofs_topological(V, fdim, support), V
        )
    ]
    for name in ("symmetry_slave", "symmetry_master"):
        facets = tagged.facet_tags.find(markers[name])
        dofs = dolfinx.fem.locate_dofs_topological(V.sub(0), fdim, facets)
        bcs.append(dolfinx.fem.dirichletbc(np.float64(0.0), dofs, V.sub(0)))
    return F, traction, bcs


def main(argv=None, comm: MPI.Intracomm = MPI.COMM_WORLD) -> dict:
    parser = cli.parser(__doc__)
    parser.add_argument(
        "--case", choices=tuple(CASES), default="B", help="A rigid plate, B block, C two cylinders"
    )
    parser.add_argument("--radius", type=float, default=8.0, help="cylinder radius R")
    parser.add_argument(
        "--load",
        type=float,
        default=None,
        help="force P per unit thickness (None: the case's, " + _case_values("load") + ")",
    )
    parser.add_argument(
        "--E-cylinder", type=float, default=200.0, help="Young's modulus of the cylinder"
    )
    parser.add_argument(
        "--nu-cylinder", type=float, default=0.3, help="Poisson's ratio of the cylinder"
    )
    parser.add_argument(
        "--E-block",
        type=float,
        default=None,
        help="Young's modulus of the lower body (None: the case's, "
        + _case_values("E_block")
        + ")",
    )
    parser.add_argument(
        "--nu-block",
        type=float,
        default=None,
        help="Poisson's ratio of the lower body (None: the case's, 0.3)",
    )
    parser.add_argument(
        "--slave",
        choices=meshes.HERTZ_SLAVES,
        default="cylinder",
        help="slave surface: the cylinder's arc or the lower body's contact surface",
    )
    cli.add_material_argument(
        parser, "linear (small strain, what Hertz theory assumes) or finite-strain models"
    )
    parser.add_argument(
        "--refinement", type=int, default=2, help="halves the element sizes per level"
    )
    parser.add_argument(
        "--cell-type", choices=("triangle", "quadrilateral"), default="triangle", help="cells"
    )
    parser.add_argument("--steps", type=int, default=2, help="load steps")
    cli.add_common_arguments(
        parser,
        normals=None,
        normals_help="None: the block's for --material linear (master, or slave with "
        "--slave block), else averaged",
    )
    cli.add_predictor_argument(parser)
    args = parser.parse_args(argv)
    if args.normals is None:
        block_side = "master" if args.slave == "cylinder" else "slave"
        args.normals = block_side if args.material == "linear" else "averaged"
    configure_logging(comm)
    case = CASES[args.case]
    load = args.load if args.load is not None else case["load"]
    E_block = args.E_block if args.E_block is not None else case["E_block"]
    nu_block = args.nu_block if args.nu_block is not None else case["nu_block"]
    for option, value in (
        ("--radius", args.radius),
        ("--load", load),
        ("--E-cylinder", args.E_cylinder),
        ("--E-block", E_block),
    ):
        if not value > 0.0:
            parser.error(f"{option} must be positive, got {value}")
    for option, value in (("--nu-cylinder", args.nu_cylinder), ("--nu-block", nu_block)):
        if not -1.0 < value < 0.5:
            parser.error(f"{option} must lie in (-1, 0.5), got {value}")
    exact = hertz_solution(
        load, args.radius, args.E_cylinder, args.nu_cylinder, E_block, nu_block, args.case
    )
    start = time.perf_counter()

    # the refined zone follows the Hertz a of this load and these moduli, so that
    # the same dimensionless problem gets the same mesh in every unit system
    tagged = meshes.hertz(
        case=args.case,
        refinement=args.refinement,
        radius=args.radius,
        cell_type=args.cell_type,
        comm=comm,
        half_width=exact["a"],
        slave=args.slave,
    )
    mesh, markers = tagged.mesh, tagged.markers
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    u = dolfinx.fem.Function(V, name="displacement")
    materials = {
        markers["cylinder"]: Material(args.E_cylinder, args.nu_cylinder, args.material),
        markers["block"]: Material(E_block, nu_block, args.material),
    }
    F, traction, bcs = bulk_problem(tagged, u, materials)

    configuration = "reference" if args.material == "linear" else "current"
    pair = ContactPair(
        tagged.facet_tags,
        markers["contact_slave"],
        markers["contact_master"],
        name="cylinder-block",
    )
    problem = ContactProblem(
        F, u, bcs, [pair], configuration=configuration, **problem_options(args)
    )

    # start the floating cylinder pressed into the block by a fraction of the
    # Hertz approach, so that Newton's first iterate already has active nodes
    cylinder_cells = tagged.cell_tags.find(markers["cylinder"])
    indentation = (0.5 * exact["a"]) ** 2 / (2.0 * exact["R_star"])
    u.interpolate(lambda x: np.vstack([0.0 * x[0], -indentation + 0.0 * x[0]]), cylinder_cells)
    u.x.scatter_forward()

    width = 2.0 * args.radius

    def apply_load(t: float) -> None:
        traction.value[:] = (0.0, -t * load / width)

    output = ContactOutput(problem, args.output / "paraview") if args.output else None
    records = solve_load_steps(problem, apply_load, args.steps, output=output,
                               predictor=args.predictor)
    if output is not None:
        output.close()
    wall_time = comm.allreduce(time.perf_counter() - start, op=MPI.MAX)

    coordinates, pressure = problem.gathered_pressure()
    x_nodes = coordinates[:, 0]
    in_contact = pressure > 1e-8 * exact["p0"]
    a_contact = (
        0.5 * (x_nodes[in_contact].max() - x_nodes[in_contact].min()) if in_contact.any() else 0.0
    )
    zone = np.abs(x_nodes) < 3.0 * exact["a"]
    spacing = float(np.max(np.diff(x_nodes[zone]))) if zone.sum() > 1 else float("nan")
    error, error_rel = l2_pressure_error(x_nodes[zone], pressure[zone], exact["a"], exact["p0"])
    slave_force, master_force = problem.contact_forces()
    # the upward force on the cylinder
    cylinder_force = slave_force if args.slave == "cylinder" else master_force
    summary = {
        "case": args.case,
        "radius": args.radius,
        "load": load,
        "E_cylinder": args.E_cylinder,
        "nu_cylinder": args.nu_cylinder,
        "E_block": E_block,
        "nu_block": nu_block,
        "slave": args.slave,
        "material": args.material,
        "configuration": configuration,
        **option_record(args),
        "linear_solver": problem.linear_solver,
        "c_n": problem.c_n,
        "penalty_used": problem.penalty,
        "refinement": args.refinement,
        "cell_type": args.cell_type,
        "num_ranks": comm.size,
        "num_dofs": V.dofmap.index_map.size_global * 2,
        "num_slave_nodes": int(x_nodes.size),
        "h_contact": spacing,
        "p_max": float(pressure.max()),
        "p0_exact": exact["p0"],
        "p_max_error_rel": float(pressure.max() / exact["p0"] - 1.0),
        "a_contact": float(a_contact),
        "a_exact": exact["a"],
        "a_error_in_elements": float(abs(a_contact - exact["a"]) / spacing),
        "total_force": float(cylinder_force[1]),
        "total_force_error_rel": float(abs(cylinder_force[1] - load) / load),
        "force_balance": float(np.linalg.norm(slave_force + master_force) / load),
        "l2_pressure_error": error,
        "l2_pressure_error_rel": error_rel,
        "pressure_profile": {
            "x": x_nodes[zone].tolist(),
            "y": coordinates[zone, 1].tolist(),
            "pressure": pressure[zone].tolist(),
        },
        "newton_iterations": [r.iterations for r in records],
        "linear_iterations": [r.report.linear_iterations for r in records],
        "residuals_last_step": records[-1].report.residuals,
        "residuals_per_step": [r.report.residuals for r in records],
        "active_nodes": records[-1].active,
        "cutbacks": sum(r.cutbacks for r in records),
        "wall_time_s": wall_time,
        "timings": {
            key: sum(r.report.timings.get(key, 0.0) for r in records)
            for key in (
                "bulk assembly",
                "contact search",
                "mortar integration",
                "linear solve",
                "total",
            )
        },
        "contact_statistics": problem.statistics(),
    }
    if comm.rank == 0:
        print(
            f"Hertz case {args.case}: p_max {summary['p_max']:.4f} (exact p0 {exact['p0']:.4f}, "
            f"{100 * summary['p_max_error_rel']:+.2f} %), "
            f"a {a_contact:.4f} (exact {exact['a']:.4f}), "
            f"total force {summary['total_force']:.10g} (load {load}), "
            f"L2 pressure error {100 * error_rel:.2f} %",
            flush=True,
        )
        write_summary(args.json, summary)
        if args.output:
            plot(args.output / "hertz_pressure.png", x_nodes, pressure, exact, summary)
            write_profile(args.output / "hertz_pressure.csv", x_nodes, pressure, exact)
            print(
                f"results written to {args.output}/ (hertz_pressure.png, hertz_pressure.csv, "
                "paraview/*.bp)"
            )
    problem.destroy()
    return summary


def _case_values(key: str) -> str:
    return ", ".join(f"{name} {values[key]:g}" for name, values in CASES.items())


def write_profile(path: pathlib.Path, x_nodes, pressure, exact) -> None:
    """The slave nodes' pressure and Hertz's at their x, as CSV."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as stream:
        writer = csv.writer(stream)
        writer.writerow(["x", "pressure", "pressure_hertz"])
        for x, p, p_exact in zip(
            x_nodes, pressure, hertz_pressure(x_nodes, exact["a"], exact["p0"]), strict=True
        ):
            writer.writerow([repr(float(x)), repr(float(p)), repr(float(p_exact))])


def plot(path: pathlib.Path, x_nodes, pressure, exact, summary) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    a, p0 = exact["a"], exact["p0"]
    x = np.linspace(-1.5 * a, 1.5 * a, 801)
    zone = np.abs(x_nodes) < 1.5 * a
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(x, hertz_pressure(x, a, p0), "k-", label="Hertz")
    ax.plot(
        x_nodes[zone],
        pressure[zone],
        "o-",
        ms=3,
        label=f"mortar ({summary['method']}, {summary['integration']})",
    )
    ax.set_xlabel("x")
    ax.set_ylabel("contact pressure")
    ax.set_title(f"Hertz case {summary['case']}: p_max {summary['p_max']:.3f} vs p0 {p0:.3f}")
    ax.legend()
    ax.grid(alpha=0.3)
    cli.save_figure(fig, path)


if __name__ == "__main__":
    main()
