"""The equations of a contact problem at an iterate: its state, residual and Jacobian.

:class:`ContactEquations` holds what the Newton iterates change (u, the normal multipliers
z_j, their weighted gaps g~_j, areas A_j and active sets, the friction state) and
evaluates the residual and the Jacobian of the monolithic system [u | z_1 | z_2 ...]:

    R_u = F(u) - sum_pairs B(u)^T z
    R_z = C(z, u)

Slave nodes that no master facet covers cannot become active and stay inactive
(z_j = 0) without any mortar work. With no active node the z-rows are identity rows, so
the system is regular whenever the bulk problem is; a body held only by contact that
loses every active node has a singular rigid mode, which MUMPS' null-pivot detection
(ICNTL(24) with CNTL(3) = 1e-8, on by default) sets to a zero step instead of an
arbitrary huge one; the residual test stays exact, so this can only slow Newton down,
never change a solution. The iterative solver is given the translations that are exactly
null (:meth:`ContactEquations.set_null_space`).

Every row is a force (unit E x length in plane strain), whatever the enforcement
(:mod:`dolfinx_mortar.enforcement`); the Dirichlet rows are k (u - u_D) with k ~ E the
bulk stiffness scale. Scaling a row changes neither the Newton step nor the solution;
it makes SNES' norms and tolerances independent of units, of c_n and of eps (an
unscaled c_n g~ row at c_n = 1e3 E/h has a rounding floor above any sensible absolute
tolerance).

Its :meth:`~ContactEquations.residual` and :meth:`~ContactEquations.jacobian` are the
SNES callbacks (held by the SNES through a weak reference, :class:`SnesCallbacks`). It
knows neither the SNES nor the :class:`~dolfinx_mortar.problem.ContactProblem` that owns
it: no reference cycle.
"""

from __future__ import annotations

import time
import weakref

import dolfinx
import dolfinx.fem.petsc
import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from . import compat, diagnostics, enforcement
from . import friction as friction_rules
from .system import Tangential

NULL_SPACE_TOLERANCE = 1e-10
"""A candidate null vector v of the Newton matrix J is one if |J v| is at most this times
k |v| (k the bulk stiffness scale of the Dirichlet rows)."""


