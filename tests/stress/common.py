"""Set-ups and measurements shared by the stress cases (see docs/stress.md).

Every set-up builds its own :class:`ContactProblem` (the demos return only a
summary, and the stress cases need the problem itself: the whole pressure
vector, the displacement, the active set, NaN checks, scaled coordinates). The
set-ups follow the demos: ``patch_traction`` is ``demos/patch_test.py``,
``hertz`` is ``demos/hertz.py`` (case B), ``ironing`` is ``demos/ironing.py``.

All functions are collective; results (pressures, forces, NaN flags) are the
same on every rank.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import math
import os
import pathlib
import time
import typing

import dolfinx
import numpy as np
import ufl
from mpi4py import MPI

from dolfinx_mortar import (
    ContactPair,
    ContactProblem,
    Material,
    SolveReport,
    StepRecord,
    compat,
    internal_work,
    meshes,
    solve_load_steps,
)

DEMOS = pathlib.Path(__file__).parents[2] / "demos"

# patch test (demos/patch_test.py)
PATCH_E, PATCH_NU, PATCH_PRESSURE = 1000.0, 0.4, 10.0
# Hertz case B (demos/hertz.py)
HERTZ_E, HERTZ_NU, HERTZ_LOAD, HERTZ_RADIUS = 200.0, 0.3, 10.0, 8.0
# ironing (demos/ironing.py)
DIE_E, BLOCK_E, IRONING_NU = 6.896e9, 6.896e8, 0.32


def demo(name: str):
    """Import demos/<name>.py as a module (its ``main(argv, comm)`` returns a summary)."""
    spec = importlib.util.spec_from_file_location(f"stress_demo_{name}", DEMOS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


# ----------------------------------------------------------------------------------------
# measurements


def non_finite(problem: ContactProblem) -> bool:
    """Collective: does the displacement or any multiplier hold a NaN or inf?"""
    bad = not np.all(np.isfinite(problem.u.x.array))
    for z in problem.multipliers:
        bad |= not np.all(np.isfinite(z.getArray(readonly=True)))
    return bool(problem.comm.allreduce(bad, op=MPI.LOR))


def inverted_cells(u: dolfinx.fem.Function) -> int:
    """Collective: number of cells whose signed area (any corner for quads) changed sign
    or vanished between the reference and the current configuration."""
    mesh = u.function_space.mesh
    geometry = compat.geometry_dofmap(mesh)
    num_cells = mesh.topology.index_map(mesh.topology.dim).size_local
    X = mesh.geometry.x[:, :2][geometry[:num_cells]]
    x = X + u.x.array.reshape(-1, 2)[u.function_space.dofmap.list[:num_cells]]
    corners = (
        [(0, 1, 2)] if geometry.shape[1] == 3 else [(0, 1, 2), (1, 3, 0), (3, 2, 1), (2, 0, 3)]
    )

    def cross(p, q):
        return p[:, 0] * q[:, 1] - p[:, 1] * q[:, 0]

    bad = np.zeros(num_cells, dtype=bool)
    for a, b, c in corners:
        current = cross(x[:, b] - x[:, a], x[:, c] - x[:, a])
        reference = cross(X[:, b] - X[:, a], X[:, c] - X[:, a])
        bad |= current * reference <= 0.0
    return int(mesh.comm.allreduce(int(bad.sum()), op=MPI.SUM))


def gathered_displacement(u: dolfinx.fem.Function) -> tuple[np.ndarray, np.ndarray]:
    """(reference node coordinates, nodal displacement) of all owned nodes on every rank,
    in the order of the dofs (rank by rank): comparable between runs on the same mesh
    built on the same communicator (the builders are deterministic). Not sorted by
    coordinates: the two bodies have distinct nodes at the same place, whose order
    would then depend on rounding."""
    V = u.function_space
    owned = V.dofmap.index_map.size_local
    coordinates = V.tabulate_dof_coordinates()[:owned, :2]
    values = u.x.array.reshape(-1, 2)[:owned]
    comm = V.mesh.comm
    return np.vstack(comm.allgather(coordinates)), np.vstack(comm.allgather(values))


def relative_difference(a: np.ndarray, b: np.ndarray) -> float:
    """max |a - b| / max |b| (0 when both vanish)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    scale = float(np.max(np.abs(b), initial=0.0))
    difference = float(np.max(np.abs(a - b), initial=0.0))
    if scale == 0.0:
        return difference
    return difference / scale


