"""Ironing under a rigid die: plane strain against a 3D slab free to bulge out of plane.

The ironing plateau of the reference (3.38e8, ``benchmarks.md`` section 3) is the
lowest of the published curves of this benchmark, and Kratos' validation of it
(``KratosMultiphysics/Examples``, ``validation/shallow_ironing_3D``,
``ProjectParameters_literature.json``) reproduces it with a 3D slab one unit thick
whose out-of-plane displacement is held only on the back face z = 0: the front
face is free, so the slab is not in plane strain. This script measures what that
constraint does to the forces, independently of the mortar code: the block alone,
pressed and slid by a rigid die (the arc and side walls of ``demos/ironing.py`` as
an analytic obstacle; penalty ``--penalty`` E/h on the block top), in three models
on the same in-plane mesh of bilinear quadrilaterals / trilinear hexahedra (2 x 2
(x 2) Gauss points):

* ``2d``: plane strain;
* ``3d-plane-strain``: the slab with u_z = 0 on both faces; it must reproduce
  ``2d`` (a check of the 3D model);
* ``3d-back-face``: u_z = 0 on z = 0 only, as in Kratos' literature setup.

Printed: the vertical force on the die at t = 1 and its mean over the sliding
window t in [--window-start, --end-time] (default [1.2, 1.3]) for each model, and
their ratios to ``2d``. Compressible Neo-Hookean block (the library's law), E = 6.896e8,
nu = 0.32; the die's lowest point starts 0.2 above the block, moves down 1 over
t in [0, 1], then 10 horizontally over t in [1, 2].

The 3D models take about 40 and 65 minutes here (45 738 dofs, penalty ramps and
step cut-backs at the start of the sliding); run them side by side and merge:

    tools/run python3 benchmarks/ironing_out_of_plane.py --end-time 1.25 \\
        --models 2d --json scratch/oop_2d.json    # and 3d-plane-strain, 3d-back-face
    tools/run python3 benchmarks/ironing_out_of_plane.py --end-time 1.25 --merge \\
        scratch/oop_2d.json scratch/oop_3d-plane-strain.json scratch/oop_3d-back-face.json \\
        --markdown benchmarks/results/ironing_out_of_plane.md
"""

from __future__ import annotations

import argparse
import json
import pathlib
import time

import dolfinx
import dolfinx.fem.petsc
import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_mortar import Material, compat

BLOCK_E, NU = 6.896e8, 0.32
RADIUS, HALF_WIDTH, LOWEST, CENTRE_X = 0.75, 0.6, 4.2, 0.8
MODELS = ("2d", "3d-plane-strain", "3d-back-face")


def die_position(t: float) -> tuple[float, float]:
    """Centre (x, y) of the die's arc at pseudo-time t."""
    down = min(t, 1.0)
    return CENTRE_X + 10.0 * max(t - 1.0, 0.0), LOWEST + RADIUS - down


def build(model: str, cells: tuple[int, int, int], comm):
    nx, ny, nz = cells
    if model == "2d":
        mesh = dolfinx.mesh.create_rectangle(
            comm, [[0.0, 0.0], [12.0, 4.0]], [nx, ny], dolfinx.mesh.CellType.quadrilateral
        )
    else:
        mesh = dolfinx.mesh.create_box(
            comm,
            [[0.0, 0.0, 0.0], [12.0, 4.0, 1.0]],
            [nx, ny, nz],
            dolfinx.mesh.CellType.hexahedron,
        )
    gdim = mesh.geometry.dim
    fdim = gdim - 1
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (gdim,)))
    bottom = dolfinx.mesh.locate_entities_boundary(mesh, fdim, lambda x: np.isclose(x[1], 0.0))
    bcs = [
        dolfinx.fem.dirichletbc(
            np.zeros(gdim), dolfinx.fem.locate_dofs_topological(V, fdim, bottom), V
        )
    ]
    if gdim == 3:
        held = (0.0,) if model == "3d-back-face" else (0.0, 1.0)
        faces = dolfinx.mesh.locate_entities_boundary(
            mesh, fdim, lambda x: np.any([np.isclose(x[2], z) for z in held], axis=0)
        )
        Vz = V.sub(2)
        bcs.append(
            dolfinx.fem.dirichletbc(
                PETSc.ScalarType(0.0), dolfinx.fem.locate_dofs_topological(Vz, fdim, faces), Vz
            )
        )
    top = dolfinx.mesh.locate_entities_boundary(mesh, fdim, lambda x: np.isclose(x[1], 4.0))
    tags = dolfinx.mesh.meshtags(mesh, fdim, top, np.ones_like(top))
    return mesh, V, bcs, tags


