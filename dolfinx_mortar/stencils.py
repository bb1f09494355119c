"""Pair stencils: what one kernel needs of each (slave facet, master facet) pair.

:class:`~dolfinx_mortar.mortar.MortarInterface` is dimension-free: after a
search it has a node table (this rank's slave and master nodes and the facets
other ranks sent, each node with its global dof block and coordinates) and
candidate pairs. A stencil turns those into the arrays its kernel takes,
calls the kernel, and expresses the derivatives on the pair's *stencil*: the
nodes whose coordinates the pair's quantities depend on, slave facet nodes
first, then master facet nodes, then whatever else enters (the nodes of the
slave normals). Everything above sees ``slots`` and ``width``, never
"six nodes p, a, b, q, c, d".

Every stencil calls its kernel through the one contract of
:mod:`dolfinx_mortar.kernels` (:class:`~dolfinx_mortar.kernels.MortarKernel`: a
:class:`~dolfinx_mortar.kernels.PairGeometry` in, a
:class:`~dolfinx_mortar.kernels.PairQuantities` out); what differs per dimension
lives in one class each, chosen once by :data:`STENCILS`:

- :class:`Line2Stencil`: 2D, the stencil ``p, a, b, q, c, d`` of
  :mod:`~dolfinx_mortar.kernels.line2`, whose gradients are already on it
  (:class:`~dolfinx_mortar.kernels.PairGradients`, the compiled kernel's
  :class:`~dolfinx_mortar.kernels.line2_compiled.FullGradients`).
- :class:`Surface3Stencil`: 3D, slave facet nodes, master facet nodes and, per
  slave node, the nodes of its averaged normal's star; the kernel
  :mod:`~dolfinx_mortar.kernels.surface3` differentiates with respect to the
  nodal normals, which are chained here with the normals' own derivatives
  (:mod:`~dolfinx_mortar.normals`).

Outputs of a pair are numbered alike in both dimensions: ``Dn`` (j, k, c) first,
then ``Mn`` (j, l, c), ``area`` (j), ``gap`` (j); ``D`` (j, k) and ``M`` (j, l) when
the kernel kept their gradients (in 2D the gradients always hold D's),
then the slave nodal normals (j, c), kernel variables in 3D
(:meth:`PairStencil.dn` and its siblings).
"""

from __future__ import annotations

import numpy as np

from . import normals as normals_module
from .dual import RowSubsetDual, rows_of
from .kernels import (
    NUM_PAIR_VARIABLES,
    KernelOptions,
    Line2Kernel,
    MortarKernel,
    PairGeometry,
    PairQuantities,
    Surface3Kernel,
    compiled,
)
from .kernels.contract import IndexedPairGeometry


def lookup(keys: np.ndarray, values: np.ndarray, queries: np.ndarray):
    """values[i] for keys[i] == query, and whether it was found (first match)."""
    if keys.size == 0:
        return np.zeros_like(queries), np.zeros(queries.shape, dtype=bool)
    order = np.argsort(keys, kind="stable")
    sorted_keys = keys[order]
    position = np.clip(np.searchsorted(sorted_keys, queries), 0, keys.size - 1)
    found = sorted_keys[position] == queries
    return values[order[position]], found


def _gradient_rows(item: RowSubsetDual, rows: np.ndarray) -> np.ndarray:
    """The gradients of ``rows`` of a :class:`RowSubsetDual`, without building its full
    gradient."""
    return rows_of(item.grad_rows, item.rows, rows)


def _add_combined(result: np.ndarray, grad: np.ndarray, entries: list) -> None:
    """result (terms, rows, nv) += weight * grad[:, index, :] into row p of result for each
    (p, index, weight) of ``entries`` (a weight is a number or one per row), in C: one pass
    over the rows of grad (rows, outputs, nv)."""
    n, size, nv = grad.shape
    if n == 0 or not entries:
        return
    term = np.array([p for p, _, _ in entries], dtype=np.intc)
    index = np.array([i for _, i, _ in entries], dtype=np.intc)
    weight_start, step, weights = compiled.packed_weights([w for _, _, w in entries], n)
    grad = np.ascontiguousarray(grad, dtype=np.float64)
    module = compiled.load("surface3")
    ffi = module.ffi

    def pointer(array, ctype="double *"):
        return compiled._pointer(ffi, array, ctype)

    status = module.lib.gradients_combine(
        n, nv, size, pointer(grad), len(entries), pointer(term, "int *"),
        pointer(index, "int *"), pointer(weight_start, "long *"), pointer(step, "int *"),
        pointer(weights), pointer(result))
    if status != 0:
        raise ValueError(f"an output index outside the {size} of its family")


