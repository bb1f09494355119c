"""Broad-phase search: candidate (slave facet, master facet) pairs and when to redo it.

Candidates are pairs whose axis-aligned boxes, grown by a margin, overlap.
The boxes are *swept*: a facet's box covers it at the positions of the
previous search and at the current ones (the union of both boxes), so it
contains the facet at every point of the straight path between the two
(each point of the moving facet is a convex combination of the four end
positions). A slave facet that a Newton iterate or a large load step pushed
through the master surface by more than the margin is then still paired with
the master facets it crossed; the kernels decide from the current geometry,
where its nodes are behind the master surface: a negative gap, an active
node, pushed back. A search on the current positions alone finds nothing in
that case, the bulk residual of a rigidly moved body is zero, and the body
passes through unnoticed. A translated or moderately turned facet keeps
facing its master (the kernels' test n_slave . n_master < 0); a facet turned
by more than 90 degrees relative to the master within one update is still
found here but rejected by the kernels as not facing.

This is what 4C does (``Mortar::BaseBinaryTreeNode::calculate_slabs_dop``:
k-DOP slabs of the current node positions, with SEARCH_USE_AUX_POS enlarged
by an auxiliary position, the current position moved along the facet normal
back to the last converged state). Kratos' contact search
(``BaseContactSearchProcess``) searches once per solution step around the
positions at its start (optionally predicted by velocity times the time
step) and MOOSE's patch search asks the user for a ``patch_size`` large
enough for the sliding of one step: both rely on steps small compared with
the search radius, which a Newton iterate of a large step is not.

A search is expensive compared with reusing its result, and contact moves
little between Newton iterations, so :class:`SearchReuse` keeps the pairs
while no surface node has moved more than half the margin since the last
search: then no pair that could overlap has been missed (each side moved at
most margin/2, together at most the margin the boxes were grown by). It also
keeps the positions of the last search, from which the next one sweeps.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .kernels import compiled


def facet_boxes(
    coordinates: np.ndarray,
    facets: np.ndarray,
    previous_coordinates: np.ndarray | None = None,
    depth: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) corners, each (num_facets, gdim), of the boxes of facets of k nodes.

    With ``previous_coordinates`` (the same nodes at an earlier state): the
    swept boxes, the union of the boxes at both states. With ``depth`` > 0
    each box also holds its facet moved by ``depth`` against its outward
    normal (into its body): a surface that already lies up to ``depth``
    inside the other body, with no earlier state to sweep from, is still
    paired.

    Examples:
        >>> x = np.array([[1.5, 0.0], [0.5, 0.0], [4.0, 0.0], [3.0, 0.0]])
        >>> lower, upper = facet_boxes(x, np.array([[0, 1], [2, 3]]))
        >>> lower
        array([[0.5, 0. ],
               [3. , 0. ]])
        >>> upper
        array([[1.5, 0. ],
               [4. , 0. ]])
    """
    lower, upper = _corner_box(coordinates, facets)
    if depth > 0.0 and facets.shape[0]:
        behind = _facet_outward(coordinates, facets) * -depth
        np.minimum(lower, lower + behind, out=lower)
        np.maximum(upper, upper + behind, out=upper)
    if previous_coordinates is not None:
        before_lower, before_upper = _corner_box(previous_coordinates, facets)
        # fmin/fmax: a NaN state (a diverged iterate) does not erase the other one
        lower = np.fmin(lower, before_lower)
        upper = np.fmax(upper, before_upper)
    return lower, upper


def _facet_outward(coordinates: np.ndarray, facets: np.ndarray) -> np.ndarray:
    """Unit outward normal of each facet (2D: (t_y, -t_x); 3D: along (x_2 - x_0) x
    (x_{k-1} - x_1), the cross product of the diagonals for quadrilaterals)."""
    start = coordinates[facets[:, 0]]
    if start.shape[1] == 2:
        tangent = coordinates[facets[:, 1]] - start
        normal = np.stack([tangent[:, 1], -tangent[:, 0]], axis=1)
    else:
        normal = np.cross(coordinates[facets[:, 2]] - start,
                          coordinates[facets[:, -1]] - coordinates[facets[:, 1]])
    length = np.linalg.norm(normal, axis=1, keepdims=True)
    return normal / np.where(length > 0.0, length, 1.0)


