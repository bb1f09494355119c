"""Contact against bonded elasticity on the same mesh, in one run (issue 26).

The yardstick of a contact Newton iteration is one linear elasticity solve of the same
size: what the same machine needs for the same mesh without contact. On the mesh of
``demos/hertz_sphere.py`` (same ``--cell``, ``--refinement``, ``--elements-per-radius``)
this script

1. solves the bonded problem: linear elasticity of both bodies with the demo's
   materials, quadrature and Dirichlet conditions (support, symmetry planes), each
   body's contact surface glued to a rigid plane (u = 0 there; the sphere floats
   otherwise), loaded by the demo's traction and a uniform body force. Plain dolfinx:
   assembly, then CG + GAMG (dolfinx's elasticity demo options) with the six rigid-body
   modes as the near-nullspace (``--per-body-modes``: six per body) and block size 3,
   rtol 1e-8. Reported: the cells' edge ratios (longest / shortest edge),
   assembly, GAMG set-up and CG solve times (the slowest rank), CG iterations and the
   peak resident set per rank;
2. runs the demo itself (its options after ``--``) with the condensed preconditioner
   instrumented: per Newton iteration the linear solve, the outer (FGMRES) iterations,
   the inner (GMRES) iterations of each application, the condensation's matrix products
   (sub-matrices, the rows near the contact, K_c's products on them, the
   inner matrix), the inner solver's set-up (AMG), the
   applications (inner solves), the bulk assembly and the mortar search and integration.

and prints the ratio (contact time per Newton iteration) / (bonded solve). With
friction (``-- --mu 0.3``) ``auto`` chooses as without (iterative from
``solvers.AUTO_ITERATIVE_MIN_DOFS`` dofs on): the record says which solver ran.

    tools/run mpirun -n 2 python3 benchmarks/contact_vs_bonded.py --cell hexahedron \\
        --refinement 1 --json scratch/cvb_hex1.json
    tools/run mpirun -n 2 python3 benchmarks/contact_vs_bonded.py --refinement 2 \\
        --elements-per-radius 3 -- --linear-solver iterative --steps 1

``--box N`` also solves the bonded problem on a uniform unit cube of N^3 cells (the
issue's first yardstick, a box of about the same size; 25 hexahedra a side: 52,728 dofs),
in the same run; ``--bonded-only`` skips the contact run; ``--bonded-repeats`` solves the
bonded problem more than once (the first solve pays one-off costs; every solve is
recorded, and the ratio uses the median of those after the first: a bonded solve of
5e4 dofs took 0.64 to 0.94 s within minutes on a quiet machine).
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import os
import pathlib
import statistics
import time

import dolfinx
import dolfinx.fem.petsc
import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_mortar import (
    Material,
    allocator,
    compat,
    condensation,
    inner_matrix,
    internal_work,
    meshes3d,
    solvers,
)

from suite.runner import demo

BONDED_OPTIONS = {
    # dolfinx's elasticity demo (python/demo/demo_elasticity.py)
    "ksp_type": "cg",
    "ksp_rtol": 1e-8,
    "pc_type": "gamg",
    "pc_gamg_coarse_eq_limit": 1000,
    "mg_levels_ksp_type": "chebyshev",
    "mg_levels_pc_type": "jacobi",
    "mg_levels_esteig_ksp_type": "cg",
    "matptap_via": "scalable",
}
BODY_FORCE = 0.01
"""Uniform downward body force of the bonded problem (both bodies are loaded)."""


def memory_mib() -> dict:
    """VmRSS and VmHWM of this process in MiB."""
    values = {}
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith(("VmRSS", "VmHWM")):
                key, value = line.split(":")
                values[key] = int(value.split()[0]) / 1024
    return values


def slowest(comm, seconds: float) -> float:
    return comm.allreduce(seconds, op=MPI.MAX)


def hertz_mesh(args, comm):
    """The demo's mesh and its Hertz radius (the demo's defaults for the other options)."""
    module = demo("hertz_sphere")
    exact = module.hertz_solution(0.15, 1.0, 200.0, 0.3, 200.0, 0.3, "block")
    builder = meshes3d.hertz_sphere if args.cell == "tetrahedron" else (
        meshes3d.hertz_sphere_hexahedral)
    return builder(case="block", refinement=args.refinement, radius=1.0,
                   contact_radius=exact["a"], block_size=1.0, slave="sphere",
                   elements_per_radius=args.elements_per_radius, comm=comm)


def global_rigid_body_modes(V) -> list[np.ndarray]:
    """The six rigid-body modes of the whole mesh (about the origin), orthonormal: what a
    plain dolfinx elasticity solve gives GAMG. :func:`solvers.rigid_body_modes` gives each
    body its own six (twelve on the Hertz mesh), which the contact problem's floating
    sphere needs; GAMG then carries twelve columns per aggregate, six of them zero."""
    comm = V.mesh.comm
    owned = V.dofmap.index_map.size_local
    x = V.tabulate_dof_coordinates()[:owned]
    zero, one = np.zeros(owned), np.ones(owned)
    fields = [np.column_stack([one, zero, zero]), np.column_stack([zero, one, zero]),
              np.column_stack([zero, zero, one]),
              np.column_stack([-x[:, 1], x[:, 0], zero]),
              np.column_stack([zero, -x[:, 2], x[:, 1]]),
              np.column_stack([x[:, 2], zero, -x[:, 0]])]
    basis: list[np.ndarray] = []
    for field in fields:
        mode = field.reshape(-1).copy()
        for other in basis:
            mode -= comm.allreduce(float(mode @ other), op=MPI.SUM) * other
        basis.append(mode / np.sqrt(comm.allreduce(float(mode @ mode), op=MPI.SUM)))
    return basis


CELL_EDGES = {
    "tetrahedron": ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)),
    # dolfinx's hexahedron: vertices 0-7 in lexicographic order, edges along x, y, z
    "hexahedron": ((0, 1), (2, 3), (4, 5), (6, 7), (0, 2), (1, 3), (4, 6), (5, 7),
                   (0, 4), (1, 5), (2, 6), (3, 7)),
}


def edge_ratios(mesh) -> dict:
    """Longest over shortest edge of every cell (owned cells, gathered): the mesh's
    stretching, which algebraic multigrid feels. Collective."""
    owned = mesh.topology.index_map(3).size_local
    nodes = mesh.geometry.x[compat.geometry_dofmap(mesh)[:owned]]
    lengths = np.stack([np.linalg.norm(nodes[:, i] - nodes[:, j], axis=1)
                        for i, j in CELL_EDGES[mesh.topology.cell_name()]], axis=1)
    ratios = np.concatenate(mesh.comm.allgather(lengths.max(axis=1) / lengths.min(axis=1)))
    return {"median": float(np.median(ratios)), "p90": float(np.percentile(ratios, 90)),
            "max": float(ratios.max()), "fraction_above_10": float(np.mean(ratios > 10.0))}


def bonded_solve(args, comm) -> dict:
    """Build the mesh, assemble and solve the bonded problem ``args.bonded_repeats``
    times (see the module docstring); times are the slowest rank's."""
    start = time.perf_counter()
    tagged = hertz_mesh(args, comm)
    mesh, markers = tagged.mesh, tagged.markers
    mesh_time = slowest(comm, time.perf_counter() - start)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (3,)))
    u, v = dolfinx.fem.Function(V), ufl.TestFunction(V)
    materials = {markers[name]: Material(200.0, 0.3, "linear") for name in ("sphere", "block")}
    work = internal_work(u, v, materials, tagged.cell_tags)
    bilinear = ufl.derivative(work, u, ufl.TrialFunction(V))
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=tagged.facet_tags)
    linear = (ufl.inner(dolfinx.fem.Constant(mesh, np.array([0.0, 0.0, -BODY_FORCE])), v)
              * ufl.dx(domain=mesh)
              + ufl.inner(dolfinx.fem.Constant(mesh, np.array([0.0, 0.0, -0.1])), v)
              * ds(markers["load"]))
    bcs = []
    fixed = [("support", (2,)), ("symmetry_x", (0,)), ("symmetry_y", (1,)),
             ("contact_slave", (0, 1, 2)), ("contact_master", (0, 1, 2))]
    for name, components in fixed:
        facets = tagged.facet_tags.find(markers[name])
        for c in components:
            dofs = dolfinx.fem.locate_dofs_topological(V.sub(c), 2, facets)
            bcs.append(dolfinx.fem.dirichletbc(np.float64(0.0), dofs, V.sub(c)))
    start = time.perf_counter()
    a, L = dolfinx.fem.form(bilinear), dolfinx.fem.form(linear)
    compile_time = slowest(comm, time.perf_counter() - start)
    modes = (solvers.rigid_body_modes(V) if args.per_body_modes
             else global_rigid_body_modes(V))
    solves = []
    for _ in range(args.bonded_repeats):
        solves.append(_one_bonded_solve(comm, V, a, L, bcs, modes))
    memory = memory_mib()
    return {
        "num_dofs": V.dofmap.index_map.size_global * 3,
        "num_cells": mesh.topology.index_map(3).size_global,
        "cell": args.cell,
        "mesh_s": mesh_time,
        "form_compile_s": compile_time,
        "options": BONDED_OPTIONS,
        "near_nullspace_vectors": len(modes),
        "edge_ratio": edge_ratios(mesh),
        "solves": solves,
        "peak_mib_per_rank": comm.gather(memory["VmHWM"], root=0),
        "rss_mib_per_rank": comm.gather(memory["VmRSS"], root=0),
    }


