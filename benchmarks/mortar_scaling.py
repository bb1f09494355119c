"""Time of one full mortar evaluation against the number of slave facets (serial).

Two thin strips of quadrilaterals, built with ``dolfinx.mesh.create_mesh``
from numpy arrays (no gmsh, so that large sizes are cheap to set up):

* lower body (master): x in [0, 1], y in [-w, 0], ``round(N / 1.37)`` cells
  along x, one cell thick;
* upper body (slave): x in [0, 1], y in [0, w], ``N`` cells along x;

w = 1 / N, the bodies share no node and the meshes do not match. The slave
(tag 1) and master (tag 2) surfaces are the exterior facets at y = 0, told
apart by the centroid of their cell. Both bodies are bent by the same smooth
vertical displacement (so the normals turn), the upper one is pushed a tenth
of a cell into the lower one and slid sideways a little.

For each N the interface is built with default options (averaged normals,
segment integration, standard basis, 3 Gauss points), updated once (first
search), then, ``--repeats`` times (medians reported):

* (a) ``update`` with a forced new search (``reuse.invalidate()`` first):
  search + segmentation + integration + derivatives; split into its
  ``search`` and ``integration`` parts from ``MortarInterface.statistics``;
* (c) PETSc assembly right after that search, so the matrix patterns are
  rebuilt too: D and M, weighted gap, gap Jacobian, constraint matrix B,
  force Jacobian at z = 1;
* (b) ``update`` that reuses the search (a Newton iteration: the nodes are
  moved by 1e-2 w first, so that the evaluation is not skipped);
* (c') the same assembly again, with the patterns reused;
* total = (a) + (c), one full evaluation after a search.

With ``--dim 3`` the bodies are two slabs of tetrahedra one cell thick,
[0, 1]^2 x [-w, 0] (master, ``round(n / 1.37)`` cells per side) and
[0, 1]^2 x [0, w] (slave, n cells per side, N = 2 n^2 triangle facets), bent
in x and y alike, the upper one pushed 0.1 w down and slid 0.3 w. With
``--cell hexahedron`` the slabs are of hexahedra (N = n^2 quadrilateral facets).

``--kernels numpy compiled`` measures each size with the numpy oracle's kernels
(``tests/oracle``, the package's former numpy kernels, run by the interface through
``oracle.use_oracle``) and with the package's compiled ones in turn (default: compiled only).
Per size and implementation the peak resident memory of the process while it is measured
(:class:`PeakMemory`: mesh, interface and the repeats) is reported too, and the peak of
what the first update (a search and an evaluation) allocates (tracemalloc).

Prints a markdown table, the log-log slope of the total against N (least
squares over all N) and the total at the largest N. The goal is linear
growth (slope <= 1.1) and under a second for 1e5 slave facets.

    tools/run python3 benchmarks/mortar_scaling.py
    tools/run python3 benchmarks/mortar_scaling.py --sizes 1000 10000 --repeats 3 \\
        --json scratch/scaling.json --png scratch/scaling.png
    tools/run python3 benchmarks/mortar_scaling.py --dim 3 --repeats 3
    tools/run python3 benchmarks/mortar_scaling.py --dim 3 --sizes 1000 10000 100000 \\
        --kernels numpy compiled
    tools/run python3 benchmarks/mortar_scaling.py --dim 3 --cell hexahedron --sizes 1000 10000 \\
        --kernels numpy compiled
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import json
import os
import pathlib
import platform
import statistics
import sys
import threading
import time
import tracemalloc

import basix.ufl
import dolfinx
import numpy as np
import ufl
from mpi4py import MPI

from dolfinx_mortar import MortarInterface, kernels

DEFAULT_SIZES = (1000, 2000, 5000, 10000, 20000, 50000, 100000)
SLAVE_TAG, MASTER_TAG = 1, 2
RATIO = 1.37
KERNELS = ("numpy", "compiled")
"""``--kernels``: the numpy oracle of tests/oracle, the package's compiled kernels."""
PHASES = ("update_search", "search", "integration", "assembly", "update_reuse", "assembly_reuse",
          "total")
LABELS = {
    "update_search": "(a) update, new search",
    "search": "  of which search",
    "integration": "  of which integration",
    "assembly": "(c) assembly after search",
    "update_reuse": "(b) update, search reused",
    "assembly_reuse": "(c') assembly, pattern reused",
    "total": "total (a)+(c)",
}


