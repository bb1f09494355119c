"""Which side to make the slave: the README's punch example with either side as slave.

A Neo-Hookean punch [0.5, 1.5] x [1, 1.5] is pressed 0.05 into a block [0, 2] x [0, 1]
by a prescribed displacement of its top, then slid 0.2 sideways (the README's punch example).
For each variant (meshes, moduli, which side is the slave) it reports the contact force on
the punch after pressing and after sliding, the force balance of the two sides, Newton
iterations, and how deep the nodes of each surface sit behind the other surface (absolute,
and in element sizes of the surface they sit behind). Mortar contact enforces the gap at the
slave nodes in a weighted sense, int Phi_j g = 0 for every active slave node j, so neither
side's nodes are held exactly on the other surface; those numbers show by how much.

A second table refines one side at a time (punch as slave): how deep the deepest punch node
sits inside the block as the slave or the master mesh gets finer.

Run (about 5 s serially; mpirun -n 2 gives the same tables; quoted in the README):

    tools/run python3 benchmarks/slave_side.py
    tools/run python3 benchmarks/slave_side.py --json benchmarks/results/slave_side.json
"""

from __future__ import annotations

import argparse
import json
import pathlib

import dolfinx
import numpy as np
import ufl
from mpi4py import MPI

from dolfinx_mortar import (
    ContactPair,
    ContactProblem,
    Material,
    internal_work,
    merge_meshes,
    solve_load_steps,
)

VARIANTS = [
    # (label, punch cells, block cells, E punch, E block, slave)
    ("fine soft punch as slave (README)", (16, 8), (20, 10), 100.0, 1000.0, "punch"),
    ("the same, block as slave", (16, 8), (20, 10), 100.0, 1000.0, "block"),
    ("coarse punch on a fine block, punch as slave", (5, 3), (40, 20), 1000.0, 1000.0, "punch"),
    ("the same, block as slave", (5, 3), (40, 20), 1000.0, 1000.0, "block"),
]