def box_solve(args, comm) -> dict:
    """The bonded solve of the issue's first measurement, in this run: the unit cube of
    ``args.box``^3 cells of ``args.cell`` (uniform, aspect ratio 1), clamped at z = 0,
    the same material and solver, loaded by the body force."""
    cell = {"tetrahedron": dolfinx.mesh.CellType.tetrahedron,
            "hexahedron": dolfinx.mesh.CellType.hexahedron}[args.cell]
    mesh = dolfinx.mesh.create_unit_cube(comm, args.box, args.box, args.box, cell)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (3,)))
    u, v = dolfinx.fem.Function(V), ufl.TestFunction(V)
    work = internal_work(u, v, {0: Material(200.0, 0.3, "linear")})
    a = dolfinx.fem.form(ufl.derivative(work, u, ufl.TrialFunction(V)))
    L = dolfinx.fem.form(ufl.inner(dolfinx.fem.Constant(mesh, np.array([0.0, 0.0, -BODY_FORCE])),
                                   v) * ufl.dx)
    bottom = dolfinx.mesh.locate_entities_boundary(mesh, 2, lambda x: np.isclose(x[2], 0.0))
    dofs = dolfinx.fem.locate_dofs_topological(V, 2, bottom)
    bcs = [dolfinx.fem.dirichletbc(np.zeros(3), dofs, V)]
    modes = global_rigid_body_modes(V)
    solves = [_one_bonded_solve(comm, V, a, L, bcs, modes) for _ in range(args.bonded_repeats)]
    return {"num_dofs": V.dofmap.index_map.size_global * 3, "cells_per_edge": args.box,
            "cell": args.cell, "solves": solves}


