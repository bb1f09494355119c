"""Hertz contact of a sphere on an elastic block (3D), against the exact solution.

A sphere of radius R = 1 (E = 200, nu = 0.3) on a block of the same material,
pressed by a force F = 0.15 applied as a uniform traction on the flat top of
its lower half. Hertz: 1/E* = (1 - nu1^2)/E1 + (1 - nu2^2)/E2,
a = (3 F R / (4 E*))^(1/3) = 0.1008, p0 = 3 F / (2 pi a^2) = 7.05,
p(r) = p0 sqrt(1 - r^2/a^2). ``--case sphere``: two equal spheres (R/2 in
these formulas).

Quarter model: both bodies are cut by the symmetry planes x = 0 (u_x = 0) and
y = 0 (u_y = 0); the upper body, the lower half of the ball centred at
(0, 0, R), carries a traction on z = R whose total is F/4 and is held only by
contact: the first Newton iterate starts it slightly pressed into the lower
body. The block is [0, L]^2 x [-L, 0], L = ``--block-size`` R (default R), on
rollers (u_z = 0) at its bottom; Hertz theory assumes half-spaces, so L and the
sphere's own size bound the agreement (``--block-size`` measures it).

Normals: for ``--material linear`` the lower body's (``master`` with the sphere as
the slave, ``slave`` with ``--slave block``): on the block it is the common normal z of
the linearized theory, and a curved body's normals tilt by r/R; ``averaged`` for the
finite-strain models. At refinement 1 the lower body's normals keep the recovered p_max
within 3 % of p0 for moduli ratios 1e-2, 1 and 1e2 in both slave assignments (each ratio
with its own Hertz radius and mesh), while the upper sphere's normals give up to +4.5 %
(docs/benchmarks.md, "Contact pressure: nodal multipliers and their recovery"); a stiff
sphere as the slave on a 100 times softer sphere oscillates (docs/benchmarks.md,
"Contrast sweep in 3D"), so by default (``--slave-side auto``) the problem solves such a
pair with its sides swapped and says so; ``--slave-side given`` keeps the slave given.

Mesh (dolfinx_mortar.meshes3d.hertz_sphere): tetrahedra of size a / (4 2^k)
(k = --refinement) within 1.5 a of the contact point, growing with the
distance, with a the Hertz radius of the given load and moduli: the same
dimensionless problem in other units gives the same p_max / p0.

Load steps: the sphere starts pressed in so that the bodies overlap within a/2, and
the load grows so that the Hertz radius grows linearly from a/2 to a, in steps that move
the contact edge by at most 3 slave elements (``--steps`` overrides the count): the
semismooth Newton iterations of a step grow with that distance (docs/benchmarks.md,
"Newton iterations per load step in 3D Hertz").

Measured (defaults, L = R; Newton iterations per step; serial, refinement 2 on 2 ranks):

    refinement  dofs   p_max/p0-1  multipliers  a_contact-a  L2 error  Newton
    0            2703  -1.06 %     +3.2 %       -0.26 h      9.5 %     5
    1           13407  +0.11 %     +3.8 %       -0.02 h      5.8 %     5, 5
    2           84726  +1.07 %     +4.1 %       -0.12 h      2.9 %     6, 6, 6

The total force equals the load to 4e-15. p_max is the largest recovered pressure
(``problem.gathered_pressure()``, dolfinx_mortar.recovery), "multipliers" the largest
nodal multiplier (``raw=True``): on gmsh's tetrahedra the multipliers scatter about
Hertz's curve (within 0.8 a: standard deviation 4.7, 3.4, 2.2 % of p0 at refinement 0,
1, 2) and their maximum stays 3-4 % above p0; the recovery averages the scatter
(within 0.3 a: 2.9, 1.4, 1.0 %), so its maximum stays within about 1 % of p0, set by
what scatter remains, not by the mesh size (docs/benchmarks.md, "Contact pressure:
nodal multipliers and their recovery"). ``p0_fit`` (the ellipse p^2 = p0^2 (1 - r^2/a^2)
fitted to the nodes with r < 0.8 a) is within 1 % of p0. L = 2R moves p_max and p0_fit
by less than 0.2 % at refinement 1, so the block's size is not the cause. The default
``--linear-solver auto`` takes the iterative solver from 50,000 dofs on
(benchmarks/README.md, "Direct or iterative by default"); both give the same answer.

``--cell hexahedron`` (dolfinx_mortar.meshes3d.hertz_sphere_hexahedral): structured
graded hexahedral grids, the upper body a column [0, R/2]^2 whose bottom face is the
sphere's surface. Its nodal multipliers do not scatter as on gmsh's tetrahedra, so
their maximum itself converges to p0 (docs/benchmarks.md, "3D Hertz on hexahedra"); the
recovered pressure's peak differs from it by the linear fit's curvature error,
O(p0 h^2 / a^2) (+1.2 % at h = a/2, 0.02 % at the default h = a/4).

Pressure error: the L2 norm over the slave surface (surface quadrature of
degree 8 on the slave facets, reference configuration) of p_h - p_Hertz(r),
p_h the P1 interpolant of the recovered nodal pressures, r = sqrt(x^2 + y^2),
relative to the norm of p_Hertz; ``l2_multiplier_error_rel`` in the JSON is the same
norm for the nodal multipliers. The recovery's linear fit lowers a concave pressure at
every node with a full patch (by about h^2 |laplacian p| / 4 on a uniform quadrilateral
patch of side h), which on hexahedra, whose multipliers do not scatter, makes the
recovered pressure's error the larger of the two (docs/benchmarks.md, "Contrast sweep in
3D on hexahedra").

Outputs (``--output DIR``): hertz_sphere_pressure.png (recovered pressure and nodal
multipliers vs r, and Hertz's curve), paraview/displacement.bp and paraview/contact_pressure.bp
(every load step); ``--json FILE`` writes the summary.

Run:  mpirun -n 2 python3 demos/hertz_sphere.py --refinement 1 --json hs.json --output results/hs
"""

