"""Cattaneo-Mindlin: a cylinder pressed onto a block, then pulled sideways (plane strain).

The geometry and materials of Hertz case B (demos/hertz.py: a half-cylinder of
radius R = 8 on a block, both E = 200, nu = 0.3, so the normal and tangential
problems decouple): first the force P = 10 (per unit thickness), then, at fixed
P, a tangential force Q = ``--tangential-ratio`` mu P, both applied on the
cylinder's flat top, with Coulomb friction mu = ``--mu`` on the contact.
Cattaneo (1938) and Mindlin (1949): the pressure stays Hertz's,
p = p0 sqrt(1 - x^2/a^2), a central zone |x| < c = a sqrt(1 - Q/(mu P)) sticks
and the rest slips, with the tangential traction

    q(x) = mu p0 (sqrt(1 - x^2/a^2) - (c/a) sqrt(1 - x^2/c^2))   for |x| < c,
    q(x) = mu p(x)                                               for c <= |x| <= a.

Loading without a moment about the contact point: Q enters as a uniform shear
traction Q/(2R) on the top (at height R) together with a vertical traction
varying linearly along the top, 3 Q R x / (2 R^3) (x in [-R, R]), whose couple
cancels Q R; the cylinder is held only by contact and friction (no symmetry
constraint), the block clamped at its bottom. The mortar integrals and normals
are those of demos/hertz.py for linear elasticity (reference configuration,
master normals, dual multipliers, semismooth Newton).

``--normal-phase``: by default P is applied without friction, so that no
tangential traction is locked in before Q, as the theory assumes; with
friction during P (``frictional``), the finite cylinder's and block's unequal
tangential surface displacements leave a traction of about 12 % of mu p0 in
the contact zone (measured at refinement 2), which Q then adds to.

Measured (mu = 0.2, frictionless normal phase, 2 + 4 load steps; L2 rate fitted
over refinements 0-3; serial):

    Q/(mu P)  dofs (ref. 0 .. 3)  |c - c_exact| / h   L2 error (ref. 0 .. 3)   Newton
    0.3       1,500 .. 76,846     <= 0.92            32, 14, 6.2, 3.4 %       <= 5
    0.7       1,500 .. 76,846     <= 0.85            10, 5.5, 3.0, 1.6 %      <= 5

fitted L2 rates 1.11 (0.3) and 0.91 (0.7); the tangential force is -Q to 1.4e-14;
10 and 40 load steps give the same tractions to 5e-14 of mu p0.

JSON keys: ``stick_half_width`` (half the extent of the sticking slave nodes),
``stick_half_width_exact``, ``stick_error_in_elements``, ``q_max``,
``l2_traction_error_rel`` (L2 norm over |x| < 3a of the piecewise-linear nodal
traction minus q, relative to that of q), ``total_tangential_force`` (the
friction force on the cylinder, -Q exactly at equilibrium) and its error,
``total_force``, ``p_max``, ``a_contact``, ``newton_iterations`` (per step:
``--steps`` normal ones, then ``--tangential-steps``), ``min_nodal_dissipation_rel``
(the smallest nodal frictional work y_j u~_j of any step over the largest of any
step: >= 0 but for rounding), ``num_dofs``, ``wall_time_s``.

Outputs (``--output DIR``): cattaneo_mindlin.png (pressure and tangential
traction against the exact curves), cattaneo_mindlin.csv, paraview/*.bp
(displacement, pressure, tangential traction and stick/slip status per step).

Run:  mpirun -n 2 python3 demos/cattaneo_mindlin.py --mu 0.2 --tangential-ratio 0.7 --refinement 2
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
    meshes3d,
    solve_load_steps,
)

DEMOS = pathlib.Path(__file__).resolve().parent
if str(DEMOS) not in sys.path:  # loaded from its path (tests, benchmarks): find demos/cli.py
    sys.path.insert(0, str(DEMOS))
import hertz_sphere  # noqa: E402

import cli  # noqa: E402
from cli import write_summary  # noqa: E402

E, NU, LOAD, RADIUS = 200.0, 0.3, 10.0, 8.0


def exact_solution(load: float, radius: float, mu: float, ratio: float) -> dict:
    """Hertz a, p0 and the stick half-width c of Cattaneo-Mindlin (equal materials)."""
    effective_modulus = 1.0 / (2.0 * (1.0 - NU**2) / E)
    a = math.sqrt(4.0 * load * radius / (math.pi * effective_modulus))
    return {"a": a, "p0": 2.0 * load / (math.pi * a), "c": a * math.sqrt(1.0 - ratio),
            "mu": mu}


def exact_traction(x, exact: dict) -> np.ndarray:
    """q(x) of the module docstring."""
    a, c, p0, mu = exact["a"], exact["c"], exact["p0"], exact["mu"]
    full = mu * p0 * np.sqrt(np.clip(1.0 - (x / a) ** 2, 0.0, None))
    if c <= 0.0:
        return full
    return full - np.where(np.abs(x) < c,
                           mu * p0 * (c / a) * np.sqrt(np.clip(1.0 - (x / c) ** 2, 0.0, None)),
                           0.0)


def l2_error(x_nodes, values, exact_values, samples_per_facet: int = 64) -> tuple[float, float]:
    """Absolute and relative L2 error of the piecewise-linear nodal values along x."""
    total, norm = 0.0, 0.0
    s = (np.arange(samples_per_facet) + 0.5) / samples_per_facet
    for i in range(x_nodes.size - 1):
        x = x_nodes[i] + s * (x_nodes[i + 1] - x_nodes[i])
        value = values[i] + s * (values[i + 1] - values[i])
        weight = (x_nodes[i + 1] - x_nodes[i]) / samples_per_facet
        exact = exact_values(x)
        total += weight * np.sum((value - exact) ** 2)
        norm += weight * np.sum(exact**2)
    return math.sqrt(total), math.sqrt(total / norm) if norm > 0 else math.nan


def bulk_problem(tagged, u):
    """(F, (normal, tangential) load Constants, bcs): the block clamped at its bottom."""
    mesh, markers = tagged.mesh, tagged.markers
    V = u.function_space
    v = ufl.TestFunction(V)
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=tagged.facet_tags)
    normal = dolfinx.fem.Constant(mesh, 0.0)
    tangential = dolfinx.fem.Constant(mesh, 0.0)
    x = ufl.SpatialCoordinate(mesh)
    width = 2.0 * RADIUS
    # -P/(2R) down, Q/(2R) along x, and 3 Q x / (2 R^2) up: no moment about the origin
    traction = ufl.as_vector([tangential / width,
                              -normal / width + 3.0 * tangential * x[0] / (2.0 * RADIUS**2)])
    material = Material(E, NU, "linear")
    F = (internal_work(u, v, {markers["cylinder"]: material, markers["block"]: material},
                       tagged.cell_tags)
         - ufl.inner(traction, v) * ds(markers["load"]))
    support = tagged.facet_tags.find(markers["support"])
    bcs = [dolfinx.fem.dirichletbc(
        np.zeros(2), dolfinx.fem.locate_dofs_topological(V, mesh.topology.dim - 1, support), V)]
    return F, (normal, tangential), bcs


def press_then_pull(problem, press, pull, steps: int, args) -> tuple[list, list]:
    """The normal load in ``steps`` steps (without friction unless ``--normal-phase
    frictional``), then the tangential one in ``--tangential-steps``, ParaView output of
    each step with ``--output``: the step records and, per step, the smallest and the
    largest nodal frictional work (over all ranks). Collective."""
    comm = problem.comm
    dissipation = []

    def record(step) -> None:
        work = problem.friction_state()["dissipation"]
        dissipation.append((comm.allreduce(float(work.min(initial=0.0)), op=MPI.MIN),
                            comm.allreduce(float(np.abs(work).max(initial=0.0)), op=MPI.MAX)))

    output = ContactOutput(problem, args.output / "paraview") if args.output else None
    law = problem.friction.laws[0]
    if args.normal_phase == "frictionless":
        problem.friction.laws[0] = None
    records = solve_load_steps(problem, press, steps, output=output, on_step=record,
                               predictor=args.predictor)
    problem.friction.laws[0] = law
    records += solve_load_steps(problem, pull, args.tangential_steps, output=output,
                                on_step=record, predictor=args.predictor)
    if output is not None:
        output.close()
    return records, dissipation


def main(argv=None, comm: MPI.Intracomm = MPI.COMM_WORLD) -> dict:
    parser = cli.parser(__doc__)
    parser.add_argument(
        "--tangential-ratio", type=float, default=0.5, help="Q / (mu P), in [0, 1)")
    parser.add_argument("--dim", type=int, choices=(2, 3), default=2,
                        help="2: the cylinder (plane strain); 3: a sphere on a block")
    parser.add_argument(
        "--refinement", type=int, default=None,
        help="halves the element sizes per level (default 1 in 2D, 0 in 3D)")
    parser.add_argument(
        "--steps", type=int, default=None,
        help="load steps of the normal force (default 2 in 2D; in 3D enough that the "
        "contact edge moves by at most 3 elements per step)")
    parser.add_argument(
        "--tangential-steps", type=int, default=4, help="load steps of the tangential force")
    parser.add_argument(
        "--normal-phase", choices=("frictionless", "frictional"), default="frictionless",
        help="friction while P is applied (the theory has no tangential traction after it)")
    cli.add_common_arguments(parser, normals="master", mu=0.2)
    cli.add_predictor_argument(parser)
    args = parser.parse_args(argv)
    if args.tresca is not None:
        parser.error("this demo is about Coulomb friction: use --mu, not --tresca")
    if not args.mu > 0.0:
        parser.error(f"--mu must be positive, got {args.mu}")
    if not 0.0 <= args.tangential_ratio < 1.0:
        parser.error(f"--tangential-ratio must lie in [0, 1), got {args.tangential_ratio}")
    configure_logging(comm)
    if args.dim == 3:
        return main_3d(args, comm)
    args.refinement = 1 if args.refinement is None else args.refinement
    args.steps = 2 if args.steps is None else args.steps
    exact = exact_solution(LOAD, RADIUS, args.mu, args.tangential_ratio)
    tangential_load = args.tangential_ratio * args.mu * LOAD
    start = time.perf_counter()

    tagged = meshes.hertz(case="B", refinement=args.refinement, radius=RADIUS, comm=comm,
                          half_width=exact["a"])
    markers = tagged.markers
    V = dolfinx.fem.functionspace(tagged.mesh, ("Lagrange", 1, (2,)))
    u = dolfinx.fem.Function(V, name="displacement")
    F, (normal, tangential), bcs = bulk_problem(tagged, u)
    pair = ContactPair(tagged.facet_tags, markers["contact_slave"], markers["contact_master"],
                       name="cylinder-block")
    problem = ContactProblem(F, u, bcs, [pair], configuration="reference",
                             **cli.problem_options(args))

    cylinder_cells = tagged.cell_tags.find(markers["cylinder"])
    indentation = (0.5 * exact["a"]) ** 2 / (2.0 * RADIUS)
    u.interpolate(lambda x: np.vstack([0.0 * x[0], -indentation + 0.0 * x[0]]), cylinder_cells)
    u.x.scatter_forward()

    def press(t: float) -> None:
        normal.value = t * LOAD

    def pull(t: float) -> None:
        tangential.value = t * tangential_load

    records, dissipation = press_then_pull(problem, press, pull, args.steps, args)
    wall_time = comm.allreduce(time.perf_counter() - start, op=MPI.MAX)

    coordinates, pressure = problem.gathered_pressure()
    state = problem.friction_state()
    gathered = {key: np.concatenate(comm.allgather(state[key]))
                for key in ("traction", "sticking", "slipping")}
    x_all = np.concatenate(comm.allgather(state["coordinates"][:, 0]))
    order = np.argsort(x_all)
    x_nodes = x_all[order]
    traction, sticking, slipping = (gathered[key][order]
                                    for key in ("traction", "sticking", "slipping"))
    zone = np.abs(x_nodes) < 3.0 * exact["a"]
    spacing = float(np.max(np.diff(x_nodes[zone])))
    stuck = x_nodes[sticking]
    stick_half_width = 0.5 * float(stuck.max() - stuck.min()) if stuck.size else 0.0
    error, error_rel = l2_error(x_nodes[zone], traction[zone],
                                lambda x: exact_traction(x, exact))
    in_contact = pressure > 1e-8 * exact["p0"]
    x_pressure = coordinates[:, 0]
    a_contact = 0.5 * float(np.ptp(x_pressure[in_contact])) if in_contact.any() else 0.0
    slave_force, master_force = problem.contact_forces()
    summary = {
        "mu": args.mu,
        "tangential_ratio": args.tangential_ratio,
        "load": LOAD,
        "tangential_load": tangential_load,
        "normal_phase": args.normal_phase,
        **cli.option_record(args),
        "c_n": problem.c_n,
        "c_t": problem.c_t,
        "refinement": args.refinement,
        "num_ranks": comm.size,
        "num_dofs": V.dofmap.index_map.size_global * 2,
        "h_contact": spacing,
        "a_exact": exact["a"],
        "a_contact": a_contact,
        "p0_exact": exact["p0"],
        "p_max": float(pressure.max()),
        "stick_half_width": stick_half_width,
        "stick_half_width_exact": exact["c"],
        "stick_error_in_elements": abs(stick_half_width - exact["c"]) / spacing,
        "num_sticking": int(sticking.sum()),
        "num_slipping": int(slipping.sum()),
        "q_max": float(np.max(np.abs(traction))),
        "q_max_exact": float(np.max(np.abs(exact_traction(x_nodes[zone], exact)))),
        "l2_traction_error": error,
        "l2_traction_error_rel": error_rel,
        "total_force": float(slave_force[1]),
        "total_force_error_rel": float(abs(slave_force[1] - LOAD) / LOAD),
        "total_tangential_force": float(slave_force[0]),
        "total_tangential_force_error_rel": (
            float(abs(slave_force[0] + tangential_load) / tangential_load)
            if tangential_load > 0 else float(abs(slave_force[0]) / LOAD)),
        "force_balance": float(np.linalg.norm(slave_force + master_force) / LOAD),
        "newton_iterations": [r.iterations for r in records],
        "min_nodal_dissipation_rel": float(
            min(low for low, _ in dissipation) / max(max(high for _, high in dissipation), 1e-300)),
        "residuals_last_step": records[-1].report.residuals,
        "cutbacks": sum(r.cutbacks for r in records),
        "wall_time_s": wall_time,
        "profile": {"x": x_nodes[zone].tolist(), "traction": traction[zone].tolist(),
                    "sticking": sticking[zone].astype(int).tolist()},
    }
    if comm.rank == 0:
        print(
            f"Cattaneo-Mindlin mu {args.mu}, Q/(mu P) {args.tangential_ratio}: stick half-width "
            f"{stick_half_width:.4f} (exact {exact['c']:.4f}, "
            f"{summary['stick_error_in_elements']:.2f} elements), q_max {summary['q_max']:.4f}, "
            f"L2 traction error {100 * error_rel:.2f} %, tangential force "
            f"{summary['total_tangential_force']:.10g} (-Q = {-tangential_load:g}), Newton "
            f"{summary['newton_iterations']}",
            flush=True,
        )
        write_summary(args.json, summary)
        if args.output:
            plot(args.output / "cattaneo_mindlin.png", x_nodes[zone], traction[zone],
                 sticking[zone], coordinates[:, 0], pressure, exact, summary)
            write_profile(args.output / "cattaneo_mindlin.csv", x_nodes[zone], traction[zone],
                          sticking[zone], exact)
    problem.destroy()
    return summary


def write_profile(path: pathlib.Path, x_nodes, traction, sticking, exact) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as stream:
        writer = csv.writer(stream)
        writer.writerow(["x", "tangential_traction", "sticking", "tangential_traction_exact"])
        for x, q, stick, q_exact in zip(x_nodes, traction, sticking,
                                        exact_traction(x_nodes, exact), strict=True):
            writer.writerow([repr(float(x)), repr(float(q)), int(stick), repr(float(q_exact))])


def plot(path: pathlib.Path, x_nodes, traction, sticking, x_pressure, pressure, exact,
         summary) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    a, mu = exact["a"], exact["mu"]
    x = np.linspace(-1.3 * a, 1.3 * a, 801)
    fig, ax = plt.subplots(figsize=(6.5, 4))
    ax.plot(x, mu * exact["p0"] * np.sqrt(np.clip(1 - (x / a) ** 2, 0, None)), "k:",
            label="mu p (Hertz)")
    ax.plot(x, exact_traction(x, exact), "k-", label="Cattaneo-Mindlin q")
    zone = np.abs(x_pressure) < 1.3 * a
    ax.plot(x_pressure[zone], mu * pressure[zone], ".", color="0.5", ms=3, label="mu z_j")
    ax.plot(x_nodes, traction, "o-", ms=3, label="mortar y_j")
    ax.plot(x_nodes[sticking], traction[sticking], "s", ms=4, mfc="none", label="sticking")
    ax.axvline(exact["c"], color="k", lw=0.5)
    ax.axvline(-exact["c"], color="k", lw=0.5)
    ax.set_xlim(-1.3 * a, 1.3 * a)
    ax.set_xlabel("x")
    ax.set_ylabel("tangential traction")
    ax.set_title(f"mu {summary['mu']}, Q/(mu P) {summary['tangential_ratio']}: c "
                 f"{summary['stick_half_width']:.3f} vs {exact['c']:.3f}")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    cli.save_figure(fig, path)


# --- 3D: a sphere on a block --------------------------------------------------------

LOAD_3D = 0.15
"""The total normal force P of the 3D case: demos/hertz_sphere.py's (R = 1, E = 200,
nu = 0.3 for both bodies: a = 0.1008, p0 = 7.05)."""


def exact_solution_3d(load: float, mu: float, ratio: float) -> dict:
    """Hertz a and p0 of a sphere (R = 1) on a half-space of the same material, and the
    stick radius c = a (1 - Q / (mu P))^(1/3) of Mindlin (1949)."""
    hertz = hertz_sphere.hertz_solution(load, 1.0, E, NU, E, NU, "block")
    return {"a": hertz["a"], "p0": hertz["p0"], "c": hertz["a"] * (1.0 - ratio) ** (1.0 / 3.0),
            "mu": mu, "R_star": hertz["R_star"]}


def exact_traction_3d(r, exact: dict) -> np.ndarray:
    """|q(r)|: the 2D formula of the module docstring with x the distance r from the
    axis (Mindlin's traction, parallel to Q; Johnson, Contact Mechanics, 7.2)."""
    return exact_traction(np.asarray(r, dtype=float), exact)


def bulk_problem_3d(tagged, u):
    """(F, (normal, tangential) load Constants, bcs) of the half model y >= 0: u_y = 0 on
    y = 0, the block clamped at its bottom, the sphere held by contact and friction only.

    On the sphere's flat top (z = R, a half disc of area A and second moment
    I = int x^2 dA about the y axis): -P/2 / A along z, Q/2 / A along x, and
    (Q/2) R x / I along z, whose moment about the contact point cancels the shear's,
    so that the sphere is pulled without a moment, as the theory assumes."""
    mesh, markers = tagged.mesh, tagged.markers
    V = u.function_space
    v = ufl.TestFunction(V)
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=tagged.facet_tags)
    x = ufl.SpatialCoordinate(mesh)

    def integral(form) -> float:
        local = dolfinx.fem.assemble_scalar(dolfinx.fem.form(form * ds(markers["load"])))
        return mesh.comm.allreduce(local, op=MPI.SUM)

    area = integral(dolfinx.fem.Constant(mesh, 1.0))
    moment = integral(x[0] ** 2)  # of the discrete (faceted) top: the totals are exact
    height = 1.0
    normal = dolfinx.fem.Constant(mesh, 0.0)
    tangential = dolfinx.fem.Constant(mesh, 0.0)
    traction = ufl.as_vector([
        0.5 * tangential / area, 0.0,
        -0.5 * normal / area + 0.5 * tangential * height * x[0] / moment])
    material = Material(E, NU, "linear")
    F = (internal_work(u, v, {markers["sphere"]: material, markers["block"]: material},
                       tagged.cell_tags)
         - ufl.inner(traction, v) * ds(markers["load"]))
    support = tagged.facet_tags.find(markers["support"])
    bcs = [dolfinx.fem.dirichletbc(
        np.zeros(3), dolfinx.fem.locate_dofs_topological(V, 2, support), V)]
    symmetry = tagged.facet_tags.find(markers["symmetry_y"])
    dofs = dolfinx.fem.locate_dofs_topological(V.sub(1), 2, symmetry)
    bcs.append(dolfinx.fem.dirichletbc(np.float64(0.0), dofs, V.sub(1)))
    return F, (normal, tangential), bcs