def _one_bonded_solve(comm, V, a, L, bcs, modes) -> dict:
    """Assembly, GAMG set-up and CG solve of the bonded problem, timed apart."""
    comm.Barrier()
    start = time.perf_counter()
    A = dolfinx.fem.petsc.assemble_matrix(a, bcs=bcs)
    A.assemble()
    b = dolfinx.fem.petsc.assemble_vector(L)
    dolfinx.fem.petsc.apply_lifting(b, [a], bcs=[bcs])
    b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    compat.set_bc(b, bcs)
    vectors = []
    for values in modes:
        vector = A.createVecRight()
        vector.getArray()[:] = values
        vectors.append(vector)
    A.setNearNullSpace(PETSc.NullSpace().create(vectors=vectors, comm=comm))
    assembly = slowest(comm, time.perf_counter() - start)
    options = PETSc.Options()
    prefix = "bonded_"
    for key, value in BONDED_OPTIONS.items():
        options[prefix + key] = value
    ksp = PETSc.KSP().create(comm)
    ksp.setOptionsPrefix(prefix)
    ksp.setOperators(A)
    ksp.setFromOptions()
    comm.Barrier()
    start = time.perf_counter()
    ksp.setUp()
    set_up = slowest(comm, time.perf_counter() - start)
    x = A.createVecRight()
    comm.Barrier()
    start = time.perf_counter()
    ksp.solve(b, x)
    solve = slowest(comm, time.perf_counter() - start)
    record = {"assembly_s": assembly, "set_up_s": set_up, "solve_s": solve,
              "total_s": assembly + set_up + solve,
              "iterations": ksp.getIterationNumber(), "reason": ksp.getConvergedReason(),
              "block_size": A.getBlockSize()}
    for key in BONDED_OPTIONS:
        options.delValue(prefix + key)
    for obj in (ksp, A, b, x, *vectors):
        obj.destroy()
    return record