from __future__ import annotations

import functools
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
    meshes3d,
    solve_load_steps,
)

DEMOS = pathlib.Path(__file__).resolve().parent
if str(DEMOS) not in sys.path:  # loaded from its path (tests, benchmarks): find demos/cli.py
    sys.path.insert(0, str(DEMOS))
import cli  # noqa: E402
from cli import option_record, problem_options, write_summary  # noqa: E402

TIMINGS = ("bulk assembly", "contact search", "mortar integration", "linear solve", "total")
INITIAL_RADIUS = 0.5
"""Radius of the initial overlap (the first iterate's active set), a fraction of a."""
EDGE_ELEMENTS_PER_STEP = 3.0
"""How far the contact edge moves in one automatic load step, in slave elements."""


def automatic_steps(elements_per_radius: int, refinement: int) -> int:
    """Load steps (uniform in the Hertz radius) that move the contact edge by at most
    :data:`EDGE_ELEMENTS_PER_STEP` slave elements each.

    The semismooth Newton method's iterations in a step grow with that distance: its
    first iterate overshoots the new contact zone and the next ones shed the overshoot
    about half of it at a time (docs/benchmarks.md, "Newton iterations per load step in 3D").
    """
    elements = elements_per_radius * 2**refinement
    return max(1, math.ceil((1.0 - INITIAL_RADIUS) * elements / EDGE_ELEMENTS_PER_STEP))


def hertz_solution(load, radius, E1, nu1, E2, nu2, case) -> dict:
    """Contact radius a, peak pressure p0 and effective quantities of 3D Hertz contact."""
    effective_modulus = 1.0 / ((1 - nu1**2) / E1 + (1 - nu2**2) / E2)
    effective_radius = radius / 2.0 if case == "sphere" else radius
    a = (3.0 * load * effective_radius / (4.0 * effective_modulus)) ** (1.0 / 3.0)
    return {
        "a": a,
        "p0": 3.0 * load / (2.0 * math.pi * a**2),
        "E_star": effective_modulus,
        "R_star": effective_radius,
        "approach": a**2 / effective_radius,
    }


def hertz_pressure(r, a, p0):
    return p0 * np.sqrt(np.clip(1.0 - (r / a) ** 2, 0.0, None))