REFINEMENTS = [
    # the README example (punch as slave), one side refined at a time
    *[(f"punch {n}x{n // 2}", (n, n // 2), (20, 10)) for n in (8, 16, 32, 64)],
    *[(f"block {n}x{n // 2}", (16, 8), (n, n // 2)) for n in (40, 80)],
]


def depth_behind(comm, points: np.ndarray, x: np.ndarray, facets: np.ndarray) -> np.ndarray:
    """Depth of each point behind the polyline (x, facets).

    Positive: behind (inside the other body). Only points that project onto their nearest
    facet count (others get -inf). Collective: the polyline is gathered from every rank.
    """
    start = np.vstack(comm.allgather(x[facets[:, 0]]))
    end = np.vstack(comm.allgather(x[facets[:, 1]]))
    tangent = end - start
    length = np.linalg.norm(tangent, axis=1)
    normal = np.stack([tangent[:, 1], -tangent[:, 0]], axis=1) / length[:, None]
    relative = points[:, None, :] - start[None, :, :]
    t = np.einsum("nkc,kc->nk", relative, tangent) / length**2
    closest = start[None] + np.clip(t, 0.0, 1.0)[..., None] * tangent[None]
    nearest = np.argmin(np.linalg.norm(points[:, None, :] - closest, axis=2), axis=1)
    rows = np.arange(points.shape[0])
    depth = -np.einsum("nc,nc->n", relative[rows, nearest], normal[nearest])
    inside = (t[rows, nearest] >= 0.0) & (t[rows, nearest] <= 1.0)
    return np.where(inside, depth, -np.inf)


def max_depth(comm, problem: ContactProblem) -> dict[str, tuple[float, float]]:
    """(depth, reference x) of the deepest slave node behind the master surface and of the
    deepest master node behind the slave surface."""
    interface = problem.interfaces[0]
    result = {}
    for side, other in (("slave", "master"), ("master", "slave")):
        a, b = getattr(interface, side), getattr(interface, other)
        xa, xb = a.current_coordinates(problem.u), b.current_coordinates(problem.u)
        depth = depth_behind(comm, xa[a.node_owned], xb, b.facets)
        local = (-np.inf, np.nan)
        if depth.size:
            i = int(np.argmax(depth))
            local = (float(depth[i]), float(a.reference_coordinates[a.node_owned][i, 0]))
        result[side] = max(comm.allgather(local))
    return result


def run(
    punch_cells: tuple[int, int],
    block_cells: tuple[int, int],
    E_punch: float,
    E_block: float,
    slave: str,
    comm: MPI.Intracomm = MPI.COMM_WORLD,
) -> dict:
    """Press and slide one variant; its forces, Newton iterations and penetration depths.

    Args:
        punch_cells, block_cells: cells of ``create_rectangle`` along x and y.
        E_punch, E_block: Young's moduli (nu = 0.3, Neo-Hookean).
        slave: ``"punch"`` or ``"block"``, the side that carries the multipliers.
        comm: communicator of the meshes (collective on it).
    """
    punch_mesh = dolfinx.mesh.create_rectangle(comm, [[0.5, 1.0], [1.5, 1.5]], punch_cells)
    block_mesh = dolfinx.mesh.create_rectangle(comm, [[0.0, 0.0], [2.0, 1.0]], block_cells)
    tagged = merge_meshes(
        {
            "punch": (punch_mesh, {"contact": lambda x: np.isclose(x[1], 1.0),
                                   "top": lambda x: np.isclose(x[1], 1.5)}),
            "block": (block_mesh, {"contact": lambda x: np.isclose(x[1], 1.0),
                                   "bottom": lambda x: np.isclose(x[1], 0.0)}),
        }
    )
    mesh, markers, facet_tags = tagged.mesh, tagged.markers, tagged.facet_tags
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    u = dolfinx.fem.Function(V)
    materials = {
        markers["punch"]: Material(E_punch, 0.3, "neo-hookean"),
        markers["block"]: Material(E_block, 0.3, "neo-hookean"),
    }
    F = internal_work(u, ufl.TestFunction(V), materials, tagged.cell_tags)
    fdim = mesh.topology.dim - 1
    top = dolfinx.fem.locate_dofs_topological(V, fdim, facet_tags.find(markers["punch_top"]))
    bottom = dolfinx.fem.locate_dofs_topological(V, fdim, facet_tags.find(markers["block_bottom"]))
    top_displacement = dolfinx.fem.Constant(mesh, np.zeros(2))
    bcs = [
        dolfinx.fem.dirichletbc(top_displacement, top, V),
        dolfinx.fem.dirichletbc(np.zeros(2), bottom, V),
    ]
    surfaces = (markers["punch_contact"], markers["block_contact"])
    if slave == "block":
        surfaces = surfaces[::-1]
    problem = ContactProblem(F, u, bcs, [ContactPair(facet_tags, *surfaces)])

    def press(t):
        top_displacement.value[:] = (0.0, -0.05 * t)

    def slide(t):
        top_displacement.value[:] = (0.2 * t, -0.05)

    def on_punch(forces):
        return forces[0] if slave == "punch" else forces[1]

    pressed = solve_load_steps(problem, press, num_steps=4)
    pressed_forces = problem.contact_forces()
    pressed_depth = max_depth(comm, problem)
    slid = solve_load_steps(problem, slide, num_steps=4)
    slid_forces = problem.contact_forces()
    slid_depth = max_depth(comm, problem)
    punch_side = "slave" if slave == "punch" else "master"
    block_side = "master" if slave == "punch" else "slave"
    result = {
        "punch_cells": list(punch_cells),
        "block_cells": list(block_cells),
        "E_punch": E_punch,
        "E_block": E_block,
        "slave": slave,
        "force_pressed": on_punch(pressed_forces).tolist(),
        "force_slid": on_punch(slid_forces).tolist(),
        "force_balance_rel": float(
            max(np.linalg.norm(s + m) / np.linalg.norm(s) for s, m in (pressed_forces, slid_forces))
        ),
        "newton_iterations": sum(r.iterations for r in pressed + slid),
        "steps": len(pressed) + len(slid),
        "active_nodes": problem.num_active(),
        "h_punch": 1.0 / punch_cells[0],
        "h_block": 2.0 / block_cells[0],
        # (depth behind the other surface, reference x of that node)
        "punch_nodes_depth_pressed": pressed_depth[punch_side],
        "block_nodes_depth_pressed": pressed_depth[block_side],
        "punch_nodes_depth_slid": slid_depth[punch_side],
        "block_nodes_depth_slid": slid_depth[block_side],
    }
    problem.destroy()
    return result


def depth(value: tuple[float, float], h: float | None = None) -> str:
    """A (depth, x) pair for the table, or the depth over h: "none" if no node is more
    than 1e-12 h behind the other surface."""
    if not value[0] > 1e-12 * (h or 0.1):
        return "none"
    return f"{value[0] / h:.2g}" if h else f"{value[0]:.2g} (x = {value[1]:.3g})"


def main(argv: list[str] | None = None) -> list[dict]:
    """Run every variant and refinement; print the tables on rank 0."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--json", type=pathlib.Path, help="write the results here")
    args = parser.parse_args(argv)
    comm = MPI.COMM_WORLD
    results = []
    for label, punch_cells, block_cells, E_punch, E_block, slave in VARIANTS:
        result = run(punch_cells, block_cells, E_punch, E_block, slave, comm)
        result["variant"] = label
        results.append(result)
    if comm.rank == 0:
        print(
            "| variant | punch / block cells | force on punch, pressed | after sliding | "
            "Newton its (8 steps) | deepest punch node behind the block, pressed: depth "
            "(at x) | the same, in block elements | deepest block node behind the punch, "
            "pressed | in punch elements |"
        )
        print("|---|---|---|---|---|---|---|---|---|")
        for r in results:
            print(
                f"| {r['variant']} | {r['punch_cells'][0]}x{r['punch_cells'][1]} / "
                f"{r['block_cells'][0]}x{r['block_cells'][1]} | "
                f"({r['force_pressed'][0]:.3g}, {r['force_pressed'][1]:.4f}) | "
                f"({r['force_slid'][0]:.3g}, {r['force_slid'][1]:.4f}) | "
                f"{r['newton_iterations']} | "
                f"{depth(r['punch_nodes_depth_pressed'])} | "
                f"{depth(r['punch_nodes_depth_pressed'], r['h_block'])} | "
                f"{depth(r['block_nodes_depth_pressed'])} | "
                f"{depth(r['block_nodes_depth_pressed'], r['h_punch'])} |"
            )
    refinements = []
    for label, punch_cells, block_cells in REFINEMENTS:
        result = run(punch_cells, block_cells, 100.0, 1000.0, "punch", comm)
        result["variant"] = label
        refinements.append(result)
    if comm.rank == 0:
        print()
        print(
            "| punch as slave, refined | force on punch, pressed | deepest punch node inside "
            "the block (at x) | in block elements |"
        )
        print("|---|---|---|---|")
        for r in refinements:
            print(
                f"| {r['variant']} | {r['force_pressed'][1]:.4f} | "
                f"{depth(r['punch_nodes_depth_pressed'])} | "
                f"{depth(r['punch_nodes_depth_pressed'], r['h_block'])} |"
            )
        if args.json:
            args.json.parent.mkdir(parents=True, exist_ok=True)
            args.json.write_text(
                json.dumps({"variants": results, "refinements": refinements}, indent=2)
            )
    return results + refinements


if __name__ == "__main__":
    main()
