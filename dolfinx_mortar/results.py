"""What a solved contact problem gives: pressures, forces, the friction state, fields
for ParaView and the search counters.

:class:`ContactResults` is the part of :class:`~dolfinx_mortar.problem.ContactProblem`
that reads its state; it adds no state of its own.
"""

from __future__ import annotations

import dolfinx
import numpy as np
from mpi4py import MPI

from . import recovery


class ContactResults:
    """The results of a contact problem (a base class of
    :class:`~dolfinx_mortar.problem.ContactProblem`, whose state it reads: ``comm``,
    ``V``, ``pairs``, ``swapped``, ``interfaces``, ``multipliers``, ``active``, ``areas``,
    ``friction``, ``pressure_recovery`` and ``equations``)."""

    def num_active(self) -> int:
        """Active slave nodes of all pairs, summed over the ranks. Collective."""
        return int(self.comm.allreduce(sum(int(a.sum()) for a in self.active), op=MPI.SUM))

    def contact_pressure(self, k: int = 0, raw: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """(reference coordinates, contact pressure) of pair k's slave nodes owned by this
        rank: coordinates (n, gdim), pressures (n,); :meth:`gathered_pressure` gives all of
        them on every rank. The rows are those of :meth:`friction_state`, in the same order.
        The slave side is the one pair k is solved with (``solved_pair(k).slave``: the
        ContactPair's master where ``slave_side="auto"`` swapped the sides).

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
        """Total contact force on the slave and on the master side of pair k, as the
        ContactPair names them (also where ``slave_side="auto"`` swapped the sides).

        Each is a vector of gdim components ((x, y) in 2D, (x, y, z) in 3D): the force the
        other body exerts on that side, the normal pressure's and, with friction, the
        friction traction's; the two balance. Collective: call it on every rank (each gets
        the sums over all ranks).
        """
        interface = self.interfaces[k]
        q = interface.quantities
        if q is None:
            return np.zeros(interface.gdim), np.zeros(interface.gdim)
        rows = interface.contributing_pairs()
        z_pair = interface.node_values(self.multipliers[k])[interface.pair_slave_nodes[rows]]
        coefficients = interface.force_coefficients(rows)  # -Dn (slave), Mn (master)
        ns = interface.stencil.ns
        slave = np.einsum("nj,njkc->c", z_pair, coefficients[:, :, :ns])
        master = np.einsum("nj,njlc->c", z_pair, coefficients[:, :, ns:])
        if self.friction is not None:
            slave_friction, master_friction = self.friction.forces(k, rows)
            slave, master = slave + slave_friction, master + master_friction
        forces = (self.comm.allreduce(slave, op=MPI.SUM), self.comm.allreduce(master, op=MPI.SUM))
        return forces[::-1] if self.swapped[k] else forces

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
        return self.friction.state(k, self.equations.tangential_rows(k), self.active[k],
                                   self.areas[k])

    def tangential_traction(self, k: int = 0, raw: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """(reference coordinates, tangential traction) of pair k's owned slave nodes, the
        rows of :meth:`friction_state`: the traction as ``friction_state`` gives it ((n,) in
        2D, (n, 2) in the nodes' tangent frames in 3D).

        With ``pressure_recovery`` (the default in 3D) the traction is recovered on the
        active nodes' patches as the pressure is (:func:`.recovery.recovered_traction`:
        the linear fit of the traction field, in 3D of its vectors y_j . tau_j, evaluated
        at the node), which averages the node to node scatter of the tangential
        multipliers; otherwise, or with ``raw=True``, the multipliers y_j. Coulomb's law
        holds node by node for the multipliers, not for the fit. Collective.
        """
        state = self.friction_state(k)
        return state["coordinates"].copy(), self._tangential_traction(k, state, raw)

    def _tangential_traction(self, k: int, state: dict, raw: bool) -> np.ndarray:
        """The traction of :meth:`tangential_traction` from pair k's ``friction_state``."""
        traction = state["traction"]
        if not self.pressure_recovery or raw:
            return traction.copy()
        interface = self.interfaces[k]
        if traction.ndim == 1:
            vector = interface.create_multiplier_vector()
            vector.getArray()[:] = traction
            recovered = recovery.recovered_scalar(interface, vector, self.active[k])
            vector.destroy()
        else:
            frames = state["frames"]
            vectors = np.einsum("na,nac->nc", traction, frames)
            recovered = np.einsum("nc,nac->na", recovery.recovered_traction(
                interface, vectors, self.active[k]), frames)
        return recovered

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

    def friction_functions(self, k: int = 0, functions: tuple | None = None,
                           raw: bool = False) -> tuple:
        """(tangential traction, status) as P1 scalar Functions for ParaView (0 away
        from the slave nodes): the traction of :meth:`tangential_traction` (recovered
        with ``pressure_recovery``, the multipliers y_j with ``raw``; in 3D its
        magnitude); status 0 inactive, 1 slipping, 2 sticking. Collective."""
        if functions is None:
            space = dolfinx.fem.functionspace(self.V.mesh, ("Lagrange", 1))
            functions = (dolfinx.fem.Function(space, name="tangential_traction"),
                         dolfinx.fem.Function(space, name="friction_status"))
        state = self.friction_state(k)
        status = np.where(state["sticking"], 2.0, np.where(state["slipping"], 1.0, 0.0))
        traction = self._tangential_traction(k, state, raw)
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
                    int(np.count_nonzero(~self.equations.covered(k))), op=MPI.SUM
                ),
                "time_search": s.time_search,
                "time_integration": s.time_integration,
            }
        return result