def solve(model: str, cells, penalty: float, t_values, comm) -> dict:
    mesh, V, bcs, tags = build(model, cells, comm)
    u = dolfinx.fem.Function(V)
    v, du = ufl.TestFunction(V), ufl.TrialFunction(V)
    centre = dolfinx.fem.Constant(mesh, np.array(die_position(0.0)))
    h = 12.0 / cells[0]
    epsilon = dolfinx.fem.Constant(mesh, PETSc.ScalarType(0.0))
    penalties = [e for e in (10.0, 100.0, 1000.0, 10000.0) if e < penalty] + [penalty]
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=tags, metadata={"quadrature_degree": 4})
    x = ufl.variable(ufl.SpatialCoordinate(mesh) + u)
    px, py = x[0] - centre[0], x[1] - centre[1]
    below_centre = ufl.conditional(ufl.lt(py, 0.0), RADIUS - ufl.sqrt(px**2 + py**2), 1.0)
    penetration = ufl.min_value(below_centre, HALF_WIDTH - abs(px))
    pressure = epsilon * ufl.max_value(penetration, 0.0)
    contact_energy = 0.5 * pressure * ufl.max_value(penetration, 0.0) * ds(1)
    material = Material(BLOCK_E, NU, "neo-hookean")
    dx = ufl.Measure("dx", domain=mesh, metadata={"quadrature_degree": 2})
    F = ufl.inner(material.stress(u), ufl.grad(v)) * dx + ufl.derivative(contact_energy, u, v)
    residual = dolfinx.fem.form(F)
    jacobian = dolfinx.fem.form(ufl.derivative(F, u, du))
    die_force = dolfinx.fem.form(pressure * ufl.diff(penetration, x)[1] * ds(1))
    A = compat.create_matrix(jacobian)
    b = compat.create_vector(residual)
    ksp = PETSc.KSP().create(comm)
    ksp.setOperators(A)
    ksp.setType("preonly")
    ksp.getPC().setType("lu")
    ksp.getPC().setFactorSolverType("mumps")
    dx_vec = A.createVecRight()

    def residual_norm() -> float:
        with b.localForm() as local:
            local.set(0.0)
        dolfinx.fem.petsc.assemble_vector(b, residual)
        dolfinx.fem.petsc.apply_lifting(b, [jacobian], [bcs], x0=[u.x.petsc_vec], alpha=-1.0)
        b.ghostUpdate(PETSc.InsertMode.ADD, PETSc.ScatterMode.REVERSE)
        compat.set_bc(b, bcs, u.x.petsc_vec, -1.0)
        return b.norm()

    def newton(t: float) -> int:
        for iteration in range(1, 26):
            norm = residual_norm()
            if not np.isfinite(norm):
                break
            if iteration == 1:
                first = max(norm, 1e-300)
            if norm <= max(1e-9 * first, 1e-8 * BLOCK_E) and iteration > 1:
                return iteration - 1
            A.zeroEntries()
            dolfinx.fem.petsc.assemble_matrix(A, jacobian, bcs)
            A.assemble()
            ksp.solve(b, dx_vec)
            step = 1.0
            for _ in range(8):
                u.x.petsc_vec.axpy(-step, dx_vec)
                u.x.scatter_forward()
                if residual_norm() < (1.0 - 1e-4 * step) * norm:
                    break
                u.x.petsc_vec.axpy(step, dx_vec)
                step *= 0.5
            else:
                u.x.petsc_vec.axpy(-2.0 * step, dx_vec)
                u.x.scatter_forward()
        raise RuntimeError(f"{model}: no convergence at t = {t}, penalty {epsilon.value:.3g}")

    history = []
    start = time.perf_counter()

    def step(t: float, previous: np.ndarray) -> int:
        """Newton at the target penalty; failing that, from ``previous`` (the last
        converged state) ramp the penalty up from 10 E/h."""
        centre.value[:] = die_position(t)
        epsilon.value = penalty * BLOCK_E / h
        try:
            return newton(t)
        except RuntimeError:
            u.x.array[:] = previous
            for e in penalties:
                epsilon.value = e * BLOCK_E / h
                iteration = newton(t)
            return iteration

    reached = 0.2
    for target in t_values:
        pending = [target]
        while pending:
            t = pending[0]
            previous = u.x.array.copy()
            try:
                iteration = step(t, previous)
            except RuntimeError:
                u.x.array[:] = previous
                if t - reached < 1e-3:
                    raise
                pending.insert(0, 0.5 * (reached + t))
                continue
            reached = pending.pop(0)
        force = comm.allreduce(dolfinx.fem.assemble_scalar(die_force), op=MPI.SUM)
        history.append({"t": float(target), "vertical_force": float(force), "newton": iteration})
        if comm.rank == 0:
            print(f"{model:16s} t = {target:.3f}  V = {force:.4e}  newton {iteration}", flush=True)
    ksp.destroy()
    A.destroy()
    b.destroy()
    return {
        "model": model,
        "num_dofs": V.dofmap.index_map.size_global * V.dofmap.index_map_bs,
        "wall_time_s": time.perf_counter() - start,
        "history": history,
    }


