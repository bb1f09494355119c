"""Mortar coupling of a slave and a master surface: D, M, weighted gaps, derivatives.

:class:`MortarInterface` is the parallel layer around :mod:`kernels`: it
extracts the two surfaces, numbers one multiplier per slave node across
ranks, brings in the master facets (and slave neighbours) that other ranks
own near this rank's slave facets, keeps candidate pairs while nothing moved
past the search margin, evaluates all pairs in one batched kernel call and
assembles the results into PETSc objects whose sparsity is fixed between
searches (COO preallocation: no allocation inside a Newton loop).

The interface is dimension-free: the kernel of the facets' dimension and
the nodes each pair depends on are a :mod:`stencils` object (2D:
:class:`~dolfinx_mortar.stencils.Line2Stencil`, 3D:
:class:`~dolfinx_mortar.stencils.Surface3Stencil`), chosen once.

The solver assembles the pairs' contributions itself
(:class:`~dolfinx_mortar.system.ContactSystem`) from the public per-pair pieces:
:meth:`MortarInterface.contributing_pairs`, :meth:`~MortarInterface.force_coefficients`
(B), :meth:`~MortarInterface.combined_gradients` with the terms of
:meth:`~MortarInterface.force_jacobian_terms` and of the multiplier rows, and the
dofs :attr:`~MortarInterface.pair_dofs`, :attr:`~MortarInterface.pair_force_dofs`.
:meth:`~MortarInterface.gap_jacobian`, :meth:`~MortarInterface.constraint_matrix` and
:meth:`~MortarInterface.force_jacobian` put the same pieces into matrices of their
own, for checks and benchmarks.

Layouts: rows of D, M, the weighted gap and its Jacobian are multipliers
(one per slave node, owned by the rank owning the node's dofs); columns of D
and M are global dof blocks (nodes) of the displacement space; columns of
Jacobians are global displacement dofs (block * gdim + component).
"""

from __future__ import annotations

import dataclasses
import time

import dolfinx
import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from . import covered, kernels, search, self_contact, stencils, surface
from .deprecation import renamed_keywords
from .dual import RowSubsetDual
from .kernels import BasisOption, IntegrationOption, KernelOptions, NormalOption, PairQuantities
from .layout import BlockIncidence, CooMatrix

CONFIGURATIONS = ("current", "reference")


@dataclasses.dataclass
class MortarStatistics:
    """Counters and timings of one interface, for reports and benchmarks."""

    pairs: int = 0
    segments: int = 0
    searches_done: int = 0
    searches_skipped: int = 0
    evaluations: int = 0
    evaluations_skipped: int = 0
    widenings: int = 0
    """patterns widened between searches for slave facets found partly covered
    (covered dual basis)"""
    time_search: float = 0.0
    time_exchange: float = 0.0
    time_integration: float = 0.0
    time_assembly: float = 0.0


def _owner_of_blocks(index_map, local_blocks: np.ndarray, rank: int) -> np.ndarray:
    owners = np.full(local_blocks.shape, rank, dtype=np.int32)
    ghost = local_blocks >= index_map.size_local
    owners[ghost] = index_map.owners[local_blocks[ghost] - index_map.size_local]
    return owners