def hertz_fit(r_nodes, pressure, a) -> tuple[float, float]:
    """(p0, a) of the ellipse p^2 = p0^2 (1 - r^2 / a^2) fitted (least squares in p^2)
    to the nodes with r < 0.8 a: the peak and radius of the nodal pressure with its
    node-to-node scatter averaged out."""
    inner = r_nodes < 0.8 * a
    if np.count_nonzero(inner) < 2:
        return math.nan, math.nan
    A = np.column_stack([np.ones(np.count_nonzero(inner)), -r_nodes[inner] ** 2])
    (c0, c1), *_ = np.linalg.lstsq(A, pressure[inner] ** 2, rcond=None)
    if not (c0 > 0.0 and c1 > 0.0):
        return math.nan, math.nan
    return math.sqrt(c0), math.sqrt(c0 / c1)


def bulk_problem(tagged, u, materials):
    """(F, traction, bcs): internal work minus a uniform traction (a Constant, set per
    step) on "load"; u_z = 0 on "support", u_x = 0 on "symmetry_x", u_y = 0 on
    "symmetry_y" (both bodies)."""
    mesh, markers = tagged.mesh, tagged.markers
    V = u.function_space
    v = ufl.TestFunction(V)
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=tagged.facet_tags)
    traction = dolfinx.fem.Constant(mesh, np.zeros(3))
    F = internal_work(u, v, materials, tagged.cell_tags) - ufl.inner(traction, v) * ds(
        markers["load"]
    )
    bcs = []
    for name, component in (("support", 2), ("symmetry_x", 0), ("symmetry_y", 1)):
        facets = tagged.facet_tags.find(markers[name])
        dofs = dolfinx.fem.locate_dofs_topological(V.sub(component), 2, facets)
        bcs.append(dolfinx.fem.dirichletbc(np.float64(0.0), dofs, V.sub(component)))
    return F, traction, bcs


def surface_area(tagged, name: str) -> float:
    """Area of the facets ``name`` of the mesh (collective)."""
    mesh = tagged.mesh
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=tagged.facet_tags)
    one = dolfinx.fem.Constant(mesh, 1.0)
    local = dolfinx.fem.assemble_scalar(dolfinx.fem.form(one * ds(tagged.markers[name])))
    return mesh.comm.allreduce(local, op=MPI.SUM)


def l2_pressure_error(problem, tagged, a, p0, degree: int = 8,
                      raw: bool = False) -> tuple[float, float]:
    """Absolute and relative L2 error over the slave surface of the P1 pressure against
    Hertz's (surface quadrature of ``degree`` on the reference slave facets); ``raw``: of
    the nodal multipliers' P1 field instead of the recovered pressure's (on structured
    hexahedra the recovery's linear fit lowers a concave pressure at every node, so the
    two differ by more than the scatter the recovery is for)."""
    mesh = tagged.mesh
    pressure = problem.pressure_function(raw=raw)
    x = ufl.SpatialCoordinate(mesh)
    ratio = (x[0] ** 2 + x[1] ** 2) / a**2
    exact = p0 * ufl.sqrt(ufl.max_value(1.0 - ratio, 0.0))
    ds = ufl.Measure(
        "ds",
        domain=mesh,
        subdomain_data=tagged.facet_tags,
        metadata={"quadrature_degree": degree},
    )(problem.solved_pair().slave)

    def integral(form):
        local = dolfinx.fem.assemble_scalar(dolfinx.fem.form(form))
        return mesh.comm.allreduce(local, op=MPI.SUM)

    error2 = integral((pressure - exact) ** 2 * ds)
    norm2 = integral(exact**2 * ds)
    return math.sqrt(error2), math.sqrt(error2 / norm2)


def slave_edge_length(tagged, radius: float, slave: int) -> float:
    """Mean edge length of the facets tagged ``slave`` whose midpoint lies within
    ``radius`` of the z axis (collective); nan if there are none."""
    mesh = tagged.mesh
    mesh.topology.create_connectivity(2, 0)
    facets = tagged.facet_tags.find(slave)
    owned = facets[facets < mesh.topology.index_map(2).size_local]
    total, count = 0.0, 0
    if owned.size:
        vertices = dolfinx.mesh.entities_to_geometry(mesh, 2, owned, False)
        points = mesh.geometry.x[vertices]
        centre = points.mean(axis=1)
        near = np.hypot(centre[:, 0], centre[:, 1]) < radius
        cycle = [0, 1, 2] if points.shape[1] == 3 else [0, 1, 3, 2]  # dolfinx quad order
        ring = points[near][:, cycle]
        edges = np.roll(ring, -1, axis=1) - ring
        lengths = np.linalg.norm(edges, axis=2)
        total, count = float(lengths.sum()), int(lengths.size)
    total = mesh.comm.allreduce(total, op=MPI.SUM)
    count = mesh.comm.allreduce(count, op=MPI.SUM)
    return total / count if count else math.nan


