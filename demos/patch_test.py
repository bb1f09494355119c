"""Contact patch test: a uniform pressure must pass through a non-matching interface exactly.

Foundation 8 x 5 with a punch [4, 6] x [5, 7] on top (plane strain, both
E = 1000, nu = 0.4), pressure 10 on the whole top, bottom on rollers. The
exact solution is uniform: contact pressure 10 and sigma_yy = -10 everywhere
(benchmarks.md, section 2). Segment-based mortar integration with Lagrange
multipliers reproduces it to solver tolerance for any mesh ratio and either
slave side; element-based integration does not (its error is reported);
penalty gives a uniform pressure with a uniform penetration p / eps.

Run:  mpirun -n 3 python3 demos/patch_test.py --ratio 3:7 --slave bottom --json patch.json
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import dolfinx
import numpy as np
import ufl
from mpi4py import MPI

from dolfinx_mortar import compat, meshes
from dolfinx_mortar.materials import Material, internal_work
from dolfinx_mortar.problem import ContactPair, ContactProblem

E, NU, PRESSURE = 1000.0, 0.4, 10.0


def add_common_arguments(parser: argparse.ArgumentParser) -> None:
    """Options every contact demo shares (method, integration, normals, ...)."""
    parser.add_argument(
        "--method", choices=("lagrange", "penalty", "augmented"), default="lagrange"
    )
    parser.add_argument("--integration", choices=("segment", "element"), default="segment")
    parser.add_argument("--gauss-points", type=int, default=None, help="per segment / slave facet")
    parser.add_argument("--normals", choices=("averaged", "slave", "master"), default="averaged")
    parser.add_argument("--multipliers", choices=("standard", "dual"), default="dual")
    parser.add_argument("--active-set", choices=("semismooth", "fixed-point"), default="semismooth")
    parser.add_argument("--c-n", type=float, default=None, help="complementarity parameter")
    parser.add_argument("--penalty", type=float, default=None, help="penalty parameter eps")
    parser.add_argument(
        "--condensation",
        action="store_true",
        help="condense the (dual) multipliers: factorize a displacement-sized matrix",
    )
    parser.add_argument(
        "--search-margin", type=float, default=None, help="contact search margin (a length)"
    )
    parser.add_argument("--json", type=Path, help="write a JSON summary here")


def write_summary(path: Path | None, summary: dict) -> None:
    """The --json option: write the demo's summary there (call it on one rank)."""
    if path:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(summary, indent=2))


def problem_options(args) -> dict:
    return {
        "method": args.method,
        "integration": args.integration,
        "num_gauss_points": args.gauss_points,
        "normals": args.normals,
        "multipliers": args.multipliers,
        "active_set": args.active_set,
        "c_n": args.c_n,
        "penalty": args.penalty,
        "condensation": args.condensation,
        "search_margin": args.search_margin,
    }


def main(argv=None, comm: MPI.Intracomm = MPI.COMM_WORLD) -> dict:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--ratio", default="3:2", help="punch:foundation interface elements")
    parser.add_argument("--slave", choices=("top", "bottom"), default="top")
    parser.add_argument("--refinement", type=int, default=0)
    parser.add_argument("--cell-type", choices=("triangle", "quadrilateral"), default="triangle")
    parser.add_argument(
        "--material", choices=("linear", "neo-hookean", "saint-venant-kirchhoff"), default="linear"
    )
    add_common_arguments(parser)
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
    problem.destroy()
    return summary


if __name__ == "__main__":
    main()
