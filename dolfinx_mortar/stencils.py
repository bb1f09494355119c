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

- :class:`Line2Stencil`: 2D, the stencil ``p, a, b, q, c, d`` of
  :mod:`~dolfinx_mortar.kernels.line2`, whose gradients are already on it.
- :class:`Surface3Stencil`: 3D, slave facet nodes, master facet nodes and, per
  slave node, the nodes of its averaged normal's star; the kernel
  :mod:`~dolfinx_mortar.kernels.surface3` differentiates with respect to the
  nodal normals, which are chained here with the normals' own derivatives
  (:mod:`~dolfinx_mortar.normals`).

Outputs of a pair are numbered as in 2D: ``Dn`` (j, k, c) first, then
``Mn`` (j, l, c), ``area`` (j), ``gap`` (j); in 3D, when the kernel kept them
(friction), ``D`` (j, k), ``M`` (j, l) and the slave nodal normals (j, c)
follow (:meth:`PairStencil.dn` and its siblings).
"""

from __future__ import annotations

import numpy as np

from . import kernels
from .dual import RowSubsetDual


def lookup(keys: np.ndarray, values: np.ndarray, queries: np.ndarray):
    """values[i] for keys[i] == query, and whether it was found (first match)."""
    if keys.size == 0:
        return np.zeros_like(queries), np.zeros(queries.shape, dtype=bool)
    order = np.argsort(keys, kind="stable")
    sorted_keys = keys[order]
    position = np.clip(np.searchsorted(sorted_keys, queries), 0, keys.size - 1)
    found = sorted_keys[position] == queries
    return values[order[position]], found


def _rows_of(array: np.ndarray, kept: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """The entries of ``rows`` of an array whose entries are those of the rows ``kept``
    (zero for rows not kept): a slice where they are consecutive kept rows."""
    if rows is kept:
        return array
    sorter = None if kept.size < 2 or np.all(kept[1:] > kept[:-1]) else np.argsort(kept)
    position = np.minimum(np.searchsorted(kept, rows, sorter=sorter), max(kept.size - 1, 0))
    if sorter is not None and kept.size:
        position = sorter[position]
    found = kept[position] == rows if kept.size else np.zeros(rows.shape, dtype=bool)
    if found.all():
        if sorter is None and rows.size and np.all(position[1:] == position[:-1] + 1):
            return array[position[0]:position[-1] + 1]
        return array[position]
    result = np.zeros((rows.size,) + array.shape[1:])
    result[found] = array[position[found]]
    return result


def _gradient_rows(item, rows: np.ndarray) -> np.ndarray:
    """The gradients of ``rows`` of a Dual; of a :class:`RowSubsetDual` without building
    its full gradient."""
    if not isinstance(item, RowSubsetDual):
        return item.grad[rows]
    return _rows_of(item.grad_rows, item.rows, rows)


def _affine_factors(q):
    """The factorized gradients of Dn, Mn and the areas, if the kernel kept them so
    (:class:`~dolfinx_mortar.kernels.surface3.AffineFactors`)."""
    factors = getattr(q.Dn, "factors", None)
    if not hasattr(factors, "chain"):
        return None
    if not all(getattr(item, "factors", None) is factors for item in (q.Mn, q.area)):
        return None
    return factors


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
    """

    gdim: int
    ns: int
    nm: int

    def __init__(self, nodes: np.ndarray, present: np.ndarray, slave_facets: np.ndarray):
        self.nodes = nodes
        self.present = present
        self.slave_facets = slave_facets

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

    def _normal_variable(self, q, index: int) -> int | None:
        """The kernel variable of nodal normal component ``index`` (j gdim + c), None where
        the normals are not variables."""
        return None

    # kernel variables of the slave and master coordinates (reference configuration)
    slave_variables: np.ndarray
    master_variables: np.ndarray
    num_variables: int

    def evaluate(self, node_x: np.ndarray, **options):
        raise NotImplementedError

    def _kernel_gradients(self, q, rows: np.ndarray, terms) -> np.ndarray:
        """(len(terms), num_variables, len(rows)) on the kernel's own variables."""
        return np.ascontiguousarray(self._row_gradients(q, rows, terms).transpose(0, 2, 1))

    def _row_gradients(self, q, rows: np.ndarray, terms) -> np.ndarray:
        """(len(terms), len(rows), num_variables): per row of ``terms``, the weighted sum of
        the outputs' gradients over the kernel's own variables, without first copying
        every output's gradient into one array (in 3D they are ~1,600 numbers a pair)."""
        nv = self.num_variables
        parts, starts = [], []
        start = 0
        items = [q.Dn, q.Mn, q.area, q.gap]
        if getattr(q, "D_dual", None) is not None:
            items += [q.D_dual, q.M_dual]
        affine = _affine_factors(q)
        for item in items:
            size = int(np.prod(item.value.shape[1:]))
            if affine is not None and item.factors is affine:
                parts.append(None)
            else:
                parts.append(_gradient_rows(item, rows).reshape(rows.size, size, nv))
            starts.append(start)
            start += size
        result = np.zeros((len(terms), rows.size, nv))
        if affine is not None:
            # the terms summed over the plane coordinates first, chained once at the end
            kept = q.Dn.rows
            local = _rows_of(affine.local.transpose(1, 0, 2), kept, rows)  # (rows, 57, 12)
            weights = {"Dn": _rows_of(affine.slave_weights, kept, rows),
                       "Mn": _rows_of(affine.master_weights, kept, rows)}
            local_sum = np.zeros((len(terms), rows.size, local.shape[-1]))
            offsets = affine.offsets
            first = nv - 3 * self.ns
        for p, row in enumerate(terms):
            for o, weight in row:
                if o >= self.NORMAL:
                    variable = self._normal_variable(q, o - self.NORMAL)
                    if variable is not None:
                        result[p, :, variable] += weight
                    continue
                if o >= start:
                    raise ValueError(f"output {o} was not kept by the kernel")
                part = int(np.searchsorted(starts, o, side="right")) - 1
                index = o - starts[part]
                weight = np.reshape(weight, (-1, 1))
                if parts[part] is None:
                    name = ("Dn", "Mn", "area")[part]
                    local_sum[p] += local[:, offsets[name] + index] * weight
                    if name != "area":
                        jl, c = divmod(index, 3)
                        j, node = divmod(jl, self.ns if name == "Dn" else self.nm)
                        result[p][:, first + c::3] += weights[name][:, j, node] * weight
                    continue
                result[p] += parts[part][:, index, :] * weight
        if affine is not None:
            result += (local_sum.transpose(1, 0, 2) @ _rows_of(affine.chain, kept, rows)
                       ).transpose(1, 0, 2)
        return result

    def combined_gradients(self, q, rows: np.ndarray, terms) -> np.ndarray:
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
    slave_variables = np.arange(2, 6)
    master_variables = np.arange(8, 12)
    num_variables = kernels.NUM_PAIR_VARIABLES

    def __init__(self, nodes, has_neighbour, slave_facets):
        present = np.ones(nodes.shape, dtype=bool)
        present[:, 0] = has_neighbour[:, 0]
        present[:, 3] = has_neighbour[:, 1]
        super().__init__(nodes, present, slave_facets)
        self.has_neighbour = has_neighbour
        self._nodes_T = np.ascontiguousarray(nodes.T)

    @classmethod
    def build(cls, node_blocks, all_slave_facets, local_slave_facets, all_master_facets, pairs):
        """Stencils of ``pairs`` (slave facet, index into ``all_master_facets``).

        The neighbours p, q are matched by global block among all slave facets
        known here (this rank's and those other ranks sent).
        """
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

    def evaluate(self, node_x: np.ndarray, *, normals, integration, basis, num_gauss_points,
                 crosspoint):
        # the pairs' coordinates (12, n), variable-major: x of p, y of p, x of a, ...
        X = np.empty((kernels.NUM_PAIR_VARIABLES, self.num_pairs))
        for component in range(2):
            X[component::2] = np.ascontiguousarray(node_x[:, component])[self._nodes_T]
        return kernels._pair_quantities(
            X, self.has_neighbour, normals=normals, integration=integration, basis=basis,
            num_gauss_points=num_gauss_points, crosspoint=crosspoint,
            slave_facet=self.slave_facets)

    def combined_gradients(self, q, rows, terms) -> np.ndarray:
        factors = [getattr(item, "factors", None) for item in (q.Dn, q.Mn, q.area, q.gap)]
        gradients = factors[0][0] if factors[0] is not None else None
        if (gradients is not None and all(f is not None and f[0] is gradients for f in factors)
                and q.gap.rows is rows and gradients.num_pairs == rows.size):
            return gradients.combine(terms)
        return self._kernel_gradients(q, rows, terms)


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

    def __init__(self, nodes, present, slave_facets, ns, nm, max_star, star_table,
                 pair_star_rows):
        super().__init__(nodes, present, slave_facets)
        self.ns, self.nm, self.max_star = ns, nm, max_star
        self.num_variables = 3 * (2 * ns + nm)
        self.slave_variables = np.arange(3 * ns)
        self.master_variables = np.arange(3 * ns, 3 * (ns + nm))
        self._star_table = star_table          # (node table rows of the unique slave nodes, facets)
        self._pair_star_rows = pair_star_rows  # (n, ns) row of each pair's slave node in it
        self._normal_jacobian: np.ndarray | None = None
        self._nodal_normals: np.ndarray | None = None

    @classmethod
    def build(cls, node_blocks, node_x, all_slave_facets, local_slave_facets, all_master_facets,
              pairs, normals: str, nodal_frames: bool = False):
        from . import normals as normals_module

        ns = local_slave_facets.shape[1]
        nm = all_master_facets.shape[1]
        facet = pairs[:, 0]
        slave = local_slave_facets[facet]
        master = all_master_facets[pairs[:, 1]]
        if normals != "averaged" and not nodal_frames:
            nodes = np.concatenate([slave, master], axis=1)
            return cls(nodes, np.ones(nodes.shape, dtype=bool), facet, ns, nm, 0, None, None)
        # the slave nodes known here, one row per global block
        blocks, representative, inverse = np.unique(
            node_blocks[all_slave_facets], return_index=True, return_inverse=True)
        table_rows = all_slave_facets.reshape(-1)[representative]
        star_facets = inverse.reshape(all_slave_facets.shape)
        star = normals_module.averaged_nodal_normals(node_x[table_rows], star_facets).star
        max_star = star.shape[1]
        pair_star_rows = np.searchsorted(blocks, node_blocks[slave])
        star_nodes = star[pair_star_rows]  # (n, ns, max_star) rows of the unique table, -1 pad
        present_star = star_nodes >= 0
        star_table_nodes = np.where(present_star, table_rows[np.maximum(star_nodes, 0)], 0)
        # (int32: a pair has ~30 stencil slots, kept from one search to the next)
        nodes = np.concatenate(
            [slave, master, star_table_nodes.reshape(slave.shape[0], ns * max_star)], axis=1,
            dtype=np.int32 if node_blocks.size < 2**31 else np.int64)
        present = np.concatenate(
            [np.ones((slave.shape[0], ns + nm), dtype=bool),
             present_star.reshape(slave.shape[0], ns * max_star)], axis=1)
        return cls(nodes, present, facet, ns, nm, max_star, (table_rows, star_facets),
                   pair_star_rows)

    @property
    def slave_slots(self) -> np.ndarray:
        return np.arange(self.ns)

    @property
    def master_slots(self) -> np.ndarray:
        return np.arange(self.ns, self.ns + self.nm)

    def slave_normals(self, rows: np.ndarray) -> np.ndarray:
        """(rows, ns, 3) the averaged unit nodal normals of the pairs' slave nodes at the
        last evaluation (the kernel's normal variables)."""
        if self._nodal_normals is None:
            raise ValueError("no nodal normals: the stencil was built without normal stars")
        return self._nodal_normals[self._pair_star_rows[rows]]

    def _normal_variable(self, q, index: int) -> int | None:
        if self._nodal_normals is None or not getattr(q, "normals_vary", True):
            return None
        return 3 * (self.ns + self.nm) + index

    def evaluate(self, node_x: np.ndarray, *, normals, integration, basis, num_gauss_points,
                 crosspoint, scalar_gradients=False):
        from . import normals as normals_module
        from .kernels import surface3

        slave_x = node_x[self.slave_nodes]
        master_x = node_x[self.master_nodes]
        if self._star_table is not None:
            table_rows, star_facets = self._star_table
            nodal = normals_module.averaged_nodal_normals(node_x[table_rows], star_facets)
            slave_normals = nodal.normals[self._pair_star_rows]
            # d n_j / d x over the star, in the order of the star slots of the stencil; per
            # unique slave node, gathered per pair only for the rows that contribute
            self._normal_jacobian = nodal.jacobian  # (nodes, 3, s, 3)
            self._nodal_normals = nodal.normals
        else:
            slave_normals = np.zeros_like(slave_x)
            self._normal_jacobian = None
            self._nodal_normals = None
        return surface3.pair_quantities(
            slave_x, master_x, slave_normals, normals=normals, integration=integration,
            basis=basis, num_gauss_points=num_gauss_points, crosspoint=crosspoint,
            slave_facet=self.slave_facets, scalar_gradients=scalar_gradients)

    def combined_gradients(self, q, rows, terms) -> np.ndarray:
        kernel = self._row_gradients(q, rows, terms)  # (T, rows, nv)
        direct = 3 * (self.ns + self.nm)
        chain = bool(self.max_star) and self._normal_jacobian is not None
        result = np.zeros((len(terms), 3 * self.width, rows.size))
        width = 3 * self.max_star
        # in blocks of rows: the transposes to the pair axis last stay in cache
        for start in range(0, rows.size, 512):
            block = slice(start, min(rows.size, start + 512))
            result[:, :direct, block] = kernel[:, block, :direct].transpose(0, 2, 1)
            for j in range(self.ns if chain else 0):
                # d n_j[a] / d x[star, b] of the rows (rows, a, s b), one product per row
                J = self._normal_jacobian[self._pair_star_rows[rows[block], j]].reshape(
                    -1, 3, width)
                by_normal = kernel[:, block, direct + 3 * j:direct + 3 * j + 3].transpose(1, 0, 2)
                chained = np.ascontiguousarray(by_normal) @ J  # (rows, T, s b)
                result[:, direct + j * width:direct + (j + 1) * width, block] = chained.transpose(
                    1, 2, 0)
        return result