def _alltoallv(
    comm: MPI.Intracomm, chunks: list[np.ndarray], dtype, width: int
) -> tuple[np.ndarray, np.ndarray]:
    """Send chunks[r] (rows of ``width`` values) to rank r; return the rows and their sources."""
    send_counts = np.array([c.shape[0] * width for c in chunks], dtype=np.int64)
    recv_counts = np.array(comm.alltoall(send_counts.tolist()), dtype=np.int64)
    send = (
        np.concatenate([np.asarray(c, dtype=dtype).reshape(-1) for c in chunks])
        if chunks
        else np.zeros(0, dtype)
    )
    recv = np.empty(int(recv_counts.sum()), dtype=dtype)
    mpi_type = MPI._typedict[np.dtype(dtype).char]
    comm.Alltoallv([send, (send_counts, None), mpi_type], [recv, (recv_counts, None), mpi_type])
    sources = np.repeat(np.arange(comm.size), recv_counts // width)
    return recv.reshape(-1, width), sources


def _check_options(configuration: str, normals: str, integration: str, basis: str,
                   num_gauss_points: int | None) -> None:
    """ValueError naming the first option of :class:`MortarInterface` out of its range."""
    for value, allowed, what in (
        (configuration, CONFIGURATIONS, "configuration"),
        (normals, kernels.NORMAL_OPTIONS, "normals"),
        (integration, kernels.INTEGRATION_OPTIONS, "integration"),
        (basis, kernels.BASIS_OPTIONS, "basis"),
    ):
        if value not in allowed:
            raise ValueError(f"unknown {what} option {value!r}; expected one of {allowed}")
    if num_gauss_points is not None and num_gauss_points < 1:
        raise ValueError("num_gauss_points must be >= 1")


class MortarInterface:
    """One slave/master pair of surfaces and its mortar quantities.

    Args:
        V: P1 vector displacement space on a 2D (triangles, quadrilaterals) or
            3D (tetrahedra, hexahedra) mesh.
        facet_tags: facet meshtags naming the surfaces.
        slave, master: tag values of the slave (non-mortar) and
            master (mortar) surfaces.
        normals: ``averaged`` (default), ``slave`` or ``master`` normal field.
        integration: ``segment`` (default, exact) or ``element``.
        basis: multiplier basis, ``standard`` (default) or ``dual`` (biorthogonal over
            the covered part of each slave facet: :mod:`~dolfinx_mortar.covered`).
        num_gauss_points: per segment (or per slave facet for ``element``).
        search_margin: the pairs of a search are kept until a node moves more
            than half of it. The boxes are grown by it in 2D (facets within two
            margins of each other are paired) and by half of it in 3D (within one
            margin: what the reuse needs, since each side moved at most half a
            margin; the number of candidate pairs grows with the square of the
            growth there). Default twice the mean slave facet edge length h in 2D
            and h/2 in 3D. In 3D the boxes also reach 2 margins (default h) behind
            each facet, so that surfaces that already penetrate each other by up to
            2 h + 1 margin before any displacement are paired (2D: up to 2 margins).
        configuration: ``current`` (default): everything on x = X + u, for
            large deformations; ``reference``: integrals and normals on the
            undeformed surfaces, computed once, gap linear in u (small strain,
            to pair with linear elasticity).
    """

    _facing_pairs: np.ndarray | None = None
    """A self-contact surface's facing pairs at the last search (sorted global blocks of the
    slave facet, then the master facet's): they keep facing while penetrated."""

    @renamed_keywords(slave_marker="slave", master_marker="master")
    def __init__(
        self,
        V: dolfinx.fem.FunctionSpace,
        facet_tags: dolfinx.mesh.MeshTags,
        slave: int,
        master: int,
        *,
        normals: NormalOption = "averaged",
        integration: IntegrationOption = "segment",
        basis: BasisOption = "standard",
        num_gauss_points: int | None = None,
        search_margin: float | None = None,
        configuration: str = "current",
    ):
        _check_options(configuration, normals, integration, basis, num_gauss_points)
        self.V = V
        self.comm: MPI.Intracomm = V.mesh.comm
        self.normals = normals
        self.integration = integration
        self.basis = basis
        self.configuration = configuration
        self._reference_quantities: PairQuantities | None = None
        self._evaluated_x: np.ndarray | None = None
        self._evaluated_version = -1
        self.self_contact = slave == master
        """One surface that may touch itself (:mod:`~dolfinx_mortar.self_contact`): it is
        its own master, and each search decides which facets of each zone are slaves."""
        self.slave = surface.extract_surface(V, facet_tags, slave, "slave")
        if self.self_contact:
            self.master = self.slave
        else:
            self.master = surface.extract_surface(V, facet_tags, master, "master")
            surface.check_disjoint(self.slave, self.master, self.comm)
        self.gdim = self.slave.reference_coordinates.shape[1]
        self.origin = self.slave.bounding_box_centre(self.comm)
        """The point the interface's coordinates are taken from (the slave surface's
        bounding-box centre): the gaps, D and M do not depend on it, but their rounding
        does, as eps |x| against the displacements that make a gap."""
        self._stencil_type = stencils.STENCILS[self.gdim]
        self.num_gauss_points = (num_gauss_points
                                 or self._stencil_type.kernel.default_gauss_points[integration])
        if search_margin is None:
            search_margin = self._stencil_type.search_margin * self.mean_slave_edge_length()
        if not search_margin > 0.0:
            raise ValueError(f"search_margin must be positive, got {search_margin}")
        self.reuse = search.SearchReuse(margin=float(search_margin))
        self.search_growth = self._stencil_type.search_growth * self.reuse.margin
        self.search_depth = self._stencil_type.search_depth * self.reuse.margin
        self.statistics = MortarStatistics()

        index_map = V.dofmap.index_map
        self.block_size = V.dofmap.index_map_bs
        self.num_owned_dofs = index_map.size_local * self.block_size
        self.num_global_dofs = index_map.size_global * self.block_size
        self.num_owned_blocks = index_map.size_local
        self.num_global_blocks = index_map.size_global
        self._number_multipliers()
        self._pattern_version = 0
        self._matrices: dict[str, tuple[int, PETSc.Mat]] = {}
        self._pair_block_sides: dict[str, tuple[int, BlockIncidence]] = {}
        self.quantities: PairQuantities | None = None
        self._crosspoint_blocks = np.zeros(0, dtype=np.int64)
        self._fold_blocks = np.zeros(0, dtype=np.int64)
        self._slave_side_facets: np.ndarray | None = None
        self.stencil: stencils.PairStencil | None = None
        self.without_pairs = False
        """No pair on any rank at the last search (one allreduce): every rank alike skips this
        interface's evaluation, gaps, forces and blocks (a self-contact surface far away)."""
        self.scalar_gradients = False
        """3D: the kernel also keeps the gradients of D and M, and the stencils hold the
        averaged normals' stars whatever the normal option (friction's tangent frames;
        set before the first search)."""
        self.assembly_chunk: int | None = self._stencil_type.assembly_chunk
        """Pairs whose gradient blocks (G, K) are formed at once in an assembly (None:
        all, summed as one array; 2D's kernel gradients combine all pairs in one go)."""

    def mean_slave_edge_length(self) -> float:
        """h: the mean length of the undeformed slave facets' edges, over all ranks (every
        edge of every facet; a 2D facet is its one edge). Collective."""
        lengths = self.slave.edge_lengths()
        total = self.comm.allreduce(np.array([lengths.sum(), lengths.size]), op=MPI.SUM)
        return total[0] / total[1]

    # -- multipliers -------------------------------------------------------

    def _number_multipliers(self) -> None:
        """One multiplier per slave node, owned by the owner of its dofs.

        A node may belong only to slave facets of other ranks; those ranks
        tell the owner, which numbers all its slave nodes, then answers with
        the global numbers.
        """
        comm = self.comm
        index_map = self.V.dofmap.index_map
        slave = self.slave
        owners = _owner_of_blocks(index_map, slave.node_blocks, comm.rank)
        ghosts = ~slave.node_owned
        requests = [
            np.column_stack([slave.node_global_blocks[ghosts & (owners == r)],
                             slave.reference_coordinates[ghosts & (owners == r)].view(np.int64)])
            for r in range(comm.size)
        ]
        received, sources = _alltoallv(comm, requests, np.int64, 1 + self.gdim)
        own_blocks = np.concatenate([slave.node_global_blocks[slave.node_owned], received[:, 0]])
        own_coordinates = np.concatenate(
            [slave.reference_coordinates[slave.node_owned], received[:, 1:].copy().view(np.float64)]
        )
        unique_blocks, first = np.unique(own_blocks, return_index=True)
        self.num_owned_multipliers = unique_blocks.size
        self.multiplier_offset = comm.exscan(unique_blocks.size) or 0
        self.num_global_multipliers = comm.allreduce(unique_blocks.size, op=MPI.SUM)
        self.owned_multiplier_blocks = unique_blocks
        self.owned_multiplier_coordinates = own_coordinates[first]
        answers = [
            self.multiplier_offset + np.searchsorted(unique_blocks, received[sources == r, 0])
            for r in range(comm.size)
        ]
        answered, _ = _alltoallv(comm, [a[:, None] for a in answers], np.int64, 1)
        numbers = np.empty(slave.num_nodes, dtype=np.int64)
        numbers[slave.node_owned] = self.multiplier_offset + np.searchsorted(
            unique_blocks, slave.node_global_blocks[slave.node_owned]
        )
        order = np.concatenate([np.flatnonzero(ghosts & (owners == r)) for r in range(comm.size)])
        numbers[order.astype(np.int64)] = answered[:, 0]
        self.node_multipliers = numbers
        ghost_multipliers = np.unique(numbers[ghosts])
        self._ghost_multipliers = ghost_multipliers[
            (ghost_multipliers < self.multiplier_offset)
            | (ghost_multipliers >= self.multiplier_offset + self.num_owned_multipliers)
        ]

    def set_crosspoints(self, global_blocks: np.ndarray) -> None:
        """Slave nodes (global dof blocks) that carry no multiplier.

        Used where the slave surface meets a Dirichlet boundary: the node's
        basis function is merged into its neighbour's (see
        :func:`kernels.pair_quantities`); its multiplier rows become empty.
        Collective: pass this rank's blocks, all ranks' are gathered.
        """
        gathered = np.concatenate(self.comm.allgather(np.asarray(global_blocks, dtype=np.int64)))
        self._crosspoint_blocks = np.unique(gathered)
        self.reuse.invalidate()
        self.quantities = None
        self._reference_quantities = None

    @property
    def owned_crosspoint_multipliers(self) -> np.ndarray:
        """Global numbers of the owned multipliers that are crosspoints."""
        owned = np.isin(self.owned_multiplier_blocks, self._crosspoint_blocks)
        return self.multiplier_offset + np.flatnonzero(owned)

    def create_multiplier_vector(self) -> PETSc.Vec:
        """A ghosted vector in the multiplier layout (ghosts: this rank's slave nodes)."""
        return PETSc.Vec().createGhost(
            self._ghost_multipliers.astype(PETSc.IntType),
            size=(self.num_owned_multipliers, self.num_global_multipliers),
            comm=self.comm,
        )

    def node_values(self, z: PETSc.Vec) -> np.ndarray:
        """Values of a ghosted multiplier vector at this rank's slave nodes (collective)."""
        z.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        with z.localForm() as local:
            array = local.getArray(readonly=True)
            owned = self.node_multipliers - self.multiplier_offset
            result = np.empty(self.slave.num_nodes)
            is_owned = (owned >= 0) & (owned < self.num_owned_multipliers)
            result[is_owned] = array[owned[is_owned]]
            position = np.searchsorted(self._ghost_multipliers, self.node_multipliers[~is_owned])
            result[~is_owned] = array[self.num_owned_multipliers + position]
        return result

    # -- search and geometry ----------------------------------------------

    def update(self, u: dolfinx.fem.Function | None = None) -> PairQuantities:
        """Evaluate all mortar quantities at x = X + u (collective).

        Re-searches only when a surface node moved more than half the margin
        since the last search; otherwise only coordinates are exchanged. The
        search sweeps the facets from their positions at the last search (the
        undeformed surfaces before the first) to the current ones, so that
        pairs are found however far one update moved the surfaces through
        each other (:mod:`search`). With
        ``configuration="reference"`` the integrals are taken on the undeformed
        surfaces (again only after a new search) and only the gap follows u
        (small strain); the search still follows x, swept from the undeformed
        surfaces, so pairs that start further apart than the margin are found
        once the gap closes and kept however deep a penalty lets them sink.
        """
        stats = self.statistics
        start = time.perf_counter()
        slave_x = self.slave.current_coordinates(u, self.origin)
        master_x = slave_x if self.self_contact else self.master.current_coordinates(u, self.origin)
        moving = np.concatenate([slave_x, master_x])
        reference = self.configuration == "reference"
        if self.reuse.needs_search(moving, self.comm) or (
            reference and self._reference_quantities is None
        ):
            ns = self.slave.num_nodes
            undeformed = np.concatenate(
                [self.slave.reference_coordinates, self.master.reference_coordinates]
            ) - self.origin
            if reference:
                # swept from the undeformed surfaces, whose pairs the linearized gap
                # holds at any penetration (a soft penalty sinks far past the margin);
                # the integrals are then taken again on the undeformed surfaces
                self._search(slave_x, master_x, undeformed[:ns], undeformed[ns:])
                self.reuse.searched(moving)
                self._refresh_coordinates(undeformed[:ns], undeformed[ns:])
                self._reference_node_x = self._node_x.copy()
                self._reference_quantities = None
                self._refresh_coordinates(slave_x, master_x)
            else:
                origin = self.reuse.sweep_start(moving, undeformed)
                self._search(slave_x, master_x, origin[:ns], origin[ns:])
                # a long sweep's pairs are dropped by searching again at the next update;
                # a sweep that kept none on any rank has none to drop: its search holds
                self.reuse.searched(moving, None if self.without_pairs else origin, self.comm)
        else:
            self.reuse.skipped()
            if not self.without_pairs:  # (no pair reads the node table: not refreshed)
                self._refresh_coordinates(slave_x, master_x)
        stats.searches_done = self.reuse.searches_done
        stats.searches_skipped = self.reuse.searches_skipped
        stats.time_search += time.perf_counter() - start

        start = time.perf_counter()
        if self.configuration == "reference":
            if self._reference_quantities is None:
                self._reference_quantities = self._evaluate(self._reference_node_x)
            self.quantities = self._with_current_gap(self._reference_quantities)
        elif (self.quantities is not None and self._evaluated_version == self._pattern_version
              and (self.stencil.num_pairs == 0
                   or np.array_equal(self._evaluated_x, self._node_x))):
            # nothing moved since the last evaluation (a Jacobian after its
            # residual, a repeated line-search point), or no pair here whose quantities
            # could change: keep the quantities
            stats.evaluations_skipped += 1
            self._widen_partly_covered()
            stats.time_integration += time.perf_counter() - start
            return self.quantities
        else:
            # the old quantities (their gradients are ~13 kB a pair in 3D) go first
            self.quantities = None
            self.quantities = self._evaluate(self._node_x)
            self._evaluated_x = self._node_x.copy()
            self._evaluated_version = self._pattern_version
            self._widen_partly_covered()
        stats.segments = int(np.count_nonzero(self.quantities.valid))
        stats.evaluations += 1
        stats.time_integration += time.perf_counter() - start
        return self.quantities

    def _widen_partly_covered(self) -> None:
        """With the covered dual basis, the slave facets an evaluation found partly covered
        were given their coupling to the facet's other master nodes
        (:class:`covered.CoveredStencil`): then every rank takes the new pattern.
        Collective: every rank calls it at every update of the current configuration."""
        if self.basis != "dual" or self.configuration == "reference" or self.without_pairs:
            return  # only the covered dual basis of the current configuration widens pairs
        stencil = self.stencil
        changed = stencil.widenings != self._stencil_widenings
        if not self.comm.allreduce(changed, op=MPI.LOR):
            return
        self._stencil_widenings = stencil.widenings
        self._pattern_version += 1
        # the quantities do not depend on the partner slots: no new evaluation
        self._evaluated_version = self._pattern_version
        self.statistics.widenings += 1

    def _evaluate(self, node_x: np.ndarray) -> PairQuantities:
        options = KernelOptions(
            normals=self.normals, integration=self.integration, basis=self.basis,
            num_gauss_points=self.num_gauss_points, scalar_gradients=self.scalar_gradients)
        return self.stencil.evaluate(node_x, options, crosspoint=self.pair_crosspoint)

    def _with_current_gap(self, reference: PairQuantities) -> PairQuantities:
        """Reference integrals, constant in u (the nodal normals too); the gap linear in the
        current positions. Every quantity is zero outside the pairs that contribute."""
        stencil = self.stencil
        rows, n = reference.rows, reference.valid.shape[0]
        Dn, Mn = reference.Dn.value_rows, reference.Mn.value_rows  # (rows, j, k, c)
        gap = (np.einsum("njlc,nlc->nj", Mn, self._node_x[stencil.master_nodes[rows]])
               - np.einsum("njkc,nkc->nj", Dn, self._node_x[stencil.slave_nodes[rows]]))
        nv, ns = stencil.num_variables, stencil.ns
        grad = np.zeros((rows.size, ns, nv))
        grad[:, :, stencil.slave_variables] = -Dn.reshape(-1, ns, ns * self.gdim)
        grad[:, :, stencil.master_variables] = Mn.reshape(-1, ns, stencil.nm * self.gdim)

        def constant(value_rows: np.ndarray) -> RowSubsetDual:
            return RowSubsetDual.of_constant(value_rows, rows, nv, n)

        frozen_scalars = {}
        if reference.D_dual is not None:
            frozen_scalars = {"D_dual": constant(reference.D_rows),
                              "M_dual": constant(reference.M_rows)}
        return reference.replaced(Dn=constant(Dn), Mn=constant(Mn),
                                  area=constant(reference.area.value_rows),
                                  gap=RowSubsetDual(gap, rows, grad, n), normals_vary=False,
                                  **frozen_scalars)

    def _exchange_plan(self, slave_x: np.ndarray, master_x: np.ndarray,
                       slave_origin: np.ndarray | None = None,
                       master_origin: np.ndarray | None = None) -> None:
        """Which owned master and slave facets each other rank needs (swept boxes
        from the ``origin`` positions, as in the search itself)."""
        comm = self.comm
        growth = self.search_growth
        depth = self.search_depth
        slave_lower, slave_upper = search.facet_boxes(
            slave_x, self.slave.facets, slave_origin, depth)
        gdim = self.gdim
        if self.slave.num_facets:
            my_box = np.concatenate([slave_lower.min(axis=0), slave_upper.max(axis=0)])
        else:
            my_box = np.concatenate([np.full(gdim, np.inf), np.full(gdim, -np.inf)])
        boxes = np.array(comm.allgather(my_box))
        master_lower, master_upper = search.facet_boxes(
            master_x, self.master.facets, master_origin, depth)
        self._send_master = []
        self._send_slave = []
        for r in range(comm.size):
            if r == comm.rank:
                self._send_master.append(np.zeros(0, dtype=np.int64))
                self._send_slave.append(np.zeros(0, dtype=np.int64))
                continue
            lower, upper = boxes[r, :gdim], boxes[r, gdim:]
            self._send_master.append(np.flatnonzero(
                search.boxes_overlap(master_lower, master_upper, lower, upper, growth)))
            self._send_slave.append(np.flatnonzero(
                search.boxes_overlap(slave_lower, slave_upper, lower, upper, growth)))

    def _receive(self, owned: surface.ContactSurface, plan: list[np.ndarray], *states: np.ndarray):
        """Global blocks (m, k) and, per state of the nodes in ``states``, the
        coordinates (m, k, gdim) of the m facets of k nodes others send."""
        k, gdim = owned.facets.shape[1], self.gdim
        chunks = []
        for facets in plan:
            nodes = owned.facets[facets]
            chunks.append(np.column_stack(
                [np.ascontiguousarray(owned.node_global_blocks[nodes]).view(np.float64)]
                + [x[nodes].reshape(-1, k * gdim) for x in states]
            ))
        width = k * gdim
        data, _ = _alltoallv(self.comm, chunks, np.float64, k + width * len(states))
        blocks = data[:, :k].copy().view(np.int64)
        coordinates = (data[:, k + width * i:k + width * (i + 1)].reshape(-1, k, gdim)
                       for i in range(len(states)))
        return (blocks, *coordinates)

    def _search(self, slave_x: np.ndarray, master_x: np.ndarray,
                slave_origin: np.ndarray | None = None,
                master_origin: np.ndarray | None = None) -> None:
        """New candidate pairs at the positions ``x``; with ``origin`` positions
        (the last search's), the boxes are swept from there (:mod:`search`)."""
        # what belongs to the last search's pairs (their quantities, the assembly patterns'
        # lookups) goes before the new pairs' arrays are made (an interface without pairs
        # has none: it keeps them, in case this search finds none again)
        if not self.without_pairs:
            self.quantities = None
            for _, matrix in self._matrices.values():
                matrix.release_pattern()
            self._pair_block_sides.clear()
        slave, master = self.slave, self.master
        parallel = self.comm.size > 1
        swept = slave_origin is not None
        if not swept:
            slave_origin, master_origin = slave_x, master_x
        start = time.perf_counter()
        if parallel:
            self._exchange_plan(slave_x, master_x, slave_origin, master_origin)
            remote_master_blocks, remote_master_x, remote_master_origin = self._receive(
                master, self._send_master, master_x, master_origin)
            remote_slave_blocks, remote_slave_x, remote_slave_origin = self._receive(
                slave, self._send_slave, slave_x, slave_origin)
        else:
            gdim, km, ks = self.gdim, master.facets.shape[1], slave.facets.shape[1]
            remote_master_blocks = np.zeros((0, km), dtype=np.int64)
            remote_slave_blocks = np.zeros((0, ks), dtype=np.int64)
            remote_master_x = remote_master_origin = np.zeros((0, km, gdim))
            remote_slave_x = remote_slave_origin = np.zeros((0, ks, gdim))
        self.statistics.time_exchange += time.perf_counter() - start

        # node table: local slave nodes, local master nodes, remote master
        # facet ends, remote slave facet ends
        gdim = self.gdim
        ns, nm = slave.num_nodes, master.num_nodes
        km, ks = master.facets.shape[1], slave.facets.shape[1]
        nrm, nrs = remote_master_blocks.shape[0], remote_slave_blocks.shape[0]
        self._node_blocks = np.concatenate([
            slave.node_global_blocks, master.node_global_blocks,
            remote_master_blocks.reshape(-1), remote_slave_blocks.reshape(-1),
        ])
        self._node_x = np.concatenate([
            slave_x, master_x, remote_master_x.reshape(-1, gdim), remote_slave_x.reshape(-1, gdim)
        ])
        all_master_facets = np.concatenate([
            master.facets + ns, ns + nm + np.arange(km * nrm).reshape(-1, km)
        ]).astype(np.int64)
        all_slave_facets = np.concatenate([
            slave.facets, ns + nm + km * nrm + np.arange(ks * nrs).reshape(-1, ks)
        ]).astype(np.int64)

        node_origin = None
        if swept:
            node_origin = np.concatenate([
                slave_origin, master_origin,
                remote_master_origin.reshape(-1, gdim), remote_slave_origin.reshape(-1, gdim),
            ])
        faced_before = self._facing_pairs is not None and self._facing_pairs.shape[0] > 0
        if self.self_contact and not faced_before and not self_contact.may_face(
                self._node_x, self._node_blocks, slave.facets, all_master_facets,
                self.search_growth, node_origin, self.search_depth):
            pairs = np.zeros((0, 2), dtype=np.int64)  # far from itself here: nothing to find
        else:
            pairs = search.candidate_pairs(
                self._node_x, slave.facets, self._node_x, all_master_facets, self.search_growth,
                slave_previous=node_origin, master_previous=node_origin,
                depth=self.search_depth)
        if self.self_contact:
            pairs, all_slave_facets = self._one_sided(pairs, all_slave_facets,
                                                      all_master_facets)
        found = self.comm.allreduce(pairs.shape[0], op=MPI.SUM)
        if found == 0 and self.without_pairs and self.stencil is not None:
            # no pair before, none now (on any rank): the empty stencil, its pattern version
            # (the system keeps its matrix) and its empty quantities still hold
            return
        self._set_pairs(pairs, all_slave_facets, all_master_facets)
        self.without_pairs = found == 0

    def _one_sided(self, pairs: np.ndarray, all_slave_facets: np.ndarray,
                   all_master_facets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Of a self-contact surface's candidate pairs, those of facets that face each other,
        each once, its slave on the zone's slave side (:mod:`self_contact`); and the slave
        facets without the master sides' (the slave nodes' averaged normals). Collective."""
        slave_nodes = self.slave.facets[pairs[:, 0]]
        master_nodes = all_master_facets[pairs[:, 1]]
        slave_blocks = self._node_blocks[slave_nodes]
        master_blocks = self._node_blocks[master_nodes]
        slave_x, master_x = self._node_x[slave_nodes], self._node_x[master_nodes]
        keys = np.column_stack([np.sort(slave_blocks, axis=1), np.sort(master_blocks, axis=1)])
        faced = (self_contact.rows_in(keys, self._facing_pairs)
                 if self._facing_pairs is not None else None)
        facing = self_contact.facing(slave_blocks, master_blocks, slave_x, master_x,
                                     self.search_depth, faced)
        self._facing_pairs = keys[facing]
        if self.comm.allreduce(int(np.count_nonzero(facing)), op=MPI.SUM) == 0:
            # no zone anywhere: what slave_side would decide, without gathering
            self._slave_side_facets = np.zeros((0, slave_nodes.shape[1]), dtype=np.int64)
            self._fold_blocks = np.zeros(0, dtype=np.int64)
            return pairs[:0], all_slave_facets
        pairs, slave_nodes, master_nodes = (
            pairs[facing], slave_nodes[facing], master_nodes[facing])
        sizes = [self_contact.facet_frames(self._node_x, nodes)[2]
                 for nodes in (slave_nodes, master_nodes)]
        slave_side, master_side, self._slave_side_facets = self_contact.slave_side(
            self.comm, slave_blocks[facing], master_blocks[facing], *sizes,
            previous_slaves=self._slave_side_facets)
        on_master_side = self_contact.rows_in(
            np.sort(self._node_blocks[all_slave_facets], axis=1), master_side)
        # a node on both sides of a zone (a slit's tip) has a weighted gap of zero whatever
        # the displacement: it carries no multiplier, as a crosspoint
        self._fold_blocks = np.unique(master_side)
        return pairs[slave_side], all_slave_facets[~on_master_side]

    def _set_pairs(self, pairs: np.ndarray, all_slave_facets: np.ndarray,
                   all_master_facets: np.ndarray) -> None:
        """The stencils of a search's candidate ``pairs`` and what the assembly reads of
        them (their multipliers, crosspoints; a new pattern version)."""
        # the last search's per-pair arrays go before the new ones are made; its slave
        # surface's stars stay while they describe the same surface
        slave_surface = None if self.stencil is None else self.stencil.slave_surface
        self.stencil = self.pair_slave_facets = self.pair_multipliers = None
        self.pair_crosspoint = None
        stencil = self._stencil_type.build(
            self._node_blocks, self._node_x, all_slave_facets,
            self.slave.facets.astype(np.int64), all_master_facets, pairs,
            normals=self.normals, nodal_frames=self.scalar_gradients,
            slave_surface=slave_surface)
        if self.basis == "dual":
            stencil = covered.CoveredStencil(
                stencil, coupled=self.configuration != "reference",
                master_boundary=covered.boundary_nodes(all_master_facets,
                                                       self._node_blocks.size))
        self.stencil = stencil
        self._stencil_widenings = stencil.widenings
        self.pair_slave_facets = stencil.slave_facets
        self.pair_multipliers = self.node_multipliers[stencil.slave_nodes]
        slave_blocks = self._node_blocks[stencil.slave_nodes]
        carry_none = np.union1d(self._crosspoint_blocks, self._fold_blocks)
        if carry_none.size:
            self.pair_crosspoint = np.isin(slave_blocks, carry_none)
        else:
            self.pair_crosspoint = np.zeros(slave_blocks.shape, dtype=bool)
        self._pattern_version += 1
        self.statistics.pairs = int(pairs.shape[0])

    @property
    def pair_node_blocks(self) -> np.ndarray:
        """(n, width) global dof block of each pair's stencil nodes (made on each use:
        the patterns are built once a search)."""
        return self._node_blocks[self.stencil.nodes]

    @property
    def _pair_col_blocks(self) -> np.ndarray:
        """The block pattern of the stencil columns: node blocks, -1 where a slot is absent."""
        return self._col_blocks_of(None)

    def _col_blocks_of(self, rows: np.ndarray | None) -> np.ndarray:
        """The rows of :attr:`_pair_col_blocks` of the pairs ``rows`` (None: all)."""
        stencil = self.stencil
        if rows is None:
            return np.where(stencil.present, self._node_blocks[stencil.nodes], -1)
        return np.where(stencil.present[rows], self._node_blocks[stencil.nodes[rows]], -1)

    @property
    def _pair_force_blocks(self) -> np.ndarray:
        """The blocks of the slave and master facet nodes."""
        stencil = self.stencil
        return self._node_blocks[stencil.nodes[:, np.concatenate([stencil.slave_slots,
                                                                   stencil.master_slots])]]

    def pair_sides(self) -> tuple[np.ndarray, ...]:
        """The facets of this rank's pairs at the last update, slave side then master side,
        each as (global node blocks (m,), positions (m, gdim), facets (f, k) indexing them):
        what :func:`~dolfinx_mortar.diagnostics.penetration_report` compares (of a
        self-contact surface, the sides its search decided)."""
        sides = []
        for facet_nodes in (self.stencil.slave_nodes, self.stencil.master_nodes):
            facets = np.unique(facet_nodes, axis=0)
            nodes, compact = np.unique(facets, return_inverse=True)
            sides += [self._node_blocks[nodes], self._node_x[nodes],
                      compact.reshape(facets.shape)]
        return tuple(sides)

    @property
    def pair_slave_nodes(self) -> np.ndarray:
        """(n, nodes per slave facet) node-table indices of each pair's slave facet nodes."""
        return self.stencil.slave_nodes

    @property
    def pair_dofs(self) -> np.ndarray:
        """(n, width * gdim) displacement dofs of each pair's stencil nodes (-1: absent).

        Made at each use, not kept: only a new pattern of the monolithic matrix needs them.
        """
        return self.pair_dofs_of(None)

    def pair_dofs_of(self, rows: np.ndarray | None) -> np.ndarray:
        """The rows of :attr:`pair_dofs` of the pairs ``rows`` (None: all)."""
        blocks = self._col_blocks_of(rows)
        gdim = self.gdim
        dofs = np.empty(blocks.shape + (gdim,), dtype=np.int64)
        for component in range(gdim):  # (not a broadcast over a short last axis: slow)
            dofs[:, :, component] = blocks * self.block_size + component
        dofs[blocks < 0] = -1
        return dofs.reshape(blocks.shape[0], blocks.shape[1] * gdim)

    def _refresh_coordinates(self, slave_x: np.ndarray, master_x: np.ndarray) -> None:
        self._fill_node_table(self._node_x, slave_x, master_x)

    def _fill_node_table(self, table: np.ndarray, slave_values: np.ndarray,
                         master_values: np.ndarray) -> None:
        """Per-node values (gdim per node) of the surfaces into a node table (collective)."""
        ns, nm = self.slave.num_nodes, self.master.num_nodes
        table[:ns] = slave_values
        table[ns:ns + nm] = master_values
        if self.comm.size > 1:
            start = time.perf_counter()
            _, remote_master = self._receive(self.master, self._send_master, master_values)
            _, remote_slave = self._receive(self.slave, self._send_slave, slave_values)
            table[ns + nm:] = np.concatenate(
                [remote_master.reshape(-1, self.gdim), remote_slave.reshape(-1, self.gdim)]
            )
            self.statistics.time_exchange += time.perf_counter() - start

    def node_field(self, values: np.ndarray) -> np.ndarray:
        """A vector field (an array of the displacement space, ghosts up to date) at every
        node of the node table, as the pairs' stencils index it. Collective."""
        blocks = values.reshape(-1, self.block_size)
        table = np.empty_like(self._node_x)
        self._fill_node_table(table, blocks[self.slave.node_blocks, :self.gdim],
                              blocks[self.master.node_blocks, :self.gdim])
        return table

    # -- PETSc objects -----------------------------------------------------

    @property
    def _multiplier_sizes(self):
        return (self.num_owned_multipliers, self.num_global_multipliers)

    @property
    def _dof_sizes(self):
        return (self.num_owned_dofs, self.num_global_dofs)

    @property
    def _block_sizes(self):
        return (self.num_owned_blocks, self.num_global_blocks)

    def _require(self) -> PairQuantities:
        if self.quantities is None:
            raise RuntimeError("call update(u) before assembling mortar quantities")
        return self.quantities

    def _block_matrix(self, name: str, row_blocks: str, col_blocks: str, block_shape,
                      row_sizes, col_sizes) -> CooMatrix:
        """A matrix of a dense block per pair (rows and columns: :meth:`_pair_blocks`),
        whose pattern is rebuilt only after a new search."""
        version, matrix = self._matrices.get(name, (-1, None))
        if version != self._pattern_version:
            if matrix is not None:
                matrix.destroy()
            matrix = CooMatrix.from_blocks(self.comm, self._pair_blocks(row_blocks),
                                           self._pair_blocks(col_blocks), block_shape,
                                           row_sizes, col_sizes)
            self._matrices[name] = (self._pattern_version, matrix)
        return matrix

    def _pair_blocks(self, name: str) -> BlockIncidence:
        """The pairs' blocks of one side of the matrix patterns, built once per search and
        shared: ``multipliers`` (rows of D, M, G, B), ``slave`` and ``master`` nodes
        (columns of D, M), ``stencil`` (columns of G, K), ``force`` (B's columns, K's rows)."""
        version, side = self._pair_block_sides.get(name, (-1, None))
        if version != self._pattern_version:
            stencil = self.stencil
            blocks = {
                "multipliers": lambda: self.pair_multipliers,
                "slave": lambda: self._node_blocks[stencil.slave_nodes],
                "master": lambda: self._node_blocks[stencil.master_nodes],
                "stencil": lambda: self._pair_col_blocks,
                "force": lambda: self._pair_force_blocks,
            }[name]()
            side = BlockIncidence(blocks)
            self._pair_block_sides[name] = (self._pattern_version, side)
        return side

    # -- the pairs' contributions, as the solver assembles them ---------------------------

    def contributing_pairs(self) -> np.ndarray:
        """The candidate pairs whose quantities may be nonzero at the last update (sorted);
        every assembly skips the others."""
        return self._require().rows

    @property
    def differentiated_columns(self) -> np.ndarray | None:
        """The stencil columns (slot * gdim + component, :attr:`pair_dofs`) on which the
        pairs' quantities may have nonzero derivatives, when fewer than all (None: all). On
        the undeformed surfaces (``configuration="reference"``) the integrals and normals
        are frozen and the weighted gaps are linear in the facets' own nodes: the slave and
        master facet nodes, in that order (the columns of :attr:`pair_force_dofs`); the
        normals' stars are read, never differentiated, and the Newton matrix gets no
        blocks of zeros for them."""
        stencil = self.stencil
        if self.configuration != "reference" or stencil is None:
            return None
        slots = np.concatenate([stencil.slave_slots, stencil.master_slots])
        if slots.size == stencil.width:
            return None
        return (slots[:, None] * self.gdim + np.arange(self.gdim)).reshape(-1)

    @property
    def pair_force_dofs(self) -> np.ndarray:
        """(n, (ns + nm) * gdim) displacement dofs of each pair's slave and master facet
        nodes: the rows of its force terms (-1: absent)."""
        stencil = self.stencil
        slots = np.concatenate([stencil.slave_slots, stencil.master_slots])
        return self.pair_dofs.reshape(-1, stencil.width, self.gdim)[:, slots, :].reshape(
            stencil.num_pairs, slots.size * self.gdim)

    def pair_force_dofs_of(self, rows: np.ndarray) -> np.ndarray:
        """(rows, (ns + nm) * gdim) the rows of :attr:`pair_force_dofs` of the pairs
        ``rows``, made from their facet nodes (a residual needs the contributing pairs'
        only)."""
        stencil = self.stencil
        slots = np.concatenate([stencil.slave_slots, stencil.master_slots])
        blocks = self._node_blocks[stencil.nodes[rows][:, slots]]
        dofs = blocks[:, :, None] * self.block_size + np.arange(self.gdim)
        return dofs.reshape(np.size(rows), slots.size * self.gdim)

    def force_coefficients(self, rows: np.ndarray) -> np.ndarray:
        """(rows, j, ns + nm nodes, gdim): B's entries of the pairs ``rows``, -Dn on the slave
        nodes and +Mn on the master nodes (the contact force is -B^T z)."""
        q = self._require()
        return np.concatenate([-q.Dn.value_of(rows), q.Mn.value_of(rows)], axis=2)

    def combined_gradients(self, rows: np.ndarray, terms) -> np.ndarray:
        """(len(terms), width * gdim, len(rows)): per row of ``terms`` (a list of (output,
        weight)), the sum of weight * d output / d x over the stencils of the pairs ``rows``
        (:mod:`stencils` numbers the outputs; a weight is a number or one per row)."""
        return self.stencil.combined_gradients(self._require(), rows, terms)

    def force_jacobian_terms(self, z_pair: np.ndarray) -> list:
        """The :meth:`combined_gradients` terms of d(-B^T z)/du at fixed z, one per force
        row (slave nodes, then master nodes, gdim components each); z_pair (rows, ns): the
        multipliers at the pairs' slave nodes."""
        stencil, gdim, js = self.stencil, self.gdim, range(self.stencil.ns)
        # -sum_j z_j d(coefficient_jkc): +Dn for the slave nodes, -Mn for the master nodes
        terms = [[(stencil.dn(j, k, c), z_pair[:, j]) for j in js]
                 for k in range(stencil.ns) for c in range(gdim)]
        terms += [[(stencil.mn(j, k, c), -z_pair[:, j]) for j in js]
                  for k in range(stencil.nm) for c in range(gdim)]
        return terms

    def _assemble_gradients(self, matrix: CooMatrix, rows: np.ndarray, terms) -> PETSc.Mat:
        """``matrix`` assembled from the combined gradients of ``terms`` (a row of the
        matrix block per term), ``assembly_chunk`` pairs at a time: in 3D their values on
        the stencil are ~1.2e4 numbers a pair for K."""
        if self.assembly_chunk is None:
            return matrix.assemble_groups(self.combined_gradients(rows, terms), rows)

        def values(start: int, stop: int) -> np.ndarray:
            if (start, stop) == (0, rows.size):
                return self.combined_gradients(rows, terms)
            part = [[(o, w if np.ndim(w) == 0 else w[start:stop]) for o, w in row]
                    for row in terms]
            return self.combined_gradients(rows[start:stop], part)

        return matrix.assemble_groups(values, rows, chunk=self.assembly_chunk)

    def mortar_matrices(self) -> tuple[PETSc.Mat, PETSc.Mat]:
        """D (multipliers x slave nodes) and M (multipliers x master nodes).

        Columns are global dof blocks of the displacement space (one per node). The
        matrices are the interface's: the next assembly overwrites them and a new search
        destroys them.
        """
        q = self._require()
        rows = q.rows
        sizes = (self._multiplier_sizes, self._block_sizes)
        D = self._block_matrix("D", "multipliers", "slave", (1, 1), *sizes)
        M = self._block_matrix("M", "multipliers", "master", (1, 1), *sizes)
        return (D.assemble_groups(q.D_rows.transpose(1, 2, 0), rows),
                M.assemble_groups(q.M_rows.transpose(1, 2, 0), rows))

    def weighted_gap(self, vector: PETSc.Vec | None = None) -> PETSc.Vec:
        """The weighted gaps g~_j in the multiplier layout."""
        q = self._require()
        rows = q.rows
        if vector is None:
            vector = self.create_multiplier_vector()
        vector.zeroEntries()
        vector.setValues(
            self.pair_multipliers[rows].reshape(-1).astype(PETSc.IntType),
            q.gap.value_rows.reshape(-1),
            addv=PETSc.InsertMode.ADD_VALUES,
        )
        vector.assemble()
        return vector

    # -- the same contributions as matrices of their own, for checks and benchmarks -------

    def gap_jacobian(self) -> PETSc.Mat:
        """G = d g~ / d u (multipliers x displacement dofs), exact: the solver's gap terms
        (:meth:`combined_gradients`) as a matrix of its own (overwritten by the next call,
        destroyed by a new search)."""
        rows = self.contributing_pairs()
        terms = [[(self.stencil.GAP + j, 1.0)] for j in range(self.stencil.ns)]
        matrix = self._block_matrix("G", "multipliers", "stencil", (1, self.gdim),
                                    self._multiplier_sizes, self._dof_sizes)
        return self._assemble_gradients(matrix, rows, terms)

    def constraint_matrix(self) -> PETSc.Mat:
        """B with B_j,(k,c) = -Dn_jk[c] (slave), +Mn_jl[c] (master) (:meth:`force_coefficients`
        as a matrix of its own).

        The contact force is -B^T z: slave nodes are pushed along -n by the
        pressure z >= 0, master nodes along +n (paper, eq. 1).
        """
        rows = self.contributing_pairs()
        values = self.force_coefficients(rows).transpose(1, 2, 3, 0)  # (j, k, c, n)
        matrix = self._block_matrix("B", "multipliers", "force", (1, self.gdim),
                                    self._multiplier_sizes, self._dof_sizes)
        return matrix.assemble_groups(values, rows)

    def force_jacobian(self, z: PETSc.Vec) -> PETSc.Mat:
        """d(-B(u)^T z)/du at fixed z (displacement dofs x displacement dofs): the solver's
        :meth:`force_jacobian_terms` as a matrix of its own."""
        rows = self.contributing_pairs()
        z_pair = self.node_values(z)[self.stencil.slave_nodes[rows]]  # (n, ns)
        matrix = self._block_matrix("K", "force", "stencil", (self.gdim, self.gdim),
                                    self._dof_sizes, self._dof_sizes)
        return self._assemble_gradients(matrix, rows, self.force_jacobian_terms(z_pair))

    def contact_force(self, z: PETSc.Vec, vector: PETSc.Vec) -> PETSc.Vec:
        """Add -B^T z to ``vector`` (displacement layout), without forming B. Collective."""
        if self.without_pairs:
            return vector
        rows = self.contributing_pairs()
        z_pair = self.node_values(z)[self.pair_slave_nodes[rows]]
        force = -np.einsum("nj,njkc->nkc", z_pair, self.force_coefficients(rows))
        vector.setValues(self.pair_force_dofs_of(rows).reshape(-1).astype(PETSc.IntType),
                         force.reshape(-1), addv=PETSc.InsertMode.ADD_VALUES)
        vector.assemble()
        return vector

    def destroy(self) -> None:
        for _, matrix in self._matrices.values():
            matrix.destroy()
        self._matrices.clear()
        self._pair_block_sides.clear()