def _strip(num_cells: int, y0: float, y1: float, first_node: int) -> tuple[np.ndarray, np.ndarray]:
    """Nodes and quadrilaterals (dolfinx tensor-product vertex order) of a strip one cell thick."""
    x = np.linspace(0.0, 1.0, num_cells + 1)
    nodes = np.vstack([np.column_stack([x, np.full_like(x, y0)]),
                       np.column_stack([x, np.full_like(x, y1)])])
    i = np.arange(num_cells, dtype=np.int64)
    top = num_cells + 1
    cells = first_node + np.column_stack([i, i + 1, top + i, top + i + 1])
    return nodes, cells


def two_strips(num_slave: int, comm: MPI.Intracomm = MPI.COMM_WORLD):
    """Mesh, facet tags and cell masks (upper, lower) of the two strips."""
    num_master = max(1, round(num_slave / RATIO))
    width = 1.0 / num_slave
    if comm.rank == 0:
        lower_x, lower_cells = _strip(num_master, -width, 0.0, 0)
        upper_x, upper_cells = _strip(num_slave, 0.0, width, lower_x.shape[0])
        x = np.vstack([lower_x, upper_x])
        cells = np.vstack([lower_cells, upper_cells])
    else:
        x = np.zeros((0, 2))
        cells = np.zeros((0, 4), dtype=np.int64)
    domain = ufl.Mesh(basix.ufl.element("Lagrange", "quadrilateral", 1, shape=(2,)))
    # keywords: dolfinx 0.9 takes (comm, cells, x, e), 0.10 onwards (comm, cells, e, x)
    mesh = dolfinx.mesh.create_mesh(comm, cells=cells, x=x, e=domain)
    return _tag_interface(mesh, width, axis=1)


def _slab(cells_per_side: int, z0: float, z1: float, first_node: int, cell: str = "tetrahedron"):
    """Nodes and cells of a slab one cell thick: tetrahedra (six per cube, dolfinx's
    create_box split) or hexahedra."""
    box = dolfinx.mesh.create_box(MPI.COMM_SELF, [[0.0, 0.0, z0], [1.0, 1.0, z1]],
                                  [cells_per_side, cells_per_side, 1],
                                  getattr(dolfinx.mesh.CellType, cell))
    from dolfinx_mortar import compat

    return box.geometry.x.copy(), first_node + compat.geometry_dofmap(box).astype(np.int64)


def two_slabs(num_slave: int, comm: MPI.Intracomm = MPI.COMM_WORLD, cell: str = "tetrahedron"):
    """Mesh, facet tags and cell masks (upper, lower) of two slabs of tetrahedra (the slave
    surface has about ``num_slave`` triangles, 2 n^2) or hexahedra (quadrilaterals, n^2)."""
    n = max(1, round(np.sqrt(num_slave / (2.0 if cell == "tetrahedron" else 1.0))))
    n_master = max(1, round(n / RATIO))
    width = 1.0 / n
    if comm.rank == 0:
        lower_x, lower_cells = _slab(n_master, -width, 0.0, 0, cell)
        upper_x, upper_cells = _slab(n, 0.0, width, lower_x.shape[0], cell)
        x = np.vstack([lower_x, upper_x])
        cells = np.vstack([lower_cells, upper_cells])
    else:
        x = np.zeros((0, 3))
        cells = np.zeros((0, 4 if cell == "tetrahedron" else 8), dtype=np.int64)
    domain = ufl.Mesh(basix.ufl.element("Lagrange", cell, 1, shape=(3,)))
    mesh = dolfinx.mesh.create_mesh(comm, cells=cells, x=x, e=domain)
    return _tag_interface(mesh, width, axis=2)