@dataclasses.dataclass
class Outcome:
    """What a stress run measured; ``row()`` is what the report table shows."""

    converged: bool
    iterations: list[int]
    nan: bool
    active: int
    cutbacks: int = 0
    pressure: np.ndarray | None = None  # gathered, sorted by x
    coordinates: np.ndarray | None = None
    displacement: np.ndarray | None = None  # gathered nodal displacement, sorted
    slave_force: np.ndarray | None = None
    master_force: np.ndarray | None = None
    inverted: int = 0
    wall_time: float = 0.0
    extra: dict = dataclasses.field(default_factory=dict)

    @property
    def force_balance(self) -> float:
        """|f_slave + f_master| / |f_slave| (0 without contact force)."""
        size = float(np.linalg.norm(self.slave_force))
        if size == 0.0:
            return float(np.linalg.norm(self.slave_force + self.master_force))
        return float(np.linalg.norm(self.slave_force + self.master_force) / size)


def measure(
    problem: ContactProblem,
    reports: typing.Sequence[SolveReport | StepRecord],
    wall_time: float = 0.0,
    **extra,
) -> Outcome:
    """Collect an :class:`Outcome` from a solved problem (collective)."""
    converged, iterations, cutbacks = True, [], 0
    for item in reports:
        report = item.report if isinstance(item, StepRecord) else item
        converged &= bool(report.converged)
        iterations.append(int(report.iterations))
        cutbacks += getattr(item, "cutbacks", 0)
    coordinates, pressure = problem.gathered_pressure()
    slave, master = problem.contact_forces()
    _, displacement = gathered_displacement(problem.u)
    return Outcome(
        converged=converged,
        iterations=iterations,
        nan=non_finite(problem),
        active=problem.num_active(),
        cutbacks=cutbacks,
        pressure=pressure,
        coordinates=coordinates,
        displacement=displacement,
        slave_force=slave,
        master_force=master,
        inverted=inverted_cells(problem.u),
        wall_time=wall_time,
        extra=extra,
    )


# ----------------------------------------------------------------------------------------
# mesh surgery (before the function space is created)


def body_nodes(tagged: meshes.TaggedMesh, body: str) -> np.ndarray:
    """Local geometry node indices of the cells of one body (owned and ghost)."""
    cells = tagged.cell_tags.find(tagged.markers[body])
    return np.unique(compat.geometry_dofmap(tagged.mesh)[cells].reshape(-1))


def move_body(tagged: meshes.TaggedMesh, body: str, transform: typing.Callable) -> None:
    """x <- transform(x) (an (n, 2) array) for the nodes of one body, in place."""
    nodes = body_nodes(tagged, body)
    x = tagged.mesh.geometry.x
    x[nodes, :2] = transform(x[nodes, :2].copy())


# ----------------------------------------------------------------------------------------
# set-ups


def contact_problem(tagged: meshes.TaggedMesh, F, u, bcs, name: str, **options) -> ContactProblem:
    """The ContactProblem of one pair, the mesh's contact_slave against contact_master."""
    markers = tagged.markers
    pair = ContactPair(
        tagged.facet_tags, markers["contact_slave"], markers["contact_master"], name=name
    )
    return ContactProblem(F, u, bcs, [pair], **options)


def clamped_and_driven(V, tagged: meshes.TaggedMesh, clamped: str, driven: str):
    """Dirichlet conditions u = 0 on the facets ``clamped`` and u = motion on ``driven``;
    returns (bcs, motion), motion a Constant vector to set per load."""
    mesh, markers = tagged.mesh, tagged.markers
    fdim = mesh.topology.dim - 1
    motion = dolfinx.fem.Constant(mesh, np.zeros(2))
    bcs = []
    for name, value in ((clamped, np.zeros(2)), (driven, motion)):
        facets = tagged.facet_tags.find(markers[name])
        dofs = dolfinx.fem.locate_dofs_topological(V, fdim, facets)
        bcs.append(dolfinx.fem.dirichletbc(value, dofs, V))
    return bcs, motion