def tangential_tractions(problem, comm) -> dict:
    """Every slave node's reference coordinates, tangential traction vector y_j . tau_j
    (the friction traction on the master; on the slave it is the opposite), stick and
    slip flags, gathered on every rank. Collective."""
    state = problem.friction_state()
    traction = np.einsum("na,nai->ni", state["traction"], state["frames"])
    recovered = np.einsum("na,nai->ni", problem.tangential_traction()[1], state["frames"])
    keys = {"coordinates": state["coordinates"], "traction": traction, "recovered": recovered,
            "coulomb_ratio": np.linalg.norm(state["traction"], axis=1)
            / np.maximum(problem.friction.laws[0].mu * state["pressure"], 1e-300),
            "sticking": state["sticking"], "slipping": state["slipping"]}
    return {key: np.concatenate(comm.allgather(value)) for key, value in keys.items()}


def main_3d(args, comm: MPI.Intracomm) -> dict:
    """Cattaneo-Mindlin in 3D (``--dim 3``): a sphere pressed onto a block by P, then
    pulled along x by Q = ``--tangential-ratio`` mu P at fixed P; half model y >= 0,
    equal materials (the normal and tangential problems decouple), gmsh tetrahedra
    (dolfinx_mortar.meshes3d.hertz_sphere with ``half=True``)."""
    refinement = 0 if args.refinement is None else args.refinement
    exact = exact_solution_3d(LOAD_3D, args.mu, args.tangential_ratio)
    tangential_load = args.tangential_ratio * args.mu * LOAD_3D
    start = time.perf_counter()
    tagged = meshes3d.hertz_sphere(case="block", refinement=refinement,
                                   contact_radius=exact["a"], half=True, comm=comm)
    markers = tagged.markers
    V = dolfinx.fem.functionspace(tagged.mesh, ("Lagrange", 1, (3,)))
    u = dolfinx.fem.Function(V, name="displacement")
    F, (normal, tangential), bcs = bulk_problem_3d(tagged, u)
    pair = ContactPair(tagged.facet_tags, markers["contact_slave"], markers["contact_master"],
                       name="sphere-block")
    problem = ContactProblem(F, u, bcs, [pair], configuration="reference",
                             **cli.problem_options(args))
    sphere_cells = tagged.cell_tags.find(markers["sphere"])
    initial = hertz_sphere.INITIAL_RADIUS
    indentation = (initial * exact["a"]) ** 2 / (2.0 * exact["R_star"])
    u.interpolate(lambda x: np.vstack([0.0 * x[0], 0.0 * x[0], -indentation + 0.0 * x[0]]),
                  sphere_cells)
    u.x.scatter_forward()

    def press(t: float) -> None:
        # the Hertz radius grows linearly in t from the initial overlap's to a
        normal.value = (initial + (1.0 - initial) * t) ** 3 * LOAD_3D

    def pull(t: float) -> None:
        tangential.value = t * tangential_load

    steps = args.steps or hertz_sphere.automatic_steps(meshes3d.ELEMENTS_PER_RADIUS, refinement)
    records, dissipation = press_then_pull(problem, press, pull, steps, args)
    wall_time = comm.allreduce(time.perf_counter() - start, op=MPI.MAX)

    nodes = tangential_tractions(problem, comm)
    r = np.hypot(nodes["coordinates"][:, 0], nodes["coordinates"][:, 1])
    order = np.argsort(r)
    r = r[order]
    traction, recovered, ratio, sticking, slipping = (
        nodes[key][order]
        for key in ("traction", "recovered", "coulomb_ratio", "sticking", "slipping"))
    h = tagged.h_contact
    stick_radius = float(r[sticking].max()) if sticking.any() else 0.0
    zone = r < 1.5 * exact["a"]
    q_exact = exact_traction_3d(r, exact)
    # the traction's x component against |q|: Mindlin's traction is parallel to Q; the
    # recovered traction (what problem.tangential_traction() gives) and the multipliers
    error_rel, multiplier_error_rel = (
        float(np.sqrt(np.sum((values[zone, 0] - q_exact[zone]) ** 2)
                      / np.sum(q_exact[zone] ** 2))) for values in (recovered, traction))
    coordinates, pressure = problem.gathered_pressure()
    in_contact = pressure > 1e-8 * exact["p0"]
    r_pressure = np.hypot(coordinates[:, 0], coordinates[:, 1])
    a_contact = float(r_pressure[in_contact].max()) if in_contact.any() else 0.0
    slave_force, master_force = problem.contact_forces()
    # the full model's forces on the sphere (twice the half model's)
    tangential_force, normal_force = 2.0 * float(slave_force[0]), 2.0 * float(slave_force[2])
    summary = {
        "dim": 3,
        "mu": args.mu,
        "tangential_ratio": args.tangential_ratio,
        "load": LOAD_3D,
        "tangential_load": tangential_load,
        "normal_phase": args.normal_phase,
        **cli.option_record(args),
        "linear_solver": problem.linear_solver,
        "c_n": problem.c_n,
        "c_t": problem.c_t,
        "refinement": refinement,
        "num_ranks": comm.size,
        "num_dofs": V.dofmap.index_map.size_global * 3,
        "h_contact": h,
        "a_exact": exact["a"],
        "a_contact": a_contact,
        "p0_exact": exact["p0"],
        "p_max": float(pressure.max()),
        "stick_radius": stick_radius,
        "stick_radius_exact": exact["c"],
        "stick_error_in_elements": abs(stick_radius - exact["c"]) / h,
        "num_sticking": int(sticking.sum()),
        "num_slipping": int(slipping.sum()),
        "q_max": float(np.max(traction[zone, 0])),
        "q_max_exact": float(np.max(q_exact[zone])),
        # |y_j| / (mu z_j): 1 at slipping nodes, below 1 at sticking ones (Coulomb's law)
        "coulomb_ratio_slipping": [float(ratio[slipping].min(initial=1.0)),
                                   float(ratio[slipping].max(initial=1.0))],
        "coulomb_ratio_sticking_max": float(ratio[sticking].max(initial=0.0)),
        "max_traction_y_rel": float(np.max(np.abs(traction[zone, 1]))
                                    / (exact["mu"] * exact["p0"])),
        "l2_traction_error_rel": error_rel,
        "l2_multiplier_traction_error_rel": multiplier_error_rel,
        "total_force": normal_force,
        "total_force_error_rel": abs(normal_force - LOAD_3D) / LOAD_3D,
        "total_tangential_force": tangential_force,
        "total_tangential_force_error_rel": (
            abs(tangential_force + tangential_load) / tangential_load
            if tangential_load > 0 else abs(tangential_force) / LOAD_3D),
        "force_balance": float(np.linalg.norm(slave_force + master_force) * 2.0 / LOAD_3D),
        "newton_iterations": [rec.iterations for rec in records],
        "min_nodal_dissipation_rel": float(
            min(low for low, _ in dissipation)
            / max(max(high for _, high in dissipation), 1e-300)),
        "cutbacks": sum(rec.cutbacks for rec in records),
        "wall_time_s": wall_time,
        "profile": {"r": r[zone].tolist(), "traction_x": traction[zone, 0].tolist(),
                    "recovered_traction_x": recovered[zone, 0].tolist(),
                    "sticking": sticking[zone].astype(int).tolist()},
    }
    if comm.rank == 0:
        print(
            f"Cattaneo-Mindlin 3D mu {args.mu}, Q/(mu P) {args.tangential_ratio}: stick radius "
            f"{stick_radius:.4f} (exact {exact['c']:.4f}, "
            f"{summary['stick_error_in_elements']:.2f} elements), q_max {summary['q_max']:.4f} "
            f"(exact {summary['q_max_exact']:.4f}), L2 traction error {100 * error_rel:.2f} % "
            f"(multipliers {100 * multiplier_error_rel:.2f} %), "
            f"tangential force {tangential_force:.10g} (-Q = {-tangential_load:g}), Newton "
            f"{summary['newton_iterations']}", flush=True)
        write_summary(args.json, summary)
        if args.output:
            plot_3d(args.output / "cattaneo_mindlin_3d.png", r[zone], traction[zone, 0],
                    sticking[zone], exact, summary)
            write_profile_3d(args.output / "cattaneo_mindlin_3d.csv", r[zone], traction[zone],
                             sticking[zone], exact)
    problem.destroy()
    return summary