class PairStencil:
    """The pairs of one search and their stencils (base of the per-dimension classes).

    Attributes:
        gdim: geometric dimension.
        ns, nm: nodes per slave and master facet.
        nodes: (n, width) node-table index of each stencil slot (always a valid
            index, for gathering coordinates).
        present: (n, width) whether the slot is a real node (columns of the
            Jacobians skip the others).
        slave_facets: (n,) local slave facet of each pair.
        widenings: how often the pattern was widened since the search (only the covered
            dual basis widens it, :class:`~dolfinx_mortar.covered.CoveredStencil`).
    """

    gdim: int
    ns: int
    nm: int
    kernel: MortarKernel
    widenings: int = 0
    search_margin: float
    """The default search margin in mean slave edge lengths (3D: the number of candidate
    pairs grows with its square)."""
    search_growth: float
    """How much each search box grows, in margins. Half a margin is what the reuse of a
    search needs (boxes that overlap now were within one margin at the search, since each
    side moved at most half of it); 2D grows by a whole margin, so that surfaces closing
    in are paired a step earlier (the crushed ring of tests/test_self_contact.py needs a
    cut-back otherwise), 3D by half (the candidates grow with its square, and the
    contributing pairs of the benchmarks stay the same: docs/benchmarks.md)."""
    search_depth: float
    """How far behind each facet (into its body) its search box reaches, in margins."""
    assembly_chunk: int | None
    """Pairs whose gradient blocks are formed at once in an assembly (None: all). In 3D a
    frictional Newton matrix's block of a pair is 27 rows by up to some 200 columns: 512
    pairs' blocks are about 20 MB."""

    def __init__(self, nodes: np.ndarray, present: np.ndarray, slave_facets: np.ndarray):
        self.nodes = nodes
        self.present = present
        self.slave_facets = slave_facets
        self.slave_surface: SlaveSurfaceStars | None = None
        """3D: the slave surface's stars, for the next search's stencil"""

    @classmethod
    def build(cls, node_blocks: np.ndarray, node_x: np.ndarray, all_slave_facets: np.ndarray,
              local_slave_facets: np.ndarray, all_master_facets: np.ndarray, pairs: np.ndarray,
              *, normals: str = "averaged", nodal_frames: bool = False,
              slave_surface: SlaveSurfaceStars | None = None) -> PairStencil:
        """Stencils of ``pairs`` (local slave facet, index into ``all_master_facets``).

        Args:
            node_blocks, node_x: global dof block and coordinates of each node-table row.
            all_slave_facets: the slave facets known here (this rank's, then those other
                ranks sent), as node-table rows; local_slave_facets: this rank's.
            all_master_facets: the master facets known here.
            pairs: (n, 2) candidate pairs.
            normals: the normal option (3D: the averaged normals' stars enter the stencil).
            nodal_frames: 3D: the stars also with the ``slave`` and ``master`` options
                (friction's tangent frames are built on the averaged normals).
            slave_surface: 3D, the last search's :class:`SlaveSurfaceStars`, taken over
                while it describes the same surface.
        """
        raise NotImplementedError

    @property
    def num_pairs(self) -> int:
        return self.nodes.shape[0]

    @property
    def width(self) -> int:
        return self.nodes.shape[1]

    @property
    def slave_slots(self) -> np.ndarray:
        raise NotImplementedError

    @property
    def master_slots(self) -> np.ndarray:
        raise NotImplementedError

    @property
    def slave_nodes(self) -> np.ndarray:
        """(n, ns) node-table indices of the slave facet nodes."""
        return self.nodes[:, self.slave_slots]

    @property
    def master_nodes(self) -> np.ndarray:
        return self.nodes[:, self.master_slots]

    # output numbering
    @property
    def DN(self) -> int:  # noqa: N802
        return 0

    @property
    def MN(self) -> int:  # noqa: N802
        return self.ns * self.ns * self.gdim

    @property
    def AREA(self) -> int:  # noqa: N802
        return self.MN + self.ns * self.nm * self.gdim

    @property
    def GAP(self) -> int:  # noqa: N802
        return self.AREA + self.ns

    @property
    def D(self) -> int:  # noqa: N802
        return self.GAP + self.ns

    @property
    def M(self) -> int:  # noqa: N802
        return self.D + self.ns * self.ns

    @property
    def NORMAL(self) -> int:  # noqa: N802
        return self.M + self.ns * self.nm

    def dn(self, j: int, k: int, c: int) -> int:
        return self.DN + (j * self.ns + k) * self.gdim + c

    def mn(self, j: int, l: int, c: int) -> int:  # noqa: E741
        return self.MN + (j * self.nm + l) * self.gdim + c

    def d(self, j: int, k: int) -> int:
        return self.D + j * self.ns + k

    def m(self, j: int, l: int) -> int:  # noqa: E741
        return self.M + j * self.nm + l

    def normal(self, j: int, c: int) -> int:
        """The output number of component c of slave node j's nodal normal (a kernel
        variable: its gradient is one on that variable)."""
        return self.NORMAL + j * self.gdim + c

    def _normal_variable(self, q: PairQuantities, index: int) -> int | None:
        """The kernel variable of nodal normal component ``index`` (j gdim + c), None where
        the normals are not variables."""
        return None

    # kernel variables of the slave and master coordinates (reference configuration)
    slave_variables: np.ndarray
    master_variables: np.ndarray
    num_variables: int

    def evaluate(self, node_x: np.ndarray, options: KernelOptions,
                 crosspoint: np.ndarray | None = None) -> PairQuantities:
        """Every pair's quantities at the node-table coordinates ``node_x`` (crosspoint:
        (n, ns) slave nodes without a multiplier)."""
        raise NotImplementedError

    def _kernel_gradients(self, q: PairQuantities, rows: np.ndarray, terms) -> np.ndarray:
        """(len(terms), num_variables, len(rows)) on the kernel's own variables."""
        return np.ascontiguousarray(self._row_gradients(q, rows, terms).transpose(0, 2, 1))

    def _row_gradients(self, q: PairQuantities, rows: np.ndarray, terms) -> np.ndarray:
        """(len(terms), len(rows), num_variables): per row of ``terms``, the weighted sum of
        the outputs' gradients over the kernel's own variables, without first copying
        every output's gradient into one array (in 3D they are ~1,600 numbers a pair)."""
        nv = self.num_variables
        outputs = q.outputs()
        sizes = [int(np.prod(item.shape[1:])) for item in outputs]
        starts = np.cumsum([0] + sizes[:-1])
        end = int(starts[-1]) + sizes[-1]
        result = np.zeros((len(terms), rows.size, nv))
        entries: dict[int, list] = {}  # per output family: (term, index in it, weight)
        for p, row in enumerate(terms):
            for o, weight in row:
                if o >= self.NORMAL:
                    variable = self._normal_variable(q, o - self.NORMAL)
                    if variable is not None:
                        result[p, :, variable] += weight
                    continue
                if o >= end:
                    raise ValueError(f"output {o} was not kept by the kernel")
                part = int(np.searchsorted(starts, o, side="right")) - 1
                if outputs[part].constant:
                    continue  # (zero gradients: the reference configuration's integrals)
                entries.setdefault(part, []).append((p, o - int(starts[part]), weight))
        made = None  # the kernel's gradients of rows, made again
        if q.gradients_on_demand is not None and entries:
            made = q.gradients_on_demand.gradients(rows, sorted(entries))
        for part, family in entries.items():
            grad = made[part] if made is not None else _gradient_rows(outputs[part], rows)
            _add_combined(result, grad.reshape(rows.size, sizes[part], nv), family)
        return result

    def combined_gradients(self, q: PairQuantities, rows: np.ndarray, terms) -> np.ndarray:
        """(len(terms), width * gdim, len(rows)): per row of ``terms``, the sum of
        weight * d output / d x over the stencil (a weight is a number or one per row)."""
        raise NotImplementedError