def all_pairs(slave: np.ndarray, master: np.ndarray):
    """Every (slave facet, master facet) pair of two polylines in the layout of
    kernels.pair_quantities; slave facet i joins slave nodes i, i + 1. Missing
    neighbours get NaN coordinates (any use would show).
    Returns (x, has_neighbour, slave facet, master facet) per pair."""
    num_slave, num_master = len(slave) - 1, len(master) - 1
    facet_s, facet_m = (
        a.ravel() for a in np.meshgrid(np.arange(num_slave), np.arange(num_master), indexing="ij")
    )
    padded = np.concatenate([[np.full(2, np.nan)], slave, [np.full(2, np.nan)]])
    x = np.stack(
        [
            padded[facet_s],
            slave[facet_s],
            slave[facet_s + 1],
            padded[facet_s + 3],
            master[facet_m],
            master[facet_m + 1],
        ],
        axis=1,
    )
    has_neighbour = np.stack([facet_s > 0, facet_s + 1 < num_slave], axis=1)
    return x, has_neighbour, facet_s, facet_m


class TooManySteps(RuntimeError):
    """The load stepping went on with tiny steps (see Setup.steps)."""


@dataclasses.dataclass
class Setup:
    """A contact problem and what drives it."""

    tagged: meshes.TaggedMesh
    problem: ContactProblem
    apply_load: typing.Callable[[float], None]
    info: dict = dataclasses.field(default_factory=dict)

    def solve(self, t: float = 1.0) -> Outcome:
        """One Newton solve at load t (no load stepping)."""
        self.apply_load(t)
        start = time.perf_counter()
        report = self.problem.solve()
        return measure(self.problem, [report], time.perf_counter() - start)

    def steps(
        self, num_steps: int, *, max_steps: int | None = None, on_step=None, **options
    ) -> Outcome:
        """solve_load_steps over t in [start, end] (default [0, 1]).

        Raises TooManySteps once ``max_steps`` steps (default 20 times the nominal
        number, at least 100) are accepted before the end: after a cut-back the stepper
        may go on with tiny increments for a very long time.
        """
        limit = max_steps or max(100, 20 * num_steps)
        end = options.get("end", 1.0)
        accepted = []

        def guarded(step_record: StepRecord) -> None:
            accepted.append(step_record)
            if on_step is not None:
                on_step(step_record)
            if len(accepted) >= limit and step_record.load < end - 1e-12:
                increment = step_record.load - (accepted[-2].load if len(accepted) > 1 else 0.0)
                raise TooManySteps(
                    f"load stepping accepted {len(accepted)} steps and reached only "
                    f"t = {step_record.load:.6g} of {end:g} (last increment {increment:.3g}, "
                    f"{sum(r.cutbacks for r in accepted)} cut-backs)"
                )

        start = time.perf_counter()
        records = solve_load_steps(
            self.problem, self.apply_load, num_steps, on_step=guarded, **options
        )
        outcome = measure(self.problem, records, time.perf_counter() - start)
        outcome.extra["records"] = records
        return outcome

    def destroy(self) -> None:
        self.problem.destroy()


def neo_hookean_uniaxial_stretches(E: float, nu: float, pressure: float) -> tuple[float, float]:
    """Stretches (a, b) of the uniform plane-strain state F = diag(a, b) of a compressible
    Neo-Hookean body (materials.neo_hookean_stress) under the nominal stresses
    P_xx = 0, P_yy = -pressure.

    P = mu (F - F^-T) + lambda ln(J) F^-T: P_xx = 0 and P_yy = -p give
    mu (b^2 - a^2) = -p b, then one equation in b.
    """
    from scipy.optimize import brentq

    material = Material(E, nu, "neo-hookean")
    mu, lmbda = material.mu, material.lmbda

    def stretch_a(b):
        return math.sqrt(b * b + pressure * b / mu)

    def equation(b):
        a = stretch_a(b)
        return mu * (b * b - 1.0) + lmbda * math.log(a * b) + pressure * b

    b = brentq(equation, 0.05, 1.0 + 1e-12, xtol=1e-16, rtol=1e-15)
    return stretch_a(b), b