class CondensationTimer:
    """Wraps the condensed preconditioner's phases with wall clocks (this rank's), for
    the contact run; ``restore`` puts the originals back."""

    PHASES = {(condensation.CondensedPreconditioner, "_split"): "sub-matrices",
              (condensation.CondensedPreconditioner, "_choose_rows"): "rows near the contact",
              (condensation.CondensedPreconditioner, "_condensed_rows"): "condensed products",
              (inner_matrix.InnerMatrix, "fill"): "inner matrix",
              (condensation.CondensedPreconditioner, "setUp"): "set-up",
              (condensation.CondensedPreconditioner, "apply"): "application"}

    def __init__(self):
        self.seconds = {label: 0.0 for label in self.PHASES.values()}
        self.calls = {label: 0 for label in self.PHASES.values()}
        self.set_ups: list[dict] = []
        self.originals = {}
        for (cls, name), label in self.PHASES.items():
            original = getattr(cls, name)
            self.originals[cls, name] = original
            setattr(cls, name, self._timed(original, label))

    def _timed(self, original, label):
        timer = self

        @functools.wraps(original)
        def timed(condenser, *args, **kwargs):
            if label == "set-up":
                before = dict(timer.seconds)
                count = len(condenser.inner_iterations)
            start = time.perf_counter()
            result = original(condenser, *args, **kwargs)
            timer.seconds[label] += time.perf_counter() - start
            timer.calls[label] += 1
            if label == "set-up":
                timer.set_ups.append({
                    "seconds": {k: timer.seconds[k] - before[k] for k in timer.seconds},
                    "first_application": count, "active": condenser.num_active,
                    "rebuilds": condenser.rebuilds, "reuses": condenser.reuses})
                timer.inner_solver = condenser.ksp.getPC().getType()
                timer.inner = condenser.inner_iterations  # the list, still filled later
            return result

        return timed

    def restore(self) -> None:
        for (cls, name), original in self.originals.items():
            setattr(cls, name, original)

    def summary(self) -> dict:
        """Seconds per phase; the inner solver's set-up is the set-up less the products."""
        s = dict(self.seconds)
        products = (s["sub-matrices"] + s["rows near the contact"] + s["condensed products"]
                    + s["inner matrix"])
        s["condensation products"] = products
        s["inner solver set-up (AMG)"] = s["set-up"] - products
        inner = list(getattr(self, "inner", []))
        per_set_up = []
        for k, entry in enumerate(self.set_ups):
            end = (self.set_ups[k + 1]["first_application"] if k + 1 < len(self.set_ups)
                   else len(inner))
            per_set_up.append(inner[entry["first_application"]:end])
        return {"seconds": s, "calls": dict(self.calls), "inner_iterations": per_set_up,
                "inner_solver": getattr(self, "inner_solver", None)}


