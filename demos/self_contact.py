"""Self-contact: one surface that touches itself, found and enforced by the mortar method.

``--case patch``: the self-contact patch test. One block [0, 2] x [0, 2] (3D: times
[0, 1/2]) is slit along x = 1 from y = 0 to y = 1.2; its halves are one mesh above the
tip, and the slit's two lips, one surface (one facet tag) meshed non-matching in the ratio
``--ratio``, are its only contact surface: ``ContactPair(tags, slit, slit)``. The sides are
pushed together (u_x = +d at x = 0, -d at x = 2; rollers at y = 0 and, 3D, z = 0), so
that the lips press on each other and the stress is uniform: sigma_xx = -p everywhere, a
uniform contact pressure p along the whole slit (linear material: p = E d in 3D,
4 mu (lambda + mu) / (lambda + 2 mu) d in plane strain). The search pairs the lips' facets
that face each other, the finer lip becomes the slave (the tip's node, on both lips,
carries no multiplier), and the mortar integrals pass the uniform pressure through the
non-matching lips exactly.

``--case crush``: half a Neo-Hookean ring (radii 0.7 and 1, E = 1, the plane x = 0 a
symmetry plane) between two plates (E = 100) that touch it; the upper plate is driven
down by ``--depth`` (1.5: the plates end 0.5 apart) in ``--steps`` equal steps. The ring's
outer arc is the slave of one pair with each plate; its inner arc is one self-contact
surface, ``ContactPair(tags, inner, inner)``: its walls meet at about 0.9 of the travel and
flatten against each other from the middle out. ``--dim 3``: the same cross-section as a
slice of a tube, ``--length`` long (default the wall thickness, 0.3), its ends and the
plates' held in z (a slice of a long tube; tetrahedra, ``meshes3d.crushed_tube``); the
inner cylinder is the self-contact surface. The plate force against its travel goes to
a CSV and a PNG, the displacement to ParaView at every step (``--output``).

JSON (``--json``), patch: ``max_pressure_deviation_rel`` (largest |p_node - p| / p over the
slave lip's nodes, linear material; with a nonlinear material the spread
(max - min) / mean), ``max_penetration_rel`` (deepest node behind the other lip, in facet
lengths), ``force_balance`` (|slave force + master force| / |slave force|),
``newton_iterations``, ``converged``. Crush: ``converged`` (every step), ``newton_iterations``
and ``cutbacks`` per step, ``max_penetration_rel`` (the deepest node of either wall behind
the other over all steps, in facet lengths), ``force_balance`` (|F_top + F_bottom| /
|F_top| of the plates' forces on the ring: the self-contact forces cancel within the
ring), ``plate_force``, ``plate_travel`` and ``inner_active`` (the inner walls' nodes in
contact) per step.

Run:  python3 demos/self_contact.py --ratio 5:7 --json self.json
      python3 demos/self_contact.py --case crush --output crush
      python3 demos/self_contact.py --dim 3 --case crush --output tube
      mpirun -n 3 python3 demos/self_contact.py --dim 3 --cell hexahedron --ratio 4:6
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
    diagnostics,
    internal_work,
    meshes,
    meshes3d,
    solve_load_steps,
)

DEMOS = pathlib.Path(__file__).resolve().parent
if str(DEMOS) not in sys.path:  # loaded from its path (tests, benchmarks): find demos/cli.py
    sys.path.insert(0, str(DEMOS))
import cli  # noqa: E402
from cli import option_record, problem_options, write_summary  # noqa: E402

E, NU, SQUEEZE = 1000.0, 0.3, 0.01


def exact_pressure(gdim: int, E: float = E, nu: float = NU, squeeze: float = SQUEEZE) -> float:
    """The uniform contact pressure of the linear patch test (strain -squeeze across)."""
    if gdim == 3:
        return E * squeeze
    lam, mu = E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))
    return 4.0 * mu * (lam + mu) / (lam + 2.0 * mu) * squeeze


def main(argv=None, comm: MPI.Intracomm = MPI.COMM_WORLD) -> dict:
    parser = cli.parser(__doc__)
    parser.add_argument("--dim", type=int, choices=(2, 3), default=2, help="2D or 3D")
    parser.add_argument("--case", choices=("patch", "crush"), default="patch",
                        help="which problem")
    parser.add_argument("--ratio", default="5:7", help="left:right lip elements along the slit")
    parser.add_argument("--cell-type", "--cell", choices=meshes.CELL_TYPES + meshes.CELL_TYPES_3D,
                        default=None, help="cells (default: triangle in 2D, tetrahedron in 3D)")
    parser.add_argument("--steps", type=int, default=60, help="load steps (crush)")
    parser.add_argument("--depth", type=float, default=1.5, help="plate travel (crush)")
    parser.add_argument("--refinement", type=int, default=0, help="halves h per level (crush)")
    parser.add_argument("--length", type=float, default=None,
                        help="the slice's length (3D crush; default: the wall thickness)")
    parser.add_argument("--no-self-contact", dest="self_contact", action="store_false",
                        help="crush without the inner walls' pair (what self-contact costs "
                        "while the walls are apart: --depth 1.3)")
    cli.add_material_argument(parser)
    cli.add_common_arguments(parser)
    args = parser.parse_args(argv)
    if args.case == "crush":
        if args.cell_type not in (None, "triangle", "tetrahedron"):
            parser.error("--case crush is meshed with triangles (2D) or tetrahedra (3D)")
        return crush(args, comm)
    allowed = meshes.CELL_TYPES if args.dim == 2 else meshes.CELL_TYPES_3D
    if args.cell_type is None:
        args.cell_type = allowed[0]
    if args.cell_type not in allowed:
        parser.error(f"--cell-type {args.cell_type} is not a {args.dim}D cell (one of {allowed})")
    ratio = tuple(int(n) for n in args.ratio.split(":"))
    start = time.perf_counter()
    tagged = meshes.slit_block(ratio, args.cell_type, comm)
    mesh, markers, gdim = tagged.mesh, tagged.markers, args.dim
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (gdim,)))
    u = dolfinx.fem.Function(V, name="displacement")
    F = internal_work(u, ufl.TestFunction(V), {markers["block"]: Material(E, NU, args.material)},
                      tagged.cell_tags)

    def held(tag: str, component: int, value: float):
        facets = tagged.facet_tags.find(markers[tag])
        dofs = dolfinx.fem.locate_dofs_topological(V.sub(component), gdim - 1, facets)
        return dolfinx.fem.dirichletbc(dolfinx.default_scalar_type(value), dofs, V.sub(component))

    bcs = [held("left", 0, SQUEEZE), held("right", 0, -SQUEEZE), held("bottom", 1, 0.0)]
    if gdim == 3:
        bcs.append(held("back", 2, 0.0))
    pair = ContactPair(tagged.facet_tags, markers["slit"], markers["slit"], name="slit")
    configuration = "reference" if args.material == "linear" else "current"
    with ContactProblem(F, u, bcs, [pair], configuration=configuration,
                        **problem_options(args)) as problem:
        report = problem.solve()
        if args.output:
            output = ContactOutput(problem, args.output / "paraview")
            output.write(1.0)
            output.close()
        carrying = _carrying_multipliers(problem, comm)
        p, raw = (np.concatenate(comm.allgather(problem.contact_pressure(raw=raw)[1][carrying]))
                  for raw in (False, True))
        if args.material == "linear":
            expected = exact_pressure(gdim)
            deviation = float(np.max(np.abs(p - expected)) / expected)
            raw_deviation = float(np.max(np.abs(raw - expected)) / expected)
        else:
            deviation, raw_deviation = (float(np.ptp(v) / np.mean(v)) for v in (p, raw))
        penetration = diagnostics.penetration_report(
            comm, 0.0, *problem.interfaces[0].pair_sides())
        slave_force, master_force = problem.contact_forces()
        balance = float(np.linalg.norm(slave_force + master_force) / np.linalg.norm(slave_force))
        summary = {
            "case": args.case, "dim": gdim, "ratio": list(ratio), "cell_type": args.cell_type,
            "material": args.material, **option_record(args), "num_ranks": comm.size,
            "converged": report.converged, "newton_iterations": report.iterations,
            "slave_nodes": int(p.size),
            "surface_nodes": interface_nodes(problem),
            "pressure_min": float(p.min()), "pressure_max": float(p.max()),
            "max_pressure_deviation_rel": deviation,
            "max_multiplier_deviation_rel": raw_deviation,
            "max_penetration_rel": float(penetration.depth),
            "force_balance": balance, "slave_force": slave_force.tolist(),
            "num_dofs": V.dofmap.index_map.size_global * gdim,
            "wall_time_s": comm.allreduce(time.perf_counter() - start, op=MPI.MAX),
        }
    if comm.rank == 0:
        print(f"self-contact patch test {gdim}D {args.cell_type} {args.ratio}: pressure "
              f"deviation {deviation:.3e} over {summary['slave_nodes']} slave nodes, "
              f"penetration {penetration.depth:.2e} facet lengths, force balance "
              f"{balance:.1e}, {report.iterations} Newton iterations", flush=True)
        write_summary(args.json, summary)
    return summary


def crush(args, comm) -> dict:
    """``--case crush``: see the module docstring."""
    start = time.perf_counter()
    gdim = args.dim
    tagged = (meshes.crushed_ring(args.refinement, comm=comm) if gdim == 2
              else meshes3d.crushed_tube(args.refinement, length=args.length, comm=comm))
    mesh, markers, facet_tags = tagged.mesh, tagged.markers, tagged.facet_tags
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (gdim,)))
    u = dolfinx.fem.Function(V, name="displacement")
    materials = {markers["ring"]: Material(1.0, NU, "neo-hookean"),
                 markers["plate_top"]: Material(100.0, NU, "neo-hookean"),
                 markers["plate_bottom"]: Material(100.0, NU, "neo-hookean")}
    F = internal_work(u, ufl.TestFunction(V), materials, tagged.cell_tags)

    def dofs(name: str, component: int | None = None):
        space = V if component is None else V.sub(component)
        return dolfinx.fem.locate_dofs_topological(space, gdim - 1,
                                                   facet_tags.find(markers[name]))

    travel = dolfinx.fem.Constant(mesh, 0.0)
    bcs = [dolfinx.fem.dirichletbc(np.float64(0.0), dofs("symmetry", 0), V.sub(0)),
           dolfinx.fem.dirichletbc(np.zeros(gdim), dofs("plate_bottom_support"), V),
           dolfinx.fem.dirichletbc(np.float64(0.0), dofs("plate_top_load", 0), V.sub(0)),
           dolfinx.fem.dirichletbc(travel, dofs("plate_top_load", 1), V.sub(1))]
    if gdim == 3:  # the slice's ends held in z: a slice of a long tube
        bcs.append(dolfinx.fem.dirichletbc(np.float64(0.0), dofs("ends", 2), V.sub(2)))
    pairs = [ContactPair(facet_tags, markers["ring_outer_top"], markers["plate_top_contact"],
                         name="ring-top plate"),
             ContactPair(facet_tags, markers["ring_outer_bottom"],
                         markers["plate_bottom_contact"], name="ring-bottom plate"),
             ContactPair(facet_tags, markers["ring_inner"], markers["ring_inner"],
                         name="inner walls")][:3 if args.self_contact else 2]
    history = []
    with ContactProblem(F, u, bcs, pairs, **problem_options(args)) as problem:
        inner = problem.interfaces[2] if args.self_contact else None

        def apply_load(t: float) -> None:
            travel.value = -args.depth * t

        def record(step) -> None:
            top, bottom = (problem.contact_forces(k)[0] for k in (0, 1))
            slave, master = problem.contact_forces(2) if inner else (np.zeros(gdim),) * 2
            penetration = (diagnostics.penetration_report(comm, 0.0, *inner.pair_sides())
                           if inner else diagnostics.Penetration())
            history.append({
                "t": step.load, "plate_travel": args.depth * step.load,
                "newton_iterations": step.iterations, "cutbacks": step.cutbacks,
                "plate_force": float(-top[1]), "bottom_force": float(bottom[1]),
                "inner_force": float(np.linalg.norm(slave)),
                "inner_balance": float(np.linalg.norm(slave + master)),
                "penetration_rel": float(penetration.depth),
                "inner_active": int(comm.allreduce(int(problem.active[2].sum()))) if inner
                else 0,
            })

        output = ContactOutput(problem, args.output / "paraview") if args.output else None
        records = solve_load_steps(problem, apply_load, args.steps, output=output,
                                   on_step=record)
        if output is not None:
            output.close()
    top = np.array([h["plate_force"] for h in history])
    bottom = np.array([h["bottom_force"] for h in history])
    summary = {
        "case": "crush", "dim": gdim, "refinement": args.refinement, **option_record(args),
        "num_ranks": comm.size, "steps": args.steps, "depth": args.depth,
        "self_contact": args.self_contact,
        "converged": bool(records) and abs(records[-1].load - 1.0) < 1e-12,
        "newton_iterations": [h["newton_iterations"] for h in history],
        "cutbacks": [h["cutbacks"] for h in history],
        "max_penetration_rel": max(h["penetration_rel"] for h in history),
        "force_balance": float(np.max(np.abs(top - bottom)) / np.max(np.abs(top))),
        "inner_balance_rel": max(h["inner_balance"] for h in history)
        / max(max(h["inner_force"] for h in history), 1e-300),
        "solve_time_s": float(sum(r.wall_time for r in records)),
        "plate_travel": [h["plate_travel"] for h in history],
        "plate_force": top.tolist(), "inner_force": [h["inner_force"] for h in history],
        "inner_active": [h["inner_active"] for h in history],
        "num_dofs": V.dofmap.index_map.size_global * gdim,
        "wall_time_s": comm.allreduce(time.perf_counter() - start, op=MPI.MAX),
    }
    if comm.rank == 0:
        print(f"crushed {'ring' if gdim == 2 else 'tube'}: {len(history)} steps, Newton "
              f"iterations per step at most {max(summary['newton_iterations'])}, "
              f"{sum(summary['cutbacks'])} cut-backs, "
              f"plate force {top[-1]:.4g} at travel {args.depth:g}, "
              f"{summary['inner_active'][-1]} inner nodes in contact, deepest penetration "
              f"{summary['max_penetration_rel']:.3g} facet "
              f"lengths, force balance {summary['force_balance']:.1e}", flush=True)
        write_summary(args.json, summary)
        if args.output:
            _plot_crush(args.output, history, gdim)
    return summary


def _plot_crush(folder: pathlib.Path, history: list[dict], gdim: int) -> None:
    import csv

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    folder.mkdir(parents=True, exist_ok=True)
    keys = ("plate_travel", "plate_force", "inner_force", "newton_iterations", "cutbacks",
            "penetration_rel", "inner_active")
    with open(folder / "crush_force.csv", "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(keys)
        writer.writerows([h[k] for k in keys] for h in history)
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    travel = [h["plate_travel"] for h in history]
    ax.plot(travel, [h["plate_force"] for h in history], "o-", ms=3, label="plate force")
    ax.plot(travel, [h["inner_force"] for h in history], "s--", ms=3,
            label="inner walls' contact force")
    ax.set_xlabel("plate travel")
    ax.set_ylabel("force (half model, per unit thickness)" if gdim == 2
                  else "force (half model, the slice)")
    ax.legend()
    ax.grid(True, alpha=0.3)
    cli.save_figure(fig, folder / "crush_force.png")


def interface_nodes(problem: ContactProblem) -> int:
    """The number of nodes of the self-contact surface (each carries a multiplier slot)."""
    return int(problem.interfaces[0].num_global_multipliers)


def _carrying_multipliers(problem: ContactProblem, comm) -> np.ndarray:
    """Which of this rank's multipliers carry the contact: those of nodes on the slave side
    of the pairs and not on the master side (the slit's tip is on both: it carries none).
    Collective."""
    interface = problem.interfaces[0]
    sides = interface.pair_sides()
    slave, master = (np.concatenate(comm.allgather(blocks)) for blocks in (sides[0], sides[3]))
    return np.isin(interface.owned_multiplier_blocks, np.setdiff1d(slave, master))


if __name__ == "__main__":
    main()
