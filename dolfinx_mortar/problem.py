"""Frictionless mortar contact of deforming bodies, solved with PETSc SNES.

:class:`ContactProblem` couples a bulk residual F(u; v) given in UFL with one
or more mortar contact pairs. The unknowns are the displacements u and one
normal multiplier z_j >= 0 (contact pressure) per slave node, assembled in
one AIJ matrix (layout [u | z_1 | z_2 ...] per rank) and solved by Newton's
method in PETSc SNES with our own residual and Jacobian callbacks:

    R_u = F(u) - sum_pairs B(u)^T z                      (paper, eq. 1)
    R_z = C(z, u)                                         (paper, section 5)

B_j = d g~_j / dx at frozen integrals (-Dn on slave dofs, +Mn on master dofs)
pushes the slave along -n and the master along +n. The multiplier rows C
depend on the enforcement, one strategy per method in
:mod:`dolfinx_mortar.enforcement`: Lagrange multipliers with a semismooth
(C_j = z_j - max(0, z_j - c_n g^_j), g^_j = g~_j / A_j) or a fixed-point active
set, penalty, or augmented Lagrange. The Newton matrix is assembled by
:class:`~dolfinx_mortar.system.ContactSystem`; SNES and the linear solver are set up
by :mod:`dolfinx_mortar.solvers`.

Slave nodes that no master facet covers cannot become active and stay
inactive (z_j = 0) without any mortar work. With no active node the z-rows
are identity rows, so the system is regular whenever the bulk problem is; a
body held only by contact that loses every active node has a singular rigid
mode, which MUMPS' null-pivot detection (ICNTL(24) with CNTL(3) = 1e-8, on
by default) sets to a zero step instead of an arbitrary huge one; the residual
test stays exact, so this can only slow Newton down, never change a solution.

Every residual row is a force (unit E x length in plane strain), whatever the
enforcement (:mod:`dolfinx_mortar.enforcement`); the Dirichlet rows are k (u - u_D)
with k ~ E the bulk stiffness scale. Scaling a row changes neither the Newton step nor
the solution; it makes SNES' norms and tolerances independent of units, of c_n and of
eps (an unscaled c_n g~ row at c_n = 1e3 E/h has a rounding floor above any sensible
absolute tolerance).
"""

from __future__ import annotations

import dataclasses
import logging
import time
import typing
import weakref

import dolfinx
import dolfinx.fem.petsc
import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from . import compat, diagnostics, enforcement, kernels, recovery, solvers
from . import friction as friction_rules
from .diagnostics import ContactWarning
from .enforcement import ACTIVE_SET_STRATEGIES, METHODS
from .layout import BlockLayout, dirichlet_dofs
from .mortar import MortarInterface
from .solvers import SolveReport
from .surface import body_labels as surface_body_labels
from .system import ContactSystem, Tangential

logger = logging.getLogger("dolfinx_mortar")

__all__ = ["ContactPair", "ContactProblem", "ContactWarning", "SolveReport"]

INITIAL_OVERLAP = 0.05
"""A surface node deeper than this many facet lengths behind the other surface at
the start is reported as an initial overlap."""

MAX_TOLERANCE_FACTOR = 1e3
"""The default SNES atol (1e-11 k h, k the slave's stiffness scale) grows with the
master's stiffness over the slave's up to this factor: a node of the slave then moves by
at most 1e-8 h when the test passes."""

STIFF_SLAVE_RATIO = 30.0
"""In 3D, a slave side this many times stiffer (about E) than its master gets a set-up
warning advising the swap: the dual multipliers of a stiff curved slave on a much softer
curved master oscillate (docs/benchmarks.md, "Contrast sweep in 3D")."""


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