def contact_run(demo_args: list[str], args, comm) -> dict:
    """The demo with the condensed preconditioner timed (see the module docstring)."""
    timer = CondensationTimer()
    argv = ["--cell", args.cell, "--refinement", str(args.refinement),
            "--elements-per-radius", str(args.elements_per_radius), *demo_args]
    try:
        summary = demo("hertz_sphere").main(argv, comm=comm)
    finally:
        timer.restore()
    newton = sum(summary["newton_iterations"])
    parts = timer.summary()
    seconds = {key: slowest(comm, value) for key, value in parts["seconds"].items()}
    timings = summary["timings"]
    applications = sum(len(i) for i in parts["inner_iterations"])
    inner = [n for entry in parts["inner_iterations"] for n in entry]
    memory = memory_mib()
    per_newton = {key: value / newton for key, value in timings.items()}
    if parts["inner_solver"] is not None:
        per_newton.update({f"linear solve: {key}": value / newton for key, value in
                           seconds.items() if key in ("condensation products",
                                                      "inner solver set-up (AMG)",
                                                      "application")})
        per_newton["linear solve: outer rest"] = (
            timings["linear solve"] - seconds["set-up"] - seconds["application"]) / newton
    return {
        "demo_argv": argv,
        "num_dofs": summary["num_dofs"],
        "num_cells": summary["num_cells"],
        "linear_solver": summary["linear_solver"],
        "friction": summary["friction"],
        "newton_iterations": summary["newton_iterations"],
        "outer_iterations": summary["krylov_iterations"],
        "outer_per_newton": sum(summary["krylov_iterations"]) / newton,
        "inner_solver": parts["inner_solver"],
        "inner_iterations": parts["inner_iterations"],
        "inner_per_application": (sum(inner) / len(inner)) if inner else None,
        "inner_max": max(inner) if inner else None,
        "applications": applications,
        "condensation_seconds": seconds,
        "timings": timings,
        "per_newton_s": per_newton,
        "p_max_error_rel": summary["p_max_error_rel"],
        "l2_pressure_error_rel": summary["l2_pressure_error_rel"],
        "wall_time_s": summary["wall_time_s"],
        "peak_mib_per_rank": comm.gather(memory["VmHWM"], root=0),
    }