def _corner_box(coordinates: np.ndarray, facets: np.ndarray):
    start, end = coordinates[facets[:, 0]], coordinates[facets[:, 1]]
    lower, upper = np.minimum(start, end), np.maximum(start, end)
    for k in range(2, facets.shape[1]):
        corner = coordinates[facets[:, k]]
        np.minimum(lower, corner, out=lower)
        np.maximum(upper, corner, out=upper)
    return lower, upper


def boxes_overlap(lower_a, upper_a, lower_b, upper_b, margin: float) -> np.ndarray:
    """Elementwise: do the boxes, each grown by ``margin``, overlap?

    Examples:
        Two unit boxes 0.1 apart touch once each is grown by 0.05:

        >>> lower_a, upper_a = np.array([0.0, 0.0]), np.array([1.0, 1.0])
        >>> lower_b, upper_b = np.array([1.1, 0.0]), np.array([2.0, 1.0])
        >>> bool(boxes_overlap(lower_a, upper_a, lower_b, upper_b, 0.05))
        True
        >>> bool(boxes_overlap(lower_a, upper_a, lower_b, upper_b, 0.0))
        False
    """
    return np.all(
        (lower_a - margin <= upper_b + margin) & (lower_b - margin <= upper_a + margin), axis=-1
    )


def candidate_pairs(
    slave_coordinates: np.ndarray,
    slave_facets: np.ndarray,
    master_coordinates: np.ndarray,
    master_facets: np.ndarray,
    margin: float,
    *,
    slave_previous: np.ndarray | None = None,
    master_previous: np.ndarray | None = None,
    depth: float = 0.0,
) -> np.ndarray:
    """All (slave facet, master facet) index pairs whose grown boxes overlap.

    ``slave_previous`` and ``master_previous`` (the nodes at the previous
    search) make the boxes swept, ``depth`` makes them reach behind each
    facet (:func:`facet_boxes`). The overlaps are found in C
    (:func:`~dolfinx_mortar.kernels.compiled.search_boxes`): boxes are grouped by size
    (within a factor 2) and each pair of groups has a grid whose cells are as wide, in each
    coordinate, as the centres of two overlapping boxes can be apart, so that the few long
    boxes of nodes that moved far (a diverging iterate) do not widen the search of all the
    others, and a surface swept across its normal (long boxes in one direction) is not
    widened along the surface. Cost O(n log n) in the number of facets for boxes of similar
    size; nothing at all is done when the two surfaces' boxes are apart.

    Returns:
        (num_pairs, 2) int array, sorted by slave facet then master facet.

    Examples:
        A slave segment 0.1 above two master segments, of which only the first is
        within the margin:

        >>> slave_x = np.array([[0.0, 0.1], [1.0, 0.1]])
        >>> master_x = np.array([[1.5, 0.0], [0.5, 0.0], [4.0, 0.0], [3.0, 0.0]])
        >>> candidate_pairs(slave_x, np.array([[0, 1]]), master_x,
        ...                 np.array([[0, 1], [2, 3]]), margin=0.2)
        array([[0, 0]])
    """
    empty = np.zeros((0, 2), dtype=np.int64)
    if slave_facets.shape[0] == 0 or master_facets.shape[0] == 0:
        return empty
    slave_lower, slave_upper = facet_boxes(slave_coordinates, slave_facets, slave_previous, depth)
    master_lower, master_upper = facet_boxes(
        master_coordinates, master_facets, master_previous, depth)
    if not boxes_overlap(
        slave_lower.min(axis=0), slave_upper.max(axis=0),
        master_lower.min(axis=0), master_upper.max(axis=0), margin,
    ):
        return empty
    pairs, _ = compiled.search_boxes(slave_lower, slave_upper, master_lower, master_upper,
                                     margin)
    if slave_previous is not None or master_previous is not None:
        keep = _near_now_or_crossed(
            slave_coordinates, slave_facets, pairs[:, 0], master_coordinates, master_facets,
            pairs[:, 1], margin, depth,
        )
        pairs = pairs[keep]
    return pairs


