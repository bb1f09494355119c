"""Facet and averaged nodal normals of a contact surface, with their derivatives, 2D and 3D.

The averaged nodal normal of a slave node (paper, section 3) is the
normalized sum of the unit normals, at that node, of every facet around it:

    n_j = m_j / |m_j|,    m_j = sum_{f ∋ j} n_f(x_j)

so it depends on the coordinates of every node of those facets, the node's
*star*. :func:`averaged_nodal_normals` returns each normal with its exact
derivative over its star (padded to the largest star), which the 3D pair
stencil chains with the kernel's derivatives with respect to the normals
(:mod:`dolfinx_mortar.stencils`).

Facet node order (as :mod:`dolfinx_mortar.surface` builds it): in 2D start
-> end with (t_y, -t_x), t = end - start, pointing out of the body; in 3D
cyclic, counter-clockwise seen from outside, so that
(x_1 - x_0) x (x_{k-1} - x_0) points out. The normal of a facet at its
corner i is the unit vector along (x_{i+1} - x_i) x (x_{i-1} - x_i): for a
triangle the same at every corner, for a bilinear quadrilateral the normal
of the surface at that corner (the cross product of its two edge tangents
there).
"""

from __future__ import annotations

import dataclasses

import numpy as np


@dataclasses.dataclass
class NodalNormals:
    """Averaged nodal normals and their derivatives over each node's star.

    Attributes:
        normals: (num_nodes, gdim) unit normals (zero for a node on no facet).
        star: (num_nodes, max_star) the nodes each normal depends on (its own
            facets' nodes, itself included), -1 padded, increasing.
        jacobian: (num_nodes, gdim, max_star, gdim): d normals[i, a] / d x[star[i, s], b]
            (zero in padded slots).
    """

    normals: np.ndarray
    star: np.ndarray
    jacobian: np.ndarray


def _skew(v: np.ndarray) -> np.ndarray:
    """(..., 3, 3) matrices [v]_x with [v]_x w = v x w."""
    zero = np.zeros(v.shape[:-1])
    return np.stack([
        np.stack([zero, -v[..., 2], v[..., 1]], axis=-1),
        np.stack([v[..., 2], zero, -v[..., 0]], axis=-1),
        np.stack([-v[..., 1], v[..., 0], zero], axis=-1),
    ], axis=-2)


def _normalize_jacobian(n: np.ndarray, length: np.ndarray) -> np.ndarray:
    """d (v / |v|) / d v = (I - n n^T) / |v| for unit n = v / |v|."""
    gdim = n.shape[-1]
    return (np.eye(gdim) - n[..., :, None] * n[..., None, :]) / length[..., None, None]


def facet_corner_normals(x: np.ndarray, facets: np.ndarray, jacobian: bool = False):
    """Unit normals of each facet at each of its nodes, and optionally their derivatives.

    Args:
        x: (num_nodes, gdim) coordinates.
        facets: (num_facets, k) node indices (2D: k = 2; 3D: k = 3 or 4).
        jacobian: also return the derivatives.

    Returns:
        normals (num_facets, k, gdim); with ``jacobian``, also
        (num_facets, k corners, k nodes, gdim, gdim): d normal[corner, a] / d x[node, b].
    """
    x = np.asarray(x, dtype=np.float64)
    corners = x[facets]  # (nf, k, g)
    nf, k, gdim = corners.shape
    if gdim == 2:
        if k != 2:
            raise ValueError(f"2D facets have 2 nodes, got {k}")
        t = corners[:, 1] - corners[:, 0]
        length = np.linalg.norm(t, axis=1)
        n = np.column_stack([t[:, 1], -t[:, 0]]) / length[:, None]
        normals = np.repeat(n[:, None, :], 2, axis=1)
        if not jacobian:
            return normals
        rotation = np.array([[0.0, 1.0], [-1.0, 0.0]])
        J = _normalize_jacobian(n, length) @ rotation  # d n / d t
        derivative = np.zeros((nf, 2, 2, 2, 2))
        derivative[:, :, 1] = J[:, None]
        derivative[:, :, 0] = -J[:, None]
        return normals, derivative
    if gdim != 3 or k not in (3, 4):
        raise ValueError(f"3D facets have 3 or 4 nodes, got {k} nodes in {gdim}D")
    normals = np.empty((nf, k, 3))
    derivative = np.zeros((nf, k, k, 3, 3)) if jacobian else None
    for i in range(k):
        following, preceding = (i + 1) % k, (i - 1) % k
        a = corners[:, following] - corners[:, i]
        b = corners[:, preceding] - corners[:, i]
        v = np.cross(a, b)
        length = np.linalg.norm(v, axis=1)
        n = v / length[:, None]
        normals[:, i] = n
        if jacobian:
            P = _normalize_jacobian(n, length)
            # dv = da x b + a x db = -[b]_x da + [a]_x db, da = dx_f - dx_i, db = dx_p - dx_i
            skew_a, skew_b = _skew(a), _skew(b)
            derivative[:, i, following] = -P @ skew_b
            derivative[:, i, preceding] = P @ skew_a
            derivative[:, i, i] = P @ (skew_b - skew_a)
    return (normals, derivative) if jacobian else normals