def _tag_interface(mesh, width: float, axis: int):
    tdim, fdim = mesh.topology.dim, mesh.topology.dim - 1
    mesh.topology.create_connectivity(fdim, tdim)
    facets = dolfinx.mesh.exterior_facet_indices(mesh.topology)
    midpoints = dolfinx.mesh.compute_midpoints(mesh, fdim, facets)
    on_interface = facets[np.abs(midpoints[:, axis]) < 0.25 * width]
    f_to_c = mesh.topology.connectivity(fdim, tdim)
    facet_cells = f_to_c.array[f_to_c.offsets[on_interface]]
    centroid = dolfinx.mesh.compute_midpoints(mesh, tdim, facet_cells)[:, axis]
    values = np.where(centroid > 0.0, SLAVE_TAG, MASTER_TAG).astype(np.int32)
    order = np.argsort(on_interface)
    tags = dolfinx.mesh.meshtags(mesh, fdim, on_interface[order].astype(np.int32), values[order])
    cell_map = mesh.topology.index_map(tdim)
    all_cells = np.arange(cell_map.size_local + cell_map.num_ghosts, dtype=np.int32)
    cell_position = dolfinx.mesh.compute_midpoints(mesh, tdim, all_cells)[:, axis]
    return mesh, tags, all_cells[cell_position > 0.0], all_cells[cell_position < 0.0], width


def displacement3d(V, upper, lower, width: float) -> dolfinx.fem.Function:
    """As :func:`displacement`, bent in x and y."""
    u = dolfinx.fem.Function(V)
    amplitude = 0.01

    def bend(x):
        return amplitude * (np.sin(2.0 * np.pi * x[0]) * np.cos(np.pi * x[1])
                            + 0.3 * np.cos(5.0 * x[0] + 2.0 * x[1]))

    u.interpolate(lambda x: np.vstack([np.full(x.shape[1], 0.3 * width),
                                       np.full(x.shape[1], 0.1 * width),
                                       bend(x) - 0.1 * width]), upper)
    u.interpolate(lambda x: np.vstack([np.zeros(x.shape[1]), np.zeros(x.shape[1]), bend(x)]),
                  lower)
    u.x.scatter_forward()
    return u


def displacement(V, upper, lower, width: float) -> dolfinx.fem.Function:
    """Both bodies bent alike (slopes up to ~0.07); the upper one 0.1 w down, 0.3 w sideways."""
    u = dolfinx.fem.Function(V)
    amplitude = 0.01

    def bend(x):
        return amplitude * np.sin(2.0 * np.pi * x[0]) + 0.3 * amplitude * np.cos(5.0 * x[0])

    u.interpolate(lambda x: np.vstack([np.full(x.shape[1], 0.3 * width), bend(x) - 0.1 * width]),
                  upper)
    u.interpolate(lambda x: np.vstack([np.zeros(x.shape[1]), bend(x)]), lower)
    u.x.scatter_forward()
    return u


class PeakMemory:
    """The peak resident memory of the process while in the ``with`` block, sampled from
    ``/proc/self/statm`` every ``interval`` seconds by a thread (``VmHWM`` cannot be reset
    in every kernel, and would cover the sizes measured before)."""

    def __init__(self, interval: float = 0.002):
        self.interval, self.peak = interval, 0.0
        self._stop = threading.Event()
        self._page = os.sysconf("SC_PAGE_SIZE")

    def _resident(self) -> float:
        try:
            with open("/proc/self/statm") as f:
                return float(f.read().split()[1]) * self._page
        except OSError:
            return 0.0

    def _sample(self) -> None:
        while not self._stop.is_set():
            self.peak = max(self.peak, self._resident())
            self._stop.wait(self.interval)

    def __enter__(self) -> PeakMemory:
        self._thread = threading.Thread(target=self._sample, daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()
        self.peak = max(self.peak, self._resident())


def _assemble(interface: MortarInterface, z) -> None:
    interface.mortar_matrices()
    interface.weighted_gap()
    interface.gap_jacobian()
    interface.constraint_matrix()
    interface.force_jacobian(z)


def measure(num_slave: int, repeats: int, normals: str, integration: str, dim: int = 2,
            cell: str = "tetrahedron") -> dict:
    """Median times (seconds) of each phase at one size, and counters (``cell``: of the 3D
    slabs)."""
    gc.collect()
    if dim == 3:
        mesh, tags, upper, lower, width = two_slabs(num_slave, cell=cell)
        V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (3,)))
        u = displacement3d(V, upper, lower, width)
    else:
        mesh, tags, upper, lower, width = two_strips(num_slave)
        V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
        u = displacement(V, upper, lower, width)
    interface = MortarInterface(V, tags, SLAVE_TAG, MASTER_TAG, normals=normals,
                                integration=integration)
    gc.collect()
    tracemalloc.start()  # the first search and evaluation (and warm-up), untimed
    interface.update(u)
    update_memory = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    z = interface.create_multiplier_vector()
    z.set(1.0)
    _assemble(interface, z)
    # two states a hundredth of a cell apart (well inside the search margin):
    # every update sees moved nodes, so none is skipped as a repeated point
    states = [u.x.array.copy(), u.x.array + 1e-2 * width * np.sin(np.arange(u.x.array.size))]
    samples: dict[str, list[float]] = {phase: [] for phase in PHASES}
    stats = interface.statistics
    for _ in range(repeats):
        gc.collect()
        u.x.array[:] = states[0]
        search_before, integration_before = stats.time_search, stats.time_integration
        interface.reuse.invalidate()
        start = time.perf_counter()
        interface.update(u)
        samples["update_search"].append(time.perf_counter() - start)
        samples["search"].append(stats.time_search - search_before)
        samples["integration"].append(stats.time_integration - integration_before)
        start = time.perf_counter()
        _assemble(interface, z)
        samples["assembly"].append(time.perf_counter() - start)
        samples["total"].append(samples["update_search"][-1] + samples["assembly"][-1])
        searches = stats.searches_done
        u.x.array[:] = states[1]
        start = time.perf_counter()
        interface.update(u)
        samples["update_reuse"].append(time.perf_counter() - start)
        if stats.searches_done != searches:
            raise RuntimeError("the second update searched again; the benchmark expects reuse")
        start = time.perf_counter()
        _assemble(interface, z)
        samples["assembly_reuse"].append(time.perf_counter() - start)
    result = {phase: statistics.median(values) for phase, values in samples.items()}
    u.x.array[:] = states[0]
    interface.update(u)
    result.update(
        update_memory=update_memory,
        N=interface.slave.num_facets,
        master_facets=interface.master.num_facets,
        pairs=stats.pairs,
        segments=stats.segments,
        weighted_gap_sum=float(interface.weighted_gap().sum()),
    )
    z.destroy()
    interface.destroy()
    return result