def main(argv=None, comm: MPI.Intracomm = MPI.COMM_WORLD) -> dict:
    parser = cli.parser(__doc__)
    parser.add_argument(
        "--case",
        choices=meshes3d.HERTZ_SPHERE_CASES,
        default="block",
        help="block: sphere on a block; sphere: two equal spheres",
    )
    parser.add_argument("--radius", type=float, default=1.0, help="sphere radius R")
    parser.add_argument("--load", type=float, default=0.15, help="total force F")
    parser.add_argument("--E1", type=float, default=200.0, help="Young's modulus, upper sphere")
    parser.add_argument("--nu1", type=float, default=0.3, help="Poisson's ratio, upper sphere")
    parser.add_argument("--E2", type=float, default=200.0, help="Young's modulus, lower body")
    parser.add_argument("--nu2", type=float, default=0.3, help="Poisson's ratio, lower body")
    parser.add_argument(
        "--block-size", type=float, default=1.0, help="L / R of the block [0, L]^2 x [-L, 0]"
    )
    parser.add_argument(
        "--slave",
        choices=("sphere", "block"),
        default="sphere",
        help="slave surface: the sphere's curved surface or the lower body's",
    )
    cli.add_material_argument(
        parser, "linear (small strain, what Hertz theory assumes) or finite-strain models"
    )
    parser.add_argument(
        "--refinement", type=int, default=0, help="halves the element sizes per level"
    )
    parser.add_argument(
        "--cell",
        choices=meshes3d.CELL_TYPES_3D,
        default="tetrahedron",
        help="tetrahedron: gmsh mesh of the half balls; hexahedron: structured graded grids "
        "(the upper body a column with the sphere's surface as its bottom face)",
    )
    parser.add_argument(
        "--elements-per-radius",
        type=int,
        default=meshes3d.ELEMENTS_PER_RADIUS,
        help="n0: element size a / (n0 2^refinement) in the contact zone",
    )
    parser.add_argument(
        "--lower-size-ratio", type=float, default=1.0,
        help="the lower body's element sizes over the upper body's (tetrahedra)",
    )
    parser.add_argument(
        "--steps", type=int, default=None,
        help="load steps, uniform in the Hertz radius from the initial indentation's to a "
        f"(None: enough that the contact edge moves by at most {EDGE_ELEMENTS_PER_STEP:g} "
        "slave elements per step)",
    )
    cli.add_common_arguments(
        parser, normals=None,
        normals_help="None: the lower body's for --material linear (master with the sphere "
        "as the slave, slave with --slave block), else averaged",
    )
    cli.add_predictor_argument(parser)
    args = parser.parse_args(argv)
    if args.normals is None:
        lower = "master" if args.slave == "sphere" else "slave"
        args.normals = lower if args.material == "linear" else "averaged"
    configure_logging(comm)
    for option in ("radius", "load", "E1", "E2", "block_size"):
        value = getattr(args, option)
        if not value > 0.0:
            parser.error(f"--{option.replace('_', '-')} must be positive, got {value}")
    for option in ("nu1", "nu2"):
        value = getattr(args, option)
        if not -1.0 < value < 0.5:
            parser.error(f"--{option} must lie in (-1, 0.5), got {value}")
    exact = hertz_solution(args.load, args.radius, args.E1, args.nu1, args.E2, args.nu2,
                           args.case)
    if not 1.5 * exact["a"] < meshes3d.CAP_RADIUS * args.radius:
        parser.error(f"the Hertz radius a = {exact['a']:.4g} is not below R/3: lower --load")
    start = time.perf_counter()

    if args.cell == "tetrahedron":
        builder = functools.partial(meshes3d.hertz_sphere,
                                    lower_size_ratio=args.lower_size_ratio)
    elif args.lower_size_ratio != 1.0:
        parser.error("--lower-size-ratio applies to --cell tetrahedron")
    else:
        builder = meshes3d.hertz_sphere_hexahedral
    tagged = builder(
        case=args.case,
        refinement=args.refinement,
        radius=args.radius,
        contact_radius=exact["a"],
        block_size=args.block_size,
        slave=args.slave,
        elements_per_radius=args.elements_per_radius,
        comm=comm,
    )
    mesh, markers = tagged.mesh, tagged.markers
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (3,)))
    u = dolfinx.fem.Function(V, name="displacement")
    materials = {
        markers["sphere"]: Material(args.E1, args.nu1, args.material),
        markers["block"]: Material(args.E2, args.nu2, args.material),
    }
    F, traction, bcs = bulk_problem(tagged, u, materials)

    configuration = "reference" if args.material == "linear" else "current"
    pair = ContactPair(
        tagged.facet_tags, markers["contact_slave"], markers["contact_master"],
        name="sphere-" + args.case,
    )
    problem = ContactProblem(
        F, u, bcs, [pair], configuration=configuration, **problem_options(args)
    )

    # start the floating sphere pressed into the lower body so that the bodies overlap
    # within INITIAL_RADIUS a, so that Newton's first iterate already has active nodes
    sphere_cells = tagged.cell_tags.find(markers["sphere"])
    indentation = (INITIAL_RADIUS * exact["a"]) ** 2 / (2.0 * exact["R_star"])
    u.interpolate(
        lambda x: np.vstack([0.0 * x[0], 0.0 * x[0], -indentation + 0.0 * x[0]]), sphere_cells
    )
    u.x.scatter_forward()

    # the traction's total over the discrete (faceted) top face is exactly F/4
    load_area = surface_area(tagged, "load")

    def apply_load(t: float) -> None:
        # the Hertz radius grows linearly in t, from INITIAL_RADIUS a to a (F ~ a^3)
        fraction = (INITIAL_RADIUS + (1.0 - INITIAL_RADIUS) * t) ** 3
        traction.value[:] = (0.0, 0.0, -fraction * 0.25 * args.load / load_area)

    steps = args.steps or automatic_steps(args.elements_per_radius, args.refinement)
    output = ContactOutput(problem, args.output / "paraview") if args.output else None
    records = solve_load_steps(problem, apply_load, steps, output=output,
                               predictor=args.predictor)
    if output is not None:
        output.close()
    wall_time = comm.allreduce(time.perf_counter() - start, op=MPI.MAX)

    coordinates, pressure = problem.gathered_pressure()
    multipliers = problem.gathered_pressure(raw=True)[1]
    r_nodes = np.hypot(coordinates[:, 0], coordinates[:, 1])
    in_contact = pressure > 1e-8 * exact["p0"]
    a_contact = float(r_nodes[in_contact].max()) if in_contact.any() else 0.0
    solved_slave = problem.solved_pair().slave
    h_slave = slave_edge_length(tagged, exact["a"], solved_slave)
    error, error_rel = l2_pressure_error(problem, tagged, exact["a"], exact["p0"])
    multiplier_error_rel = l2_pressure_error(problem, tagged, exact["a"], exact["p0"],
                                             raw=True)[1]
    p0_fit, a_fit = hertz_fit(r_nodes, pressure, exact["a"])
    slave_force, master_force = problem.contact_forces()
    # the upward force on the sphere, from the full model (4 quarters)
    sphere_force = slave_force if args.slave == "sphere" else master_force
    total_force = 4.0 * float(sphere_force[2])
    zone = r_nodes < 1.5 * exact["a"]
    order = np.argsort(r_nodes[zone])
    summary = {
        "case": args.case,
        "radius": args.radius,
        "load": args.load,
        "E1": args.E1,
        "nu1": args.nu1,
        "E2": args.E2,
        "nu2": args.nu2,
        "block_size": args.block_size,
        "lower_size_ratio": args.lower_size_ratio,
        "slave": args.slave,
        "swapped": problem.swapped[0],
        "material": args.material,
        "configuration": configuration,
        **option_record(args),
        "linear_solver": problem.linear_solver,
        "c_n": problem.c_n,
        "penalty_used": problem.penalty,
        "refinement": args.refinement,
        "cell": args.cell,
        "elements_per_radius": args.elements_per_radius,
        "num_ranks": comm.size,
        "num_cells": mesh.topology.index_map(3).size_global,
        "num_dofs": V.dofmap.index_map.size_global * 3,
        "num_slave_nodes": int(r_nodes.size),
        "h_contact": tagged.h_contact,
        "h_slave_measured": h_slave,
        "p_max": float(pressure.max()),
        "p0_exact": exact["p0"],
        "p_max_error_rel": float(pressure.max() / exact["p0"] - 1.0),
        "p_max_multiplier": float(multipliers.max()),
        "p_max_multiplier_error_rel": float(multipliers.max() / exact["p0"] - 1.0),
        "p0_fit": p0_fit,
        "p0_fit_error_rel": p0_fit / exact["p0"] - 1.0,
        "a_fit": a_fit,
        "a_contact": a_contact,
        "a_exact": exact["a"],
        "a_error_in_elements": float((a_contact - exact["a"]) / h_slave),
        "total_force": total_force,
        "total_force_error_rel": abs(total_force - args.load) / args.load,
        "force_balance": float(np.linalg.norm(slave_force + master_force) / args.load),
        "l2_pressure_error": error,
        "l2_pressure_error_rel": error_rel,
        "l2_pressure_error_weighting": "surface quadrature (degree 8) on the slave facets",
        "l2_multiplier_error_rel": multiplier_error_rel,
        "pressure_profile": {
            "x": coordinates[zone, 0][order].tolist(),
            "y": coordinates[zone, 1][order].tolist(),
            "r": r_nodes[zone][order].tolist(),
            "pressure": pressure[zone][order].tolist(),
            "multiplier": multipliers[zone][order].tolist(),
        },
        "newton_iterations": [r.iterations for r in records],
        "load_steps": steps,
        "krylov_iterations": [r.report.linear_iterations for r in records],
        "residuals_per_step": [r.report.residuals for r in records],
        "active_nodes": records[-1].active,
        "cutbacks": sum(r.cutbacks for r in records),
        "wall_time_s": wall_time,
        "timings": {
            key: sum(r.report.timings.get(key, 0.0) for r in records) for key in TIMINGS
        },
        "contact_statistics": problem.statistics(),
    }
    if comm.rank == 0:
        print(
            f"Hertz sphere ({args.case}, refinement {args.refinement}, "
            f"{summary['num_dofs']} dofs): p_max {summary['p_max']:.4f} "
            f"(exact p0 {exact['p0']:.4f}, {100 * summary['p_max_error_rel']:+.2f} %; "
            f"largest multiplier {100 * summary['p_max_multiplier_error_rel']:+.2f} %), "
            f"a {a_contact:.4f} (exact {exact['a']:.4f}), "
            f"total force {total_force:.10g} (load {args.load}), "
            f"L2 pressure error {100 * error_rel:.2f} %, "
            f"Newton {summary['newton_iterations']}, {wall_time:.1f} s",
            flush=True,
        )
        write_summary(args.json, summary)
        if args.output:
            plot(args.output / "hertz_sphere_pressure.png", r_nodes, pressure, multipliers,
                 exact, summary)
            print(f"results written to {args.output}/ (hertz_sphere_pressure.png, "
                  "paraview/*.bp)")
    problem.destroy()
    return summary


def plot(path: pathlib.Path, r_nodes, pressure, multipliers, exact, summary) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    a, p0 = exact["a"], exact["p0"]
    r = np.linspace(0.0, 1.5 * a, 601)
    zone = r_nodes < 1.5 * a
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(r, hertz_pressure(r, a, p0), "k-", label="Hertz")
    ax.plot(r_nodes[zone], multipliers[zone], ".", ms=2, color="0.6",
            label="nodal multipliers")
    ax.plot(
        r_nodes[zone],
        pressure[zone],
        "o",
        ms=3,
        label=f"recovered pressure ({summary['method']}, {summary['normals']} normals)",
    )
    ax.set_xlabel("r")
    ax.set_ylabel("contact pressure")
    ax.set_title(
        f"Hertz sphere ({summary['case']}, refinement {summary['refinement']}): "
        f"p_max {summary['p_max']:.3f} vs p0 {p0:.3f}"
    )
    ax.legend(loc="lower left")
    ax.grid(alpha=0.3)
    cli.save_figure(fig, path)


if __name__ == "__main__":
    main()
