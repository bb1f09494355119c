"""The dual basis over the covered part of each slave facet (2D and 3D).

The whole-facet dual basis (Phi = A N with A from the full facet's mass
matrix) is pair-local, but on a facet the master covers only in part the
nodal weights int Phi_j over the covered part can be zero or negative and a
weighted gap can take the wrong sign. Here, as Popp, Wohlmuth, Gee and Wall
did for 3D dual mortar, the coefficients are built on the covered part: per
slave facet e with pairs p,

    M_e = sum_p D^std_p   (int N_j N_k over the union of the overlaps)
    D_e = diag(M_e 1)     (int N_j over it: positive)
    A_e = D_e M_e^-1

and every dual quantity of a pair is A_e (then the crosspoint merge P_e)
applied to its standard-basis one: D_p = P A D^std_p (summed over the facet:
P D_e, diagonal), M_p, Dn_p, Mn_p, the weighted gaps and the nodal areas. A
constant gap g gives g~_j = g int N_j over the covered part (right sign);
a gap in the slave space gives its nodal values. On a fully covered facet
M_e is the whole facet's mass matrix and nothing changes.

Derivatives: dA = (dD_e - A dM_e) M_e^-1 with dM_e = sum_p' dD^std_p', so a
linear combination sum w dY_p of a pair's outputs is a combination of its own
standard outputs (weights A^T P^T w) plus sum_p' W . dD^std_p' over every
pair p' of the facet. The slave nodes and the normal stars of p' are those
of p; the master nodes of the facet's other candidate pairs are appended to
each pair's stencil (:class:`CoveredStencil`), so the Jacobians' patterns
hold the coupling.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .dual import RowSubsetDual, rows_of
from .kernels import KernelOptions, PairQuantities

COVERAGE_FLOOR = 1e-12
"""Nodal weights int N_j over the covered part below this fraction of the covered
measure / ns are raised to it in the Jacobi scaling of M_e only (which keeps the
scaling finite on slivers; A_e does not depend on the scaling)."""


def merge_matrices(crosspoint: np.ndarray) -> np.ndarray:
    """(n, ns, ns) P with Phi_new = P Phi: a crosspoint node's basis function shared
    equally by the facet's other nodes (rows of crosspoints zero), as the kernels do."""
    cross = np.asarray(crosspoint, dtype=bool)
    n, ns = cross.shape
    others = (~cross).sum(axis=1)
    share = np.where(others > 0, 1.0 / np.maximum(others, 1), 0.0)
    keep = (~cross).astype(float)
    P = keep[:, :, None] * (np.eye(ns)[None] + share[:, None, None] * cross[:, None, :])
    return P