def main(argv=None) -> list[dict]:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--cells",
        type=int,
        nargs=3,
        default=(120, 20, 5),
        help="cells along x, y, z (Kratos' mesh: 120 20 5)",
    )
    parser.add_argument("--penalty", type=float, default=100.0, help="penalty in E/h")
    parser.add_argument("--press-step", type=float, default=0.05)
    parser.add_argument("--slide-step", type=float, default=0.01)
    parser.add_argument("--window-start", type=float, default=1.2)
    parser.add_argument("--end-time", type=float, default=1.3)
    parser.add_argument("--models", nargs="+", choices=MODELS, default=list(MODELS))
    parser.add_argument("--json", type=pathlib.Path, help="write the results")
    parser.add_argument(
        "--merge",
        type=pathlib.Path,
        nargs="+",
        help="instead of solving, tabulate the results of earlier --json files "
        "(e.g. one run per model, run side by side)",
    )
    parser.add_argument("--markdown", type=pathlib.Path)
    args = parser.parse_args(argv)
    comm = MPI.COMM_WORLD
    pressing = np.arange(0.2, 1.0 + 1e-12, args.press_step)[1:]
    sliding = np.arange(1.0, args.end_time + 1e-12, args.slide_step)[1:]
    t_values = np.concatenate([pressing, sliding])
    results = []
    for path in args.merge or []:
        results.extend(json.loads(path.read_text())["results"])
    for model in [] if args.merge else args.models:
        result = solve(model, tuple(args.cells), args.penalty, t_values, comm)
        results.append(result)
    for result in results:
        t = np.array([h["t"] for h in result["history"]])
        force = np.array([h["vertical_force"] for h in result["history"]])
        window = t >= args.window_start - 1e-12
        result["end_time"] = float(t[-1])
        result["vertical_force_at_t1"] = float(np.interp(1.0, t, force))
        result["vertical_force_window_mean"] = (
            float(force[window].mean()) if window.any() else float("nan")
        )
    base = {r["model"]: r for r in results}.get("2d")
    lines = [
        f"Rigid die on the ironing block, {args.cells[0]} x {args.cells[1]} cells in plane"
        f" ({args.cells[2]} through the thickness in 3D), penalty {args.penalty:g} E/h; "
        f"window t in [{args.window_start}, {args.end_time}].",
        "",
        "| model | dofs | reached t | V(t = 1) | V window mean | ratios to 2d | time (s) |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in results:
        ratios = "-"
        if base is not None:
            ratios = (
                f"{r['vertical_force_at_t1'] / base['vertical_force_at_t1']:.4f}, "
                f"{r['vertical_force_window_mean'] / base['vertical_force_window_mean']:.4f}"
            )
        lines.append(
            f"| {r['model']} | {r['num_dofs']} | {r['end_time']:.2f} "
            f"| {r['vertical_force_at_t1']:.4g} | {r['vertical_force_window_mean']:.4g} "
            f"| {ratios} | {r['wall_time_s']:.0f} |"
        )
    text = "\n".join(lines) + "\n"
    if comm.rank == 0:
        print(text)
        if args.markdown:
            args.markdown.write_text(text)
        if args.json:
            args.json.write_text(
                json.dumps(
                    {"args": vars(args) | {"json": None, "markdown": None}, "results": results},
                    indent=1,
                    default=str,
                )
            )
    return results


if __name__ == "__main__":
    main()