def patch_traction(
    *,
    ratio=(3, 2),
    slave: str = "top",
    material: str = "linear",
    cell_type: str = "triangle",
    length_scale: float = 1.0,
    modulus_scale: float = 1.0,
    punch_shift: float = 0.0,
    pressure_on: str = "all",
    pressure: float = PATCH_PRESSURE,
    comm: MPI.Intracomm = MPI.COMM_WORLD,
    **options,
) -> Setup:
    """The contact patch test of demos/patch_test.py, with knobs.

    Foundation [0, 8] x [0, 5], punch [4, 6] x [5, 7], E = 1000, nu = 0.4, a
    pressure 10 at t = 1 (dead load) on the whole top (``pressure_on="all"``: the
    exact state is uniform) or on the punch top only (``"punch"``), bottom on
    rollers, u_x prescribed at (0, 0) and (4, 7) to the exact uniform lateral
    strain (of the linear or the Neo-Hookean material).

    length_scale multiplies every coordinate (mesh.geometry.x in place, before the
    function space exists), modulus_scale E and the pressure (so that the
    dimensionless solution, pressure / E and u / length, does not change).
    punch_shift moves the punch horizontally (before scaling). ``material``
    ``linear`` runs in the reference configuration (small strain), the others in
    the current one.
    """
    tagged = meshes.patch_test(ratio=ratio, slave=slave, cell_type=cell_type, comm=comm)
    mesh, markers = tagged.mesh, tagged.markers
    if punch_shift:
        move_body(tagged, "punch", lambda x: x + np.array([punch_shift, 0.0]))
    if length_scale != 1.0:
        mesh.geometry.x[:] *= length_scale
    E, p = PATCH_E * modulus_scale, pressure * modulus_scale
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    u = dolfinx.fem.Function(V, name="displacement")
    v = ufl.TestFunction(V)
    model = Material(E, PATCH_NU, material)
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=tagged.facet_tags)
    traction = dolfinx.fem.Constant(mesh, np.array([0.0, 0.0]))
    loaded = ds(markers["punch_top"])
    if pressure_on == "all":
        loaded = loaded + ds(markers["foundation_top_free"])
    F = internal_work(u, v, {0: model}) - ufl.inner(traction, v) * loaded

    if material == "linear":
        strain_xx = p * PATCH_NU * (1.0 + PATCH_NU) / E
    elif material == "neo-hookean":
        strain_xx = neo_hookean_uniaxial_stretches(E, PATCH_NU, p)[0] - 1.0
    else:
        strain_xx = 0.0
    fdim = mesh.topology.dim - 1
    bottom = tagged.facet_tags.find(markers["foundation_bottom"])
    bcs = [
        dolfinx.fem.dirichletbc(
            np.float64(0.0), dolfinx.fem.locate_dofs_topological(V.sub(1), fdim, bottom), V.sub(1)
        )
    ]
    mesh.topology.create_connectivity(0, mesh.topology.dim)
    corner_values = []
    for corner in ((0.0, 0.0), (4.0 + punch_shift, 7.0)):
        c = np.array(corner) * length_scale
        tolerance = 1e-8 * length_scale
        vertices = dolfinx.mesh.locate_entities(
            mesh,
            0,
            lambda x, c=c, tol=tolerance: (
                (np.abs(x[0] - c[0]) <= tol) & (np.abs(x[1] - c[1]) <= tol)
            ),
        )
        dofs = dolfinx.fem.locate_dofs_topological(V.sub(0), 0, vertices)
        value = dolfinx.fem.Constant(mesh, np.float64(0.0))
        corner_values.append((value, strain_xx * c[0]))
        bcs.append(dolfinx.fem.dirichletbc(value, dofs, V.sub(0)))

    configuration = "reference" if material == "linear" else "current"
    problem = contact_problem(
        tagged, F, u, bcs, "punch-foundation", configuration=configuration, **options
    )

    def apply_load(t: float) -> None:
        traction.value[:] = (0.0, -t * p)
        for constant, value in corner_values:
            constant.value = t * value if material == "linear" else value_at(t, value)

    def value_at(t: float, value_at_one: float) -> float:
        # the Neo-Hookean lateral strain is not linear in the load
        if t == 1.0:
            return value_at_one
        a, _ = neo_hookean_uniaxial_stretches(E, PATCH_NU, t * p)
        return (a - 1.0) * value_at_one / strain_xx if strain_xx else 0.0

    info = {"E": E, "pressure": p, "length_scale": length_scale, "strain_xx": strain_xx}
    return Setup(tagged, problem, apply_load, info)


