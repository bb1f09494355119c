"""The monolithic Newton matrix of a contact problem, [u | z_1 | z_2 ...] per rank.

The bulk Jacobian form is assembled in place; each candidate pair adds one
dense block (10 x 14 in 2D): rows are the 8 force dofs (slave a, b, master c, d)
and the 2 slave multipliers, columns the 12 pair dofs and the 2 multipliers.
Dirichlet rows and the multiplier rows' own diagonal (delta of the
enforcement) go on the diagonal. With friction (:mod:`dolfinx_mortar.friction`)
each pair also has a tangential multiplier field (fields P + 1 .. 2P of the
layout in 2D, P + 1 .. 3P in 3D: d - 1 per pair): the dense blocks grow by the
slave nodes' tangential rows and columns (2D: 12 x 16), and each tangential
row gets its own diagonal, one entry on its node's normal multiplier and, in
3D, one on the node's other tangential multiplier. Only the candidate pairs whose facets
overlap have blocks; the matrix and its pattern are rebuilt when a new search changed
the pairs (not on every search) or, on the current configuration, when a Newton iterate
makes a pair overlap that has none.
"""

from __future__ import annotations

import time
import typing

import dolfinx
import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from . import compat
from .friction import coefficient_names
from .kernels import compiled
from .layout import BlockLayout, ChunkedValues, MonolithicMatrix

if typing.TYPE_CHECKING:
    from .enforcement import Rows
    from .mortar import MortarInterface


class Tangential(typing.NamedTuple):
    """What the matrix needs of friction: a callable k -> :class:`~dolfinx_mortar.friction.
    TangentialRows` (the tangential conditions of pair k's owned slave nodes), du =
    u - u_start at each pair's node table, and callables k -> y^a at the node table
    (collective) and (k, pairs) -> those pairs' :class:`~dolfinx_mortar.friction.PairTangents`."""

    conditions: typing.Callable
    increments: list
    node_multipliers: typing.Callable
    tangents: typing.Callable