class FacetCoefficients:
    """A_e, M_e^-1 and the merge P_e of the slave facets of some pairs.

    Args:
        D_standard: (rows, ns, ns) int N_j N_k over each pair's overlap.
        facet: (rows,) slave facet of each pair.
        crosspoint: (rows, ns) crosspoint flags of each pair's slave nodes.
    """

    def __init__(self, D_standard: np.ndarray, facet: np.ndarray, crosspoint: np.ndarray):
        ns = D_standard.shape[1]
        self.facets, self.index = np.unique(facet, return_inverse=True)
        self.index = self.index.reshape(-1)
        # (None: the pairs come facet by facet, as the search orders them)
        self._order = (None if np.all(self.index[1:] >= self.index[:-1])
                       else np.argsort(self.index, kind="stable"))
        sorted_index = self.index if self._order is None else self.index[self._order]
        self._starts = np.flatnonzero(np.r_[True, sorted_index[1:] != sorted_index[:-1]]) \
            if sorted_index.size else np.zeros(0, dtype=np.int64)
        mass = self.facet_sums(D_standard)
        mass = 0.5 * (mass + mass.transpose(0, 2, 1))
        lumped = mass.sum(axis=2)
        total = lumped.sum(axis=1, keepdims=True)
        empty = total[:, 0] <= 0.0  # a degenerate facet: no multiplier weight at all
        floor = COVERAGE_FLOOR * np.where(empty[:, None], 1.0, total) / ns
        scale = 1.0 / np.sqrt(np.maximum(lumped, floor))
        scaled = mass * scale[:, :, None] * scale[:, None, :]
        scaled[empty] = np.eye(ns)
        inverse = np.linalg.inv(scaled) * scale[:, :, None] * scale[:, None, :]
        inverse[empty] = 0.0
        self.mass, self.lumped, self.inverse = mass, lumped, inverse
        self.A = lumped[:, :, None] * inverse
        P = np.zeros((self.facets.size, ns, ns))
        P[self.index] = merge_matrices(crosspoint)
        self.P = P
        self.T = P @ self.A

    def facet_sums(self, values: np.ndarray) -> np.ndarray:
        """(facets, ...) the sums of the pairs' ``values`` (rows, ...) over each facet:
        ``np.add.at``'s sums (to rounding) without its cost per element."""
        result = np.zeros((self.facets.size,) + values.shape[1:])
        if self._starts.size:
            ordered = values if self._order is None else values[self._order]
            result[:] = np.add.reduceat(ordered, self._starts, axis=0)
        return result

    def pair(self, name: str, rows: np.ndarray | None = None) -> np.ndarray:
        """A facet array per pair (rows: positions among the pairs given)."""
        index = self.index if rows is None else self.index[rows]
        return getattr(self, name)[index]

    def apply(self, X: np.ndarray) -> np.ndarray:
        """P A X per pair, X (rows, ns, ...)."""
        T = self.pair("T")
        return np.einsum("nji,ni...->nj...", T, X)


def _family(stencil, o: int):
    """(name, first-index j, index of the rest) of output o of ``stencil``'s numbering."""
    ns, nm, g = stencil.ns, stencil.nm, stencil.gdim
    if o < stencil.MN:
        j, rest = divmod(o - stencil.DN, ns * g)
        return "Dn", j, divmod(rest, g), stencil.DN + j * ns * g
    if o < stencil.AREA:
        j, rest = divmod(o - stencil.MN, nm * g)
        return "Mn", j, divmod(rest, g), stencil.MN + j * nm * g
    if o < stencil.GAP:
        return "area", o - stencil.AREA, (), stencil.AREA
    if o < stencil.D:
        return "gap", o - stencil.GAP, (), stencil.GAP
    if o < stencil.M:
        j, k = divmod(o - stencil.D, ns)
        return "D", j, (k,), stencil.D + j * ns
    j, l = divmod(o - stencil.M, nm)  # noqa: E741
    return "M", j, (l,), stencil.M + j * nm


def _stride(stencil, name: str) -> int:
    """How far apart the outputs of consecutive first indices j are."""
    ns, nm, g = stencil.ns, stencil.nm, stencil.gdim
    return {"Dn": ns * g, "Mn": nm * g, "area": 1, "gap": 1, "D": ns, "M": nm}[name]


@dataclasses.dataclass(kw_only=True)
class CoveredQuantities(PairQuantities):
    """Pair quantities in the covered dual basis, with what their derivatives need: the
    standard-basis quantities they were made from (``standard``, nonzero on the pairs
    ``standard.rows``), the facets' coefficients, and the per-evaluation gradients of
    D^std (``facet_gradients``, made on first use by :class:`CoveredStencil`)."""

    standard: PairQuantities
    coefficients: FacetCoefficients
    facet_gradients: tuple[np.ndarray, np.ndarray] | None = None