class Line2Stencil(PairStencil):
    """2D pairs: the six nodes ``p, a, b, q, c, d`` of :mod:`~dolfinx_mortar.kernels.line2`.

    ``p`` and ``q`` (the other ends of the slave facets meeting at ``a`` and
    ``b``) enter the averaged normals; where a slave facet has no neighbour
    they are absent (``has_neighbour``) and point at ``a`` or ``b``.
    """

    gdim, ns, nm = 2, 2, 2
    kernel = Line2Kernel()
    search_margin, search_growth, search_depth, assembly_chunk = 2.0, 1.0, 0.0, None
    slave_variables = np.arange(2, 6)
    master_variables = np.arange(8, 12)
    num_variables = NUM_PAIR_VARIABLES

    def __init__(self, nodes, has_neighbour, slave_facets):
        present = np.ones(nodes.shape, dtype=bool)
        present[:, 0] = has_neighbour[:, 0]
        present[:, 3] = has_neighbour[:, 1]
        super().__init__(nodes, present, slave_facets)
        self.has_neighbour = has_neighbour

    @classmethod
    def build(cls, node_blocks, node_x, all_slave_facets, local_slave_facets, all_master_facets,
              pairs, *, normals="averaged", nodal_frames=False, slave_surface=None):
        """The neighbours p, q are matched by global block among all slave facets known
        here (this rank's and those other ranks sent); they enter the stencil whatever
        the normal option."""
        starts = node_blocks[all_slave_facets[:, 0]]
        ends = node_blocks[all_slave_facets[:, 1]]
        facet_a, facet_b = local_slave_facets[:, 0], local_slave_facets[:, 1]
        facet_p, facet_has_p = lookup(ends, all_slave_facets[:, 0], node_blocks[facet_a])
        facet_q, facet_has_q = lookup(starts, all_slave_facets[:, 1], node_blocks[facet_b])
        facet_p = np.where(facet_has_p, facet_p, facet_a)
        facet_q = np.where(facet_has_q, facet_q, facet_b)
        facet = pairs[:, 0]
        nodes = np.stack([facet_p[facet], facet_a[facet], facet_b[facet], facet_q[facet],
                          all_master_facets[pairs[:, 1], 0], all_master_facets[pairs[:, 1], 1]],
                         axis=1)
        has_neighbour = np.stack([facet_has_p[facet], facet_has_q[facet]], axis=1)
        return cls(nodes, has_neighbour, pairs[:, 0])

    @property
    def slave_slots(self) -> np.ndarray:
        return np.array([1, 2])

    @property
    def master_slots(self) -> np.ndarray:
        return np.array([4, 5])

    def evaluate(self, node_x: np.ndarray, options: KernelOptions,
                 crosspoint: np.ndarray | None = None) -> PairQuantities:
        slave_x, master_x, neighbour_x = compiled.line2_gather(self.nodes, node_x)
        geometry = PairGeometry(slave_x=slave_x, master_x=master_x, neighbour_x=neighbour_x,
                                has_neighbour=self.has_neighbour)
        return self.kernel.evaluate(geometry, options, crosspoint=crosspoint,
                                    slave_facet=self.slave_facets)

    def combined_gradients(self, q: PairQuantities, rows, terms) -> np.ndarray:
        gradients = q.segment_gradients
        if gradients is not None and q.rows is rows and gradients.num_pairs == rows.size:
            return gradients.combine(terms)
        return self._kernel_gradients(q, rows, terms)