def facet_normals(x: np.ndarray, facets: np.ndarray) -> np.ndarray:
    """Unit normal of each facet (quadrilaterals: along the cross product of the diagonals,
    the normal at the centre of a bilinear facet).

    Examples:
        Two segments of a V, each pointing out of the body below it, and a triangle
        counter-clockwise seen from +z:

        >>> x = np.array([[-1.0, 1.0], [0.0, 0.0], [1.0, 1.0]])
        >>> facet_normals(x, np.array([[0, 1], [1, 2]]))
        array([[-0.70710678, -0.70710678],
               [ 0.70710678, -0.70710678]])
        >>> x = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
        >>> facet_normals(x, np.array([[0, 1, 2]]))
        array([[0., 0., 1.]])
    """
    corners = np.asarray(x, dtype=np.float64)[facets]
    if corners.shape[1] == 4:
        v = np.cross(corners[:, 2] - corners[:, 0], corners[:, 3] - corners[:, 1])
        return v / np.linalg.norm(v, axis=1, keepdims=True)
    return facet_corner_normals(x, facets)[:, 0]


def averaged_nodal_normals(x: np.ndarray, facets: np.ndarray) -> NodalNormals:
    """The averaged nodal normal of every node of ``x`` and its derivative over its star.

    Vectorized over nodes and facets; no loop over nodes.

    Examples:
        The V of :func:`facet_normals`: its bottom node's normal is the mean direction
        of both segments' and depends on all three nodes, each end node's on its
        segment's two:

        >>> x = np.array([[-1.0, 1.0], [0.0, 0.0], [1.0, 1.0]])
        >>> nodal = averaged_nodal_normals(x, np.array([[0, 1], [1, 2]]))
        >>> nodal.normals
        array([[-0.70710678, -0.70710678],
               [ 0.        , -1.        ],
               [ 0.70710678, -0.70710678]])
        >>> nodal.star
        array([[ 0,  1, -1],
               [ 0,  1,  2],
               [ 1,  2, -1]])
        >>> nodal.jacobian.shape
        (3, 2, 3, 2)
    """
    x = np.asarray(x, dtype=np.float64)
    stars = NormalStars(facets, x.shape[0])
    normals, jacobian = stars.normals_and_jacobian(x)
    return NodalNormals(normals=normals, star=stars.star, jacobian=jacobian)


class NormalStars:
    """The star of every node of a set of facets, and the averaged normals at any positions
    of their nodes.

    The stars are topology: a stencil builds them once per search and evaluates the
    normals at every update from them, their derivatives only when a Jacobian asks
    (a residual or a values-only update needs none).

    Attributes:
        star: (num_nodes, max_star) the nodes each normal depends on, -1 padded,
            increasing (:attr:`NodalNormals.star`).
    """

    def __init__(self, facets: np.ndarray, num_nodes: int):
        facets = np.asarray(facets, dtype=np.int64)
        self.facets, self.num_nodes = facets, int(num_nodes)
        nf, k = facets.shape
        node = np.repeat(facets, k, axis=1).reshape(-1)          # j: the corner's node
        other = np.tile(facets, (1, k)).reshape(-1)              # s: a node of the same facet
        keys, inverse = np.unique(node * num_nodes + other, return_inverse=True)
        rows, columns = keys // num_nodes, keys % num_nodes
        first = np.searchsorted(rows, np.arange(num_nodes))
        slot = np.arange(keys.size) - first[rows]
        max_star = int(slot.max()) + 1 if keys.size else 0
        self.star = np.full((num_nodes, max_star), -1, dtype=np.int64)
        self.star[rows, slot] = columns
        self._entry = inverse.reshape(-1)  # (facet, corner, node) -> its (node, star node) key
        self._rows, self._slot = rows, slot

    def normals(self, x: np.ndarray) -> np.ndarray:
        """(num_nodes, gdim) unit averaged normals of the nodes at positions ``x`` (zero for
        a node on no facet)."""
        return self._averaged(facet_corner_normals(x, self.facets))[0]

    def normals_and_jacobian(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The normals and (num_nodes, gdim, max_star, gdim) their derivatives
        d normals[i, a] / d x[star[i, s], b] (zero in padded slots)."""
        corner_normals, corner_derivative = facet_corner_normals(x, self.facets, jacobian=True)
        normals, length, on_surface = self._averaged(corner_normals)
        gdim = normals.shape[1]
        # d m_j / d x_s, summed over the (facet, corner) entries with node j at the corner
        blocks = corner_derivative.reshape(-1, gdim * gdim)
        accumulated = np.stack([np.bincount(self._entry, blocks[:, c], self._rows.size)
                                for c in range(gdim * gdim)], axis=1).reshape(-1, gdim, gdim)
        P = np.zeros((self.num_nodes, gdim, gdim))
        P[on_surface] = _normalize_jacobian(normals[on_surface], length[on_surface])
        jacobian = np.zeros((self.num_nodes, gdim, self.star.shape[1], gdim))
        jacobian[self._rows, :, self._slot, :] = P[self._rows] @ accumulated
        return normals, jacobian

    def _averaged(self, corner_normals: np.ndarray):
        gdim = corner_normals.shape[-1]
        corner_nodes = self.facets.reshape(-1)
        summed = np.stack([np.bincount(corner_nodes, corner_normals[..., c].reshape(-1),
                                       self.num_nodes) for c in range(gdim)], axis=1)
        length = np.linalg.norm(summed, axis=1)
        on_surface = length > 0.0
        normals = np.zeros_like(summed)
        normals[on_surface] = summed[on_surface] / length[on_surface, None]
        return normals, length, on_surface
