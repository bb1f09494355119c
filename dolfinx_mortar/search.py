"""Broad-phase search: candidate (slave facet, master facet) pairs and when to redo it.

Candidates are pairs whose axis-aligned boxes, grown by a margin, overlap.
A search is expensive compared with reusing its result, and contact moves
little between Newton iterations, so :class:`SearchReuse` keeps the pairs
while no surface node has moved more than half the margin since the last
search: then no pair that could overlap has been missed (each side moved at
most margin/2, together at most the margin the boxes were grown by).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.spatial import cKDTree


def facet_boxes(coordinates: np.ndarray, facets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) corners, each (num_facets, 2), of the facets' boxes."""
    start, end = coordinates[facets[:, 0]], coordinates[facets[:, 1]]
    return np.minimum(start, end), np.maximum(start, end)


def boxes_overlap(lower_a, upper_a, lower_b, upper_b, margin: float) -> np.ndarray:
    """Elementwise: do the boxes, each grown by ``margin``, overlap?"""
    return np.all((lower_a - margin <= upper_b + margin) & (lower_b - margin <= upper_a + margin), axis=-1)


def candidate_pairs(
    slave_coordinates: np.ndarray,
    slave_facets: np.ndarray,
    master_coordinates: np.ndarray,
    master_facets: np.ndarray,
    margin: float,
) -> np.ndarray:
    """All (slave facet, master facet) index pairs whose grown boxes overlap.

    A k-d tree of facet midpoints finds the pairs whose midpoints are closer
    than the largest possible distance of overlapping boxes, then the boxes
    themselves decide. Cost O(n log n) in the number of facets; nothing at
    all is done when the two surfaces' boxes are apart.

    Returns:
        (num_pairs, 2) int array, sorted by slave facet then master facet.
    """
    empty = np.zeros((0, 2), dtype=np.int64)
    if slave_facets.shape[0] == 0 or master_facets.shape[0] == 0:
        return empty
    slave_lower, slave_upper = facet_boxes(slave_coordinates, slave_facets)
    master_lower, master_upper = facet_boxes(master_coordinates, master_facets)
    if not boxes_overlap(
        slave_lower.min(axis=0), slave_upper.max(axis=0),
        master_lower.min(axis=0), master_upper.max(axis=0), margin,
    ):
        return empty
    slave_half = 0.5 * (slave_upper - slave_lower)
    master_half = 0.5 * (master_upper - master_lower)
    radius = np.linalg.norm(slave_half.max(axis=0) + master_half.max(axis=0) + 2.0 * margin)
    slave_tree = cKDTree(0.5 * (slave_lower + slave_upper))
    master_tree = cKDTree(0.5 * (master_lower + master_upper))
    close = slave_tree.sparse_distance_matrix(master_tree, radius, output_type="ndarray")
    slave, master = close["i"].astype(np.int64), close["j"].astype(np.int64)
    # boxes_overlap on the candidates, one coordinate at a time (the same comparisons)
    keep = np.ones(slave.size, dtype=bool)
    for k in range(slave_lower.shape[1]):
        keep &= (slave_lower[:, k] - margin)[slave] <= (master_upper[:, k] + margin)[master]
        keep &= (master_lower[:, k] - margin)[master] <= (slave_upper[:, k] + margin)[slave]
    slave, master = slave[keep], master[keep]
    order = np.lexsort((master, slave))
    return np.stack([slave[order], master[order]], axis=1)


@dataclasses.dataclass
class SearchReuse:
    """Decides whether the last search still holds, and counts searches.

    Attributes:
        margin: boxes are grown by this much in every search.
        searches_done / searches_skipped: counters for the reports.
    """

    margin: float
    searches_done: int = 0
    searches_skipped: int = 0
    _reference: np.ndarray | None = None

    def needs_search(self, coordinates: np.ndarray, comm) -> bool:
        """Collective: True if any node on any rank moved more than margin/2."""
        from mpi4py import MPI

        if self._reference is None or self._reference.shape != coordinates.shape:
            moved = np.inf
        elif coordinates.size:
            moved = float(np.max(np.linalg.norm(coordinates - self._reference, axis=1)))
        else:
            moved = 0.0
        moved = comm.allreduce(moved, op=MPI.MAX)
        return not moved <= 0.5 * self.margin

    def searched(self, coordinates: np.ndarray) -> None:
        self._reference = coordinates.copy()
        self.searches_done += 1

    def skipped(self) -> None:
        self.searches_skipped += 1

    def invalidate(self) -> None:
        self._reference = None