def punch_driven(
    *,
    ratio=(3, 2),
    slave: str = "top",
    material: str = "neo-hookean",
    cell_type: str = "triangle",
    punch_angle: float = 0.0,
    drive: typing.Callable[[float], tuple[float, float]] = lambda t: (0.0, -0.05 * t),
    comm: MPI.Intracomm = MPI.COMM_WORLD,
    **options,
) -> Setup:
    """Patch-test mesh with the punch top displaced by ``drive(t)`` (both components)
    and the foundation bottom clamped: no rigid body mode, however the contact goes.

    punch_angle rotates the punch about its corner (4, 5) (counter-clockwise: the
    corner (6, 5) lifts), so that it touches the foundation at that one corner.
    """
    tagged = meshes.patch_test(ratio=ratio, slave=slave, cell_type=cell_type, comm=comm)
    mesh = tagged.mesh
    if punch_angle:
        c, s = math.cos(punch_angle), math.sin(punch_angle)
        rotation = np.array([[c, -s], [s, c]])
        pivot = np.array([4.0, 5.0])
        move_body(tagged, "punch", lambda x: (x - pivot) @ rotation.T + pivot)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    u = dolfinx.fem.Function(V, name="displacement")
    F = internal_work(u, ufl.TestFunction(V), {0: Material(PATCH_E, PATCH_NU, material)})
    bcs, motion = clamped_and_driven(V, tagged, "foundation_bottom", "punch_top")
    configuration = "reference" if material == "linear" else "current"
    problem = contact_problem(
        tagged, F, u, bcs, "punch-foundation", configuration=configuration, **options
    )

    def apply_load(t: float) -> None:
        motion.value[:] = drive(t)

    return Setup(tagged, problem, apply_load, {})


def hertz(
    *,
    refinement: int = 0,
    load: float = HERTZ_LOAD,
    material: str = "linear",
    indentation: float | None = None,
    comm: MPI.Intracomm = MPI.COMM_WORLD,
    **options,
) -> Setup:
    """Hertz case B of demos/hertz.py: half-cylinder R = 8 on a block, E = 200, nu = 0.3,
    force ``load`` (at t = 1) as a uniform traction on the flat top, u_x = 0 on x = 0.

    The cylinder starts moved down by ``indentation`` (default, as the demo: a
    quarter of the Hertz approach, so that the first Newton iterate has active nodes).
    """
    module = demo("hertz")
    exact = module.hertz_solution(load, HERTZ_RADIUS, HERTZ_E, HERTZ_NU, HERTZ_E, HERTZ_NU, "B")
    tagged = meshes.hertz(case="B", refinement=refinement, radius=HERTZ_RADIUS, comm=comm)
    mesh, markers = tagged.mesh, tagged.markers
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    u = dolfinx.fem.Function(V, name="displacement")
    materials = {
        markers["cylinder"]: Material(HERTZ_E, HERTZ_NU, material),
        markers["block"]: Material(HERTZ_E, HERTZ_NU, material),
    }
    F, traction, bcs = module.bulk_problem(tagged, u, materials)
    configuration = "reference" if material == "linear" else "current"
    problem = contact_problem(
        tagged, F, u, bcs, "cylinder-block", configuration=configuration, **options
    )
    if indentation is None:
        indentation = (0.5 * exact["a"]) ** 2 / (2.0 * exact["R_star"])
    if indentation:
        cylinder = tagged.cell_tags.find(markers["cylinder"])
        u.interpolate(lambda x: np.vstack([0.0 * x[0], -indentation + 0.0 * x[0]]), cylinder)
        u.x.scatter_forward()
    width = 2.0 * HERTZ_RADIUS

    def apply_load(t: float) -> None:
        traction.value[:] = (0.0, -t * load / width)

    return Setup(tagged, problem, apply_load, {"exact": exact, "load": load})