class ContactProblem:
    """Mortar contact problem with multipliers, penalty or augmented Lagrange.

    Building it is collective, and so are :meth:`solve`, :meth:`num_active`,
    :meth:`contact_forces`, :meth:`gathered_pressure`, :meth:`pressure_function`,
    :meth:`statistics`, :meth:`check_penetration` and :meth:`destroy`: call them on
    every rank of the mesh's communicator (on one rank alone they wait forever).
    :meth:`contact_pressure`, :meth:`save_state` and :meth:`restore_state` are local.

    Building it checks the set-up before any load step. It raises
    :class:`ValueError` when a pair's slave and master lie on one connected mesh
    (the same body, or bodies that share nodes). It warns
    (:class:`ContactWarning`, shown once by rank 0,
    :func:`~dolfinx_mortar.diagnostics.warn`) when a slave surface looks away
    from its master where the two are closest (a tag on the wrong face of its
    body), when the bodies start overlapping by more than
    :data:`INITIAL_OVERLAP` facet lengths, and when a body is free to move as a
    rigid body (no Dirichlet condition or term of the form holds a translation
    of it, and it does not touch the other body at the start).

    Args:
        F: bulk residual form F(u; v) (internal minus external virtual work).
        u: displacement Function on a P1 vector space.
        bcs: Dirichlet conditions on u.
        pairs: the contact pairs.
        J: Jacobian form of F (default: its Gateaux derivative).
        method: ``lagrange`` (default), ``penalty`` or ``augmented``.
        integration: ``segment`` (default) or ``element`` (+ num_gauss_points).
        normals: ``averaged`` (default), ``slave`` or ``master``.
        active_set: ``semismooth`` (default) or ``fixed-point`` (lagrange only).
        multipliers: ``dual`` (default) or ``standard`` basis. Dual is the
            default: the conditions decouple node by node, and on Hertz it
            puts the contact edge within one element where standard does not
            (docs/benchmarks.md).
        c_n: complementarity parameter (unit pressure / length); default about
            E/h of the two sides in series, 1 / (1/s_slave + 1/s_master), each s
            estimated from the bulk stiffness at that side's nodes and its facet
            length. It changes the Newton path, never the solution (measured on
            ironing: max 11 Newton iterations with the slave's E/h alone, 8 with
            the series value).
        penalty: eps of penalty and augmented Lagrange; default the slave's E/h
            (10 E/h for augmented Lagrange, whose Uzawa updates converge
            faster with a stiffer eps: measured 0.87 per update at E/h, 0.43 at
            10 E/h on Hertz).
        augmented_tolerance: Uzawa stops when max|lam_new - lam| <= this
            times max(max|lam|, 1e-4 E) (E the bulk stiffness scale).
        max_outer_iterations: of the fixed-point and Uzawa loops.
        search_margin: of the contact search (default 2 slave facet lengths).
        configuration: ``current`` (finite deformation, default) or
            ``reference`` (small strain: mortar integrals on the undeformed
            surfaces, to pair with linear elasticity).
        condensation: solve the Newton systems by static condensation of
            the multipliers (dual only): a displacement-sized matrix is
            factorized (options prefix ``<prefix>condensed_``, default
            MUMPS LU) and preconditions fgmres on the monolithic system
            (``<prefix>ksp_``, default rtol 1e-12), so the solution is the
            uncondensed one (:mod:`dolfinx_mortar.condensation`).
        linear_solver: ``auto`` (default: ``iterative`` for 3D problems of at
            least :data:`~dolfinx_mortar.solvers.AUTO_ITERATIVE_MIN_DOFS`
            displacement dofs with dual multipliers and no friction, else
            ``direct``; why: :func:`~dolfinx_mortar.solvers.automatic_linear_solver`),
            ``direct`` (MUMPS LU, of the monolithic system, or of the condensed one
            with ``condensation``) or ``iterative``: condensation (dual
            multipliers only) with GMRES and hypre's BoomerAMG on the condensed
            matrix, its block size set and the rigid-body modes of each body as
            near-nullspace (options under ``<prefix>condensed_``, e.g. ``pc_type:
            gamg`` for PETSc's GAMG). ``problem.linear_solver`` is the one chosen.
            When the iterative solver that ``auto`` chose fails a linear solve, the
            direct one solves that load step again and the rest of the run, with a
            ContactWarning that says why; an explicit ``iterative`` is kept (the
            failed step is cut back, and the report says what to try).
        friction: ``None`` (frictionless, the default), ``("coulomb", mu)``,
            ``("tresca", bound)`` (a pressure), or a list of these, one per
            pair (:mod:`dolfinx_mortar.friction`; direct linear solver, with
            ``lagrange`` semismooth or ``penalty``).
        c_t: the tangential complementarity parameter (pressure / length;
            default c_n), or with ``penalty`` the tangential penalty (default
            the normal one). Like c_n it changes the Newton path, never the
            Lagrange solution.
        petsc_options: SNES/KSP options (defaults: newtonls, full steps,
            MUMPS LU); the user's options database with the prefix wins.
        petsc_options_prefix: prefix of those options.
        pressure_recovery: whether :meth:`contact_pressure` (and what reads it) gives the
            recovered pressure (:mod:`dolfinx_mortar.recovery`) or the multipliers; None
            (default): recovered in 3D, where the multipliers of tetrahedral meshes
            scatter, the multipliers in 2D, where they do not and the fit would only add
            its curvature error (docs/benchmarks.md, "Contact pressure: nodal multipliers
            and their recovery").
    """

    def __init__(
        self,
        F: ufl.Form,
        u: dolfinx.fem.Function,
        bcs: list,
        pairs: typing.Sequence[ContactPair],
        *,
        J: ufl.Form | None = None,
        method: str = "lagrange",
        integration: str = "segment",
        num_gauss_points: int | None = None,
        normals: str = "averaged",
        active_set: str = "semismooth",
        multipliers: str = "dual",
        c_n: float | None = None,
        penalty: float | None = None,
        augmented_tolerance: float = 1e-8,
        max_outer_iterations: int = 100,
        search_margin: float | None = None,
        configuration: str = "current",
        condensation: bool = False,
        linear_solver: str = "auto",
        friction=None,
        c_t: float | None = None,
        petsc_options: dict | None = None,
        petsc_options_prefix: str = "dolfinx_mortar_",
        pressure_recovery: bool | None = None,
    ):
        _check_choice("method", method, METHODS)
        _check_choice("active_set", active_set, ACTIVE_SET_STRATEGIES)
        _check_choice("integration", integration, kernels.INTEGRATION_OPTIONS)
        _check_choice("normals", normals, kernels.NORMAL_OPTIONS)
        _check_choice("multipliers", multipliers, kernels.BASIS_OPTIONS)
        _check_choice("linear_solver", linear_solver, solvers.LINEAR_SOLVERS)
        self._automatic_linear_solver = linear_solver == "auto"
        self._condensation_requested = bool(condensation)
        if linear_solver == "auto":
            V = u.function_space
            linear_solver = solvers.automatic_linear_solver(
                V.mesh.geometry.dim, V.dofmap.index_map.size_global * V.dofmap.index_map_bs,
                multipliers, any(law is not None for law in
                                 friction_rules.laws_per_pair(friction, max(len(pairs), 1))))
        if linear_solver == "iterative":
            if multipliers != "dual":
                raise ValueError(
                    "linear_solver='iterative' solves the condensed displacement system, "
                    "which needs multipliers='dual'; got multipliers="
                    f"{multipliers!r}")
            condensation = True
        if condensation and multipliers != "dual":
            raise ValueError(
                "condensation=True needs multipliers='dual' (with the standard basis the "
                f"multipliers do not decouple node by node), got multipliers={multipliers!r}"
            )
        if active_set == "fixed-point" and method != "lagrange":
            raise ValueError("active_set='fixed-point' applies to method='lagrange' only")
        if not pairs:
            raise ValueError("ContactProblem needs at least one ContactPair")
        friction_laws = friction_rules.laws_per_pair(friction, len(pairs))
        self.has_friction = any(law is not None for law in friction_laws)
        self.friction: friction_rules.Friction | None = None
        """The frictional state (:class:`~dolfinx_mortar.friction.Friction`), if any."""
        if self.has_friction:
            friction_rules.check_options(method, active_set, condensation, linear_solver)
        for value, name in ((c_n, "c_n"), (penalty, "penalty"), (c_t, "c_t")):
            if value is not None and not value > 0:
                raise ValueError(f"{name} must be positive, got {value}")

        self.u = u
        self.V = u.function_space
        self.comm: MPI.Intracomm = self.V.mesh.comm
        self.bcs = list(bcs)
        self.pressure_recovery = (self.V.mesh.geometry.dim == 3 if pressure_recovery is None
                                  else bool(pressure_recovery))
        self.method = method
        self.condensation = bool(condensation)
        self.linear_solver = linear_solver
        self._condenser = None
        self.active_set_strategy = active_set
        self.F_form = dolfinx.fem.form(F)
        if J is None:
            J = ufl.derivative(F, u, ufl.TrialFunction(self.V))
        self.J_form = dolfinx.fem.form(J)

        self.pairs = list(pairs)
        self.interfaces = [
            MortarInterface(
                self.V,
                pair.facet_tags,
                pair.slave,
                pair.master,
                normals=normals,
                integration=integration,
                basis=multipliers,
                num_gauss_points=num_gauss_points,
                search_margin=search_margin,
                configuration=configuration,
            )
            for pair in self.pairs
        ]
        if self.has_friction and u.function_space.mesh.geometry.dim == 3:
            for interface in self.interfaces:
                interface.scalar_gradients = True  # friction's tangent frames
        self._warned: set = set()
        self._building = True
        self.setup_warnings: list[str] = []
        """The texts of the ContactWarnings issued while the problem was built (on every
        rank): a failed load step's message repeats them."""
        body_labels = surface_body_labels(self.V.mesh)
        self._check_slave_body(body_labels)
        self._inversion_check = diagnostics.InversionCheck(self.V)
        self._last_inversion = diagnostics.Inversion()
        self._check_facing()
        self._check_initial_overlap()
        bs = self.V.dofmap.index_map_bs
        self._fixed_dofs = dirichlet_dofs(self.bcs, self.V)
        fixed_blocks = np.unique(self._fixed_dofs // bs)
        fully_fixed = fixed_blocks[
            np.all(np.isin(fixed_blocks[:, None] * bs + np.arange(bs), self._fixed_dofs), axis=1)
        ]
        for interface in self.interfaces:
            interface.set_crosspoints(fully_fixed)

        counts = [i.num_owned_multipliers for i in self.interfaces]
        components = (self.V.mesh.geometry.dim - 1) if self.has_friction else 0
        self.layout = BlockLayout(
            self.comm, self.interfaces[0].num_owned_dofs,
            counts + [c for c in counts for _ in range(components)])
        self.multipliers = [i.create_multiplier_vector() for i in self.interfaces]
        coefficient_names = ("gap", "area") + friction_rules.coefficient_names(components)
        self._row_coefficients = [
            {name: i.create_multiplier_vector() for name in coefficient_names}
            for i in self.interfaces
        ]
        self.active: list[np.ndarray] = [
            np.zeros(i.num_owned_multipliers, dtype=bool) for i in self.interfaces
        ]
        self.gaps: list[np.ndarray] = [np.zeros(i.num_owned_multipliers) for i in self.interfaces]
        self.areas: list[np.ndarray] = [np.zeros(i.num_owned_multipliers) for i in self.interfaces]
        self._slip_origin: np.ndarray | None = None
        self._reference_norm: float | None = None

        self._b_u = compat.create_vector(self.F_form)
        self._K = compat.create_matrix(self.J_form)
        self.x = self.layout.create_vector()
        self.b = self.layout.create_vector()
        self._read_state_into_x()

        self._row_scale, self._slave_length, master_scale, master_length = (
            self._stiffness_scale())
        self._check_stiff_slave(self._row_scale * self._slave_length
                                / (master_scale * master_length))
        free_bodies = diagnostics.free_translations(self.V, self._K, body_labels, self.bcs)
        scales = enforcement.Scales(self._row_scale, self._slave_length,
                                    self.V.mesh.geometry.dim)
        self._dirichlet_scale = scales.dirichlet
        # a moving master much stiffer than the slave holds the residual above the
        # slave-scaled tolerance by rounding (docs/benchmarks.md, "Contrast sweep in
        # 2D"); capped so that a near-rigid master does not loosen the test for the slave
        self._force_scale = scales.dirichlet * min(
            MAX_TOLERANCE_FACTOR, max(1.0, master_scale / self._row_scale))
        # the two sides in series: the compliance of the contact, so that a stiff
        # slave on a soft master (ironing's die) does not get an overly stiff c_n
        contact_scale = 1.0 / (1.0 / self._row_scale + 1.0 / master_scale)
        self.c_n = float(c_n) if c_n is not None else contact_scale
        if penalty is None:
            # Uzawa contracts like 1 / (1 + eps * contact compliance): a stiffer
            # eps makes augmented Lagrange converge in far fewer updates
            penalty = self._row_scale * (10.0 if method == "augmented" else 1.0)
        self.penalty = float(penalty)
        if c_t is None:
            c_t = self.penalty if method == "penalty" else self.c_n
        self.c_t = float(c_t)
        if self.has_friction:
            self.friction = friction_rules.Friction(
                friction_laws, self.interfaces, u, self.c_t,
                self.c_n if method == "lagrange" else None, scales.face)
            gdim = self.V.mesh.geometry.dim
            self.friction.set_fixed_components([
                np.isin(i.owned_multiplier_blocks[:, None] * bs + np.arange(gdim),
                        self._fixed_dofs) for i in self.interfaces])
        self.enforcement = enforcement.create(
            method, active_set, scales,
            [i.num_owned_multipliers for i in self.interfaces], c_n=self.c_n,
            penalty=self.penalty, augmented_tolerance=augmented_tolerance,
            max_outer_iterations=max_outer_iterations)
        self.system = ContactSystem(self.V, self.layout, self.interfaces, self._K, self.J_form,
                                    self.bcs, self._fixed_dofs, self._dirichlet_scale,
                                    tangential_components=components)
        self.timings = {
            "bulk assembly": 0.0,
            "contact search": 0.0,
            "mortar integration": 0.0,
            "linear solve": 0.0,
        }
        self._petsc_options = dict(petsc_options or {})
        self._petsc_options_prefix = petsc_options_prefix
        self._setup_snes(self._petsc_options, petsc_options_prefix)
        self._check_free_bodies(body_labels, free_bodies)
        self._building = False

    # -- setup -------------------------------------------------------------

    def _warn(self, cause: tuple, message: str) -> None:
        """Collective: a :class:`ContactWarning` the first time this problem meets ``cause``
        (:func:`~dolfinx_mortar.diagnostics.warn`: shown once, by rank 0); later ones go to
        the ``dolfinx_mortar`` logger at INFO level (rank 0), as the progress lines do."""
        if cause in self._warned:
            if self.comm.rank == 0:
                logger.info("again: %s", message)
            return
        self._warned.add(cause)
        if self._building:
            self.setup_warnings.append(message)
        diagnostics.warn(self.comm, message, stacklevel=4)

    def _check_slave_body(self, labels: np.ndarray) -> None:
        """Slave and master surfaces of a pair must lie on different bodies: meshes that share
        no node (a conforming mesh joins its parts: they move as one)."""
        for k, interface in enumerate(self.interfaces):
            slave, master = interface.slave, interface.master
            slave_bodies = np.unique(np.concatenate(self.comm.allgather(labels[slave.cells])))
            master_bodies = np.unique(np.concatenate(self.comm.allgather(labels[master.cells])))
            if not np.intersect1d(slave_bodies, master_bodies).size:
                continue
            slave_nodes = np.concatenate(self.comm.allgather(slave.node_global_blocks))
            shared = np.isin(master.node_global_blocks, slave_nodes)
            count = np.unique(np.concatenate(
                self.comm.allgather(master.node_global_blocks[shared]))).size
            points = [p for p in self.comm.allgather(
                tuple(master.reference_coordinates[np.flatnonzero(shared)[0]])
                if shared.any() else None) if p is not None]
            where = (f"; the two surfaces share {count} node(s), one at ("
                     + ", ".join(f"{c:.4g}" for c in points[0]) + ")") if count else ""
            raise ValueError(
                f"{self._pair_name(k)}: the slave and the master surface lie on one connected "
                f"mesh (cells joined through shared nodes{where}), so they cannot separate or "
                "slide. Either both tags are on the same body (is the slave or the master tag "
                "on the wrong body? self-contact is not supported), or two bodies share nodes, "
                "as a gmsh model built with fragment or coherence makes them: build each body "
                "as its own mesh and join them with dolfinx_mortar.bodies.merge_meshes."
            )

    def _pair_name(self, k: int) -> str:
        pair = self.pairs[k]
        label = f"'{pair.name}' " if pair.name else ""
        return f"contact pair {label}(slave tag {pair.slave}, master tag {pair.master})"

    def _check_facing(self) -> None:
        """Warn when a slave surface looks away from its master where the two are closest."""
        for k, interface in enumerate(self.interfaces):
            slave, master = interface.slave, interface.master
            facing = diagnostics.facing_report(
                self.comm, slave.current_coordinates(self.u), slave.facets,
                master.current_coordinates(self.u), master.facets)
            if facing.looks_away:
                self._warn(
                    ("facing", k),
                    f"{self._pair_name(k)}: the slave surface looks away from its master. Where "
                    f"the two surfaces are closest ({facing.distance:.3g} apart), "
                    f"{facing.facets_looking_away} of {facing.facets_compared} slave facets have "
                    "an outward normal pointing the same way as the nearest master facet's "
                    f"(mean cosine {facing.mean_cosine:+.2f}; facing surfaces have -1), so no "
                    "facet can ever touch its master and the bodies would pass through each "
                    "other. Likely cause: the slave or the master tag is on the wrong face of "
                    "its body (outward normals point out of each body).",
                )

    def _check_initial_overlap(self) -> None:
        """Warn when the bodies start overlapping by more than :data:`INITIAL_OVERLAP`."""
        for k, interface in enumerate(self.interfaces):
            if ("facing", k) in self._warned:
                continue  # the wrong face puts every node "behind": one message says it
            slave, master = interface.slave, interface.master
            report = diagnostics.penetration_report(
                self.comm, INITIAL_OVERLAP, slave.node_global_blocks,
                slave.current_coordinates(self.u), slave.facets, master.node_global_blocks,
                master.current_coordinates(self.u), master.facets)
            if report.count:
                other = "master" if report.side == "slave" else "slave"
                where = ", ".join(f"{c:.4g}" for c in report.where)
                self._warn(
                    ("overlap", k),
                    f"{self._pair_name(k)}: the bodies overlap at the start: {report.count} "
                    f"surface node(s) lie behind the other surface by more than "
                    f"{INITIAL_OVERLAP:g} facet lengths, the deepest a {report.side} node "
                    f"{report.depth:.3g} facet lengths behind the {other} surface, at "
                    f"({where}). The first load step pushes the bodies apart with whatever "
                    "force that takes, on top of the load. Unless the overlap is meant (an "
                    "interference fit), move a body so that the surfaces touch or are apart "
                    "(its mesh coordinates, or the initial displacement u), and check the "
                    "geometry's units and the facet tags.",
                )

    def _check_stiff_slave(self, ratio: float) -> None:
        """Advise the swap when, in 3D, the slave sides are :data:`STIFF_SLAVE_RATIO` times
        stiffer than the master sides (``ratio``: the stiffness scale s times the facet
        length h, about E, of each, slave over master)."""
        if self.V.mesh.geometry.dim != 3 or not ratio >= STIFF_SLAVE_RATIO:
            return
        names = ", ".join(self._pair_name(k) for k in range(len(self.interfaces)))
        self._warn(
            ("stiff slave",),
            f"{names}: the slave side is about {ratio:.3g} times stiffer than the master "
            "side. The contact pressure of a stiff curved slave on a much softer curved "
            "body can oscillate node to node (the mean pressure and the force stay "
            "right); the softer body as the slave does not. Swap the two tags in "
            "ContactPair(facet_tags, slave, master) unless the soft side is flat or much "
            "coarser.",
        )

    def _check_free_bodies(self, labels: np.ndarray, free: list[diagnostics.FreeBody]) -> None:
        """Warn about bodies that only contact could hold (``free``, from
        :func:`diagnostics.free_translations`) where none touches the other body at the start
        (a nodal gap within 1e-6 slave facet lengths of zero): the first Newton matrix is
        singular."""
        if not free:
            return
        holding = {}  # body label -> (pairs on it, smallest covered nodal gap)
        for k, interface in enumerate(self.interfaces):
            bodies = np.unique(np.concatenate(self.comm.allgather(np.concatenate([
                labels[interface.slave.cells], labels[interface.master.cells]]))))
            if not any(body.label in bodies for body in free):
                continue
            interface.update(self.u)
            self._assemble_gaps(k)
            covered, gap = self._nodal_gaps(k)
            smallest = self.comm.allreduce(float(gap[covered].min(initial=np.inf)), op=MPI.MIN)
            for label in bodies:
                names, gaps = holding.get(int(label), ([], []))
                holding[int(label)] = (names + [self._pair_name(k)], gaps + [smallest])
        for body in free:
            names, gaps = holding.get(body.label, ([], []))
            if any(g <= 1e-6 * self._slave_length for g in gaps):
                continue
            axes = ", ".join("xyz"[a] for a in body.axes)
            direction = "that direction" if len(body.axes) == 1 else "those directions"
            box = " .. ".join("(" + ", ".join(f"{c:.4g}" for c in corner) + ")"
                              for corner in (body.lower, body.upper))
            if not names:
                contact = "it is on no contact pair"
            elif np.isfinite(min(gaps)):
                contact = (f"no contact is active at the start: the smallest nodal gap of its "
                           f"pair(s) ({'; '.join(names)}) is {min(gaps):.3g}")
            else:
                contact = (f"no contact is active at the start: no slave node of its pair(s) "
                           f"({'; '.join(names)}) has a master facet within the search margin")
            self._warn(
                ("free body", body.label),
                f"the body with nodes in {box} is free to move as a rigid body along {axes}: "
                f"no Dirichlet condition holds it in {direction} and {contact}. The first "
                "Newton system is then singular, and the solve fails (often reported as "
                "inverted elements or a failed linear solve) or leaves the body where it is. "
                "Hold it with a Dirichlet condition (e.g. a prescribed displacement on one "
                "face), or start it touching the other body.",
            )

    def most_compressed_cell(self) -> tuple[float, tuple[float, ...] | None]:
        """(J, reference point): the smallest det F = det(current) / det(reference) of any
        cell at the current u (per corner for quadrilaterals), and that cell's midpoint.

        Collective. J <= 0 means an inverted element; J near 0 one about to invert.
        """
        return self._inversion_check.worst(self.u.x.array)

    def check_penetration(self, threshold: float = 0.5) -> list[diagnostics.Penetration]:
        """Nodes of either surface deep behind the other one, per pair; warns if any.

        Collective. Mortar contact enforces the gap in a weighted sense, so
        nodes may sit slightly inside the other body (a few per cent of an
        element at corners); a node more than ``threshold`` facet lengths
        behind the other surface means contact failed to act there.
        :func:`~dolfinx_mortar.loading.solve_load_steps` calls this after every
        accepted step.
        """
        reports = []
        for k, interface in enumerate(self.interfaces):
            slave, master = interface.slave, interface.master
            slave_x = slave.current_coordinates(self.u)
            master_x = master.current_coordinates(self.u)
            report = diagnostics.penetration_report(
                self.comm, threshold, slave.node_global_blocks, slave_x, slave.facets,
                master.node_global_blocks, master_x, master.facets)
            reports.append(report)
            if report.count:
                other = "master" if report.side == "slave" else "slave"
                where = ", ".join(f"{c:.4g}" for c in report.where)
                causes = ["the slave or master tag on the wrong face of its body (normals "
                          "reversed)", "a load step that moved the bodies through each other "
                          f"by more than the search margin ({interface.reuse.margin:.3g})"]
                if self.method != "lagrange":
                    causes.append(f"a penalty parameter too soft (penalty={self.penalty:.3g})")
                self._warn(
                    ("penetration", k),
                    f"{self._pair_name(k)}: {report.count} {report.side} node(s) ended the step "
                    f"behind the {other} surface by more than {threshold:g} facet lengths "
                    f"(deepest {report.depth:.3g} facet lengths, at ({where})), beyond what "
                    "the weighted (mortar) gap condition allows. Likely causes: "
                    + "; ".join(causes) + ".",
                )
        return reports

    def _stiffness_scale(self) -> tuple[float, float, float, float]:
        """(s, h, s_master, h_master): s about E/h of the slave side (the mean bulk
        stiffness diagonal at slave dofs over h^(d-1), h the mean slave facet length in the
        reference configuration) and the same of the master side."""
        self._K.zeroEntries()
        dolfinx.fem.petsc.assemble_matrix(self._K, self.J_form)
        self._K.assemble()
        diagonal = self._K.getDiagonal()
        start = self._K.getOwnershipRange()[0]
        scales = []
        for side in ("slave", "master"):
            sums = np.zeros(4)
            for interface in self.interfaces:
                surface = getattr(interface, side)
                dofs = surface.node_dofs()[surface.node_owned].reshape(-1) - start
                values = np.abs(diagonal.getArray()[dofs])
                X = surface.reference_coordinates[surface.facets]
                lengths = np.linalg.norm(X[:, 1] - X[:, 0], axis=1)
                sums += [values.sum(), values.size, lengths.sum(), lengths.size]
            sums = self.comm.allreduce(sums, op=MPI.SUM)
            if sums[1] == 0 or sums[3] == 0 or not sums[0] > 0 or not sums[2] > 0:
                diagonal.destroy()
                raise ValueError(
                    f"cannot estimate the stiffness scale at the {side} nodes: the bulk "
                    f"Jacobian has a zero diagonal there (is the {side} surface on a body of "
                    "the form?)"
                )
            length = float(sums[2] / sums[3])
            # a stiffness diagonal is about E h^(d-2)
            scales.append((float(sums[0] / sums[1]) / length ** (self.V.mesh.geometry.dim - 1),
                           length))
        diagonal.destroy()
        return scales[0][0], scales[0][1], scales[1][0], scales[1][1]

    def _setup_snes(self, petsc_options: dict, prefix: str) -> None:
        """SNES with our defaults (:mod:`dolfinx_mortar.solvers`); ``petsc_options`` and then
        the options database win. The default absolute tolerance 1e-11 k h is a force that
        moves a node of the slave by 1e-11 h, in the units of the problem, times the
        master's stiffness over the slave's where the master is the stiffer (at most
        :data:`MAX_TOLERANCE_FACTOR`)."""
        snes = PETSc.SNES().create(self.comm)
        self._residual_history: list[float] = []

        def callbacks() -> None:
            snes.setFunction(self._residual, self.b)
            self._assemble_system()  # creates the matrix with its pattern
            snes.setJacobian(self._jacobian, self.system.mat)
            snes.setMonitor(lambda _snes, _it, norm: self._residual_history.append(float(norm)))

        def condensation(ksp: PETSc.KSP) -> None:
            if self.condensation:
                near_nullspace = (solvers.rigid_body_modes(self.V)
                                  if self.linear_solver == "iterative" else None)
                self._condenser = solvers.condensed_preconditioner(
                    ksp, self.layout, self.interfaces, self.V.dofmap.index_map_bs, prefix,
                    near_nullspace)

        kept = solvers.configure_snes(
            snes, prefix, petsc_options, self.condensation,
            1e-11 * self._force_scale * self._slave_length, callbacks, condensation,
            self.linear_solver)
        self._options_finalizer = weakref.finalize(self, solvers.release_options, kept)
        self.snes = snes

    def _falls_back_to_direct(self, report: SolveReport) -> bool:
        """Did the iterative solver that ``auto`` chose fail a linear solve (then the
        direct one takes over)?"""
        return (self._automatic_linear_solver and self.linear_solver == "iterative"
                and not report.converged and bool(report.linear_solver_failure))

    def _fall_back_to_direct(self, report: SolveReport) -> None:
        """Replace the iterative linear solver by the direct one (MUMPS LU, of the
        monolithic system unless condensation was asked for) for the rest of the run, with
        a ContactWarning that says why. Collective.

        ``auto`` promises a solver that works where the direct one would: the direct one
        is the more robust, and a problem whose iterative solve failed once (a contrast
        or a geometry its preconditioner does not handle) would likely fail again."""
        self._warn(
            ("linear solver fallback",),
            "linear_solver='auto' chose the iterative solver (GMRES + AMG on the condensed "
            f"system) for this problem, and a linear solve failed: "
            f"{report.linear_solver_failure}. The direct solver (MUMPS LU) solves this load "
            "step again and every later one. Pass linear_solver='direct' to skip the "
            "iterative attempt, or linear_solver='iterative' to keep it (the load stepping "
            "then cuts the step back).",
        )
        self._options_finalizer()
        self.snes.destroy()
        del self.snes
        if self._condenser is not None:
            self._condenser.destroy()
            self._condenser = None
        self.linear_solver = "direct"
        self.condensation = self._condensation_requested
        self._setup_snes(self._petsc_options, self._petsc_options_prefix)

    # -- state -------------------------------------------------------------

    def _read_state_into_x(self) -> None:
        array = self.x.getArray()
        owned = self.layout.num_u[self.comm.rank]
        array[self.layout.owned_u] = self.u.x.array[:owned]
        for field, z in enumerate(self.multipliers + self.tangential, start=1):
            array[self.layout.owned(field)] = z.getArray(readonly=True)

    @property
    def tangential(self) -> list[PETSc.Vec]:
        """The tangential multipliers y^a, pair by pair (d - 1 each; none without friction)."""
        return self.friction.vectors if self.friction is not None else []

    def _write_x_into_state(self, x: PETSc.Vec) -> None:
        array = x.getArray(readonly=True)
        owned = self.layout.num_u[self.comm.rank]
        self.u.x.array[:owned] = array[self.layout.owned_u]
        self.u.x.scatter_forward()
        for field, z in enumerate(self.multipliers + self.tangential, start=1):
            z.getArray()[:] = array[self.layout.owned(field)]

    # -- contact -----------------------------------------------------------

    def _update_contact(self) -> None:
        """Geometry, gaps, areas and active sets at the current state."""
        start = time.perf_counter()
        searching = 0.0
        for k, interface in enumerate(self.interfaces):
            before = interface.statistics.time_search
            interface.update(self.u)
            searching += interface.statistics.time_search - before
            self._assemble_gaps(k)
            self.active[k] = self._decide_active(k)
            if self.friction is not None:
                self.friction.update_slip(k, self.u, self._row_coefficients[k]["slip_00"])
        self.timings["contact search"] += searching
        self.timings["mortar integration"] += time.perf_counter() - start - searching

    def _assemble_gaps(self, k: int) -> None:
        """Pair k's weighted gaps g~_j and areas A_j at its owned slave nodes, from the last
        :meth:`MortarInterface.update`."""
        interface = self.interfaces[k]
        q = interface.quantities
        for name, values, into in (("gap", q.gap.value, self.gaps),
                                   ("area", q.area.value, self.areas)):
            vector = self._row_coefficients[k][name]
            vector.zeroEntries()
            vector.setValues(
                interface.pair_multipliers.reshape(-1).astype(PETSc.IntType),
                values.reshape(-1),
                addv=PETSc.InsertMode.ADD_VALUES,
            )
            vector.assemble()
            into[k] = vector.getArray(readonly=True).copy()

    def _tangential_rows(self, k: int) -> friction_rules.TangentialRows:
        """Pair k's owned tangential rows (:mod:`dolfinx_mortar.friction`)."""
        return self.friction.rows(k, self.multipliers[k].getArray(readonly=True),
                                  self.active[k], self.gaps[k], self.areas[k])

    def _covered(self, k: int) -> np.ndarray:
        interface = self.interfaces[k]
        scale = 1e-10 * interface.reuse.margin ** (interface.gdim - 1)
        return self.areas[k] > scale

    def _nodal_gaps(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """(covered, g^): the nodal gap g~_j / A_j (a length) where covered, else 0.

        Gaps within rounding of zero (1e-12 search margins) are set to exactly 0:
        bodies that touch at the start count as touching, not as apart.
        """
        covered = self._covered(k)
        gap = np.where(covered, self.gaps[k] / np.where(covered, self.areas[k], 1.0), 0.0)
        touching = np.abs(gap) <= 1e-12 * self.interfaces[k].reuse.margin
        return covered, np.where(touching, 0.0, gap)

    def _decide_active(self, k: int) -> np.ndarray:
        """The active set of pair k's owned slave nodes (the enforcement's rule)."""
        covered, gap = self._nodal_gaps(k)
        return self.enforcement.decide_active(
            k, self.multipliers[k].getArray(readonly=True), covered, gap)

    def _multiplier_rows(self, k: int) -> enforcement.Rows:
        """Residual C_j and coefficients (alpha on dg~, beta on dA, delta on dz) of owned rows."""
        return self.enforcement.rows(k, self.multipliers[k].getArray(readonly=True),
                                     self.active[k], self.gaps[k], self.areas[k])

    # -- SNES callbacks ----------------------------------------------------

    def _residual(self, snes: PETSc.SNES, x: PETSc.Vec, b: PETSc.Vec) -> None:
        self._write_x_into_state(x)
        inversion = self._inversion_check(self.u.x.array)
        if inversion.count:
            # a NaN residual makes SNES stop with DIVERGED_FNORM_NAN; the report
            # names the inverted cells and the load stepper cuts the step back
            self._last_inversion = inversion
            b.set(np.nan)
            return
        self._update_contact()
        start = time.perf_counter()
        b_u = self._b_u
        with b_u.localForm() as local:
            local.set(0.0)
        dolfinx.fem.petsc.assemble_vector(b_u, self.F_form)
        dolfinx.fem.petsc.apply_lifting(
            b_u, [self.J_form], bcs=[self.bcs], x0=[self.u.x.petsc_vec], alpha=-1.0
        )
        b_u.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        self.timings["bulk assembly"] += time.perf_counter() - start
        start = time.perf_counter()
        for interface, z in zip(self.interfaces, self.multipliers, strict=True):
            interface.contact_force(z, b_u)
        if self.friction is not None:
            self.friction.add_forces(b_u)
        compat.set_bc(b_u, self.bcs, self.u.x.petsc_vec, -self._dirichlet_scale)
        array = b.getArray()
        array[self.layout.owned_u] = b_u.getArray(readonly=True)
        for k in range(len(self.interfaces)):
            array[self.layout.owned(k + 1)] = self._multiplier_rows(k)[0]
            if self.has_friction:
                residual = self._tangential_rows(k).residual
                for a in range(residual.shape[1]):
                    array[self.layout.owned(self.system.tangential_field(k, a))] = residual[:, a]
        self.timings["mortar integration"] += time.perf_counter() - start

    def _jacobian(self, snes, x, A, P) -> None:
        self._assemble_system()

    def _assemble_system(self) -> PETSc.Mat:
        """The monolithic Jacobian (:class:`~dolfinx_mortar.system.ContactSystem`)."""
        tangential = None
        if self.has_friction:
            tangential = Tangential(self._tangential_rows, self.friction.increments,
                                    self.friction.node_multipliers, self.friction.tangents)
        rebuilt, contact, bulk = self.system.assemble(
            self.multipliers, self._row_coefficients, self._multiplier_rows, tangential)
        if rebuilt and hasattr(self, "snes"):
            self.snes.setJacobian(self._jacobian, self.system.mat)
        self.timings["bulk assembly"] += bulk
        self.timings["mortar integration"] += contact
        return self.system.mat

    # -- solving -----------------------------------------------------------

    def solve(self) -> SolveReport:
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
        self._read_state_into_x()
        rtol, atol, stol, max_it = self.snes.getTolerances()
        if self._reference_norm is not None:
            self.snes.setTolerances(atol=max(atol, rtol * self._reference_norm))
        self._reference_norm = None
        step_atol = self.snes.getTolerances()[1]
        may_fall_back = self._automatic_linear_solver and self.linear_solver == "iterative"
        saved = self.save_state() if may_fall_back else None
        try:
            report = self.enforcement.solve(self)
            if self._falls_back_to_direct(report):
                self._fall_back_to_direct(report)
                self.restore_state(saved)
                self.snes.setTolerances(atol=step_atol)
                report = self.enforcement.solve(self)
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

    def _newton(self) -> SolveReport:
        self._residual_history = []
        self._last_inversion = diagnostics.Inversion()
        if self._condenser is not None:
            self._condenser.inner_failure = ""
        self.snes.solve(None, self.x)
        reason = self.snes.getConvergedReason()
        self._write_x_into_state(self.x)
        report = SolveReport(
            converged=reason > 0,
            reason=reason,
            iterations=self.snes.getIterationNumber(),
            residuals=list(self._residual_history),
            active=0,
            linear_iterations=self.snes.getLinearSolveIterations(),
        )
        if reason <= 0:
            report.inversion = self._last_inversion
        if reason == PETSc.SNES.ConvergedReason.DIVERGED_LINEAR_SOLVE:
            # SNES stops before the step is applied (a NaN step included): x is the last
            # iterate, and the load stepping cuts the step back
            ksp = self.snes.getKSP()
            if self.linear_solver == "iterative":
                # with ``auto`` the direct solver takes over: no advice
                report.linear_solver_failure = diagnostics.describe_iterative_failure(
                    ksp, self._petsc_options_prefix, self._condenser.inner_failure,
                    advice=not self._automatic_linear_solver)
            else:
                report.linear_solver_failure = diagnostics.describe_ksp_failure(ksp)
        return report

    # -- state for load stepping --------------------------------------------

    def save_state(self) -> dict:
        """This rank's part of u, the multipliers and the Uzawa multipliers (not collective)."""
        return {
            "u": self.u.x.array.copy(),
            "z": [z.getArray(readonly=True).copy() for z in self.multipliers],
            "y": [y.getArray(readonly=True).copy() for y in self.tangential],
            "enforcement": self.enforcement.save_state(),
        }

    def restore_state(self, state: dict) -> None:
        """Put back a :meth:`save_state` (not collective; call it on every rank)."""
        self._slip_origin = None
        self._reference_norm = None
        self.u.x.array[:] = state["u"]
        for z, values in zip(self.multipliers + self.tangential, state["z"] + state["y"],
                             strict=True):
            z.getArray()[:] = values
        self.enforcement.restore_state(state["enforcement"])
        self._read_state_into_x()

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
        self._read_state_into_x()
        self._residual(self.snes, self.x, self.b)  # where an unpredicted solve would start
        self._reference_norm = self.b.norm()
        self.u.x.array[:] += ratio * (current["u"] - previous["u"])
        for z, now, before in zip(self.multipliers + self.tangential,
                                  current["z"] + current["y"], previous["z"] + previous["y"],
                                  strict=True):
            z.getArray()[:] += ratio * (now - before)
        self._read_state_into_x()
        self._slip_origin = current["u"]

    # -- results -----------------------------------------------------------

    def num_active(self) -> int:
        """Active slave nodes of all pairs, summed over the ranks. Collective."""
        return int(self.comm.allreduce(sum(int(a.sum()) for a in self.active), op=MPI.SUM))

    def contact_pressure(self, k: int = 0, raw: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """(reference coordinates, contact pressure) of pair k's slave nodes owned by this
        rank: coordinates (n, gdim), pressures (n,); :meth:`gathered_pressure` gives all of
        them on every rank. The rows are those of :meth:`friction_state`, in the same order.

        With ``pressure_recovery`` (the default in 3D) the pressure is the nodal
        multipliers recovered on their patches (:mod:`dolfinx_mortar.recovery`): the linear
        fit of the multiplier field over each active node's patch, which keeps linear
        pressures exact and averages the node to node scatter of unstructured meshes;
        otherwise, or with ``raw=True``, the multipliers z_j themselves (each node's
        contact force over its area, what the forces are made of). Collective.
        """
        interface = self.interfaces[k]
        z = self.multipliers[k]
        pressure = (recovery.recovered_pressure(interface, z, self.active[k])
                    if self.pressure_recovery and not raw
                    else z.getArray(readonly=True).copy())
        return interface.owned_multiplier_coordinates.copy(), pressure

    def gathered_pressure(self, k: int = 0, raw: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`contact_pressure` of all slave nodes, on every rank: coordinates (n, gdim)
        and pressures (n,), sorted by x, then by y coordinate. Collective."""
        coordinates, pressure = self.contact_pressure(k, raw)
        coordinates = np.vstack(self.comm.allgather(coordinates))
        pressure = np.concatenate(self.comm.allgather(pressure))
        order = np.lexsort((coordinates[:, 1], coordinates[:, 0]))
        return coordinates[order], pressure[order]

    def contact_forces(self, k: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Total contact force on the slave and on the master side of pair k.

        Each is a vector of gdim components ((x, y) in 2D, (x, y, z) in 3D): the force the
        other body exerts on that side, the normal pressure's and, with friction, the
        friction traction's; the two balance. Collective: call it on every rank (each gets
        the sums over all ranks).
        """
        interface = self.interfaces[k]
        q = interface.quantities
        if q is None:
            return np.zeros(interface.gdim), np.zeros(interface.gdim)
        rows = interface._rows(q)
        z_pair = interface.node_values(self.multipliers[k])[interface.pair_slave_nodes[rows]]
        coefficients = interface._force_coefficient_values(q, rows)  # -Dn (slave), Mn (master)
        ns = interface.stencil.ns
        slave = np.einsum("nj,njkc->c", z_pair, coefficients[:, :, :ns])
        master = np.einsum("nj,njlc->c", z_pair, coefficients[:, :, ns:])
        if self.friction is not None:
            slave_friction, master_friction = self.friction.forces(k, rows)
            slave, master = slave + slave_friction, master + master_friction
        return (self.comm.allreduce(slave, op=MPI.SUM), self.comm.allreduce(master, op=MPI.SUM))

    def friction_state(self, k: int = 0) -> dict:
        """Pair k's frictional state at this rank's owned slave nodes (not collective in 2D,
        collective in 3D).

        One row per node, the rows of :meth:`contact_pressure` in the same order. Keys:
        ``coordinates`` (reference, (n, gdim)), ``pressure`` z_j (the normal multiplier, as
        :meth:`contact_pressure` returns it), ``traction`` y_j (the tangential multiplier:
        the friction traction on the slave is -y_j tau_j), ``slip`` u~_j / A_j (the slip
        of the slave against the master since the last solve started, a length),
        ``sticking`` and ``slipping`` (active nodes in each state) and ``dissipation``
        y_j . u~_j (the frictional work of the step at the node, >= 0). In 3D traction
        and slip are (n, 2), components in the nodes' tangent frames ``frames``
        (n, 2, 3) (:mod:`dolfinx_mortar.friction`).
        """
        if self.friction is None:
            raise RuntimeError("friction_state: this problem has no friction")
        return self.friction.state(k, self._tangential_rows(k), self.active[k], self.areas[k])

    def pressure_function(self, k: int = 0, function: dolfinx.fem.Function | None = None,
                          raw: bool = False):
        """A P1 scalar Function with :meth:`contact_pressure` at the slave nodes (0
        elsewhere), in 2D and 3D; ``function`` given: that one, overwritten.

        Collective (creating a Function and updating its ghosts).
        """
        if function is None:
            space = dolfinx.fem.functionspace(self.V.mesh, ("Lagrange", 1))
            function = dolfinx.fem.Function(space, name="contact_multiplier" if raw
                                            else "contact_pressure")
        return self._slave_node_function(k, self.contact_pressure(k, raw)[1], function)

    def friction_functions(self, k: int = 0, functions: tuple | None = None) -> tuple:
        """(tangential traction y_j, status) as P1 scalar Functions for ParaView (0 away
        from the slave nodes; in 3D the traction's magnitude |y_j|; status 0 inactive,
        1 slipping, 2 sticking). Collective."""
        if functions is None:
            space = dolfinx.fem.functionspace(self.V.mesh, ("Lagrange", 1))
            functions = (dolfinx.fem.Function(space, name="tangential_traction"),
                         dolfinx.fem.Function(space, name="friction_status"))
        state = self.friction_state(k)
        status = np.where(state["sticking"], 2.0, np.where(state["slipping"], 1.0, 0.0))
        traction = state["traction"]
        if traction.ndim == 2:
            traction = np.linalg.norm(traction, axis=1)
        self._slave_node_function(k, traction, functions[0])
        self._slave_node_function(k, status, functions[1])
        return functions

    def _slave_node_function(self, k: int, values: np.ndarray, function) -> dolfinx.fem.Function:
        """``function`` (P1 scalar) with pair k's owned slave node values, 0 elsewhere."""
        interface = self.interfaces[k]
        local = interface.owned_multiplier_blocks - self.V.dofmap.index_map.local_range[0]
        function.x.array[:] = 0.0
        function.x.array[local] = values
        function.x.scatter_forward()
        return function

    def statistics(self) -> dict:
        """Search and integration counters per pair (sums over the ranks). Collective."""
        result = {}
        for k, (pair, interface) in enumerate(zip(self.pairs, self.interfaces, strict=True)):
            s = interface.statistics
            key = pair.name or f"{pair.slave}-{pair.master}"
            result[key] = {
                "pairs": self.comm.allreduce(s.pairs, op=MPI.SUM),
                "segments": self.comm.allreduce(s.segments, op=MPI.SUM),
                "searches_done": s.searches_done,
                "searches_skipped": s.searches_skipped,
                "evaluations": s.evaluations,
                "evaluations_skipped": s.evaluations_skipped,
                "slave_nodes": interface.num_global_multipliers,
                "slave_nodes_uncovered": self.comm.allreduce(
                    int(np.count_nonzero(~self._covered(k))), op=MPI.SUM
                ),
                "time_search": s.time_search,
                "time_integration": s.time_integration,
            }
        return result

    def destroy(self) -> None:
        """Free the PETSc objects. Collective."""
        self._options_finalizer()
        self.snes.destroy()
        if self._condenser is not None:
            self._condenser.destroy()
        self.system.destroy()
        self._K.destroy()
        self._b_u.destroy()
        self.x.destroy()
        self.b.destroy()
        for interface in self.interfaces:
            interface.destroy()
        if self.friction is not None:
            self.friction.destroy()


def _check_choice(name: str, value, allowed) -> None:
    if value not in allowed:
        raise ValueError(f"unknown {name} {value!r}; expected one of {tuple(allowed)}")

