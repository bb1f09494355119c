"""Mortar contact of deforming bodies, with or without friction, solved with PETSc SNES.

:class:`ContactProblem` couples a bulk residual F(u; v) given in UFL with one or more
mortar contact pairs. The unknowns are the displacements u and one normal multiplier
z_j >= 0 (contact pressure) per slave node, with friction d - 1 tangential multipliers
y_j too, in one AIJ matrix (layout [u | z_1 | z_2 ...] per rank), solved by Newton's
method in PETSc SNES with our own residual and Jacobian (paper, eq. 1 and section 5):

    R_u = F(u) - sum_pairs B(u)^T z,    R_z = C(z, u)

B_j = d g~_j / dx at frozen integrals (-Dn on slave dofs, +Mn on master dofs) pushes
the slave along -n and the master along +n. The multiplier rows C depend on the
enforcement (:mod:`dolfinx_mortar.enforcement`: Lagrange multipliers with a semismooth
or a fixed-point active set, penalty, or augmented Lagrange); friction's rows are in
:mod:`dolfinx_mortar.friction`. Every row is a force, whatever the enforcement, so
that SNES' tolerances do not depend on units, c_n or eps.

The problem is put together from parts, one module each: its options
(:mod:`dolfinx_mortar.options`), the set-up checks (:mod:`dolfinx_mortar.checks`), the
state with the residual and Jacobian (:mod:`dolfinx_mortar.equations`), the Newton
matrix (:mod:`dolfinx_mortar.system`), the Newton solver (:mod:`dolfinx_mortar.newton`,
:mod:`dolfinx_mortar.solvers`) and the results (:mod:`dolfinx_mortar.results`).
"""

from __future__ import annotations

import dataclasses
import time
import typing

import dolfinx
import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from . import allocator, checks, compat, diagnostics, enforcement, solvers
from . import friction as friction_rules
from .deprecation import moved
from .equations import ContactEquations, bulk_diagonal, stiffness_scales
from .layout import BlockLayout, dirichlet_dofs
from .mortar import MortarInterface
from .newton import ContactNewton
from .options import ContactOptions, contact_options
from .results import ContactResults
from .surface import body_labels as surface_body_labels
from .system import ContactSystem

__all__ = ["ContactPair", "ContactProblem"]

__getattr__ = moved(__name__, {
    "ContactWarning": "dolfinx_mortar.ContactWarning",
    "SolveReport": "dolfinx_mortar.SolveReport",
    "INITIAL_OVERLAP": "dolfinx_mortar.checks.INITIAL_OVERLAP",
    "STIFF_SLAVE_RATIO": "dolfinx_mortar.checks.STIFF_SLAVE_RATIO",
})

MAX_TOLERANCE_FACTOR = 1e3
"""The default SNES atol (1e-11 k h, k the slave's stiffness scale) grows with the
master's stiffness over the slave's up to this factor: a node of the slave then moves by
at most 1e-8 h when the test passes."""


@dataclasses.dataclass(frozen=True)
class ContactPair:
    """Two facet-tagged surfaces that may come into contact.

    Attributes:
        facet_tags: meshtags of the facets.
        slave: tag of the slave (non-mortar) surface, which carries the multipliers.
        master: tag of the master (mortar) surface.
        name: for logs and reports.
    """

    facet_tags: dolfinx.mesh.MeshTags
    slave: int
    master: int
    name: str = ""