def transformed_quantities(stencil, q_std: PairQuantities, crosspoint: np.ndarray,
                           keep_scalars: bool) -> CoveredQuantities:
    """The covered-dual quantities of the standard-basis ones ``q_std``."""
    rows, n = q_std.rows, q_std.valid.shape[0]
    coefficients = FacetCoefficients(q_std.D_rows, stencil.slave_facets[rows], crosspoint[rows])

    def no_gradient():
        raise NotImplementedError(
            "covered dual quantities have no per-pair gradients (they couple the pairs of "
            "a slave facet): use the stencil's combined_gradients")

    def subset(value_rows: np.ndarray) -> RowSubsetDual:
        return RowSubsetDual(coefficients.apply(value_rows), rows, no_gradient, n)

    return CoveredQuantities(
        D_rows=coefficients.apply(q_std.D_rows), M_rows=coefficients.apply(q_std.M_rows),
        Dn=subset(q_std.Dn.value_rows), Mn=subset(q_std.Mn.value_rows),
        gap=subset(q_std.gap.value_rows), area=subset(q_std.area.value_rows),
        valid=q_std.valid, overlap=q_std.overlap,
        num_variables=q_std.num_variables, normals_vary=q_std.normals_vary,
        D_dual=subset(q_std.D_rows) if keep_scalars else None,
        M_dual=subset(q_std.M_rows) if keep_scalars else None,
        standard=q_std, coefficients=coefficients)


def _standard_values(q_std, name: str, rows: np.ndarray) -> np.ndarray:
    """The standard-basis values of output family ``name`` of the pairs ``rows``."""
    if name in ("D", "M"):
        by_rows = q_std.D_rows if name == "D" else q_std.M_rows
        return rows_of(by_rows, q_std.rows, rows)
    return getattr(q_std, name).value_of(rows)


def translated_terms(stencil, q: CoveredQuantities, rows: np.ndarray, terms):
    """Terms over the covered-dual outputs of pairs ``rows`` as terms over the standard
    outputs of the same pairs, and W (len(terms), rows, ns, ns): the weights of dM_e."""
    q_std, coefficients, contributing = q.standard, q.coefficients, q.standard.rows
    ns = stencil.ns
    position = np.searchsorted(contributing, rows)
    inside = (position < contributing.size) & (
        contributing[np.minimum(position, contributing.size - 1)] == rows)
    position = np.where(inside, position, 0)
    mask = inside.astype(float)
    T = coefficients.pair("T", position) * mask[:, None, None]
    P = coefficients.pair("P", position) * mask[:, None, None]
    A = coefficients.pair("A", position)
    inverse = coefficients.pair("inverse", position)
    translated, W = [], np.zeros((len(terms), rows.size, ns, ns))
    standard, solved, merged = {}, {}, {}  # (made once per call: terms repeat them)
    for t, row in enumerate(terms):
        own = []
        for o, w in row:
            if o >= stencil.NORMAL:
                own.append((o, w))
                continue
            name, j, rest, first = _family(stencil, o)
            stride = _stride(stencil, name)
            offset = o - first
            w = np.broadcast_to(np.asarray(w, dtype=float), (rows.size,))
            for i in range(ns):
                own.append((first + (i - j) * stride + offset, T[:, j, i] * w))
            # dM_e's weights: w (P_j y - (A^T P_j) y^T), y = M_e^-1 X
            if (name, rest) not in solved:
                if name not in standard:
                    standard[name] = _standard_values(q_std, name, rows)  # (rows, ns, ...)
                X = standard[name][(slice(None), slice(None)) + tuple(rest)]
                solved[name, rest] = np.einsum("nik,nk->ni", inverse, X)
            if j not in merged:
                merged[j] = (P[:, j, :], np.einsum("nli,nl->ni", A, P[:, j, :]))
            y = solved[name, rest]
            Pj, APj = merged[j]
            W[t] += ((Pj * y)[:, :, None] - APj[:, :, None] * y[:, None, :]) * w[:, None, None]
        translated.append(own)
    return translated, W


def boundary_nodes(facets: np.ndarray, num_nodes: int) -> np.ndarray:
    """Mask of the nodes on the boundary of the surface of ``facets`` (2D: nodes of one
    segment only; triangles: nodes of an edge of one triangle only). Quadrilateral
    facets give none (their facets are always coupled, see CoveredStencil)."""
    facets = np.asarray(facets, dtype=np.int64)
    mask = np.zeros(num_nodes, dtype=bool)
    if facets.size == 0 or facets.shape[1] > 3:
        return mask
    if facets.shape[1] == 2:
        nodes, counts = np.unique(facets, return_counts=True)
    else:
        edges = np.sort(np.stack([facets, np.roll(facets, -1, axis=1)], axis=2), axis=2)
        nodes, counts = np.unique(edges.reshape(-1, 2), axis=0, return_counts=True)
    mask[nodes[counts == 1].reshape(-1)] = True
    return mask