def report(result: dict) -> None:
    bonded = result["bonded"]
    last = bonded["solves"][-1]
    print(f"bonded ({bonded['cell']}, {bonded['num_dofs']} dofs): assembly "
          f"{last['assembly_s']:.3f} s, GAMG set-up {last['set_up_s']:.3f} s, CG "
          f"{last['solve_s']:.3f} s ({last['iterations']} iterations), total "
          f"{last['total_s']:.3f} s (median of the solves after the first: "
          f"{bonded['median_s']:.3f} s); peak RSS per rank {bonded['peak_mib_per_rank']} MiB; "
          "edge ratio (longest / shortest edge of a cell) median {median:.2f}, 90th "
          "percentile {p90:.2f}, max {max:.2f}, above 10: {fraction_above_10:.1%}".format(
              **bonded["edge_ratio"]))
    if "box" in result:
        box = result["box"]["solves"][-1]
        print(f"bonded on the unit cube ({result['box']['num_dofs']} dofs): assembly "
              f"{box['assembly_s']:.3f} s, GAMG set-up {box['set_up_s']:.3f} s, CG "
              f"{box['solve_s']:.3f} s ({box['iterations']} iterations), total "
              f"{box['total_s']:.3f} s")
    contact = result.get("contact")
    if contact is None:
        return
    print(f"contact ({contact['num_dofs']} dofs, {contact['linear_solver']} solver, "
          f"inner {contact['inner_solver']}): Newton {contact['newton_iterations']}, outer "
          f"{contact['outer_iterations']} ({contact['outer_per_newton']:.1f} per Newton), "
          f"inner per application {contact['inner_per_application']} (max "
          f"{contact['inner_max']})")
    for key, value in contact["per_newton_s"].items():
        print(f"  per Newton iteration, {key}: {value:.3f} s")
    print(f"ratio (contact per Newton iteration) / (bonded solve): {result['ratio']:.1f}; "
          f"load average {result['load_before']} -> {result['load_after']}")


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter,
                                     epilog=__doc__.split("\n\n", 1)[1])
    parser.add_argument("--cell", choices=meshes3d.CELL_TYPES_3D, default="tetrahedron")
    parser.add_argument("--refinement", type=int, default=1)
    parser.add_argument("--elements-per-radius", type=int, default=meshes3d.ELEMENTS_PER_RADIUS)
    parser.add_argument("--bonded-only", action="store_true")
    parser.add_argument("--hexahedral-growth", type=float, default=None,
                        help="size ratio of neighbouring graded hexahedra (default "
                             f"meshes3d.HEXAHEDRAL_GROWTH = {meshes3d.HEXAHEDRAL_GROWTH}): "
                             "a mesh-quality experiment, for the bonded and the contact run")
    parser.add_argument("--per-body-modes", action="store_true",
                        help="the bonded solve's near-nullspace: six modes per body (as the "
                             "contact problem's K_c) instead of the mesh's six")
    parser.add_argument("--box", type=int, default=0,
                        help="also solve the bonded problem on the unit cube of BOX^3 cells "
                             "(0: not)")
    parser.add_argument("--bonded-repeats", type=int, default=4)
    parser.add_argument("--json", type=pathlib.Path, default=None)
    parser.add_argument("demo_args", nargs=argparse.REMAINDER,
                        help="after --: options of demos/hertz_sphere.py (--mu, --steps, "
                             "--linear-solver, ...)")
    args = parser.parse_args(argv)
    demo_args = args.demo_args[1:] if args.demo_args[:1] == ["--"] else args.demo_args
    comm = MPI.COMM_WORLD
    # the bonded solve runs before the contact run imports dolfinx_mortar.problem: both
    # with the same malloc (dolfinx_mortar.allocator)
    released = allocator.release_freed_memory()
    if args.hexahedral_growth is not None:
        meshes3d.HEXAHEDRAL_GROWTH = args.hexahedral_growth
    result = {"ranks": comm.size, "hexahedral_growth": meshes3d.HEXAHEDRAL_GROWTH,
              "load_before": os.getloadavg()[0],
              "petsc_options_env": os.environ.get("PETSC_OPTIONS", ""),
              "freed_memory_released": released,
              "bonded": bonded_solve(args, comm)}
    timed = result["bonded"]["solves"][1:] or result["bonded"]["solves"]
    result["bonded"]["median_s"] = statistics.median(s["total_s"] for s in timed)
    if args.box:
        result["box"] = box_solve(args, comm)
    if not args.bonded_only:
        result["contact"] = contact_run(demo_args, args, comm)
        per_newton = result["contact"]["timings"]["total"] / sum(
            result["contact"]["newton_iterations"])
        result["ratio"] = per_newton / result["bonded"]["median_s"]
    else:
        result["ratio"] = math.nan
    result["load_after"] = os.getloadavg()[0]
    if comm.rank == 0:
        report(result)
        if args.json is not None:
            args.json.parent.mkdir(parents=True, exist_ok=True)
            args.json.write_text(json.dumps(result, indent=1, default=str))
    return result


if __name__ == "__main__":
    main()