class SlaveSurfaceStars:
    """The slave nodes known here, one node-table row per global block, and the stars of
    their averaged normals (:class:`~dolfinx_mortar.normals.NormalStars`): topology of the
    slave surface, made once and taken over by the next search's stencil while the slave
    facets and the node table's blocks are the same."""

    def __init__(self, node_blocks: np.ndarray, all_slave_facets: np.ndarray):
        self._node_blocks, self._facets = node_blocks.copy(), all_slave_facets.copy()
        self.blocks, representative, inverse = np.unique(
            node_blocks[all_slave_facets], return_index=True, return_inverse=True)
        self.table_rows = all_slave_facets.reshape(-1)[representative]
        self.stars = normals_module.NormalStars(inverse.reshape(all_slave_facets.shape),
                                                self.table_rows.size)

    def describes(self, node_blocks: np.ndarray, all_slave_facets: np.ndarray) -> bool:
        return (self._node_blocks.shape == node_blocks.shape
                and self._facets.shape == all_slave_facets.shape
                and np.array_equal(self._node_blocks, node_blocks)
                and np.array_equal(self._facets, all_slave_facets))


class Surface3Stencil(PairStencil):
    """3D pairs: slave facet nodes, master facet nodes, and the stars of the slave normals.

    The averaged normal of a slave node depends on the nodes of every slave
    facet around it (:func:`~dolfinx_mortar.normals.averaged_nodal_normals`),
    here and on other ranks (the facets others sent are in the node table;
    nodes are matched by global block). Those nodes follow the facet nodes in
    the stencil, ``max_star`` slots per slave node (padded, ``present`` False).
    With the ``slave`` or ``master`` normal option the normals depend on the
    pair's own facets only and there are no star slots, unless friction's
    tangent frames need the averaged normals (``nodal_frames``).
    """

    gdim = 3
    kernel = Surface3Kernel()
    search_margin, search_growth, search_depth, assembly_chunk = 0.5, 0.5, 2.0, 512

    def __init__(self, nodes, present, slave_facets, ns, nm, max_star, star_table,
                 pair_star_rows):
        super().__init__(nodes, present, slave_facets)
        self.ns, self.nm, self.max_star = ns, nm, max_star
        self.num_variables = 3 * (2 * ns + nm)
        self.slave_variables = np.arange(3 * ns)
        self.master_variables = np.arange(3 * ns, 3 * (ns + nm))
        self._star_table = star_table          # (node table rows of the unique slave nodes, stars)
        self._pair_star_rows = pair_star_rows  # (n, ns) row of each pair's slave node in it
        self._normal_jacobian: np.ndarray | None = None
        self._nodal_normals: np.ndarray | None = None
        self._star_x: np.ndarray | None = None  # the star nodes' positions at the evaluation

    @classmethod
    def build(cls, node_blocks, node_x, all_slave_facets, local_slave_facets, all_master_facets,
              pairs, *, normals="averaged", nodal_frames=False, slave_surface=None):
        ns = local_slave_facets.shape[1]
        nm = all_master_facets.shape[1]
        facet = pairs[:, 0]
        slave = local_slave_facets[facet]
        master = all_master_facets[pairs[:, 1]]
        if normals != "averaged" and not nodal_frames:
            nodes = np.concatenate([slave, master], axis=1)
            return cls(nodes, np.ones(nodes.shape, dtype=bool), facet, ns, nm, 0, None, None)
        surface = slave_surface
        if surface is None or not surface.describes(node_blocks, all_slave_facets):
            surface = SlaveSurfaceStars(node_blocks, all_slave_facets)
        blocks, table_rows, stars = surface.blocks, surface.table_rows, surface.stars
        star = stars.star
        max_star = star.shape[1]
        # (int32: a pair has ~30 stencil slots, kept from one search to the next)
        index_type = np.int32 if node_blocks.size < 2**31 else np.int64
        # per local slave facet, then per pair: each slave node's row in the unique table,
        # and its star as node-table rows (-1 pad)
        facet_star_rows = np.searchsorted(
            blocks, node_blocks[local_slave_facets]).astype(index_type)
        # a local facet in no pair may have nodes outside the table (self-contact's master
        # side): clipped, never read
        np.minimum(facet_star_rows, max(blocks.size - 1, 0), out=facet_star_rows)
        star_table = np.where(star >= 0, table_rows[np.maximum(star, 0)], -1).astype(index_type)
        if blocks.size == 0:  # no slave node here: no pair either
            star_table = np.full((1, max_star), -1, dtype=index_type)
        facet_stars = star_table[facet_star_rows].reshape(facet_star_rows.shape[0], ns * max_star)
        pair_star_rows = facet_star_rows[facet]
        n = slave.shape[0]
        nodes = np.empty((n, ns + nm + ns * max_star), dtype=index_type)
        nodes[:, :ns], nodes[:, ns:ns + nm] = slave, master
        nodes[:, ns + nm:] = facet_stars[facet]
        present = nodes >= 0
        np.maximum(nodes, 0, out=nodes)  # absent slots: node 0, never read
        stencil = cls(nodes, present, facet, ns, nm, max_star, (table_rows, stars),
                      pair_star_rows)
        stencil.slave_surface = surface
        return stencil

    @property
    def slave_slots(self) -> np.ndarray:
        return np.arange(self.ns)

    @property
    def master_slots(self) -> np.ndarray:
        return np.arange(self.ns, self.ns + self.nm)

    @property
    def slave_nodes(self) -> np.ndarray:
        """(n, ns) node-table indices of the slave facet nodes (a view)."""
        return self.nodes[:, :self.ns]

    @property
    def master_nodes(self) -> np.ndarray:
        return self.nodes[:, self.ns:self.ns + self.nm]

    def slave_normals(self, rows: np.ndarray) -> np.ndarray:
        """(rows, ns, 3) the averaged unit nodal normals of the pairs' slave nodes at the
        last evaluation (the kernel's normal variables)."""
        if self._nodal_normals is None:
            raise ValueError("no nodal normals: the stencil was built without normal stars")
        return self._nodal_normals[self._pair_star_rows[rows]]

    def _normal_variable(self, q: PairQuantities, index: int) -> int | None:
        if self._nodal_normals is None or not q.normals_vary:
            return None
        return 3 * (self.ns + self.nm) + index

    def evaluate(self, node_x: np.ndarray, options: KernelOptions,
                 crosspoint: np.ndarray | None = None) -> PairQuantities:
        self._normal_jacobian = self._nodal_normals = self._star_x = None
        if self._star_table is not None:
            table_rows, stars = self._star_table
            self._star_x = node_x[table_rows]
            self._nodal_normals = stars.normals(self._star_x)
        geometry = IndexedPairGeometry(node_x, self.slave_nodes, self.master_nodes,
                                       self._nodal_normals, self._pair_star_rows)
        return self.kernel.evaluate(geometry, options, crosspoint=crosspoint,
                                    slave_facet=self.slave_facets)

    def _normal_jacobian_of_stars(self) -> np.ndarray:
        """(unique slave nodes, 3, s, 3) d n_j[a] / d x[star slot s, b] at the last
        evaluation, in the stencil's star slot order; made on the first Jacobian that asks."""
        if self._normal_jacobian is None:
            self._normal_jacobian = self._star_table[1].normals_and_jacobian(self._star_x)[1]
        return self._normal_jacobian

    def combined_gradients(self, q: PairQuantities, rows, terms) -> np.ndarray:
        result = np.empty((len(terms), 3 * self.width, rows.size))
        source = q.gradients_on_demand
        step = rows.size if source is None else source.chunk
        # (the kernel's gradients made again a chunk of rows at a time)
        for start in range(0, rows.size, max(step, 1)):
            stop = min(rows.size, start + step)
            part = terms if (start, stop) == (0, rows.size) else [
                [(o, w if np.ndim(w) == 0 else w[start:stop]) for o, w in row]
                for row in terms]
            self._columns(q, rows[start:stop], part, result, start)
        return result

    def _columns(self, q: PairQuantities, rows, terms, result: np.ndarray, first: int) -> None:
        """result[:, :, first:first + rows.size] = the combined gradients of ``rows`` on the
        stencil's columns: the facet nodes' directly, the nodal normals' chained through
        their stars (in C, ``stencil_columns``)."""
        kernel = self._row_gradients(q, rows, terms)  # (T, rows, nv)
        chain = bool(self.max_star) and self._star_x is not None
        J = None
        if chain:  # d n_j[a] / d x[star, b] of the rows: (rows, j, a, s b)
            J = np.ascontiguousarray(self._normal_jacobian_of_stars()[self._pair_star_rows[rows]])
        module = compiled.load("surface3")
        ffi = module.ffi
        base = ffi.cast("double *", ffi.from_buffer(result)) + first
        module.lib.stencil_columns(
            rows.size, result.shape[2], len(terms), self.num_variables, 3 * (self.ns + self.nm),
            self.ns, 3 * self.max_star, compiled._pointer(ffi, kernel, "double *"),
            compiled._pointer(ffi, J, "double *"), base)


STENCILS: dict[int, type[PairStencil]] = {2: Line2Stencil, 3: Surface3Stencil}
"""The stencil of each geometric dimension."""