class ContactSystem:
    """Pattern, assembly and lifetime of the monolithic matrix (see the module docstring).

    Args:
        V: the displacement space.
        layout: the monolithic numbering.
        interfaces: one per contact pair; field k + 1 of the layout.
        K: a matrix of the bulk Jacobian's pattern (its CSR structure is read once).
        J_form, bcs: the bulk Jacobian form and Dirichlet conditions.
        fixed_dofs: the local Dirichlet dofs (may include a few owned elsewhere).
        dirichlet_scale: the diagonal of Dirichlet rows (force units, module
            docstring of :mod:`dolfinx_mortar.enforcement`).
        tangential_components: tangential multiplier fields per pair (d - 1 with
            friction, 0 without).
    """

    def __init__(self, V: dolfinx.fem.FunctionSpace, layout: BlockLayout,
                 interfaces: list[MortarInterface], K: PETSc.Mat, J_form, bcs: list,
                 fixed_dofs: np.ndarray, dirichlet_scale: float, tangential_components: int = 0):
        self.comm = layout.comm
        self.components = tangential_components
        self.friction = tangential_components > 0
        self.interfaces = interfaces
        self.J_form = J_form
        self.bcs = bcs
        self.dirichlet_scale = dirichlet_scale
        self.matrix: MonolithicMatrix | None = None
        self._versions: tuple = ()
        self._pattern = None
        self._pairs: list[np.ndarray | None] = [None] * len(interfaces)
        indptr, indices, _ = K.getValuesCSR()
        index_map, bs = V.dofmap.index_map, V.dofmap.index_map_bs
        blocks = index_map.local_to_global(
            np.arange(index_map.size_local + index_map.num_ghosts, dtype=np.int32))
        local_dofs = (blocks[:, None] * bs + np.arange(bs)).reshape(-1)
        # the bulk pattern's columns are kept once, numbered by the current layout, and a
        # block's once (a ninth of them in 3D)
        blocks = compiled.pattern_blocks(indptr, indices, bs)
        if blocks is None:
            self._bulk = ((indptr.astype(np.int64), indices, 1), local_dofs)
        else:
            self._bulk = ((*blocks, bs), local_dofs)
        del indptr, indices, blocks
        self._fixed_dofs = fixed_dofs
        self.layout = None
        self.set_layout(layout, [True] * len(interfaces))
        # per pair, ghosted multiplier-layout vectors that carry the row coefficients of the
        # owned slave nodes to the ghost slave nodes (collective)
        names = ("gap_coefficient", "area_coefficient") + coefficient_names(
            tangential_components)
        self._coefficient_vectors = [{name: i.create_multiplier_vector() for name in names}
                                     for i in interfaces]

    def set_layout(self, layout: BlockLayout, in_layout: list[bool]) -> None:
        """Number the matrix by ``layout``, in which the pairs k with ``in_layout[k]``
        False have no multiplier rows (the next assembly builds a new matrix).
        Collective."""
        (indptr, columns, block), local_dofs = self._bulk
        if self.layout is not None:  # (monolithic indices of the old layout)
            columns = self.layout.u_global(columns, PETSc.IntType)
            local_dofs = self.layout.u_global(local_dofs)
        self._bulk = None
        self._bulk = ((indptr, layout.u(columns, PETSc.IntType), block), layout.u(local_dofs))
        del columns
        self.layout = layout
        self.in_layout = list(in_layout)
        fixed = layout.u(self._fixed_dofs)
        # (dirichlet_dofs may list a few dofs owned by another rank; their owner has them too)
        first = int(layout.offsets[self.comm.rank])
        fixed = fixed[(fixed >= first) & (fixed < first + layout.num_u[self.comm.rank])]
        self.fixed_rows = fixed
        self._fixed_all = np.unique(np.concatenate(self.comm.allgather(fixed)))
        if self.matrix is not None:
            self.matrix.destroy()
            self.matrix = None
        self._versions, self._pattern = (), None

    @property
    def mat(self) -> PETSc.Mat:
        return self.matrix.mat

    def tangential_field(self, k: int, a: int = 0) -> int:
        """The layout field of pair k's tangential multipliers y^a."""
        return len(self.interfaces) + 1 + k * self.components + a

    def assemble(self, multipliers: list[PETSc.Vec], coefficient_vectors: list[dict] | None,
                 enforcement_rows: typing.Callable[[int], Rows],
                 tangential: Tangential | None = None) -> tuple[bool, float, float]:
        """Assemble the matrix at the current contact state.

        Args:
            multipliers: the multiplier vectors, one per pair.
            coefficient_vectors: unused (the system scatters the row coefficients through
                vectors of its own); kept for the callers of the old signature.
            enforcement_rows: pair k -> the enforcement's multiplier rows (residual,
                alpha, beta, delta).
            tangential: with friction, the tangential conditions, slip increments,
                multipliers and coefficients (:class:`Tangential`).

        Returns:
            (whether the matrix was rebuilt, seconds on contact, seconds on the bulk).
        """
        start = time.perf_counter()
        rebuilt = self._update_pattern()
        zeroing = time.perf_counter()
        self.matrix.mat.zeroEntries()
        zeroing = time.perf_counter() - zeroing
        parts, groups = [], []
        offset = given = 0
        normal_conditions = [enforcement_rows(k) if present else None
                             for k, present in enumerate(self.in_layout)]
        conditions = ([tangential.conditions(k) for k in range(len(self.interfaces))]
                      if self.friction else None)
        for k in range(len(self.interfaces)):
            friction = None
            if self.friction:
                friction = (tangential, conditions[k])
            blocks = self._contact_blocks(k, multipliers[k], normal_conditions[k], friction)
            if blocks is not None:
                contributing, pair_parts = blocks
                for values, which, columns in pair_parts:
                    values = _padded_rows(values, self._block_shape[0])
                    which = given + (np.arange(contributing.size) if which is None else which)
                    parts.append((values, which, columns))
                groups.append(offset + self._groups(k, contributing))
                given += contributing.size
            offset += self._pattern[0][k].shape[0]
        if len(groups) == 1:  # (one pair's groups: all of them in every part)
            parts = [(values, None if which.size == groups[0].size else which, columns)
                     for values, which, columns in parts]
        groups = np.concatenate(groups) if groups else np.zeros(0, dtype=np.int64)
        diagonal = [np.full(self.fixed_rows.size, self.dirichlet_scale)] + [
            r[3] for r, present in zip(normal_conditions, self.in_layout, strict=True)
            if present]
        if self.friction:
            # (the order of _update_pattern's diagonal rows and point entries)
            m = self.components
            conditions = [r for r, present in zip(conditions, self.in_layout, strict=True)
                          if present]
            diagonal += [r.own[:, a, a] for r in conditions for a in range(m)]
            diagonal += [r.normal[:, a] for r in conditions for a in range(m)]
            diagonal += [r.own[:, a, b] for r in conditions for a in range(m)
                         for b in range(m) if a != b]
        diagonal = np.concatenate(diagonal)
        matrix = self.matrix.mat
        self.matrix.add(groups, parts, diagonal)
        contact = time.perf_counter() - start - zeroing
        start = time.perf_counter()
        compat.add_matrix_local(matrix, self.J_form, self.bcs)
        matrix.assemble()
        return rebuilt, contact, time.perf_counter() - start + zeroing

    def _contact_pattern(self, k: int, grown: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Monolithic rows (n, (ns + nm) gdim + ns) and columns (n, width gdim + ns) of pair
        k's dense block per pair of :meth:`_pattern_pairs` (2D: 10 x 14; on the undeformed
        surfaces the displacement columns of
        :attr:`~dolfinx_mortar.mortar.MortarInterface.differentiated_columns` only); rows of
        Dirichlet dofs are dropped (-1), they are identity rows."""
        interface = self.interfaces[k]
        if interface.quantities is None or interface.without_pairs or not self.in_layout[k]:
            self._pairs[k] = None
            return np.zeros((0, 0), dtype=PETSc.IntType), np.zeros((0, 0), dtype=PETSc.IntType)
        pairs = self._pattern_pairs(k, grown)
        every = pairs is None
        layout = self.layout
        force_dofs = layout.u(interface.pair_force_dofs if every
                              else interface.pair_force_dofs_of(pairs))
        force_dofs[np.isin(force_dofs, self._fixed_all)] = -1
        node_multipliers = interface.pair_multipliers
        node_multipliers = node_multipliers if every else node_multipliers[pairs]
        multipliers = [layout.z(node_multipliers, k + 1)]
        multipliers += [layout.z(node_multipliers, self.tangential_field(k, a))
                        for a in range(self.components)]
        displacement_dofs = interface.pair_dofs if every else interface.pair_dofs_of(pairs)
        kept = interface.differentiated_columns
        if kept is not None:
            displacement_dofs = displacement_dofs[:, kept]
        # (PETSc's integers: kept until the next build, as wide as the pairs' blocks)
        row_indices = np.concatenate([force_dofs] + multipliers, axis=1)
        column_indices = np.concatenate([layout.u(displacement_dofs)] + multipliers, axis=1)
        self._pairs[k] = pairs
        return row_indices.astype(PETSc.IntType), column_indices.astype(PETSc.IntType)

    def _pattern_pairs(self, k: int, grown: bool = False) -> np.ndarray | None:
        """The candidate pairs of interface k that get a block in the pattern (sorted; None:
        every candidate): those whose facets overlap (a sixth of the candidates on gmsh's
        tetrahedra: fewer entries to preallocate, look up, sum and factorize). On the
        undeformed surfaces (``configuration="reference"``) only a new search changes
        them; on the current ones a Newton iterate may make more pairs overlap: ``grown``,
        the pattern's pairs and those (:meth:`_outgrown`)."""
        contributing = self.interfaces[k].contributing_pairs()
        if not grown or self._pairs[k] is None:
            return contributing
        return np.union1d(self._pairs[k], contributing)

    def _outgrown(self) -> bool:
        """Whether some pair overlaps that the pattern has no block for (an iterate of the
        current configuration moved a slave facet over another master facet). Collective."""
        outgrown = False
        for k, interface in enumerate(self.interfaces):
            pairs = self._pairs[k]
            if (pairs is None or interface.quantities is None or interface.without_pairs
                    or not self.in_layout[k]):
                continue
            contributing = interface.contributing_pairs()
            position = np.minimum(np.searchsorted(pairs, contributing), max(pairs.size - 1, 0))
            outgrown |= bool(contributing.size) and (
                pairs.size == 0 or not np.array_equal(pairs[position], contributing))
        return bool(self.comm.allreduce(outgrown, op=MPI.LOR))

    def _groups(self, k: int, contributing: np.ndarray) -> np.ndarray:
        """The pattern's groups (blocks) of interface k's contributing pairs."""
        pairs = self._pairs[k]
        if pairs is None:
            return contributing
        position = np.searchsorted(pairs, contributing)
        if contributing.size and (position[-1] >= pairs.size
                                  or not np.array_equal(pairs[position], contributing)):
            raise RuntimeError("a pair overlaps that the Newton matrix's pattern has no block "
                               "for")
        return position

    def _update_pattern(self) -> bool:
        """(Re)build the matrix when a search changed the pairs or a pair overlaps that the
        pattern has no block for; True if it was rebuilt."""
        versions = tuple(i._pattern_version for i in self.interfaces)
        grown = self.matrix is not None and versions == self._versions
        if grown and not self._outgrown():
            return False
        layout = self.layout
        pattern = [self._contact_pattern(k, grown) for k in range(len(self.interfaces))]
        # pairs of different interfaces may have blocks of different shapes: pad with -1
        self._block_shape = tuple(max([p[i].shape[1] for p in pattern] + [0]) for i in range(2))
        pattern = tuple(zip(*([_pad(p[i], self._block_shape[i]) for i in range(2)]
                              for p in pattern), strict=True))
        self._versions = versions
        old = self._pattern
        same = self.matrix is not None and old is not None and all(
            np.array_equal(a, b) for a, b in zip(old[0] + old[1], pattern[0] + pattern[1],
                                                 strict=True))
        if self.comm.allreduce(same, op=MPI.LAND):
            return False  # a search found the same pairs (or none again): keep the matrix
        owned = [i.multiplier_offset + np.arange(i.num_owned_multipliers if present else 0)
                 for i, present in zip(self.interfaces, self.in_layout, strict=True)]
        normal_indices = [layout.z(o, k + 1) for k, o in enumerate(owned)]
        diagonal_indices = [self.fixed_rows] + normal_indices
        point_entries = None
        if self.friction:
            m = self.components
            tangential_indices = [[layout.z(o, self.tangential_field(k, a)) for a in range(m)]
                                  for k, o in enumerate(owned)]
            diagonal_indices += [t for pair in tangential_indices for t in pair]
            # each tangential row on its node's normal multiplier, then on its other ones
            others = [(pair[a], pair[b]) for pair in tangential_indices for a in range(m)
                      for b in range(m) if a != b]
            point_entries = (
                np.concatenate([t for pair in tangential_indices for t in pair]
                               + [r for r, _ in others]),
                np.concatenate([normal_indices[k] for k, pair in enumerate(tangential_indices)
                                for _ in pair] + [c for _, c in others]))
        if self.matrix is not None:
            self.matrix.destroy()
        bulk_pattern, local_to_global = self._bulk
        self.matrix = MonolithicMatrix(
            self.comm, (layout.num_owned, layout.num_global), local_to_global, bulk_pattern,
            np.concatenate(pattern[0]), np.concatenate(pattern[1]),
            np.concatenate(diagonal_indices), point_entries)
        self._pattern = pattern
        return True

    def _contact_blocks(self, k: int, z: PETSc.Vec, normal_condition: Rows, friction=None):
        """The candidate pairs (m,) of pair k that contribute, and their dense blocks in parts
        (values, which of them, block columns), as :meth:`MonolithicMatrix.add` takes them.

        d(-B^T z)/du, d(-B^T z)/dz = -B^T, d C/du (2D: 8 x 12, 8 x 2, 2 x 12); with
        friction also d(-T^T y)/du, -T^T and the tangential conditions' d C_t/du
        (:class:`~dolfinx_mortar.friction.PairTangents`). Only the
        pairs that contribute, from the kernel's gradients of those pairs (no full dual
        numbers over every candidate pair). The derivatives in u are a part of their own,
        of the pairs with a weight only (a slave node with a multiplier, a gap or an area
        coefficient); -B^T and -T^T (and friction's direct slip derivative) are a part over
        all contributing pairs, on their columns only.
        None before the first evaluation (no pairs yet).
        """
        interface = self.interfaces[k]
        if interface.quantities is None or interface.without_pairs or not self.in_layout[k]:
            return None  # (the same on every rank: no collective call below is skipped alone)
        contributing = interface.contributing_pairs()
        z_nodes = interface.node_values(z)
        _, alpha, beta, _ = normal_condition
        alpha_nodes, beta_nodes = self._at_nodes(
            k, {"gap_coefficient": alpha, "area_coefficient": beta}).values()
        if friction is not None:
            tangential, conditions = friction
            m = self.components
            coefficient_nodes = self._at_nodes(k, _slip_coefficients(conditions, m))
            y_nodes = tangential.node_multipliers(k)  # (collective: before any early return)
        if contributing.size == 0:
            return None
        stencil, gdim = interface.stencil, interface.gdim
        ns = stencil.ns
        slave_nodes = stencil.slave_nodes[contributing]
        z_pair, alpha_pair, beta_pair = (
            v[slave_nodes] for v in (z_nodes, alpha_nodes, beta_nodes))
        js = range(ns)
        force_terms = interface.force_jacobian_terms(z_pair)  # slave nodes, then master nodes
        multiplier_terms = [[(stencil.GAP + j, alpha_pair[:, j]),
                             (stencil.AREA + j, beta_pair[:, j])] for j in js]
        num_multipliers = ns
        if friction is not None:
            tangents = tangential.tangents(k, contributing)
            y_pair = np.stack([y[slave_nodes] for y in y_nodes], axis=1)  # (pairs, a, j)
            slave_extra, master_extra = tangents.force_terms(y_pair)
            for row, extra in zip(force_terms, slave_extra + master_extra, strict=True):
                row += extra
            coefficient = {name: values[slave_nodes]
                           for name, values in coefficient_nodes.items()}
            du_table = tangential.increments[k]
            du_slave = du_table[slave_nodes]
            du_master = du_table[stencil.master_nodes[contributing]]
            # row (a, j): sum_b dC^a/du~^b du~^b_j + dC^a/dg~ dg~_j + dC^a/dA dA_j
            multiplier_terms += [
                [term for b in range(m) for term in tangents.slip_terms(
                    j, b, du_slave, du_master, coefficient[f"slip_{a}{b}"][:, j])]
                + [(stencil.GAP + j, coefficient[f"slip_gap_{a}"][:, j]),
                   (stencil.AREA + j, coefficient[f"slip_area_{a}"][:, j])]
                for a in range(m) for j in js]
            num_multipliers = (1 + m) * ns
        terms = force_terms + multiplier_terms
        kept = interface.differentiated_columns
        columns = stencil.width * gdim if kept is None else kept.size
        parts = []
        weighted = _weighted_rows(terms, contributing.size)
        if weighted.size:
            every = weighted.size == contributing.size
            rows = contributing if every else contributing[weighted]
            parts.append((_chunked_gradients(interface, rows, terms,
                                             None if every else weighted, kept),
                          None if every else weighted, np.arange(columns)))
        multiplier_columns = np.arange(columns, columns + num_multipliers)
        force_columns = np.zeros(0, dtype=np.int64)
        if friction is not None:
            slots = np.concatenate([stencil.slave_slots, stencil.master_slots])
            force_columns = (slots[:, None] * gdim + np.arange(gdim)).reshape(-1)
            if kept is not None:
                position = np.full(stencil.width * gdim, -1)
                position[kept] = np.arange(kept.size)
                force_columns = position[force_columns]
        tangential_part = None if friction is None else (tangents.coefficients, coefficient)
        parts.append((_coefficient_values(interface, contributing, num_multipliers,
                                          force_columns.size, tangential_part),
                      None, np.concatenate([force_columns, multiplier_columns])))
        return contributing, parts

    def _at_nodes(self, k: int, owned: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Per name, owned slave-node values of pair k at its node table, through the
        system's ghosted vector of that name (collective)."""
        interface, vectors = self.interfaces[k], self._coefficient_vectors[k]
        result = {}
        for name, values in owned.items():
            vectors[name].getArray()[:] = values
            result[name] = interface.node_values(vectors[name])
        return result

    def destroy(self) -> None:
        if self.matrix is not None:
            self.matrix.destroy()
            self.matrix = None
        for vectors in self._coefficient_vectors:
            for vector in vectors.values():
                vector.destroy()
        self._coefficient_vectors = []


def _chunked_gradients(interface, rows: np.ndarray, terms, selected: np.ndarray | None = None,
                       columns: np.ndarray | None = None) -> ChunkedValues:
    """The combined gradients of ``terms`` at the pairs ``rows``, made
    ``interface.assembly_chunk`` pairs at a time as the matrix sums them: the blocks of every
    weighted pair together were the largest transient of a frictional Jacobian's assembly
    on the rank holding the contact zone. Each pair's gradients are its own, so the sums
    do not depend on the chunk. ``selected``: the rows' places in the terms' weights (None:
    in order), taken a chunk at a time too; ``columns``: the stencil columns kept (None:
    all)."""
    def gradients(start: int, stop: int) -> np.ndarray:
        where = slice(start, stop) if selected is None else selected[start:stop]
        result = interface.combined_gradients(
            rows[start:stop], [[(o, w if np.ndim(w) == 0 else w[where]) for o, w in row]
                               for row in terms])
        return result if columns is None else result[:, columns]
    return ChunkedValues(gradients, interface.assembly_chunk)


def _coefficient_values(interface, contributing: np.ndarray, num_multipliers: int,
                        first: int, tangential: tuple | None) -> ChunkedValues:
    """The contributing pairs' -B^T (force rows, normal multipliers' columns) and, with
    friction (``tangential``: T and the slip coefficients), -T^T and the slip's direct
    derivative, made a chunk of pairs at a time. Columns: ``first`` facet displacement
    columns (with friction), then the multipliers'."""
    coefficients = interface.force_coefficients(contributing)  # (m, j, k, c)
    ns = coefficients.shape[1]
    forces = coefficients.shape[2] * coefficients.shape[3]

    def values(start: int, stop: int) -> np.ndarray:
        block = np.zeros((forces + num_multipliers, first + num_multipliers, stop - start))
        block[:forces, first:first + ns] = -coefficients[start:stop].reshape(
            stop - start, ns, forces).transpose(2, 1, 0)
        if tangential is not None:
            T, coefficient = tangential
            _add_tangential_columns(block, T[start:stop],
                                    {name: c[start:stop] for name, c in coefficient.items()},
                                    ns, first)
        return block
    return ChunkedValues(values, interface.assembly_chunk)


def _weighted_rows(terms, n: int) -> np.ndarray:
    """The rows (of ``n``) where some term has a nonzero weight. The combined gradients of
    the others are zero (they are linear in the weights): the pairs whose slave nodes are
    all inactive, with zero multipliers and zero gap and area coefficients, whose kernel
    gradients are then never made."""
    weighted = np.zeros(n, dtype=bool)
    for row in terms:
        for _, weight in row:
            if np.ndim(weight) == 0:
                if weight != 0.0:
                    return np.arange(n)
            else:
                weighted |= np.asarray(weight) != 0.0
    return np.flatnonzero(weighted)


def _slip_coefficients(conditions, m: int) -> dict[str, np.ndarray]:
    """The owned coefficients of the tangential conditions that the pairs' blocks need at
    the slave nodes, by the names of :func:`~dolfinx_mortar.friction.coefficient_names`."""
    names = {}
    for a in range(m):
        for b in range(m):
            names[f"slip_{a}{b}"] = conditions.slip[:, a, b]
        names[f"slip_gap_{a}"] = conditions.gap[:, a]
        names[f"slip_area_{a}"] = conditions.area[:, a]
    return names


def _add_tangential_columns(values: np.ndarray, T: np.ndarray, coefficient: dict, ns: int,
                            first: int) -> None:
    """Into the pairs' blocks ``values`` (rows: forces, then the multipliers; columns: the
    facet nodes' displacements, ``first`` of them, then the multipliers): -T^T (the force
    rows on the tangential multipliers' columns) and the slip's direct derivative -T^a_j on
    the facet nodes' columns of the tangential rows. T (pairs, m, j, nodes, gdim)."""
    pairs, m = T.shape[0], T.shape[1]
    forces = first
    for a in range(m):
        tangent = T[:, a].reshape(pairs, ns, forces)
        block = first + (1 + a) * ns
        values[:forces, block:block + ns] = -tangent.transpose(2, 1, 0)
        # u~^a_j = -T^a_j du: its direct derivative -T^a_j on the facet nodes' columns
        for b in range(m):
            weight = coefficient[f"slip_{b}{a}"]  # dC^b/du~^a, (pairs, j)
            direct = -tangent * weight[:, :, None]
            row = forces + (1 + b) * ns
            values[row:row + ns, :first] += direct.transpose(1, 2, 0)


def _padded_rows(values, rows: int):
    """A part's values (or its :class:`ChunkedValues`) with zero rows appended up to
    ``rows``: the blocks of a pair whose blocks have fewer rows than another pair's."""
    def padded(array: np.ndarray) -> np.ndarray:
        if array.shape[0] == rows:
            return array
        result = np.zeros((rows,) + array.shape[1:])
        result[:array.shape[0]] = array
        return result
    if isinstance(values, ChunkedValues):
        return ChunkedValues(lambda start, stop: padded(values(start, stop)), values.chunk)
    return padded(values)


def _pad(indices: np.ndarray, width: int) -> np.ndarray:
    """(n, width) indices: ``indices`` with columns of -1 (dropped entries) appended."""
    if indices.shape[1] == width:
        return indices
    padded = np.full((indices.shape[0], width), -1, dtype=indices.dtype)
    padded[:, :indices.shape[1]] = indices
    return padded