def write_profile_3d(path: pathlib.Path, r, traction, sticking, exact) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as stream:
        writer = csv.writer(stream)
        writer.writerow(["r", "traction_x", "traction_y", "sticking", "traction_exact"])
        for r_j, q, stick, q_exact in zip(r, traction, sticking, exact_traction_3d(r, exact),
                                          strict=True):
            writer.writerow([repr(float(r_j)), repr(float(q[0])), repr(float(q[1])), int(stick),
                             repr(float(q_exact))])


def plot_3d(path: pathlib.Path, r_nodes, traction_x, sticking, exact, summary) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    a, mu = exact["a"], exact["mu"]
    r = np.linspace(0.0, 1.5 * a, 601)
    fig, ax = plt.subplots(figsize=(6.5, 4))
    ax.plot(r, mu * exact["p0"] * np.sqrt(np.clip(1 - (r / a) ** 2, 0, None)), "k:",
            label="mu p (Hertz)")
    ax.plot(r, exact_traction_3d(r, exact), "k-", label="Mindlin q")
    ax.plot(r_nodes[~sticking], traction_x[~sticking], ".", ms=4, label="slipping or inactive")
    ax.plot(r_nodes[sticking], traction_x[sticking], "s", ms=3, mfc="none", label="sticking")
    ax.axvline(exact["c"], color="k", lw=0.5)
    ax.set_xlabel("r")
    ax.set_ylabel("tangential traction (x)")
    ax.set_title(f"3D, mu {summary['mu']}, Q/(mu P) {summary['tangential_ratio']}: c "
                 f"{summary['stick_radius']:.4f} vs {exact['c']:.4f}")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    cli.save_figure(fig, path)


if __name__ == "__main__":
    main()