def loglog_slope(sizes, times) -> float:
    logs = np.log(np.asarray(sizes, float)), np.log(np.asarray(times, float))
    return float(np.polyfit(*logs, 1)[0])


def markdown_table(results: list[dict]) -> str:
    columns = " | ".join(f"N={r['N']:.0e}".replace("e+0", "e") for r in results)
    header = f"| phase | {columns} | slope |"
    lines = [header, "|" + "---|" * (len(results) + 2)]
    sizes = [r["N"] for r in results]
    for phase in PHASES:
        times = [r[phase] for r in results]
        slope = f"{loglog_slope(sizes, times):.2f}" if len(results) > 1 and min(times) > 0 else "-"
        cells = " | ".join(f"{1e3 * t:.1f}" for t in times)
        lines.append(f"| {LABELS[phase]} | {cells} | {slope} |")
    lines.append("| pairs | " + " | ".join(str(r["pairs"]) for r in results) + " | |")
    return "\n".join(lines)


def memory_rows(results: list[dict]) -> str:
    """The memory rows of the table: the process's peak resident memory over the whole
    size (mesh, interface, assembly), and the peak of the memory the first update allocates
    (a search and an evaluation, untimed; tracemalloc, which numpy reports its arrays to):
    what the interface keeps of it and the update's work, apart from what the allocator
    keeps of earlier sizes and of the assembly."""
    return "\n".join([
        "| peak memory [GB] | " + " | ".join(
            f"{r['peak_memory'] / 1e9:.2f}" for r in results) + " | |",
        "| first update, peak allocated [GB] | " + " | ".join(
            f"{r['update_memory'] / 1e9:.2f}" for r in results) + " | |"])