class ContactEquations:
    """The state and the equations of the contact system (module docstring).

    Args:
        u: the displacement.
        bcs: its Dirichlet conditions.
        F_form, J_form: the compiled bulk residual and Jacobian forms.
        layout: the [u | z | y] layout (:class:`~dolfinx_mortar.layout.BlockLayout`).
        interfaces: the pairs' :class:`~dolfinx_mortar.mortar.MortarInterface`.
        enforcement: the strategy of the multiplier rows.
        friction: the frictional state, or None.
        system: assembles the Newton matrix.
        dirichlet_scale: k, the scale of the Dirichlet rows.
        timings: seconds spent per phase, added to in place.
    """

    def __init__(self, u, bcs, F_form, J_form, layout, interfaces, enforcement_rules,
                 friction: friction_rules.Friction | None, system, dirichlet_scale: float,
                 timings: dict[str, float]):
        self.u = u
        self.V = u.function_space
        self.bcs = bcs
        self.F_form, self.J_form = F_form, J_form
        self.layout = layout
        self.interfaces = interfaces
        self.enforcement = enforcement_rules
        self.friction = friction
        self.system = system
        self.dirichlet_scale = dirichlet_scale
        self.timings = timings
        components = friction.components if friction is not None else 0
        self.multipliers = [i.create_multiplier_vector() for i in interfaces]
        coefficient_names = ("gap", "area") + friction_rules.coefficient_names(components)
        self.row_coefficients = [
            {name: i.create_multiplier_vector() for name in coefficient_names}
            for i in interfaces
        ]
        self.active: list[np.ndarray] = [
            np.zeros(i.num_owned_multipliers, dtype=bool) for i in interfaces]
        self.gaps: list[np.ndarray] = [np.zeros(i.num_owned_multipliers) for i in interfaces]
        self.areas: list[np.ndarray] = [np.zeros(i.num_owned_multipliers) for i in interfaces]
        self._zero_gaps = [-1] * len(interfaces)
        """Per pair, the interface's pattern version whose gaps and areas (all zero: no pair
        on any rank) are assembled already; -1 if none."""
        self.b_u = compat.create_vector(F_form)
        self.inversion_check = diagnostics.InversionCheck(self.V)
        self.last_inversion = diagnostics.Inversion()
        """Inverted cells of the last iterate whose residual was refused (NaN)."""
        self.residual_history: list[float] = []
        self.in_layout = [True] * len(interfaces)
        """Per pair, whether its multiplier fields are unknowns of the layout (an interface
        without pairs on any rank may be left out: :meth:`~dolfinx_mortar.newton.
        ContactNewton.fit_layout`); the multipliers of a pair left out are zero."""
        self.null_space_candidates: list[np.ndarray] = []
        """Owned displacement dofs of the translations that may be a null space of the Newton
        matrix (:meth:`set_null_space`); empty: none is looked for."""
        self.stale_state: dict | None = None
        """The state of the iterate at which a pair left out of the layout found pairs (its
        residual needs the pair's rows: the SNES is stopped there, and the solve goes on
        from this state in a layout with them), or None."""
        self.callbacks = SnesCallbacks(self)

    @property
    def tangential(self) -> list[PETSc.Vec]:
        """The tangential multipliers y^a, pair by pair (d - 1 each; none without friction)."""
        return self.friction.vectors if self.friction is not None else []

    # -- state <-> iterate ---------------------------------------------------

    def _fields(self) -> list[tuple[int, PETSc.Vec, bool]]:
        """(layout field, multiplier vector, whether in the layout) of every multiplier
        field: the normal ones pair by pair, then the tangential ones (pair by pair, d - 1
        each)."""
        num_pairs = len(self.interfaces)
        components = len(self.tangential) // max(num_pairs, 1)
        pair_of = list(range(num_pairs)) + [k for k in range(num_pairs)
                                            for _ in range(components)]
        return [(field, vector, self.in_layout[pair_of[field - 1]]) for field, vector
                in enumerate(self.multipliers + self.tangential, start=1)]

    def read_state(self, x: PETSc.Vec) -> None:
        """Put u and the multipliers into ``x``; the multipliers of a pair out of the
        layout are set to zero."""
        array = x.getArray()
        owned = self.layout.num_u[self.layout.comm.rank]
        array[self.layout.owned_u] = self.u.x.array[:owned]
        for field, z, present in self._fields():
            if present:
                array[self.layout.owned(field)] = z.getArray(readonly=True)
            else:
                z.zeroEntries()

    def write_state(self, x: PETSc.Vec) -> None:
        """Set u and the multipliers from ``x``."""
        array = x.getArray(readonly=True)
        owned = self.layout.num_u[self.layout.comm.rank]
        self.u.x.array[:owned] = array[self.layout.owned_u]
        self.u.x.scatter_forward()
        for field, z, present in self._fields():
            if present:
                z.getArray()[:] = array[self.layout.owned(field)]

    def save_state(self) -> dict:
        """This rank's part of u, the multipliers and the Uzawa multipliers."""
        return {
            "u": self.u.x.array.copy(),
            "z": [z.getArray(readonly=True).copy() for z in self.multipliers],
            "y": [y.getArray(readonly=True).copy() for y in self.tangential],
            "enforcement": self.enforcement.save_state(),
        }

    def restore_state(self, state: dict) -> None:
        """Put back a :meth:`save_state` (this rank's part)."""
        self.u.x.array[:] = state["u"]
        for z, values in zip(self.multipliers + self.tangential, state["z"] + state["y"],
                             strict=True):
            z.getArray()[:] = values
        self.enforcement.restore_state(state["enforcement"])

    # -- contact ---------------------------------------------------------------

    def update_contact(self) -> None:
        """Geometry, gaps, areas and active sets at the current state."""
        start = time.perf_counter()
        searching = 0.0
        for k, interface in enumerate(self.interfaces):
            before = interface.statistics.time_search
            interface.update(self.u)
            searching += interface.statistics.time_search - before
            if not self.in_layout[k]:
                continue  # no pair anywhere (or a stale layout: the residual stops)
            self.assemble_gaps(k)
            self.active[k] = self.decide_active(k)
            if self.friction is not None:
                self.friction.update_slip(k, self.u, self.row_coefficients[k]["slip_00"])
        self.timings["contact search"] += searching
        self.timings["mortar integration"] += time.perf_counter() - start - searching

    def assemble_gaps(self, k: int) -> None:
        """Pair k's weighted gaps g~_j and areas A_j at its owned slave nodes, from the last
        :meth:`MortarInterface.update`. Collective; an interface without pairs on any rank
        has zero gaps and areas until its next search: assembled once."""
        interface = self.interfaces[k]
        if interface.without_pairs and self._zero_gaps[k] == interface._pattern_version:
            return
        self._zero_gaps[k] = interface._pattern_version if interface.without_pairs else -1
        q = interface.quantities
        multipliers = interface.pair_multipliers[q.rows].reshape(-1).astype(PETSc.IntType)
        for name, values, into in (("gap", q.gap.value_rows, self.gaps),
                                   ("area", q.area.value_rows, self.areas)):
            vector = self.row_coefficients[k][name]
            vector.zeroEntries()
            vector.setValues(
                multipliers,
                values.reshape(-1),
                addv=PETSc.InsertMode.ADD_VALUES,
            )
            vector.assemble()
            into[k] = vector.getArray(readonly=True).copy()

    def covered(self, k: int) -> np.ndarray:
        """Pair k's owned slave nodes that some master facet covers (area above rounding)."""
        interface = self.interfaces[k]
        scale = 1e-10 * interface.reuse.margin ** (interface.gdim - 1)
        return self.areas[k] > scale

    def nodal_gaps(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """(covered, g^): the nodal gap g~_j / A_j (a length) where covered, else 0.

        Gaps within rounding of zero (1e-12 search margins) are set to exactly 0:
        bodies that touch at the start count as touching, not as apart.
        """
        covered = self.covered(k)
        gap = np.where(covered, self.gaps[k] / np.where(covered, self.areas[k], 1.0), 0.0)
        touching = np.abs(gap) <= 1e-12 * self.interfaces[k].reuse.margin
        return covered, np.where(touching, 0.0, gap)

    def smallest_gap(self, k: int) -> float:
        """The smallest nodal gap of pair k's covered slave nodes at the current u, over
        all ranks (inf if none is covered). Collective."""
        self.interfaces[k].update(self.u)
        self.assemble_gaps(k)
        covered, gap = self.nodal_gaps(k)
        return self.layout.comm.allreduce(float(gap[covered].min(initial=np.inf)), op=MPI.MIN)

    def decide_active(self, k: int) -> np.ndarray:
        """The active set of pair k's owned slave nodes (the enforcement's rule)."""
        covered, gap = self.nodal_gaps(k)
        return self.enforcement.decide_active(
            k, self.multipliers[k].getArray(readonly=True), covered, gap)

    def multiplier_rows(self, k: int) -> enforcement.Rows:
        """Residual C_j and coefficients (alpha on dg~, beta on dA, delta on dz) of owned rows."""
        return self.enforcement.rows(k, self.multipliers[k].getArray(readonly=True),
                                     self.active[k], self.gaps[k], self.areas[k])

    def tangential_rows(self, k: int) -> friction_rules.TangentialRows:
        """Pair k's owned tangential rows (:mod:`dolfinx_mortar.friction`)."""
        return self.friction.rows(k, self.multipliers[k].getArray(readonly=True),
                                  self.active[k], self.gaps[k], self.areas[k])

    # -- SNES callbacks --------------------------------------------------------

    def residual(self, snes: PETSc.SNES, x: PETSc.Vec, b: PETSc.Vec) -> None:
        """b = R(x); NaN where an element of the iterate is inverted (SNES then stops with
        DIVERGED_FNORM_NAN, and the report names the inverted cells). Where a pair left
        out of the layout found pairs (:attr:`stale_state`), NaN too: the SNES stops,
        and its solve goes on from that iterate with the pair's rows."""
        if self.stale_state is not None:
            b.set(np.nan)  # (a line search trying further points)
            return
        self.write_state(x)
        inversion = self.inversion_check(self.u.x.array)
        if inversion.count:
            self.last_inversion = inversion
            b.set(np.nan)
            return
        self.update_contact()
        if not all(present or interface.without_pairs
                   for present, interface in zip(self.in_layout, self.interfaces,
                                                 strict=True)):
            self.stale_state = self.save_state()
            b.set(np.nan)
            return
        start = time.perf_counter()
        b_u = self.b_u
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
        compat.set_bc(b_u, self.bcs, self.u.x.petsc_vec, -self.dirichlet_scale)
        array = b.getArray()
        array[self.layout.owned_u] = b_u.getArray(readonly=True)
        for k in range(len(self.interfaces)):
            if not self.in_layout[k]:
                continue
            array[self.layout.owned(k + 1)] = self.multiplier_rows(k)[0]
            if self.friction is not None:
                residual = self.tangential_rows(k).residual
                for a in range(residual.shape[1]):
                    array[self.layout.owned(self.system.tangential_field(k, a))] = residual[:, a]
        self.timings["mortar integration"] += time.perf_counter() - start

    def jacobian(self, snes: PETSc.SNES, x, A, P) -> None:
        """Assemble the Newton matrix at the state the last residual was evaluated at."""
        self.assemble_system(snes)

    def monitor(self, snes: PETSc.SNES, iteration: int, norm: float) -> None:
        """Record the residual norm of each Newton iterate."""
        self.residual_history.append(float(norm))

    def assemble_system(self, snes: PETSc.SNES | None = None) -> PETSc.Mat:
        """The monolithic Jacobian (:class:`~dolfinx_mortar.system.ContactSystem`); a matrix
        built anew (a new pattern) becomes ``snes``' Jacobian."""
        tangential = None
        if self.friction is not None:
            tangential = Tangential(self.tangential_rows, self.friction.increments,
                                    self.friction.node_multipliers, self.friction.tangents)
        rebuilt, contact, bulk = self.system.assemble(
            self.multipliers, self.row_coefficients, self.multiplier_rows, tangential)
        if rebuilt and snes is not None:
            snes.setJacobian(self.callbacks.jacobian, self.system.mat)
        self.timings["bulk assembly"] += bulk
        self.timings["mortar integration"] += contact
        if self.null_space_candidates:
            self.set_null_space(self.system.mat)
        return self.system.mat

    def set_null_space(self, matrix: PETSc.Mat) -> None:
        """Give ``matrix`` the candidates (with zero multipliers) that it maps to nothing, to
        rounding, as its null space. Collective.

        Why: a body that nothing but frictionless contact holds is free to slide along the
        contact when the constraints' normals do not see the slide (a flat master and the
        reference configuration): the Newton matrix is singular, with that translation as
        its null vector, and the residual has no component along it (no force does). MUMPS
        sets the null pivot's step to zero; the condensed preconditioner of the Krylov
        method removes the null space from its output instead. A translation that
        contact holds, however weakly, is not exactly null and is not given."""
        vectors = []
        image = matrix.createVecLeft()
        for values in self.null_space_candidates:
            vector = matrix.createVecRight()
            vector.zeroEntries()
            vector.getArray()[self.layout.owned_u] = values
            size = vector.norm()
            matrix.mult(vector, image)
            if size > 0.0 and image.norm() <= NULL_SPACE_TOLERANCE * self.dirichlet_scale * size:
                vector.scale(1.0 / size)
                vectors.append(vector)
            else:
                vector.destroy()
        image.destroy()
        space = PETSc.NullSpace().create(vectors=vectors, comm=self.layout.comm)
        matrix.setNullSpace(space)
        space.destroy()
        for vector in vectors:
            vector.destroy()

    def destroy(self) -> None:
        """Free the PETSc objects this holds (the multiplier vectors too). Collective."""
        self.system.destroy()
        self.b_u.destroy()
        for vector in self.multipliers + [v for c in self.row_coefficients for v in c.values()]:
            vector.destroy()
        if self.friction is not None:
            self.friction.destroy()


class SnesCallbacks:
    """The residual, Jacobian and monitor of a :class:`ContactEquations` for an SNES,
    through a weak reference: an SNES holds its callbacks, and petsc4py destroys a
    parallel SNES whose wrapper was collected only at a collective clean-up
    (``PETSc.garbage_cleanup``), so strong callbacks would keep the equations and their
    vectors alive after the problem is gone."""

    def __init__(self, equations: ContactEquations):
        self._equations = weakref.ref(equations)

    def residual(self, snes, x, b) -> None:
        self._equations().residual(snes, x, b)

    def jacobian(self, snes, x, A, P) -> None:
        self._equations().jacobian(snes, x, A, P)

    def monitor(self, snes, iteration, norm) -> None:
        self._equations().monitor(snes, iteration, norm)


def bulk_diagonal(K: PETSc.Mat, J_form) -> tuple[np.ndarray, int]:
    """The bulk Jacobian's diagonal at this rank's owned rows, and the first row's global
    index. ``K`` (the bulk Jacobian's matrix) is assembled here. Collective."""
    K.zeroEntries()
    dolfinx.fem.petsc.assemble_matrix(K, J_form)
    K.assemble()
    diagonal = K.getDiagonal()
    try:
        return diagonal.getArray().copy(), K.getOwnershipRange()[0]
    finally:
        diagonal.destroy()


def stiffness_scales(diagonal: tuple[np.ndarray, int], interfaces, comm: MPI.Intracomm,
                     gdim: int) -> tuple[float, float, float, float]:
    """(s, h, s_master, h_master): s about E/h of the slave side (the mean bulk
    stiffness diagonal at slave dofs over h^(d-1), h the mean slave facet length in the
    reference configuration) and the same of the master side; ``diagonal`` from
    :func:`bulk_diagonal`. Collective."""
    values_all, start = diagonal
    scales = []
    for side in ("slave", "master"):
        sums = np.zeros(4)
        for interface in interfaces:
            surface = getattr(interface, side)
            dofs = surface.node_dofs()[surface.node_owned].reshape(-1) - start
            values = np.abs(values_all[dofs])
            X = surface.reference_coordinates[surface.facets]
            lengths = np.linalg.norm(X[:, 1] - X[:, 0], axis=1)
            sums += [values.sum(), values.size, lengths.sum(), lengths.size]
        sums = comm.allreduce(sums, op=MPI.SUM)
        if sums[1] == 0 or sums[3] == 0 or not sums[0] > 0 or not sums[2] > 0:
            raise ValueError(
                f"cannot estimate the stiffness scale at the {side} nodes: the bulk "
                f"Jacobian has a zero diagonal there (is the {side} surface on a body of "
                "the form?)"
            )
        length = float(sums[2] / sums[3])
        # a stiffness diagonal is about E h^(d-2)
        scales.append((float(sums[0] / sums[1]) / length ** (gdim - 1), length))
    return scales[0][0], scales[0][1], scales[1][0], scales[1][1]