FULL_COVERAGE = 1e-10
"""A slave facet whose covered measure (the sum of its pairs' overlaps) equals its own
to this fraction counts as fully covered: its M_e is the whole facet's mass matrix,
which no master node moves, so its pairs need no coupling to the facet's other master nodes - unless
a candidate master facet touches the master surface's boundary (where moving a master
node can uncover the facet: the derivative has a kink there)."""


class CoveredStencil:
    """A pair stencil whose pairs carry the covered dual basis of their slave facet.

    Wraps a :class:`~dolfinx_mortar.stencils.PairStencil` (everything not overridden
    is the wrapped stencil's): the kernel runs with the standard basis, the outputs
    are transformed per slave facet (:func:`transformed_quantities`). On a facet the
    master covers only in part, A_e depends on every master node of the facet's
    candidate pairs: those facets are ``widened``, each of their pairs' stencils
    extended by the master nodes of the facet's other pairs (``partners``). A fully
    covered facet's A_e is the whole facet's and moves with its slave nodes only, so
    its pairs keep the base stencil (the Jacobians' patterns stay as narrow as the
    whole-facet basis's). Facets start narrow; every evaluation widens those it finds
    partly covered (and counts it in ``widenings``): the pattern then changes.
    """

    def __init__(self, base, coupled: bool = True, master_boundary: np.ndarray | None = None):
        self.base = base
        self.coupled = coupled
        """False: the pairs never get the partner coupling (quantities frozen in the
        reference configuration have no derivatives of A_e)"""
        facet = base.slave_facets
        n = facet.size
        order = np.argsort(facet, kind="stable")
        sorted_facets = facet[order]
        first = np.r_[True, sorted_facets[1:] != sorted_facets[:-1]] if n else np.zeros(0, bool)
        starts = np.flatnonzero(first)
        counts = np.diff(np.r_[starts, n])
        group = np.empty(n, dtype=np.int64)
        group[order] = np.repeat(np.arange(starts.size), counts)
        rank = np.empty(n, dtype=np.int64)
        rank[order] = np.arange(n) - np.repeat(starts, counts)
        self._facets = sorted_facets[starts]
        self._order, self._starts, self._counts = order, starts, counts
        self._group, self._rank = group, rank
        self.widened = np.zeros(starts.size, dtype=bool)
        """per slave facet (sorted ids): whether its pairs carry the partner coupling"""
        self.slave_facets = facet
        self.widenings = 0
        self.master_boundary = master_boundary
        self._build_slots()

    @property
    def master_boundary(self) -> np.ndarray | None:
        """Mask over the node table: nodes on the master surface's boundary (None: none)."""
        return self._master_boundary

    @master_boundary.setter
    def master_boundary(self, mask: np.ndarray | None) -> None:
        # per slave facet (sorted ids): a candidate master facet has a boundary node
        self._master_boundary = mask
        self._touches_boundary = np.zeros(self._starts.size, dtype=bool)
        if mask is not None and self._group.size:
            touches = mask[self.base.master_nodes].any(axis=1)
            self._touches_boundary = np.bincount(self._group, weights=touches,
                                                 minlength=self._starts.size) > 0

    def _build_slots(self) -> None:
        """``partners``, ``node_slots``, ``nodes`` and ``present`` for the widened facets."""
        base, group, rank = self.base, self._group, self._rank
        order, starts, counts = self._order, self._starts, self._counts
        n, nm = group.size, base.nm
        wide = self.widened[group] if n else np.zeros(0, dtype=bool)
        width = int(counts[self.widened].max()) - 1 if self.widened.any() else 0
        partners = np.full((n, width), -1, dtype=np.int64)
        for slot in range(width):
            # the facet's other pairs in their order, skipping the pair itself
            member = np.where(slot < rank, slot, slot + 1)
            has = wide & (member < counts[group])
            partners[has, slot] = order[starts[group[has]] + member[has]]
        self.partners = partners
        # a widened facet's master nodes, one slot each, the same list for its pairs
        rows = np.flatnonzero(wide)
        # (facet, master node) pairs as one integer each: np.unique of rows sorts slowly
        num_nodes = int(base.nodes.max(initial=0)) + 1
        keys = (np.repeat(group[rows], nm).astype(np.int64) * num_nodes
                + base.master_nodes[rows].reshape(-1))
        unique_keys, node_slot = np.unique(keys, return_inverse=True)
        unique_keys = np.stack(np.divmod(unique_keys, num_nodes), axis=1)
        node_slot = node_slot.reshape(-1)
        num_groups = starts.size
        group_start = np.searchsorted(unique_keys[:, 0], np.arange(num_groups))
        group_count = np.diff(np.r_[group_start, unique_keys.shape[0]]).astype(np.int64)
        slots = int(group_count.max()) if num_groups else 0
        node_slots = np.zeros((n, nm), dtype=np.int64)
        node_slots[rows] = (node_slot - group_start[np.repeat(group[rows], nm)]).reshape(-1, nm)
        extra = np.repeat(base.nodes[:, :1], slots, axis=1)  # absent slots: any valid node
        extra_present = np.arange(slots)[None, :] < group_count[group][:, None]
        if rows.size and slots:
            member = group_start[group[rows]][:, None] + np.minimum(
                np.arange(slots)[None, :], group_count[group[rows]][:, None] - 1)
            extra[rows] = np.where(extra_present[rows], unique_keys[member, 1], extra[rows])
        self.node_slots = node_slots  # (n, nm) slot of each pair's master nodes in its facet's list
        self.nodes = np.concatenate([base.nodes, extra], axis=1)
        self.present = np.concatenate([base.present, extra_present], axis=1)

    def _partly_covered(self, coefficients: FacetCoefficients, node_x: np.ndarray):
        """Facets (sorted ids) partly covered at ``node_x`` (or touching the master
        boundary) and not widened yet.
        Quadrilaterals always count as partly covered: their covered measure is a sum over
        clip cells, equal to the facet's own area only to the rules' accuracy."""
        covered = coefficients.lumped.sum(axis=1)
        group = np.searchsorted(self._facets, coefficients.facets)
        corners = node_x[self.base.slave_nodes[self._order[self._starts[group]]]]
        if corners.shape[1] == 2:
            measure = np.linalg.norm(corners[:, 1] - corners[:, 0], axis=1)
        elif corners.shape[1] == 3:
            measure = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0],
                                                    corners[:, 2] - corners[:, 0]), axis=1)
        else:
            measure = np.full(group.size, np.nan)  # never "fully covered"
        # the pairs' overlaps may also overlap each other (masters projected along their
        # own normals): then too M_e moves with the master nodes
        partial = ~(np.abs(covered - measure) <= FULL_COVERAGE * measure)
        partial |= self._touches_boundary[group]
        return group[partial & ~self.widened[group]]

    def widen(self, groups: np.ndarray) -> None:
        """Give the pairs of these facets (sorted ids) the partner coupling."""
        groups = np.asarray(groups, dtype=np.int64)
        if groups.size and not self.widened[groups].all():
            self.widened[groups] = True
            self.widenings += 1
            self._build_slots()

    def __getattr__(self, name):
        return getattr(self.base, name)

    @property
    def width(self) -> int:
        return self.nodes.shape[1]

    def evaluate(self, node_x: np.ndarray, options: KernelOptions,
                 crosspoint: np.ndarray | None = None) -> CoveredQuantities:
        """The base kernel with the standard basis, keeping the gradients of D (the 2D
        kernel always does), transformed per slave facet."""
        standard = dataclasses.replace(options, basis="standard", scalar_gradients=True)
        q_std = self.base.evaluate(node_x, standard, crosspoint=None)
        if crosspoint is None:
            crosspoint = np.zeros((self.num_pairs, self.ns), dtype=bool)
        q = transformed_quantities(self, q_std, np.asarray(crosspoint, dtype=bool),
                                   options.scalar_gradients)
        if self.coupled:
            self.widen(self._partly_covered(q.coefficients, node_x))
        return q

    def _facet_gradients(self, q: CoveredQuantities):
        """Per evaluation: d D^std of the contributing pairs on their master columns
        (contributing, ns ns, nm gdim) and its facet sums on the other columns
        (facets, ns ns, other columns)."""
        cached = q.facet_gradients
        if cached is None:
            q_std, coefficients, contributing = q.standard, q.coefficients, q.standard.rows
            ns = self.ns
            terms = [[(self.base.d(i, m), 1.0)] for i in range(ns) for m in range(ns)]
            dD = self.base.combined_gradients(q_std, contributing, terms).transpose(2, 0, 1)
            master, shared = self._column_split()
            summed = coefficients.facet_sums(dD[:, :, shared])
            cached = (np.ascontiguousarray(dD[:, :, master]), summed)
            q.facet_gradients = cached
        return cached

    def _column_split(self):
        """The base stencil's master-node columns and its other columns."""
        gdim = self.gdim
        master = (self.base.master_slots[:, None] * gdim + np.arange(gdim)).reshape(-1)
        shared = np.setdiff1d(np.arange(self.base.width * gdim), master)
        return master, shared

    def combined_gradients(self, q: PairQuantities, rows, terms) -> np.ndarray:
        gdim, base_columns = self.gdim, self.base.width * self.gdim
        result = np.zeros((len(terms), self.width * gdim, rows.size))
        if not isinstance(q, CoveredQuantities):
            # frozen (reference-configuration) quantities: pair-local, as the base's
            result[:, :base_columns] = self.base.combined_gradients(q, rows, terms)
            return result
        coefficients, contributing = q.coefficients, q.standard.rows
        translated, W = translated_terms(self, q, rows, terms)
        result[:, :base_columns] = self.base.combined_gradients(q.standard, rows, translated)
        if contributing.size == 0 or rows.size == 0:
            return result
        master_dD, summed_dD = self._facet_gradients(q)
        master, shared = self._column_split()
        # W is zero on rows outside the contributing pairs: their lookups may be anything
        weights = np.ascontiguousarray(W.reshape(len(terms), rows.size, -1).transpose(1, 0, 2))
        position = np.minimum(np.searchsorted(contributing, rows), contributing.size - 1)
        # every pair of the facet on the slave nodes and normal stars (shared by them)
        summed = (weights @ summed_dD[coefficients.index[position]]).transpose(1, 2, 0)
        first = self.base.master_slots[0] * gdim  # the master columns are one block
        result[:, :first] += summed[:, :first]
        result[:, first + master.size:base_columns] += summed[:, first:]
        # the pair's own master nodes, on partly covered facets (on a fully covered one
        # they cancel with the other pairs' to rounding: M_e is the whole facet's)
        wide = np.flatnonzero(self.widened[self._group[rows]])
        result[:, master[:, None], wide] += (
            weights[wide] @ master_dD[position[wide]]).transpose(1, 2, 0)
        # the other pairs' master nodes, in the facet's node slots
        nm = self.nm
        for r in range(self.partners.shape[1]):
            partner = self.partners[rows, r]
            found = np.minimum(np.searchsorted(contributing, partner), contributing.size - 1)
            selected = np.flatnonzero((partner >= 0) & (contributing[found] == partner))
            if selected.size == 0:
                continue
            part = weights[selected] @ master_dD[found[selected]]  # (m, T, nm gdim)
            slot = self.node_slots[partner[selected]]  # (m, nm)
            for l in range(nm):  # noqa: E741
                for c in range(gdim):
                    column = base_columns + slot[:, l] * gdim + c
                    result[:, column, selected] += part[:, :, l * gdim + c].T
        return result