def plot(results: list[dict], path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sizes = np.array([r["N"] for r in results], dtype=float)
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    for phase in PHASES:
        ax.loglog(sizes, [r[phase] for r in results], "o-" if phase == "total" else ".--",
                  label=LABELS[phase].strip(), linewidth=2.0 if phase == "total" else 1.0)
    reference = results[-1]["total"] * sizes / sizes[-1]
    ax.loglog(sizes, reference, "k:", label="slope 1")
    ax.axhline(1.0, color="grey", linewidth=0.5)
    ax.set_xlabel("slave facets N")
    ax.set_ylabel("time [s] (median)")
    ax.set_title("dolfinx_mortar: one mortar evaluation, serial")
    ax.grid(True, which="both", linewidth=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def kernels_of(implementation: str):
    """A context in which the interfaces run ``implementation``'s kernels: the package's own
    (compiled), or the numpy oracle of tests/oracle (imported from there: developer tool)."""
    if implementation == "compiled":
        return contextlib.nullcontext()
    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "tests"))
    from oracle import use_oracle

    return use_oracle()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", type=float, nargs="+", default=DEFAULT_SIZES,
                        help="numbers of slave facets (default: 1e3 ... 1e5)")
    parser.add_argument("--repeats", type=int, default=5,
                        help="timed repeats per size (median; default 5)")
    parser.add_argument("--json", help="write the results to this file")
    parser.add_argument("--png", help="write a log-log plot of the phases to this file")
    parser.add_argument("--normals", default="averaged", choices=kernels.NORMAL_OPTIONS)
    parser.add_argument("--integration", default="segment", choices=kernels.INTEGRATION_OPTIONS)
    parser.add_argument("--dim", type=int, default=2, choices=(2, 3),
                        help="2: strips of quadrilaterals; 3: slabs of --cell (default 2)")
    parser.add_argument("--cell", default="tetrahedron", choices=("tetrahedron", "hexahedron"),
                        help="3D: the slabs' cells (triangle or quadrilateral interface)")
    parser.add_argument("--kernels", nargs="+", choices=KERNELS, default=["compiled"],
                        help="kernel implementations to measure in turn, each size with each: "
                             "numpy (the tests' oracle, tests/oracle), compiled (the package's; "
                             "default)")
    args = parser.parse_args(argv)
    if MPI.COMM_WORLD.size != 1:
        parser.error("the benchmark is serial; run it without mpirun")
    sizes = [int(round(n)) for n in args.sizes]
    implementations = args.kernels
    print(f"dimension {args.dim}" + (f", {args.cell}" if args.dim == 3 else ""),
          file=sys.stderr)
    by_kernels = {}
    for n in sizes:
        for implementation in implementations:
            with kernels_of(implementation), PeakMemory() as memory:
                result = measure(n, args.repeats, args.normals, args.integration, args.dim,
                                 args.cell)
            result["kernels"] = implementation
            result["peak_memory"] = memory.peak
            by_kernels.setdefault(implementation, []).append(result)
            print(f"N={n} {implementation}: total {1e3 * result['total']:.1f} ms "
                  f"(search {1e3 * result['search']:.1f}, "
                  f"integration {1e3 * result['integration']:.1f}, "
                  f"assembly {1e3 * result['assembly']:.1f}); {result['pairs']} pairs; "
                  f"peak memory {result['peak_memory'] / 1e9:.2f} GB (first update "
                  f"allocates {result['update_memory'] / 1e9:.2f} GB at its peak)",
                  file=sys.stderr, flush=True)
    for implementation in implementations[:-1]:
        results = by_kernels[implementation]
        print(f"\n{args.dim}D, kernels {implementation}, median times in ms\n")
        print(markdown_table(results))
        print(memory_rows(results))
    results = by_kernels[implementations[-1]]
    print(f"\nkernels {implementations[-1]}:")
    sizes = [r["N"] for r in results]
    cell = f" ({args.cell})" if args.dim == 3 else ""
    print(f"\n{args.dim}D{cell}, median times in ms, {args.repeats} repeats, "
          f"normals={args.normals}, integration={args.integration}, "
          f"dolfinx {dolfinx.__version__}\n")
    print(markdown_table(results))
    print(memory_rows(results))
    summary = {}
    if len(results) > 1:
        summary["slope_total"] = loglog_slope(sizes, [r["total"] for r in results])
        print(f"\nlog-log slope of the total over N = {sizes[0]} ... {sizes[-1]}: "
              f"{summary['slope_total']:.2f}")
    summary["largest_N"] = sizes[-1]
    summary["total_at_largest_N"] = results[-1]["total"]
    print(f"total at N = {sizes[-1]}: {results[-1]['total']:.3f} s")
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"options": {"dim": args.dim, "cell": args.cell, "normals": args.normals,
                                   "integration": args.integration,
                                   "repeats": args.repeats, "dolfinx": dolfinx.__version__,
                                   "numpy": np.__version__, "python": platform.python_version()},
                       "summary": summary, "results": results,
                       "results_by_kernels": by_kernels}, f, indent=1)
    if args.png:
        plot(results, args.png)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