class ContactProblem(ContactResults):
    """Mortar contact problem with multipliers, penalty or augmented Lagrange.

    Building it is collective, and so are most methods (each says whether): call them on
    every rank of the mesh's communicator (on one rank alone they wait forever). Use it
    in a ``with`` block to free its PETSc objects on every rank when the block ends, also
    by an exception; or call :meth:`destroy`.

    Building it checks the set-up before any load step (:mod:`dolfinx_mortar.checks`): it
    raises :class:`ValueError` when a pair's slave and master lie on one connected mesh,
    and warns (a ContactWarning, shown once by rank 0) when a slave surface looks away
    from its master, when the bodies start overlapping, and when a body is free to move
    as a rigid body.

    Args:
        F: bulk residual form F(u; v) (internal minus external virtual work).
        u: displacement Function on a P1 vector space.
        bcs: Dirichlet conditions on u.
        pairs: the contact pairs.
        J: Jacobian form of F (default: its Gateaux derivative).
        options: how contact is enforced and solved
            (:class:`~dolfinx_mortar.options.ContactOptions`); ``**keywords`` are its
            fields (``method="penalty"``, ``friction=Coulomb(0.3)``, ...), over ``options``.
        petsc_options: SNES/KSP options (defaults: newtonls, full steps, MUMPS LU;
            :mod:`dolfinx_mortar.solvers`); the user's options database with the prefix
            wins. They are in the global database only while the solver is set up and
            while it solves.
        petsc_options_prefix: prefix of those options.
    """

    def __init__(self, F: ufl.Form, u: dolfinx.fem.Function, bcs: list,
                 pairs: typing.Sequence[ContactPair], *, J: ufl.Form | None = None,
                 options: ContactOptions | None = None, petsc_options: dict | None = None,
                 petsc_options_prefix: str = "dolfinx_mortar_", **keywords):
        options = contact_options(options, keywords)
        if not pairs:
            raise ValueError("ContactProblem needs at least one ContactPair")
        self.options = options
        self.u, self.V = u, u.function_space
        self.comm: MPI.Intracomm = self.V.mesh.comm
        self.bcs, self.pairs = list(bcs), list(pairs)
        self.method, self.active_set_strategy = options.method, options.active_set
        self.has_friction = options.has_friction
        self._choose_linear_solver(options)
        gdim = self.V.mesh.geometry.dim
        self.pressure_recovery = (gdim == 3 if options.pressure_recovery is None
                                  else bool(options.pressure_recovery))
        self.F_form = dolfinx.fem.form(F)
        self.J_form = dolfinx.fem.form(
            J if J is not None else ufl.derivative(F, u, ufl.TrialFunction(self.V)))
        self._destroyed = True  # nothing to free until the PETSc objects exist
        self.swapped = [False] * len(self.pairs)
        """Per pair, whether it is solved with its slave and master swapped
        (``slave_side="auto"``): its multipliers, pressures and friction state are then on
        the surface the ContactPair calls master (:meth:`solved_pair`)."""
        self.interfaces = [self._mortar_interface(pair, options) for pair in self.pairs]
        self._destroyed = False
        try:
            self._build(options, petsc_options or {}, petsc_options_prefix)
        except BaseException:
            self.destroy()
            raise

    def _mortar_interface(self, pair: ContactPair, options: ContactOptions) -> MortarInterface:
        """The mortar interface of ``pair`` as given (its slave side the slave)."""
        return MortarInterface(self.V, pair.facet_tags, pair.slave, pair.master,
                               normals=options.normals, integration=options.integration,
                               basis=options.basis,
                               num_gauss_points=options.num_gauss_points,
                               search_margin=options.search_margin,
                               configuration=options.configuration)

    def solved_pair(self, k: int = 0) -> ContactPair:
        """Pair k as it is solved: the ContactPair given, or with its slave and master tags
        swapped where ``slave_side="auto"`` swapped them (:attr:`swapped`). The slave side
        carries the multipliers: :meth:`contact_pressure` and :meth:`friction_state` are
        at its nodes."""
        pair = self.pairs[k]
        if not self.swapped[k]:
            return pair
        return dataclasses.replace(pair, slave=pair.master, master=pair.slave)

    def _choose_slave_sides(self, options: ContactOptions, diagonal, gdim: int) -> None:
        """With ``slave_side="auto"``, in 3D, swap the sides of each pair whose slave is
        STIFF_SLAVE_RATIO times stiffer than its master, unless the master's facets are
        COARSE_MASTER_RATIO times longer (a coarse slave lets the master's nodes through
        it). Collective."""
        if options.slave_side != "auto" or gdim != 3:
            return
        for k, (pair, interface) in enumerate(zip(self.pairs, self.interfaces, strict=True)):
            if pair.slave == pair.master:
                continue
            s, h, s_master, h_master = stiffness_scales(diagonal, [interface], self.comm, gdim)
            ratio = s * h / (s_master * h_master)
            if not (ratio >= checks.STIFF_SLAVE_RATIO
                    and h_master <= checks.COARSE_MASTER_RATIO * h):
                continue
            normals = {"slave": "master", "master": "slave"}.get(options.normals,
                                                                 options.normals)
            swapped = dataclasses.replace(pair, slave=pair.master, master=pair.slave)
            interface.destroy()
            self.interfaces[k] = self._mortar_interface(
                swapped, dataclasses.replace(options, normals=normals))
            self.swapped[k] = True
            checks.report_swap(self._warnings, pair, ratio, options.normals, normals)

    def _choose_linear_solver(self, options: ContactOptions) -> None:
        """The linear solver ``auto`` stands for, and whether it condenses; raise for the
        combinations friction does not support."""
        self._automatic_linear_solver = options.linear_solver == "auto"
        self._condensation_requested = bool(options.condensation)
        linear_solver = options.linear_solver
        if linear_solver == "auto":
            index_map = self.V.dofmap.index_map
            linear_solver = solvers.automatic_linear_solver(
                self.V.mesh.geometry.dim, index_map.size_global * self.V.dofmap.index_map_bs,
                options.basis, self.has_friction)
        self._linear_solver = linear_solver
        self._condensation = options.condensation or linear_solver == "iterative"
        if self._condensation:
            # before the set-up's temporaries (the bulk matrix, its CSR copy), which
            # then go back to the system when freed (allocator's docstring)
            allocator.release_freed_memory()
        solvers.advise_blas(self.comm)
        if self.has_friction:
            friction_rules.check_options(options.method, options.active_set,
                                         self._condensation, linear_solver)

    def _build(self, options: ContactOptions, petsc_options: dict, prefix: str) -> None:
        """Check the set-up, then make the state, the equations and the solver."""
        gdim = self.V.mesh.geometry.dim
        if self.has_friction and gdim == 3:
            for interface in self.interfaces:
                interface.scalar_gradients = True  # friction's tangent frames
        self._warnings = checks.ProblemWarnings(self.comm)
        self.setup_warnings = self._warnings.setup
        self._K = compat.create_matrix(self.J_form)
        diagonal = bulk_diagonal(self._K, self.J_form)
        self._choose_slave_sides(options, diagonal, gdim)
        pairs = [self.solved_pair(k) for k in range(len(self.pairs))]
        body_labels = surface_body_labels(self.V.mesh)
        checks.check_slave_body(self.comm, pairs, self.interfaces, body_labels)
        checks.check_facing(self._warnings, pairs, self.interfaces, self.u)
        checks.check_initial_overlap(self._warnings, pairs, self.interfaces, self.u)
        bs = self.V.dofmap.index_map_bs
        self._fixed_dofs = dirichlet_dofs(self.bcs, self.V)
        fixed_blocks = np.unique(self._fixed_dofs // bs)
        fully_fixed = fixed_blocks[
            np.all(np.isin(fixed_blocks[:, None] * bs + np.arange(bs), self._fixed_dofs), axis=1)]
        for interface in self.interfaces:
            interface.set_crosspoints(fully_fixed)
        counts = [i.num_owned_multipliers for i in self.interfaces]
        components = (gdim - 1) if self.has_friction else 0
        layout = BlockLayout(self.comm, self.interfaces[0].num_owned_dofs,
                             counts + [c for c in counts for _ in range(components)])
        x, b = layout.create_vector(), layout.create_vector()
        row_scale, slave_length, master_scale, master_length = stiffness_scales(
            diagonal, self.interfaces, self.comm, gdim)
        checks.check_stiff_slave(self._warnings, pairs, gdim, row_scale * slave_length
                                 / (master_scale * master_length))
        free_bodies = diagnostics.free_translations(self.V, self._K, body_labels, self.bcs)
        scales = enforcement.Scales(row_scale, slave_length, gdim)
        # a moving master much stiffer than the slave holds the residual above the
        # slave-scaled tolerance by rounding (docs/benchmarks.md, "Contrast sweep in
        # 2D"); capped so that a near-rigid master does not loosen the test for the slave
        self._force_scale = scales.dirichlet * min(
            MAX_TOLERANCE_FACTOR, max(1.0, master_scale / row_scale))
        self.c_n, self.penalty, self.c_t = enforcement.default_parameters(
            options.method, scales, master_scale, options.c_n, options.penalty, options.c_t)
        self.equations = self._create_equations(options, scales, components, layout)
        if self._linear_solver == "iterative":
            self.equations.null_space_candidates = diagnostics.translation_vectors(
                self.V, body_labels, free_bodies)
        self.equations.read_state(x)
        self.timings = self.equations.timings
        self._slip_origin: np.ndarray | None = None
        self._reference_norm: float | None = None
        # 1e-11 k h: a force that moves a node of the slave by 1e-11 h, times the master's
        # stiffness over the slave's where the master is the stiffer (at most
        # MAX_TOLERANCE_FACTOR)
        try:
            self.solver = ContactNewton(
                self.equations, x, b, prefix, petsc_options, self._linear_solver,
                self._condensation, 1e-11 * self._force_scale * slave_length,
                automatic=self._automatic_linear_solver)
        except BaseException:
            x.destroy(), b.destroy()
            raise
        checks.check_free_bodies(self._warnings, pairs, self.interfaces, body_labels,
                                 free_bodies, self.equations.smallest_gap, slave_length)
        # the bulk matrix gave its pattern and diagonal: the Newton matrix is the system's
        self._K.destroy()
        self._K = None
        self._warnings.building = False

    def _create_equations(self, options: ContactOptions, scales: enforcement.Scales,
                          components: int, layout: BlockLayout) -> ContactEquations:
        """The enforcement, the friction state, the Newton matrix and the equations."""
        self.friction: friction_rules.Friction | None = None
        """The frictional state (:class:`~dolfinx_mortar.friction.Friction`), if any."""
        if self.has_friction:
            laws = options.friction_laws(len(self.pairs))
            self.friction = friction_rules.Friction(
                laws, self.interfaces, self.u, self.c_t,
                self.c_n if options.method == "lagrange" else None, scales.face)
            gdim, bs = self.V.mesh.geometry.dim, self.V.dofmap.index_map_bs
            self.friction.set_fixed_components([
                np.isin(i.owned_multiplier_blocks[:, None] * bs + np.arange(gdim),
                        self._fixed_dofs) for i in self.interfaces])
        self.enforcement = enforcement.create(
            options.method, options.active_set, scales,
            [i.num_owned_multipliers for i in self.interfaces], c_n=self.c_n,
            penalty=self.penalty, augmented_tolerance=options.augmented_tolerance,
            max_outer_iterations=options.max_outer_iterations)
        self.system = ContactSystem(self.V, layout, self.interfaces, self._K, self.J_form,
                                    self.bcs, self._fixed_dofs, scales.dirichlet,
                                    tangential_components=components)
        timings = dict.fromkeys(
            ("bulk assembly", "contact search", "mortar integration", "linear solve"), 0.0)
        equations = ContactEquations(self.u, self.bcs, self.F_form, self.J_form, layout,
                                     self.interfaces, self.enforcement, self.friction,
                                     self.system, scales.dirichlet, timings)
        self.multipliers = equations.multipliers
        self.active, self.gaps, self.areas = equations.active, equations.gaps, equations.areas
        return equations

    @property
    def x(self) -> PETSc.Vec:
        """The iterate [u | z] (a new vector when the layout changes: ``newton.fit_layout``)."""
        return self.solver.x

    @property
    def b(self) -> PETSc.Vec:
        """The residual vector of the layout."""
        return self.solver.b

    @property
    def layout(self) -> BlockLayout:
        """The monolithic numbering of the unknowns (:class:`~dolfinx_mortar.layout.
        BlockLayout`; pairs without pairs may be left out of it)."""
        return self.equations.layout

    @property
    def snes(self) -> PETSc.SNES:
        """The SNES (a new one after the fallback to the direct solver, and when the layout
        changes: ``newton.fit_layout``)."""
        return self.solver.snes

    @property
    def linear_solver(self) -> str:
        """``direct`` or ``iterative``: the one ``linear_solver`` chose, or took over."""
        return self.solver.linear_solver

    @property
    def condensation(self) -> bool:
        """Whether the Newton systems are solved by condensing the multipliers."""
        return self.solver.condensation

    @property
    def _condenser(self):
        return self.solver.condenser

    @property
    def tangential(self) -> list[PETSc.Vec]:
        """The tangential multipliers y^a, pair by pair (d - 1 each; none without friction)."""
        return self.equations.tangential

    # -- solving -------------------------------------------------------------

    def solve(self) -> solvers.SolveReport:
        """Solve one load step from the current state (u and multipliers). Collective.

        Returns a report; does not raise when Newton fails (the load stepper
        cuts the step back), but raises for errors in the input. A failed linear solve
        stops Newton before its step is applied. If it was the iterative solver that
        ``linear_solver="auto"`` chose, the direct solver takes over and solves the step
        again from the same start.
        """
        start = time.perf_counter()
        before = dict(self.timings)
        if self.friction is not None:
            origin = self._slip_origin if self._slip_origin is not None else self.u.x.array
            self.friction.start(origin)
        self._slip_origin = None
        self.equations.read_state(self.x)
        rtol, atol, stol, max_it = self.snes.getTolerances()
        if self._reference_norm is not None:
            self.snes.setTolerances(atol=max(atol, rtol * self._reference_norm))
        self._reference_norm = None
        step_atol = self.snes.getTolerances()[1]
        may_fall_back = self._automatic_linear_solver and self.linear_solver == "iterative"
        saved = self.save_state() if may_fall_back else None
        try:
            report = self.enforcement.solve(self.solver)
            if may_fall_back and not report.converged and report.linear_solver_failure:
                self.solver.fall_back_to_direct(self._condensation_requested,
                                                report.linear_solver_failure,
                                                self._warnings.warn)
                self.restore_state(saved)
                self.snes.setTolerances(atol=step_atol)
                report = self.enforcement.solve(self.solver)
        finally:
            self.snes.setTolerances(atol=atol)
        total = time.perf_counter() - start
        spent = {key: self.timings[key] - before[key] for key in self.timings}
        spent["linear solve"] = max(0.0, total - sum(spent.values()))
        self.timings["linear solve"] += spent["linear solve"]
        spent["total"] = total
        report.timings = spent
        report.active = self.num_active()
        return report

    # -- state for load stepping ---------------------------------------------

    def save_state(self) -> dict:
        """This rank's part of u, the multipliers and the Uzawa multipliers (not collective)."""
        return self.equations.save_state()

    def restore_state(self, state: dict) -> None:
        """Put back a :meth:`save_state` (not collective; call it on every rank)."""
        self._slip_origin = None
        self._reference_norm = None
        self.equations.restore_state(state)
        self.equations.read_state(self.x)

    def predict(self, previous: dict, ratio: float) -> None:
        """Start the next solve from the current state extrapolated linearly, x + ratio (x -
        x_previous), for u and the multipliers. Collective.

        ``previous`` is a :meth:`save_state` of the step before. The solve still measures
        slips from the current state (friction's increments are from the last converged
        state, not from the guess), and its relative tolerance still refers to the residual
        at the current state (with the new load): a better guess must not tighten the
        stopping test. Uzawa multipliers are not extrapolated.
        """
        current = self.save_state()
        if self.friction is not None:
            self.friction.start(current["u"])
        self.equations.read_state(self.x)
        self.equations.residual(self.snes, self.x, self.b)  # where an unpredicted solve starts
        if self.equations.stale_state is not None:  # a pair out of the layout found pairs
            self.equations.stale_state = None
            self.solver.fit_layout()
            self.equations.residual(self.snes, self.x, self.b)
        self._reference_norm = self.b.norm()
        self.u.x.array[:] += ratio * (current["u"] - previous["u"])
        for z, now, before in zip(self.multipliers + self.tangential,
                                  current["z"] + current["y"], previous["z"] + previous["y"],
                                  strict=True):
            z.getArray()[:] += ratio * (now - before)
        self.equations.read_state(self.x)
        self._slip_origin = current["u"]

    # -- checks --------------------------------------------------------------

    def most_compressed_cell(self) -> tuple[float, tuple[float, ...] | None]:
        """(J, reference point): the smallest det F = det(current) / det(reference) of any
        cell at the current u (per corner for quadrilaterals), and that cell's midpoint.

        Collective. J <= 0 means an inverted element; J near 0 one about to invert.
        """
        return self.equations.inversion_check.worst(self.u.x.array)

    def check_penetration(self, threshold: float = 0.5) -> list[diagnostics.Penetration]:
        """Nodes of either surface deep behind the other one, per pair; warns if any.

        Collective. Mortar contact enforces the gap in a weighted sense, so
        nodes may sit slightly inside the other body (a few per cent of an
        element at corners); a node more than ``threshold`` facet lengths
        behind the other surface means contact failed to act there.
        :func:`~dolfinx_mortar.loading.solve_load_steps` calls this after every
        accepted step.
        """
        return checks.check_penetration(
            self._warnings, [self.solved_pair(k) for k in range(len(self.pairs))],
            self.interfaces, self.u, threshold,
            None if self.method == "lagrange" else self.penalty)

    # -- PETSc objects -------------------------------------------------------

    def __enter__(self) -> ContactProblem:
        return self

    def __exit__(self, *exception) -> None:
        self.destroy()

    def destroy(self) -> None:
        """Free the PETSc objects (once; later calls do nothing). Collective."""
        if self._destroyed:
            return
        self._destroyed = True
        solver = getattr(self, "solver", None)
        parts = [solver, getattr(self, "equations", None), getattr(self, "_K", None)]
        parts += [solver.x, solver.b] if solver is not None else []
        if parts[1] is None:  # a set-up that failed before the equations were made
            parts += [getattr(self, name, None) for name in ("system", "friction")]
        for part in parts + self.interfaces:
            if part is not None:
                part.destroy()
