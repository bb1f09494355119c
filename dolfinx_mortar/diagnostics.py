"""Checks that turn silent wrong answers into messages.

A contact solve can end "successfully" with a useless answer: a slave surface
tagged on the face of its body that looks away from the master never meets
it, and the bodies pass through each other with zero contact force. A failed
solve can end in PETSc reason codes that do not say what went wrong. This
module holds the checks behind the messages of :class:`ContactProblem` and
:func:`~dolfinx_mortar.loading.solve_load_steps`:

* :func:`describe_snes_reason`: a SNES (or our outer loops') reason in words;
* :class:`InversionCheck`: cells whose Jacobian determinant is not positive,
  counted, with the worst one located;
* :func:`facing_report`: where slave and master are closest, do their
  outward normals point at each other (run when a problem is built);
* :func:`penetration_report`: surface nodes deep behind the other surface (run
  when a problem is built, for bodies that start overlapping, and after each
  accepted load step);
* :func:`free_translations`: bodies whose rigid-body translation nothing in the
  bulk form holds, and :func:`translation_vectors`, those translations as vectors;
* :func:`describe_ksp_failure`, :func:`describe_iterative_failure`: why a linear
  solve failed (and, for the iterative solver, what to try);
* :func:`warn`: a :class:`ContactWarning` that the user sees, once, on rank 0.

All functions that take a communicator are collective.
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
from mpi4py import MPI
from scipy.spatial import cKDTree

from .deprecation import show
from .normals import facet_normals

FIXED_POINT_NOT_SETTLED = -100
"""SolveReport reason: the fixed-point active set kept changing."""
UZAWA_NOT_SETTLED = -101
"""SolveReport reason: the augmented Lagrange (Uzawa) updates did not settle."""

_SNES_REASON_WORDS = {
    2: "the residual norm fell below the absolute tolerance",
    3: "the residual norm fell below the relative tolerance",
    4: "the Newton step became small relative to the solution",
    5: "the maximum number of iterations was reached (counted as converged)",
    -1: "the residual could not be evaluated at the iterate",
    -2: "too many residual evaluations",
    -3: "the linear solver failed",
    -4: "the residual is NaN or infinite",
    -5: "no convergence within the maximum number of Newton iterations",
    -6: "the line search failed",
    -7: "an inner solve failed",
    -8: "Newton stalled in a local minimum of the residual norm",
    -9: "the residual grew beyond the divergence tolerance",
    -10: "the Jacobian could not be evaluated at the iterate",
    -11: "the trust region became too small",
    -13: "the objective could not be evaluated at the iterate",
    -14: "the objective is NaN or infinite",
    FIXED_POINT_NOT_SETTLED: "the fixed-point active set kept changing "
    "(max_outer_iterations reached)",
    UZAWA_NOT_SETTLED: "the augmented Lagrange updates did not settle "
    "(max_outer_iterations reached)",
}
_OUR_REASON_NAMES = {
    FIXED_POINT_NOT_SETTLED: "FIXED_POINT_NOT_SETTLED",
    UZAWA_NOT_SETTLED: "UZAWA_NOT_SETTLED",
}


class ContactWarning(UserWarning):
    """A contact set-up or result that is probably not what the user meant."""


def warn(comm: MPI.Intracomm, message: str, stacklevel: int = 2) -> None:
    """Collective: issue ``message`` as a :class:`ContactWarning`, shown once, by rank 0.

    Every rank passes the warning through the warnings filters, so that a filter
    set to ``"error"`` raises on every rank (none is left waiting in the next
    collective call) and ``"ignore"`` silences it everywhere; only rank 0 shows
    it. The texts are built from collective results, so the counts in them are
    global and the same on every rank.

    Shown as :func:`~dolfinx_mortar.deprecation.show` shows it: on stderr even where
    :mod:`logging` captures warnings and nothing would print them.
    """
    with warnings.catch_warnings(record=True) as caught:
        warnings.warn(message, ContactWarning, stacklevel=stacklevel + 1)
    if comm.rank != 0:
        return
    show(caught)


def _enum_name(enum, value: int, prefixes: tuple[str, ...] = ("CONVERGED", "DIVERGED")) -> str:
    """The name of ``value`` in a petsc4py enum class (names differ between PETSc versions:
    -4 is DIVERGED_FNORM_NAN in 3.22 and DIVERGED_FUNCTION_NANORINF in 3.25)."""
    for key in sorted(dir(enum)):
        if key.startswith(prefixes) and getattr(enum, key) == value:
            return key
    return "UNKNOWN"


def describe_snes_reason(reason: int) -> str:
    """``"-4 DIVERGED_FNORM_NAN (the residual is NaN or infinite)"`` for a reason code.

    The name is PETSc's (it differs between versions, see :func:`_enum_name`) or ours
    for the reasons of the outer loops (fixed point, Uzawa).

    Examples:
        >>> describe_snes_reason(3)
        '3 CONVERGED_FNORM_RELATIVE (the residual norm fell below the relative tolerance)'
    """
    from petsc4py import PETSc

    reason = int(reason)
    name = _OUR_REASON_NAMES.get(reason) or _enum_name(PETSc.SNES.ConvergedReason, reason)
    return f"{reason} {name} ({_SNES_REASON_WORDS.get(reason, 'no description')})"


def describe_ksp_failure(ksp) -> str:
    """Why the linear solve failed, from the KSP's and its preconditioner's reasons."""
    from petsc4py import PETSc

    reason = ksp.getConvergedReason()
    text = f"KSP reason {reason} {_enum_name(PETSc.KSP.ConvergedReason, reason)}"
    try:
        failed = ksp.getPC().getFailedReason()
    except AttributeError:  # pragma: no cover - older petsc4py
        failed = 0
    if failed:
        failure = _enum_name(PETSc.PC.FailedReason, failed, ("FACTOR", "SETUP", "SUBPC"))
        text += f", preconditioner failure {failure}"
        if "ZEROPIVOT" in failure:
            text += " (the factorization met a zero or tiny pivot: a singular system, e.g. a "
            text += "body with a free rigid-body motion)"
        elif "OUTMEMORY" in failure:
            text += (" (the factorization ran out of the working space it had estimated, e.g. "
                     "MUMPS' INFOG(1) = -9 after many delayed pivots: raise the estimate's "
                     "margin, the option <prefix>mat_mumps_icntl_14, a percentage, default 20)")
    return text


def describe_iterative_failure(ksp, prefix: str, inner_failure: str = "",
                               advice: bool = True) -> str:
    """Why the iterative linear solver failed: fgmres on the monolithic system (``ksp``),
    preconditioned by the condensed GMRES + AMG solve (:mod:`dolfinx_mortar.condensation`),
    whose breakdown, if any, ``inner_failure`` says; with ``advice``, what to try."""
    from petsc4py import PETSc

    text = describe_ksp_failure(ksp)
    if ksp.getConvergedReason() == PETSc.KSP.ConvergedReason.DIVERGED_MAX_IT:
        text += (f" (fgmres on the monolithic system did not reach its tolerance in "
                 f"{ksp.getIterationNumber()} iterations, the limit {prefix}ksp_max_it)")
    if inner_failure:
        text += f"; the condensed inner solve ({prefix}condensed_) broke down: {inner_failure}"
    if advice:
        text += (
            ". The iterative solver (GMRES + AMG on the condensed system) did not solve this "
            "Newton system: try linear_solver='direct' (MUMPS LU), or other options for the "
            f"inner solve under {prefix}condensed_ (or a larger {prefix}ksp_max_it). A body "
            "that nothing holds against a rigid-body motion makes it fail too.")
    return text


@dataclasses.dataclass
class Inversion:
    """Inverted cells of one state: how many, and where the worst one is."""

    count: int = 0
    where: tuple[float, ...] | None = None
    """Reference coordinates of the midpoint of the cell with the most negative determinant."""

    def describe(self) -> str:
        """The inverted cells in words, for messages.

        Examples:
            >>> Inversion().describe()
            'no inverted element'
            >>> print(Inversion(2, (0.5, 1.25)).describe())  # doctest: +NORMALIZE_WHITESPACE
            2 inverted elements (Jacobian determinant <= 0; the worst at reference point
            (0.5, 1.25))
        """
        if not self.count:
            return "no inverted element"
        location = ", ".join(f"{c:.4g}" for c in self.where) if self.where else "?"
        return (
            f"{self.count} inverted element{'s' if self.count != 1 else ''} (Jacobian "
            f"determinant <= 0; the worst at reference point ({location}))"
        )


class InversionCheck:
    """Counts cells with a non-positive Jacobian determinant at x = X + u (P1, 2D and 3D).

    At each corner of a cell (every vertex of a quadrilateral or hexahedron,
    the first of a simplex) the determinant of the current edges to its
    neighbours, X_b - X_a + u_b - u_a, is divided by its reference value; the
    reference edges and the dofs are kept, since this runs in every residual
    evaluation, over all cells.
    """

    def __init__(self, V):
        from . import compat

        mesh = V.mesh
        self.comm = mesh.comm
        tdim = mesh.topology.dim
        self.gdim = mesh.geometry.dim
        if self.gdim != tdim:
            raise ValueError(f"cells of dimension {tdim} in {self.gdim}D are not supported")
        geometry = compat.geometry_dofmap(mesh)
        num_cells = mesh.topology.index_map(tdim).size_local
        X = mesh.geometry.x[:, : self.gdim][geometry[:num_cells]]
        self._midpoints = X.mean(axis=1)
        blocks = np.asarray(V.dofmap.list[:num_cells], dtype=np.int64)
        num_vertices = geometry.shape[1]
        if num_vertices == tdim + 1:
            corners = [tuple(range(tdim + 1))]
        else:  # tensor-product cells: the neighbours of vertex i are i ^ 1, i ^ 2 (, i ^ 4)
            corners = [(i, *(i ^ (1 << k) for k in range(tdim))) for i in range(num_vertices)]
        self._corners = []
        for a, *others in corners:
            edges = [X[:, b] - X[:, a] for b in others]
            self._corners.append(
                (blocks[:, a], [blocks[:, b] for b in others], edges, 1.0 / _det(edges))
            )

    def local_ratios(self, u: np.ndarray) -> np.ndarray:
        """Per owned cell: min over corners of det(current) / det(reference)."""
        u = u.reshape(-1, self.gdim)
        worst = np.full(self._midpoints.shape[0], np.inf)
        for a, others, edges, inverse in self._corners:
            ua = u[a]
            current = _det([edge + (u[b] - ua) for b, edge in zip(others, edges, strict=True)])
            np.minimum(worst, current * inverse, out=worst)
        return worst

    def worst(self, u: np.ndarray) -> tuple[float, tuple[float, ...] | None]:
        """Collective: the smallest det(current) / det(reference) over all cells, and where."""
        ratios = self.local_ratios(u)
        local = (np.inf, None)
        if ratios.size:
            values = np.where(np.isnan(ratios), -np.inf, ratios)
            i = int(np.argmin(values))
            local = (float(values[i]), tuple(float(c) for c in self._midpoints[i]))
        return min(self.comm.allgather(local), key=lambda w: w[0])

    def __call__(self, u: np.ndarray) -> Inversion:
        """Collective: the inverted cells of displacement array ``u`` (owned and ghost blocks)."""
        ratios = self.local_ratios(u)
        bad = ~(ratios > 0.0)  # NaN counts as inverted
        count = self.comm.allreduce(int(np.count_nonzero(bad)), op=MPI.SUM)
        if not count:
            return Inversion()
        local_worst = (np.inf, None)
        if bad.any():
            values = np.where(np.isnan(ratios), -np.inf, ratios)
            i = int(np.argmin(values))
            local_worst = (float(values[i]), tuple(float(c) for c in self._midpoints[i]))
        candidates = [w for w in self.comm.allgather(local_worst) if w[1] is not None]
        return Inversion(count=count, where=min(candidates, key=lambda w: w[0])[1])


def _det(columns: list[np.ndarray]) -> np.ndarray:
    """Determinants of the (cells, d) column vectors, d = 2 or 3 (explicit: no stacking)."""
    if len(columns) == 2:
        (ax, ay), (bx, by) = columns[0].T, columns[1].T
        return ax * by - ay * bx
    (ax, ay, az), (bx, by, bz), (cx, cy, cz) = (c.T for c in columns)
    return ax * (by * cz - bz * cy) - ay * (bx * cz - bz * cx) + az * (bx * cy - by * cx)


def _facet_geometry(x: np.ndarray, facets: np.ndarray):
    """Centres, outward unit normals and sizes of the facets (rows of node indices into
    ``x``): 2D segments start -> end (normal (t_y, -t_x), outward as
    :func:`~dolfinx_mortar.surface.extract_surface` orients them) of their length; 3D
    triangles and quadrilaterals (normal at the centre) of their mean edge length."""
    corners = np.asarray(x, dtype=np.float64)[facets]
    centre = corners.mean(axis=1)
    if corners.shape[0] == 0:
        return centre, np.zeros_like(centre), np.zeros(0)
    edges = np.roll(corners, -1, axis=1) - corners
    if corners.shape[2] == 2:
        tangent = edges[:, 0]
        size = np.linalg.norm(tangent, axis=1)
        normal = np.stack([tangent[:, 1], -tangent[:, 0]], axis=1)
        normal /= np.where(size > 0, size, 1.0)[:, None]
        return centre, normal, size
    size = np.linalg.norm(edges, axis=2).mean(axis=1)
    return (
        centre,
        facet_normals(
            corners.reshape(-1, 3),
            np.arange(corners.shape[0] * corners.shape[1]).reshape(corners.shape[:2]),
        ),
        size,
    )


@dataclasses.dataclass
class Facing:
    """Where the two surfaces of a pair are closest, how their normals stand to each other."""

    facets_compared: int
    """Slave facets in the closest zone: within 2 slave facet lengths of the closest."""
    facets_looking_away: int
    """Of those, how many have n_slave . n_master > 0.5 with their nearest master facet."""
    mean_cosine: float
    """Mean n_slave . n_master over the compared facets (-1: facing each other)."""
    distance: float
    """The smallest distance between a slave and a master facet centre."""

    @property
    def looks_away(self) -> bool:
        """More than half the compared slave facets look away from their master."""
        return self.facets_compared > 0 and 2 * self.facets_looking_away > self.facets_compared


def facing_report(
    comm: MPI.Intracomm,
    slave_x: np.ndarray,
    slave_facets: np.ndarray,
    master_x: np.ndarray,
    master_facets: np.ndarray,
) -> Facing:
    """Collective: do the slave and the master surface face each other where they are closest?

    Contact needs opposed outward normals (the kernels pair only facets with
    n_slave . n_master < 0). A slave tagged on the wrong face of its body, or
    a master whose outward normal points into the slave's side, gives
    normals that point the same way where the surfaces are closest: contact
    can then never become active, and the bodies pass through each other.
    Surfaces in contact at an angle (cosine near 0) are not flagged.
    """
    s_centre, s_normal, s_length = _facet_geometry(slave_x, slave_facets)
    m_centre, m_normal, _ = _facet_geometry(master_x, master_facets)
    m_centre = np.vstack(comm.allgather(m_centre))
    m_normal = np.vstack(comm.allgather(m_normal))
    total_length = comm.allreduce(np.array([s_length.sum(), s_length.size]), op=MPI.SUM)
    if m_centre.shape[0] == 0 or total_length[1] == 0:
        return Facing(0, 0, float("nan"), float("inf"))
    h = total_length[0] / total_length[1]
    if s_centre.shape[0]:
        distance, nearest = cKDTree(m_centre).query(s_centre)
    else:
        distance, nearest = np.zeros(0), np.zeros(0, dtype=np.int64)
    smallest = comm.allreduce(float(np.min(distance, initial=np.inf)), op=MPI.MIN)
    zone = distance <= smallest + 2.0 * h
    cosine = np.einsum("ij,ij->i", s_normal[zone], m_normal[nearest[zone]])
    compared, away, cosines = comm.allreduce(
        np.array([zone.sum(), np.count_nonzero(cosine > 0.5), cosine.sum()], dtype=np.float64),
        op=MPI.SUM,
    )
    return Facing(int(compared), int(away), float(cosines / max(compared, 1)), smallest)


@dataclasses.dataclass
class Penetration:
    """Surface nodes that lie behind the other surface by more than a threshold."""

    count: int = 0
    depth: float = 0.0
    """The largest depth, relative to the local facet length."""
    where: tuple[float, ...] | None = None
    side: str = ""
    """"slave" (slave nodes behind the master surface) or "master" (the reverse)."""


def penetration_report(
    comm: MPI.Intracomm,
    threshold: float,
    slave_ids: np.ndarray,
    slave_x: np.ndarray,
    slave_facets: np.ndarray,
    master_ids: np.ndarray,
    master_x: np.ndarray,
    master_facets: np.ndarray,
) -> Penetration:
    """Collective: nodes of either surface that lie behind the other by > threshold x facet length.

    A node is behind a surface when the nearest facet of that surface (by
    the distance to the segment) has the node on its inner side and the
    node projects inside the facet. Mortar contact enforces the gap in a
    weighted (integral) sense, so corner nodes may sit slightly inside the
    other body (a few per cent of an element); a node deeper than
    ``threshold`` facet lengths means contact was not enforced there.

    Args:
        slave_ids, master_ids: global numbers of this rank's surface nodes (the rows of
            ``slave_x`` and ``master_x``); a node seen by several ranks counts once.
        slave_x, slave_facets, master_x, master_facets: this rank's facets.
    """
    worst = Penetration()
    for side, ids, points, x, facets in (
        ("slave", slave_ids, slave_x, master_x, master_facets),
        ("master", master_ids, master_x, slave_x, slave_facets),
    ):
        found = _behind(comm, ids, points, x, facets, threshold)
        if found.count:
            found.side = side
            if found.depth > worst.depth:
                found.count += worst.count
                worst = found
            else:
                worst.count += found.count
    return worst


def _behind(comm, ids, points, x, facets, threshold) -> Penetration:
    # every facet of the other surface: a node may be behind one at any depth
    corners = np.vstack(comm.allgather(np.asarray(x, dtype=np.float64)[facets]))
    depth = np.zeros(points.shape[0])
    deep = np.zeros(points.shape[0], dtype=bool)
    if corners.shape[0] and points.shape[0]:
        nodes = corners.shape[1]
        centre, normal, size = _facet_geometry(
            corners.reshape(-1, corners.shape[2]),
            np.arange(corners.shape[0] * nodes).reshape(-1, nodes),
        )
        k = min(8, corners.shape[0])
        _, candidates = cKDTree(centre).query(points, k=k)
        candidates = candidates.reshape(points.shape[0], k)
        distance, inside = _distance_to_facets(points, corners[candidates], normal[candidates])
        best = np.argmin(distance, axis=1)
        rows = np.arange(points.shape[0])
        facet = candidates[rows, best]
        relative = points - centre[facet]
        depth = -np.einsum("nc,nc->n", relative, normal[facet]) / size[facet]
        deep = inside[rows, best] & (depth > threshold)
    # a node on facets of several ranks is seen (and found deep) by each of them
    count = np.unique(np.concatenate(comm.allgather(np.asarray(ids)[deep]))).size
    local = (0.0, None)
    if deep.any():
        i = int(np.argmax(np.where(deep, depth, -np.inf)))
        local = (float(depth[i]), tuple(float(c) for c in points[i]))
    gathered = [g for g in comm.allgather(local) if g[1] is not None]
    if not count:
        return Penetration()
    depth_max, where = max(gathered, key=lambda g: g[0])
    return Penetration(count=int(count), depth=depth_max, where=where)


def _distance_to_facets(points: np.ndarray, corners: np.ndarray, normal: np.ndarray):
    """(distance, inside) of each point (n, d) to each of its k candidate facets
    (corners (n, k, m, d), unit normals (n, k, d)): inside when the point projects onto
    the facet (2D: onto the segment; 3D: into the polygon in the plane of its normal),
    the distance to that projection then, else to the nearest facet edge."""
    p = points[:, None, None, :]
    start = corners
    edge = (
        (np.roll(corners, -1, axis=2) - corners)
        if corners.shape[2] > 2
        else (corners[:, :, 1:] - corners[:, :, :1])
    )
    start = start[:, :, : edge.shape[2]]
    length2 = np.einsum("nkec,nkec->nke", edge, edge)
    t = np.einsum("nkec,nkec->nke", p - start, edge) / np.where(length2 > 0, length2, 1.0)
    closest = start + np.clip(t, 0.0, 1.0)[..., None] * edge
    to_edges = np.linalg.norm(p - closest, axis=3).min(axis=2)
    if corners.shape[3] == 2:
        inside = (t[:, :, 0] >= 0.0) & (t[:, :, 0] <= 1.0)
        return to_edges, inside
    side = np.einsum("nkec,nkc->nke", np.cross(edge, p - start), normal)
    inside = np.all(side >= 0.0, axis=2)
    plane = np.abs(np.einsum("nkc,nkc->nk", points[:, None, :] - corners.mean(axis=2), normal))
    return np.where(inside, plane, to_edges), inside


@dataclasses.dataclass
class FreeBody:
    """A body whose translation along some axes nothing in the bulk problem holds."""

    label: int
    """Its number from :func:`~dolfinx_mortar.surface.body_labels`."""
    axes: tuple[int, ...]
    """The coordinate axes (0 = x, 1 = y, 2 = z) of the free translations."""
    lower: tuple[float, ...]
    upper: tuple[float, ...]
    """The corners of its bounding box (reference coordinates)."""


def _block_labels(V, labels: np.ndarray) -> np.ndarray:
    """The body label of each (owned and ghost) dof block of V, from the cells' ``labels``."""
    index_map = V.dofmap.index_map
    dofmap = np.asarray(V.dofmap.list, dtype=np.int64)[: labels.size]
    block_label = np.full(index_map.size_local + index_map.num_ghosts, -1, dtype=np.int64)
    block_label[dofmap.reshape(-1)] = np.repeat(labels, dofmap.shape[1])
    return block_label