def ironing(
    *,
    refinement: int = 0,
    cell_type: str = "quadrilateral",
    depth: float = 1.0,
    slide: float = 10.0,
    comm: MPI.Intracomm = MPI.COMM_WORLD,
    **options,
) -> Setup:
    """The ironing problem of demos/ironing.py: die top moved down ``depth`` over
    t in [0, 1], then ``slide`` to the right over t in [1, 2]; Neo-Hookean."""
    tagged = meshes.ironing(refinement=refinement, cell_type=cell_type, comm=comm)
    mesh, markers = tagged.mesh, tagged.markers
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    u = dolfinx.fem.Function(V, name="displacement")
    materials = {
        markers["die"]: Material(DIE_E, IRONING_NU, "neo-hookean"),
        markers["block"]: Material(BLOCK_E, IRONING_NU, "neo-hookean"),
    }
    F = internal_work(u, ufl.TestFunction(V), materials, tagged.cell_tags)
    bcs, motion = clamped_and_driven(V, tagged, "block_bottom", "die_top")
    problem = contact_problem(tagged, F, u, bcs, "die-block", **options)

    def apply_load(t: float) -> None:
        if t <= 1.0:
            motion.value[:] = (0.0, -depth * t)
        else:
            motion.value[:] = (slide * (t - 1.0), -depth)

    return Setup(tagged, problem, apply_load, {})


def rings(
    *,
    squeeze: float,
    refinement: int = 0,
    inner_radius: float = 0.3,
    outer_radius: float = 1.0,
    E: float = 1.0,
    nu: float = 0.3,
    cell_type: str = "triangle",
    comm: MPI.Intracomm = MPI.COMM_WORLD,
    **options,
) -> Setup:
    """Two Neo-Hookean rings of meshes.rings, touching at the origin; their inner
    boundaries are moved rigidly towards each other, each by squeeze / 2 at t = 1
    (squeeze is the total approach of the centres)."""
    tagged = meshes.rings(
        refinement=refinement,
        inner_radius=inner_radius,
        outer_radius=outer_radius,
        cell_type=cell_type,
        comm=comm,
    )
    mesh, markers = tagged.mesh, tagged.markers
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    u = dolfinx.fem.Function(V, name="displacement")
    material = Material(E, nu, "neo-hookean")
    F = internal_work(
        u,
        ufl.TestFunction(V),
        {markers["ring_top"]: material, markers["ring_bottom"]: material},
        tagged.cell_tags,
    )
    fdim = mesh.topology.dim - 1
    top_motion = dolfinx.fem.Constant(mesh, np.zeros(2))
    bottom_motion = dolfinx.fem.Constant(mesh, np.zeros(2))
    bcs = []
    for name, motion in (("ring_top_inner", top_motion), ("ring_bottom_inner", bottom_motion)):
        facets = tagged.facet_tags.find(markers[name])
        bcs.append(
            dolfinx.fem.dirichletbc(motion, dolfinx.fem.locate_dofs_topological(V, fdim, facets), V)
        )
    problem = contact_problem(tagged, F, u, bcs, "rings", **options)

    def apply_load(t: float) -> None:
        top_motion.value[:] = (0.0, -0.5 * squeeze * t)
        bottom_motion.value[:] = (0.0, 0.5 * squeeze * t)

    return Setup(tagged, problem, apply_load, {"outer_diameter": 2.0 * outer_radius})


# ----------------------------------------------------------------------------------------
# the table of measured results (printed by conftest.py, written to JSON on request)

RESULTS: dict[str, dict] = {}


def record(case: int, **values) -> None:
    """Remember what the running test measured (converged, iterations, error, nan, ...).

    Keyed by the running test's node id; a later call of the same test adds to it
    (a hypothesis test records its totals at the end)."""
    current = os.environ.get("PYTEST_CURRENT_TEST", "unknown (call)")
    nodeid = current.rsplit(" (", 1)[0]
    entry = RESULTS.setdefault(nodeid, {})
    entry["case"] = case
    for key, value in values.items():
        if isinstance(value, np.generic):
            value = value.item()
        elif isinstance(value, np.ndarray):
            value = value.tolist()
        entry[key] = value


def record_outcome(case: int, outcome: Outcome, **values) -> None:
    """record() with what every solve reports: converged, iterations, cut-backs, NaN."""
    record(
        case,
        converged=outcome.converged,
        iterations=outcome.iterations,
        cutbacks=outcome.cutbacks,
        nan=outcome.nan,
        **values,
    )