def _near_now_or_crossed(
    slave_coordinates: np.ndarray,
    slave_facets: np.ndarray,
    slave: np.ndarray,
    master_coordinates: np.ndarray,
    master_facets: np.ndarray,
    master: np.ndarray,
    margin: float,
    depth: float = 0.0,
) -> np.ndarray:
    """Of swept candidates (slave facet ``slave[i]``, master facet ``master[i]``): those a
    search at the current positions also finds, and those whose slave facet has a node
    behind the master facet's line (3D: plane) now (it crossed). The other swept pairs only lie on
    the path of a body moving away: kept, they would make far-apart surfaces cost mortar
    work until the next search."""
    lower_s, upper_s = facet_boxes(slave_coordinates, slave_facets, depth=depth)
    lower_m, upper_m = facet_boxes(master_coordinates, master_facets, depth=depth)
    near = np.ones(slave.size, dtype=bool)
    for k in range(lower_s.shape[1]):  # boxes_overlap, per facet then per pair
        near &= (lower_s[:, k] - margin)[slave] <= (upper_m[:, k] + margin)[master]
        near &= (lower_m[:, k] - margin)[master] <= (upper_s[:, k] + margin)[slave]
    far = np.flatnonzero(~near)
    if far.size == 0:
        return near
    slave_far, master_far = slave_facets[slave[far]], master_facets[master[far]]
    start = master_coordinates[master_far[:, 0]]
    if start.shape[1] == 2:
        tangent = master_coordinates[master_far[:, 1]] - start
        outward = np.stack([tangent[:, 1], -tangent[:, 0]], axis=1)
    else:  # the plane of the master facet through its first node
        outward = np.cross(master_coordinates[master_far[:, 1]] - start,
                           master_coordinates[master_far[:, -1]] - start)
    behind = np.zeros(far.size, dtype=bool)
    for k in range(slave_far.shape[1]):
        offset = slave_coordinates[slave_far[:, k]] - start
        behind |= np.einsum("ij,ij->i", offset, outward) < 0.0
    near[far] = behind
    return near


@dataclasses.dataclass
class SearchReuse:
    """Decides whether the last search still holds, counts searches, and keeps the
    positions of the last search (where the next, swept, search starts from).

    Attributes:
        margin: boxes are grown by this much in every search.
        searches_done / searches_skipped: counters for the reports.
    """

    margin: float
    searches_done: int = 0
    searches_skipped: int = 0
    _reference: np.ndarray | None = None
    _valid: bool = False

    def needs_search(self, coordinates: np.ndarray, comm) -> bool:
        """Collective: True if any node on any rank moved more than margin/2."""
        from mpi4py import MPI

        if not self._valid or self._reference is None or self._reference.shape != coordinates.shape:
            moved = np.inf
        elif coordinates.size:
            moved = float(np.max(np.linalg.norm(coordinates - self._reference, axis=1)))
        else:
            moved = 0.0
        moved = comm.allreduce(moved, op=MPI.MAX)
        return not moved <= 0.5 * self.margin

    def sweep_start(self, coordinates: np.ndarray, initial: np.ndarray) -> np.ndarray:
        """Where the surfaces are swept from to ``coordinates``: the positions of the
        last search, or ``initial`` (the undeformed surfaces) before the first one."""
        if self._reference is not None and self._reference.shape == coordinates.shape:
            return self._reference
        return initial

    def searched(
        self, coordinates: np.ndarray, origin: np.ndarray | None = None, comm=None
    ) -> None:
        """Record a search at ``coordinates``, swept from ``origin`` (collective if given).

        A sweep longer than margin/2 keeps the pairs of the whole path, most of
        which the current positions no longer need (a body lifted off): the
        next update then searches again, from here, instead of carrying them.
        """
        self._reference = coordinates.copy()
        self._valid = True
        if origin is not None:
            from mpi4py import MPI

            swept = float(np.max(np.linalg.norm(coordinates - origin, axis=1), initial=0.0))
            swept = comm.allreduce(swept, op=MPI.MAX) if comm is not None else swept
            self._valid = swept <= 0.5 * self.margin
        self.searches_done += 1

    def skipped(self) -> None:
        """Count an update that kept the last search's pairs."""
        self.searches_skipped += 1

    def invalidate(self) -> None:
        """The next update searches again (still swept from the last search's positions)."""
        self._valid = False