def free_translations(V, K, labels: np.ndarray, bcs, tolerance: float = 1e-8) -> list[FreeBody]:
    """Collective: bodies that a translation along a coordinate axis moves freely.

    A body (a connected set of cells, ``labels`` per local cell as
    :func:`~dolfinx_mortar.surface.body_labels` gives them) is free along axis c
    when no Dirichlet condition fixes a component c of any of its nodes and the
    bulk Jacobian ``K`` (assembled without the conditions) maps the unit
    translation t_c of its nodes to (nearly) nothing: ``|K t_c| <= tolerance
    max|diag K| |t_c|`` on the body. A spring or Robin term in the form holds
    the body and is not reported. Only contact could hold such a body; if it is
    not active, the Newton matrix is singular.
    """
    comm = V.mesh.comm
    bs = V.dofmap.index_map_bs
    index_map = V.dofmap.index_map
    block_label = _block_labels(V, labels)
    owned_label = block_label[: index_map.size_local]
    fixed = np.zeros((0, 2), dtype=np.int64)
    for bc in bcs:
        local = np.asarray(bc.dof_indices()[0], dtype=np.int64)
        fixed = np.vstack([fixed, np.column_stack([block_label[local // bs], local % bs])])
    fixed = np.unique(np.vstack(comm.allgather(fixed)), axis=0)
    bodies = np.unique(np.concatenate(comm.allgather(np.unique(labels))))
    x = V.tabulate_dof_coordinates()[: index_map.size_local, : V.mesh.geometry.dim]
    gdim = V.mesh.geometry.dim
    diagonal_vector = K.getDiagonal()
    diagonal = np.abs(diagonal_vector.getArray(readonly=True)).reshape(-1, bs)
    diagonal_vector.destroy()
    translation, image = K.createVecs()
    found = []
    for body in bodies:
        mine = owned_label == body
        held = set(fixed[fixed[:, 0] == body, 1].tolist())
        scale = comm.allreduce(float(diagonal[mine].max(initial=0.0)), op=MPI.MAX)
        count = comm.allreduce(int(mine.sum()), op=MPI.SUM)
        axes = []
        for axis in range(gdim):
            if axis in held:
                continue
            values = np.zeros((index_map.size_local, bs))
            values[mine, axis] = 1.0
            translation.getArray()[:] = values.reshape(-1)
            K.mult(translation, image)
            if image.norm() <= tolerance * scale * np.sqrt(count):
                axes.append(axis)
        if axes:
            points = x[mine]
            lower, upper = points.min(axis=0, initial=np.inf), points.max(axis=0, initial=-np.inf)
            comm.Allreduce(MPI.IN_PLACE, lower, op=MPI.MIN)
            comm.Allreduce(MPI.IN_PLACE, upper, op=MPI.MAX)
            found.append(FreeBody(int(body), tuple(axes), tuple(map(float, lower)),
                                  tuple(map(float, upper))))
    translation.destroy()
    image.destroy()
    return found


def translation_vectors(V, labels: np.ndarray, free: list[FreeBody]) -> list[np.ndarray]:
    """This rank's owned displacement dofs of each free translation of ``free`` (one unit
    vector per body and axis, as :func:`free_translations` found them), in the order of
    the bodies and their axes. ``labels`` as for :func:`free_translations`."""
    bs = V.dofmap.index_map_bs
    index_map = V.dofmap.index_map
    owned_label = _block_labels(V, labels)[: index_map.size_local]
    vectors = []
    for body in free:
        for axis in body.axes:
            values = np.zeros((index_map.size_local, bs))
            values[owned_label == body.label, axis] = 1.0
            vectors.append(values.reshape(-1))
    return vectors
