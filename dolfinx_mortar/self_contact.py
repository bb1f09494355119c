"""Self-contact: one surface that may touch itself, as slave and master of its own pairs.

A :class:`~dolfinx_mortar.mortar.MortarInterface` whose slave and master tags are equal
searches the surface against itself. Of the candidate pairs the search finds, a pair of
facets is kept when the two facets can meet from the front (:func:`facing`): they are
different facets, their outward normals point against each other, and each lies in front
of the other (not back to back, as the two faces of a wall thicker than the search's
depth), or they faced each other at the last search (a wall that one load step or Newton
update carried through the other is a penetration to undo, not the back of a wall);
facets that share a node only when they are folded onto each other (the two lips of a
slit at its tip).

Each pair of facing facets is found twice, once from each facet. Which facet is the slave
is decided per contact zone, so that every zone is counted once and its multipliers sit
on one side (:func:`slave_side`): the pairs form a graph whose connected components are
the zones; its facets are coloured in two (breadth first from the zone's first facet), the
side of clearly finer facets is the slave, as the finer side is advised for two bodies;
between sides of about equal facets the side that was the slave at the last search stays
the slave (so that a growing zone does not swap its multipliers from one wall to the
other), and a new zone takes the finer, or on a tie the side of its first facet. The graph
is gathered on every rank and coloured identically there, so that the ranks agree. A pair
whose facets got one colour (an odd cycle: a zone that curls round onto itself) is
dropped. A surface far from itself (no two facets whose search boxes overlap face each
other: :func:`may_face`) skips the search and the gathering, and its interface, without
pairs on any rank, skips its evaluation and assembly (docs/benchmarks.md, "Self-contact:
a surface far from itself").

Friction needs nothing of its own here: the tangents are those of the slave side's
normals, as for two bodies, and the slips are measured from the start of each solve,
through the pairs of the current search.

This follows the two-pass-free, one-sided treatment of 4C's self-contact (a binary tree
search, then a master/slave assignment of the contacting elements per search) with a
simpler assignment rule.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse
import scipy.sparse.csgraph
from mpi4py import MPI

FOLDED_COSINE = -0.5
"""Facets sharing a node are paired only when their normals' cosine is below this: folded
onto each other (a slit's lips: -1), not neighbours on a smooth or bent surface."""
CLEARLY_FINER = 1.1
"""A side whose facets are this many times smaller (in mean) than the other's is the
slave whatever the last search decided; between closer sides the last decision holds."""
BEHIND_SHARE = 0.5
"""A facet whose centre lies further behind the other facet's plane than this share of the
two facets' mean size, and than the search's depth, does not face it (back to back: the
two faces of a wall)."""


def facet_frames(x: np.ndarray, facets: np.ndarray) -> tuple[np.ndarray, np.ndarray,
                                                                np.ndarray]:
    """(centres, unit outward normals, sizes) of facets (node indices into ``x``; the
    surface's node order, whose normal points out of the body). Size: length (2D),
    square root of the area (3D)."""
    corners = x[facets]
    centres = corners.mean(axis=1)
    if x.shape[1] == 2:
        tangent = corners[:, 1] - corners[:, 0]
        normal = np.stack([tangent[:, 1], -tangent[:, 0]], axis=1)
        size = np.linalg.norm(normal, axis=1)
    else:
        normal = np.cross(corners[:, 2] - corners[:, 0], corners[:, -1] - corners[:, 1])
        area = np.linalg.norm(normal, axis=1)
        size = np.sqrt(area / (2.0 if facets.shape[1] == 3 else 1.0))
    length = np.linalg.norm(normal, axis=1)
    unit = normal / np.where(length > 0.0, length, 1.0)[:, None]
    return centres, unit, size


DENSE_PAIRS = 40000
""":func:`may_face` compares the boxes of all facet pairs at once up to this many pairs;
above, it leaves the decision to the search."""


def may_face(x: np.ndarray, blocks: np.ndarray, slave_facets: np.ndarray,
             master_facets: np.ndarray, margin: float, origin: np.ndarray | None = None,
             depth: float = 0.0) -> bool:
    """Whether the search of a surface against itself may keep a pair (``slave_facets``
    against ``master_facets``: node indices into ``x``, the nodes' global dof blocks
    ``blocks``); False only if it cannot, so that the search can be skipped. The search's
    candidates (:func:`~dolfinx_mortar.search.candidate_pairs`: boxes swept from
    ``origin``, reaching ``depth`` behind each facet, overlapping once grown by
    ``margin``, then only those near now or crossed) are a subset of the pairs whose boxes
    overlap, which a small surface finds here with a few array comparisons, all pairs at
    once, instead of the search's grids per pair of size groups; :func:`facing` keeps a pair of
    those or none (it decides each pair alone, the same way in either set). A surface far
    from itself has candidates (each facet's own neighbours) but none that faces.

    :func:`facing` needs opposed normals (a negative cosine); the cosines of all pairs are
    one small matrix product of the facets' normals, so only the pairs whose boxes overlap
    and whose normals may oppose (a cosine below a rounding allowance: the product rounds
    otherwise than :func:`facing`) go to :func:`facing`. On a surface far from itself
    that is none or a few: the normals of a facet's neighbours, the only pairs whose boxes
    overlap there, point the same way."""
    num_slave, num_master = slave_facets.shape[0], master_facets.shape[0]
    if num_slave == 0 or num_master == 0:
        return False
    if num_slave * num_master > DENSE_PAIRS:
        return True
    from . import search

    slave_lower, slave_upper = search.facet_boxes(x, slave_facets, origin, depth)
    master_lower, master_upper = search.facet_boxes(x, master_facets, origin, depth)
    # (the unit normals of facet_frames, as the search's depth takes them)
    may = (search._facet_outward(x, slave_facets) @ search._facet_outward(x, master_facets).T
           < OPPOSED_ALLOWANCE)
    for k in range(x.shape[1]):  # the comparisons of candidate_pairs, for all pairs
        may &= (slave_lower[:, k] - margin)[:, None] <= (master_upper[:, k] + margin)
        may &= (master_lower[:, k] - margin) <= (slave_upper[:, k] + margin)[:, None]
    if not may.any():
        return False
    slave, master = np.nonzero(may)
    slave_nodes, master_nodes = slave_facets[slave], master_facets[master]
    return bool(facing(blocks[slave_nodes], blocks[master_nodes], x[slave_nodes],
                       x[master_nodes], depth).any())


OPPOSED_ALLOWANCE = 1e-12
""":func:`may_face` sends :func:`facing` the pairs whose normals' cosine, as a matrix
product rounds it, is below this: every pair :func:`facing` could find opposed (a cosine
below 0 as it rounds it, which differs from the product's by far less)."""


def facing(slave_blocks: np.ndarray, master_blocks: np.ndarray, slave_x: np.ndarray,
           master_x: np.ndarray, depth: float = 0.0,
           faced: np.ndarray | None = None) -> np.ndarray:
    """Which candidate pairs of one surface's facets can meet from the front (see the
    module docstring). ``*_blocks`` (n, k): each pair's facet nodes' global dof blocks;
    ``*_x`` (n, k, gdim): their positions, in the surface's node order; ``depth``: how
    far behind each other the search pairs facets (a penetration the contact is to undo,
    not the back of a wall); ``faced`` (n,): which pairs faced each other at the last
    search. Those keep facing while their normals oppose, however deep they are now: a
    load step or a Newton update that carried a wall through the other by more than the
    reach is a penetration to undo, and the back of a wall never faced its front."""
    n, k = slave_blocks.shape
    if n == 0:
        return np.zeros(0, dtype=bool)
    index = np.arange(n * k).reshape(n, k)
    slave_centre, slave_normal, slave_size = facet_frames(slave_x.reshape(n * k, -1), index)
    master_centre, master_normal, master_size = facet_frames(
        master_x.reshape(n * master_blocks.shape[1], -1),
        np.arange(n * master_blocks.shape[1]).reshape(n, -1))
    cosine = np.einsum("ij,ij->i", slave_normal, master_normal)
    shares = (slave_blocks[:, :, None] == master_blocks[:, None, :]).any(axis=(1, 2))
    offset = master_centre - slave_centre
    reach = np.maximum(BEHIND_SHARE * 0.5 * (slave_size + master_size), depth)
    in_front = ((np.einsum("ij,ij->i", offset, slave_normal) > -reach)
                & (np.einsum("ij,ij->i", offset, master_normal) < reach))
    if faced is not None:
        in_front |= faced
    return in_front & np.where(shares, cosine < FOLDED_COSINE, cosine < 0.0)


def slave_side(comm: MPI.Intracomm, slave_blocks: np.ndarray, master_blocks: np.ndarray,
               slave_size: np.ndarray, master_size: np.ndarray,
               previous_slaves: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray,
                                                                   np.ndarray]:
    """Which of this rank's facing pairs keep their slave facet as the slave (see the module
    docstring), and the master sides' facets (sorted global dof blocks, (m, k)), which
    the slave nodes' averaged normals leave out (at a slit's tip the two lips' normals
    would cancel), and the slave sides' facets (the next search's ``previous_slaves``).
    ``*_blocks`` (n, k): each pair's facets' global dof blocks; ``*_size``: their sizes;
    ``previous_slaves``: the slave sides' facets of the last search (sorted global dof
    blocks), which keep their side where neither is :data:`CLEARLY_FINER`. Collective:
    every rank calls it at every search of a self-contact surface, and all get the same
    zones and sides."""
    k = slave_blocks.shape[1]
    local = np.column_stack([np.sort(slave_blocks, axis=1), np.sort(master_blocks, axis=1)])
    gathered = comm.allgather((local, np.column_stack([slave_size, master_size])))
    keys = np.concatenate([g[0] for g in gathered]).reshape(-1, 2, k)
    sizes = np.concatenate([g[1] for g in gathered]).reshape(-1, 2)
    if keys.shape[0] == 0:
        empty = np.zeros((0, k), dtype=np.int64)
        return np.zeros(0, dtype=bool), empty, empty
    facets, ids = np.unique(keys.reshape(-1, k), axis=0, return_inverse=True)
    ids = ids.reshape(-1, 2)
    facet_size = np.zeros(facets.shape[0])
    facet_size[ids.reshape(-1)] = sizes.reshape(-1)
    colour, zone, conflict = _two_colours(facets.shape[0], ids)
    was_slave = (rows_in(facets, previous_slaves) if previous_slaves is not None
                 else np.zeros(facets.shape[0], dtype=bool))
    slave_colour = _slave_colour(colour, zone, facet_size, was_slave)
    start = sum(g[0].shape[0] for g in gathered[:comm.rank])
    mine = slice(start, start + slave_blocks.shape[0])
    first = ids[mine, 0]
    master_side = colour != slave_colour[zone]
    return ((colour[first] == slave_colour[zone[first]]) & ~conflict[mine],
            facets[master_side], facets[~master_side])


def rows_in(rows: np.ndarray, table: np.ndarray) -> np.ndarray:
    """Which rows of ``rows`` (n, k) are rows of ``table`` (m, k) (integer arrays)."""
    if rows.shape[0] == 0 or table.shape[0] == 0:
        return np.zeros(rows.shape[0], dtype=bool)
    _, inverse = np.unique(np.concatenate([table, rows]), axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    return np.isin(inverse[table.shape[0]:], inverse[:table.shape[0]])


def _two_colours(num_facets: int, pairs: np.ndarray) -> tuple[np.ndarray, np.ndarray,
                                                               np.ndarray]:
    """(colour 0/1 per facet, zone per facet, whether each pair's two facets got one
    colour): breadth first from each zone's lowest facet, the colour the parity of the
    depth."""
    graph = scipy.sparse.coo_matrix(
        (np.ones(pairs.shape[0]), (pairs[:, 0], pairs[:, 1])), shape=(num_facets,) * 2).tocsr()
    graph = graph + graph.T
    num_zones, zone = scipy.sparse.csgraph.connected_components(graph, directed=False)
    depth = np.full(num_facets, -1, dtype=np.int64)
    roots = np.unique(zone, return_index=True)[1]
    for root in roots:
        order, predecessor = scipy.sparse.csgraph.breadth_first_order(
            graph, root, directed=False, return_predecessors=True)
        depth[root] = 0
        for facet in order[1:]:
            depth[facet] = depth[predecessor[facet]] + 1
    colour = depth % 2
    return colour, zone, colour[pairs[:, 0]] == colour[pairs[:, 1]]


def _slave_colour(colour: np.ndarray, zone: np.ndarray, size: np.ndarray,
                  was_slave: np.ndarray) -> np.ndarray:
    """Per zone, the colour of its slave side: the side :data:`CLEARLY_FINER` than the
    other if one is; else the side with more facets that were slaves at the last search
    (a zone that grows keeps its sides); else the finer by the mean facet size; else
    colour 0 (the side of the zone's first facet)."""
    num_zones = int(zone.max()) + 1 if zone.size else 0
    total, count, kept = (np.zeros((num_zones, 2)) for _ in range(3))
    np.add.at(total, (zone, colour), size)
    np.add.at(count, (zone, colour), 1.0)
    np.add.at(kept, (zone, colour), was_slave.astype(float))
    mean = total / np.where(count > 0, count, 1.0)
    mean[count == 0] = np.inf
    one = np.where(mean[:, 1] * CLEARLY_FINER < mean[:, 0], True,
                   np.where(mean[:, 0] * CLEARLY_FINER < mean[:, 1], False,
                            np.where(kept[:, 1] != kept[:, 0], kept[:, 1] > kept[:, 0],
                                     mean[:, 1] < mean[:, 0] * (1.0 - 1e-9))))
    return one.astype(np.int64)
