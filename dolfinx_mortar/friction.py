"""Coulomb and Tresca friction with tangential multipliers (2D and 3D).

Per slave node j the multiplier is the vector lambda_j = z_j n_j + sum_a y_j^a tau_j^a
(a < d - 1). The contact force is -sum_j D_jk lambda_j on slave node k and
+sum_j M_jl lambda_j on master node l, so the displacement rows become

    R_u = F(u) - B^T z - sum_a (T^a)^T y^a,

with T^a_j the tangential counterpart of B_j:

- 2D: tau_j = R n_j, the normal turned by +90 degrees, and T_j = -(R Dn)_j on
  slave dofs, +(R Mn)_j on master dofs: everything comes from the kernel's Dn
  and Mn (R is constant), no new mortar integrals.
- 3D: a frame tau^1_j, tau^2_j of the tangent plane of the averaged nodal
  normal n_j (tau^1 the unit projection of a fixed axis e of the interface onto
  that plane, tau^2 = n x tau^1; the averaged normals also with the ``slave``
  and ``master`` normal options, which have no single normal per node), and
  T^a_j = -D_jk tau^a_j on slave dofs, +M_jl tau^a_j on master dofs (Gitterle,
  Popp, Gee and Wall 2010). D and M come from the kernel with their
  gradients; the frame's derivative is chained through d n_j / dx over the
  node's facet star. A tangent direction along a prescribed displacement of
  its node (a symmetry plane) carries no friction (:meth:`Friction.
  set_fixed_components`).

The weighted slip of the slave against the master over the current solve is

    u~^a_j = -T^a_j du,   du = u - u_start,

with u_start the state the solve started from (the previous converged step;
a cut-back restores it), and s_j = u~_j / A_j its nodal value (a length). It
is exact for a rigid translation; a rigid rotation by theta within one step
adds a term proportional to theta and the gap, which vanishes on active nodes.

The conditions, on active nodes (a projection, or Alart-Curnier, form of the
complementarity function of Hueber, Stadler and Wohlmuth, 2008):

    C_j = y_j - P_b(v_j),   v_j = y_j + c_t s_j,

P_b the projection onto the interval [-b, b] (2D) or the disc of radius b
(3D), b_j = mu max(0, z_j - c_n g^_j) (Coulomb) or the given bound (Tresca);
y_j = 0 on the other nodes. Stick, |v_j| < b_j: C_j = -c_t s_j, no slip.
Slip: y_j = b_j v_j / |v_j|, parallel to s_j, so the friction traction -y_j on
the slave opposes its slip and the nodal dissipation y_j . u~_j is never
negative. The semismooth Newton derivative is exact in both states (in 3D the
slip derivative b/|v| (I - v v^T/|v|^2) dv + v/|v| db couples the two
components of a node). At the kink: a node that has just come into contact
(b = 0, v = 0) starts held instead of sliding freely for one iteration,
except for mu = 0, which always slips: y = 0 with no coupling at all, the
frictionless Newton path; a node at its bound to within 1e-6 (a slipping node
at the start of the next step, where s = 0 and |y| = b to solver tolerance)
slips, instead of dragging the other body along by a whole load increment in
the first iterate (on frictional ironing that inverted elements). With the
penalty method v_j = eps_t s_j (regularized stick, y = eps_t s while it sticks).

Rows are scaled by h^(d-1), like the normal rows (:mod:`enforcement`).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from .dual import rows_of
from .options import FrictionLaw

STICK_BAND = 1e-6
"""|v| within this fraction of the slip bound counts as slipping (see tangential_rows)."""

ROTATION = np.array([[0.0, -1.0], [1.0, 0.0]])
"""R: tau = R n (2D)."""

ALIGNED = 0.99
"""3D: a tangent direction within 8 degrees of a prescribed displacement component of
its node lies along it (a symmetry plane: the averaged normal there leans a little out of
the plane, the star holding only the model's half of the node's facets)."""

FRAME_DEGENERACY = 1e-3
"""3D: an active node whose normal is this close to parallel (|(I - n n^T) e|) to the
interface's frame axis e has no usable tangent frame."""


@dataclasses.dataclass
class TangentialRows:
    """Owned tangential rows of one pair, m = d - 1 components per node: residual C_j
    (n, m) and its derivative dC_j = slip du~_j + gap dg~_j + area dA_j + normal dz_j
    + own dy_j (slip, own: (n, m, m); gap, area, normal: (n, m)); ``sticking`` (n,);
    ``pressure`` (n,): the normal multipliers z_j the rows were computed from (set by
    :meth:`Friction.rows`, so that the nodal state reports the pressure of its own rows)."""

    residual: np.ndarray
    slip: np.ndarray
    gap: np.ndarray
    area: np.ndarray
    normal: np.ndarray
    own: np.ndarray
    sticking: np.ndarray
    pressure: np.ndarray | None = None


def tangential_rows(law: FrictionLaw | None, weight: float, c_t: float, c_n: float | None,
                    y: np.ndarray, z: np.ndarray, active: np.ndarray, slip: np.ndarray,
                    gap: np.ndarray, area: np.ndarray,
                    held: np.ndarray | None = None) -> TangentialRows:
    """The rows of the module docstring at the current state (weight = h^(d-1)).

    y and slip are (n, m). ``held`` (n, m): components along a prescribed displacement
    of the slave node (a symmetry plane): y^a = 0 there, and the law acts on the others.
    ``c_n`` given (Lagrange multipliers): the Coulomb bound is
    mu max(0, z_j - c_n g^_j), the normal complementarity quantity (equal to mu z_j once
    the gap is closed), as in Hueber, Stadler and Wohlmuth and Gitterle et al.; None
    (penalty): mu max(0, z_j).

    It stays in one piece for the stick, slip, turning and held cases: they overwrite the rows
    of their nodes in turn from the same bound, direction and slip arrays.
    """
    n, m = y.shape
    identity = np.eye(m)
    residual = weight * y
    d_slip = np.zeros((n, m, m))
    d_gap, d_area, d_normal = (np.zeros((n, m)) for _ in range(3))
    d_own = np.broadcast_to(weight * identity, (n, m, m)).copy()
    sticking = np.zeros(n, dtype=bool)
    if law is None or not np.any(active):
        return TangentialRows(residual, d_slip, d_gap, d_area, d_normal, d_own, sticking)
    lagrange = c_n is not None
    free = np.ones((n, m)) if held is None else (~held).astype(float)
    a = np.where(active, area, 1.0)
    s = slip / a[:, None]
    v = ((y if lagrange else 0.0) + c_t * s) * free
    # the bound b and its derivatives over z, g~ and A
    db_dz, db_dgap, db_darea = np.zeros(n), np.zeros(n), np.zeros(n)
    if law.kind == "coulomb":
        pressure = z - c_n * gap / a if lagrange else z
        bound = law.value * np.maximum(pressure, 0.0)
        pressing = pressure > 0.0
        db_dz[pressing] = law.value
        if lagrange:
            db_dgap[pressing] = -law.value * c_n / a[pressing]
            db_darea[pressing] = law.value * c_n * (gap / a**2)[pressing]
    else:
        bound = np.full(n, law.value)
    size = np.abs(v[:, 0]) if m == 1 else np.linalg.norm(v, axis=1)
    # a node that just came into contact (b = 0, nothing slipped: v = 0) starts held, not
    # free to slide; one at its slip bound to rounding (a slipping node at the start of
    # the next step) keeps slipping instead of dragging the other body along for an iterate
    new = (bound == 0.0) & (size == 0.0) & (law.value > 0.0)
    sticking = active & ((size < (1.0 - STICK_BAND) * bound) | new)
    slipping = active & ~sticking
    moving = size > 0.0
    direction = np.zeros((n, m))
    if m == 1:
        direction[:, 0] = np.sign(v[:, 0])
    else:
        direction[moving] = v[moving] / size[moving, None]
    residual[sticking] = weight * (y - v)[sticking]
    d_slip[sticking] = -weight * c_t / a[sticking, None, None] * identity
    d_area[sticking] = weight * c_t * (slip / a[:, None] ** 2 * free)[sticking]
    d_own[sticking] = 0.0 if lagrange else weight * identity
    residual[slipping] = weight * (y - bound[:, None] * direction)[slipping]
    d_normal[slipping] = -weight * (db_dz[:, None] * direction)[slipping]
    d_gap[slipping] = -weight * (db_dgap[:, None] * direction)[slipping]
    d_area[slipping] = -weight * (db_darea[:, None] * direction)[slipping]
    if m > 1:
        # d(b v/|v|) = v/|v| db + b/|v| (I - v v^T/|v|^2) dv, dv = dy + c_t (du~/A - u~ dA/A^2)
        turning = slipping & moving
        ratio = np.where(turning, bound / np.where(moving, size, 1.0), 0.0)
        P = ratio[:, None, None] * (identity - direction[:, :, None] * direction[:, None, :])
        P *= free[:, None, :]  # dv^a = 0 for held components
        if lagrange:
            d_own[turning] -= weight * P[turning]
        d_slip[turning] = -weight * c_t * P[turning] / a[turning, None, None]
        d_area[turning] += weight * c_t * np.einsum(
            "nab,nb->na", P, slip / a[:, None] ** 2)[turning]
    if held is not None and held.any():
        # v^a = 0 whatever y^a and u~^a: nothing depends on them; their rows are y^a = 0
        d_slip *= free[:, None, :]
        rows = np.nonzero(held)
        residual[rows] = weight * y[rows]
        for out in (d_gap, d_area, d_normal):
            out[rows] = 0.0
        d_slip[rows[0], rows[1], :] = 0.0
        d_own[rows[0], rows[1], :] = 0.0
        d_own[rows[0], rows[1], rows[1]] = weight
    return TangentialRows(residual, d_slip, d_gap, d_area, d_normal, d_own, sticking)


def tangent_frames(normals: np.ndarray, axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """3D nodal frames (..., 2, 3) and their derivatives d tau^a[c] / d n[e] (..., 2, 3, 3).

    tau^1 = w / |w|, w = (I - n n^T) e, tau^2 = n x tau^1: smooth in n away from n = +-e.
    """
    e = np.asarray(axis, dtype=float)
    along = normals @ e
    w = e - along[..., None] * normals
    size = np.maximum(np.linalg.norm(w, axis=-1), 1e-300)
    tau1 = w / size[..., None]
    tau2 = np.cross(normals, tau1)
    eye = np.eye(3)
    # dw/dn = -n e^T - (n . e) I; d tau1 = (I - tau1 tau1^T) dw / |w|
    dw = -normals[..., :, None] * e - along[..., None, None] * eye
    projector = eye - tau1[..., :, None] * tau1[..., None, :]
    dtau1 = projector @ dw / size[..., None, None]
    # d(n x tau1) = dn x tau1 + n x dtau1 = -[tau1]x dn + [n]x dtau1
    dtau2 = -_cross_matrix(tau1) + _cross_matrix(normals) @ dtau1
    return np.stack([tau1, tau2], axis=-2), np.stack([dtau1, dtau2], axis=-3)


def frame_degeneracy(normals: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """|(I - n n^T) e| per normal: 1 when n is normal to the axis, 0 when parallel."""
    along = normals @ np.asarray(axis, dtype=float)
    return np.sqrt(np.maximum(1.0 - along**2, 0.0))


def _cross_matrix(a: np.ndarray) -> np.ndarray:
    """[a]x (..., 3, 3): [a]x b = a x b."""
    result = np.zeros(a.shape + (3,))
    result[..., 0, 1], result[..., 0, 2] = -a[..., 2], a[..., 1]
    result[..., 1, 0], result[..., 1, 2] = a[..., 2], -a[..., 0]
    result[..., 2, 0], result[..., 2, 1] = -a[..., 1], a[..., 0]
    return result


def frame_axis(interface) -> np.ndarray:
    """The coordinate axis least aligned with the slave surface's facet normals (the
    largest |n . e| over the undeformed facets, over all ranks, is smallest): the axis
    of the interface's 3D tangent frames (collective)."""
    corners = interface.slave.reference_coordinates[interface.slave.facets]
    if corners.shape[0]:
        if corners.shape[1] == 3:
            normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        else:
            normals = np.cross(corners[:, 2] - corners[:, 0], corners[:, 3] - corners[:, 1])
        normals /= np.linalg.norm(normals, axis=1)[:, None]
        largest = np.abs(normals).max(axis=0)
    else:
        largest = np.zeros(3)
    largest = np.ascontiguousarray(largest, dtype=np.float64)
    interface.comm.Allreduce(MPI.IN_PLACE, largest, op=MPI.MAX)
    return np.eye(3)[int(np.argmin(largest))]


class PairTangents:
    """The tangential coefficients of some pairs of one interface and the combined-gradient
    terms of their derivatives (one subclass per dimension: :class:`RotatedPairTangents`,
    :class:`FramePairTangents`).

    Attributes:
        coefficients: T (rows, m, j, ns + nm nodes, gdim): -tau D on slave nodes,
            +tau M on master nodes.
    """

    coefficients: np.ndarray

    def slip(self, du: np.ndarray) -> np.ndarray:
        """(rows, m, j): each pair's part of u~^a_j = -T^a_j du, du (rows, nodes, gdim)."""
        return -np.einsum("rajkc,rkc->raj", self.coefficients, du)

    def force(self, y: np.ndarray) -> np.ndarray:
        """(rows, nodes, gdim): -T^T y of each pair, y (rows, m, j)."""
        return -np.einsum("raj,rajkc->rkc", y, self.coefficients)

    def force_terms(self, y: np.ndarray) -> tuple[list, list]:
        """Combined-gradient terms of the force rows' d(-T^T y)/dx at fixed y (rows, m, j):
        (per slave node and component, per master node and component)."""
        raise NotImplementedError

    def slip_terms(self, j: int, a: int, du_slave: np.ndarray, du_master: np.ndarray,
                   weight: np.ndarray) -> list:
        """Combined-gradient terms of weight * u~^a_j at fixed du (du_*: (rows, nodes, gdim))."""
        raise NotImplementedError


class RotatedPairTangents(PairTangents):
    """2D: tau = R n, so T is R applied to the kernel's Dn and Mn (R constant)."""

    def __init__(self, interface, rows: np.ndarray):
        self.stencil = interface.stencil
        forces = interface.force_coefficients(rows)  # -Dn slave, +Mn master
        self.coefficients = (forces @ ROTATION.T)[:, None]

    def force_terms(self, y: np.ndarray) -> tuple[list, list]:
        stencil, js, R = self.stencil, range(self.stencil.ns), ROTATION
        slave = [[(stencil.dn(j, a, e), R[c, e] * y[:, 0, j]) for j in js for e in range(2)
                  if R[c, e]] for a in range(stencil.ns) for c in range(2)]
        master = [[(stencil.mn(j, a, e), -R[c, e] * y[:, 0, j]) for j in js
                   for e in range(2) if R[c, e]] for a in range(stencil.nm) for c in range(2)]
        return slave, master

    def slip_terms(self, j: int, a: int, du_slave: np.ndarray, du_master: np.ndarray,
                   weight: np.ndarray) -> list:
        # u~_j = sum_k Dn_jk . (R^T du_k) - sum_l Mn_jl . (R^T du_l)
        stencil = self.stencil
        rotated_slave = du_slave @ ROTATION
        rotated_master = du_master @ ROTATION
        terms = [(stencil.dn(j, k, c), weight * rotated_slave[:, k, c])
                 for k in range(stencil.ns) for c in range(2)]
        return terms + [(stencil.mn(j, m, c), -weight * rotated_master[:, m, c])
                        for m in range(stencil.nm) for c in range(2)]


class FramePairTangents(PairTangents):
    """3D: the nodal frames tau^a on the averaged normals; T^a = -D tau^a / +M tau^a, the
    frames' derivatives chained through the normals' (stencil outputs ``normal``)."""

    def __init__(self, interface, rows: np.ndarray, axis: np.ndarray):
        self.stencil = stencil = interface.stencil
        q = interface.quantities
        self.frames, self.frame_derivatives = tangent_frames(stencil.slave_normals(rows), axis)
        self.D, self.M = rows_of(q.D_rows, q.rows, rows), rows_of(q.M_rows, q.rows, rows)
        weights = np.concatenate([-self.D, self.M], axis=2)  # (rows, j, nodes)
        tau = self.frames.transpose(0, 2, 1, 3)  # (rows, a, j, 3)
        self.coefficients = weights[:, None, :, :, None] * tau[:, :, :, None, :]

    def force_terms(self, y: np.ndarray) -> tuple[list, list]:
        stencil, js = self.stencil, range(self.stencil.ns)
        # -T^T y = sum_j (D_jk on slave, -M_jl on master) y_j . tau_j
        traction = np.einsum("raj,rjac->rjc", y, self.frames)  # sum_a y^a tau^a
        turning = np.einsum("raj,rjace->rjce", y, self.frame_derivatives)
        slave = [[(stencil.d(j, k), traction[:, j, c]) for j in js]
                 + [(stencil.normal(j, e), self.D[:, j, k] * turning[:, j, c, e])
                    for j in js for e in range(3)]
                 for k in range(stencil.ns) for c in range(3)]
        master = [[(stencil.m(j, l), -traction[:, j, c]) for j in js]
                  + [(stencil.normal(j, e), -self.M[:, j, l] * turning[:, j, c, e])
                     for j in js for e in range(3)]
                  for l in range(stencil.nm) for c in range(3)]
        return slave, master

    def slip_terms(self, j: int, a: int, du_slave: np.ndarray, du_master: np.ndarray,
                   weight: np.ndarray) -> list:
        # u~^a_j = tau^a_j . r_j, r_j = sum_k D_jk du_k - sum_l M_jl du_l
        stencil = self.stencil
        tau = self.frames[:, j, a]
        r = (np.einsum("rk,rkc->rc", self.D[:, j], du_slave)
             - np.einsum("rl,rlc->rc", self.M[:, j], du_master))
        turning = np.einsum("rc,rce->re", r, self.frame_derivatives[:, j, a])
        terms = [(stencil.d(j, k), weight * np.einsum("rc,rc->r", tau, du_slave[:, k]))
                 for k in range(stencil.ns)]
        terms += [(stencil.m(j, l), -weight * np.einsum("rc,rc->r", tau, du_master[:, l]))
                  for l in range(stencil.nm)]
        return terms + [(stencil.normal(j, e), weight * turning[:, e]) for e in range(3)]


class RotatedNormal:
    """2D tangent directions of one interface: tau = R n, one component, defined wherever
    the normal is; no symmetry-plane holding (the tangent of a 2D symmetry line's node is
    along the line: a prescribed component there is the normal one)."""

    components = 1
    holds_fixed_components = False

    def __init__(self, interface):
        self.interface = interface

    def pair_tangents(self, rows: np.ndarray) -> PairTangents:
        return RotatedPairTangents(self.interface, rows)

    def check(self, active: np.ndarray) -> None:
        """Nothing to check: the rotated normal is always a tangent."""

    def per_node(self, values: np.ndarray) -> np.ndarray:
        """(n, 1) per-node component arrays as the nodal state reports them, (n,)."""
        return values[:, 0]

    def state(self) -> dict:
        return {}


class AxisFrames:
    """3D tangent frames of one interface: tau^1 the projection of the coordinate axis
    least aligned with the slave surface (:func:`frame_axis`, collective), tau^2 = n x tau^1,
    on the averaged nodal normals (:func:`tangent_frames`)."""

    components = 2
    holds_fixed_components = True

    def __init__(self, interface):
        self.interface = interface
        self.axis = frame_axis(interface)
        stencil = interface.stencil
        if stencil is not None and stencil.max_star == 0 and interface.normals != "averaged":
            raise RuntimeError("3D friction: set interface.scalar_gradients before the "
                               "first search (the stencils need the normals' stars)")

    def pair_tangents(self, rows: np.ndarray) -> PairTangents:
        return FramePairTangents(self.interface, rows, self.axis)

    def check(self, active: np.ndarray) -> None:
        """Raise (on every rank) if an active node's normal is parallel to the frame axis."""
        interface = self.interface
        bad = 0
        rows = (np.zeros(0, dtype=int) if interface.quantities is None
                else interface.contributing_pairs())
        if rows.size:
            normals = interface.stencil.slave_normals(rows)
            degenerate = frame_degeneracy(normals, self.axis) < FRAME_DEGENERACY
            local = interface.pair_multipliers[rows] - interface.multiplier_offset
            mine = (local >= 0) & (local < interface.num_owned_multipliers)
            local = np.where(mine, local, 0)
            bad = int(np.count_nonzero(degenerate & mine & active[local]))
        if interface.comm.allreduce(bad, op=MPI.SUM):
            raise RuntimeError(
                f"friction: {bad} active slave node(s) have a normal parallel to the tangent "
                f"frame's axis {self.axis} (chosen as the coordinate axis least aligned "
                "with the undeformed slave surface); a slave surface whose normals turn by "
                "90 degrees is not supported by the 3D frames yet")

    def per_node(self, values: np.ndarray) -> np.ndarray:
        return values

    def state(self) -> dict:
        return {"frames": self.nodal_frames()}

    def nodal_frames(self) -> np.ndarray:
        """(owned slave nodes, 2, 3): the tangent frames of the owned slave nodes at the
        last evaluation (zero at nodes in no candidate pair). Collective."""
        interface = self.interface
        if interface.quantities is None:
            indices, normals = np.zeros(0, dtype=PETSc.IntType), np.zeros((0, 3))
        else:
            rows = interface.contributing_pairs()
            indices = interface.pair_multipliers[rows].reshape(-1).astype(PETSc.IntType)
            normals = interface.stencil.slave_normals(rows).reshape(-1, 3)
        vector = interface.create_multiplier_vector()
        sums = []
        for values in [normals[:, c] for c in range(3)] + [np.ones(indices.size)]:
            vector.zeroEntries()
            vector.setValues(indices, values, addv=PETSc.InsertMode.ADD_VALUES)
            vector.assemble()
            sums.append(vector.getArray(readonly=True).copy())
        vector.destroy()
        count = sums[3]
        seen = count > 0
        mean = np.zeros((count.size, 3))
        mean[seen] = np.stack(sums[:3], axis=1)[seen] / count[seen, None]
        frames = np.zeros((count.size, 2, 3))
        if np.any(seen):
            unit = mean[seen] / np.linalg.norm(mean[seen], axis=1)[:, None]
            frames[seen] = tangent_frames(unit, self.axis)[0]
        return frames


TANGENT_DIRECTIONS = {2: RotatedNormal, 3: AxisFrames}
"""The tangent directions of each geometric dimension."""


def coefficient_names(components: int) -> tuple[str, ...]:
    """The ghosted multiplier-layout vectors that carry the tangential rows' coefficients
    to ghost slave nodes: slip_ab (dC^a/du~^b), slip_gap_a, slip_area_a."""
    pairs = range(components)
    return (tuple(f"slip_{a}{b}" for a in pairs for b in pairs)
            + tuple(f"slip_gap_{a}" for a in pairs) + tuple(f"slip_area_{a}" for a in pairs))


def check_options(method: str, active_set: str, condensation: bool,
                  linear_solver: str) -> None:
    """Raise for the combinations friction does not support (yet)."""
    if method not in ("lagrange", "penalty"):
        raise ValueError(f"friction works with method='lagrange' or 'penalty', got {method!r}")
    if active_set != "semismooth":
        raise ValueError("friction needs active_set='semismooth' (the stick and slip sets are "
                         "decided in the Newton iterations)")
    del condensation, linear_solver  # both solvers hold the tangential rows


class Friction:
    """The frictional part of a contact problem: per pair a law, the tangential multipliers
    y^a (m = d - 1 ghosted vectors, laid out like the normal ones), the weighted slips u~
    of the owned slave nodes since the solve started, and du = u - u_start at each node
    table.

    Args:
        laws: one law (:class:`~dolfinx_mortar.options.Coulomb` or
            :class:`~dolfinx_mortar.options.Tresca`) or None (frictionless) per pair.
        interfaces: the pairs' mortar interfaces.
        u: the displacement; slips are measured from its value now until
            :meth:`start` is called again (at each solve).
        c_t: the tangential complementarity parameter (or penalty).
        c_n: the normal complementarity parameter with Lagrange multipliers, None with
            penalty (the bound uses z itself then).
        weight: the row scale h^(d-1).
    """

    def __init__(self, laws: list, interfaces: list, u, c_t: float, c_n: float | None,
                 weight: float):
        self.laws = laws
        self.interfaces = interfaces
        self.c_t, self.c_n, self.weight = c_t, c_n, weight
        directions = TANGENT_DIRECTIONS[interfaces[0].gdim]
        self.components = directions.components
        self.multipliers = [[i.create_multiplier_vector() for _ in range(self.components)]
                            for i in interfaces]
        self.slips = [np.zeros((i.num_owned_multipliers, self.components)) for i in interfaces]
        self.increments: list[np.ndarray | None] = [None] * len(interfaces)
        self.directions = [directions(i) for i in interfaces]
        """Per pair, its tangent directions (:class:`RotatedNormal`, :class:`AxisFrames`)."""
        self.fixed: list[np.ndarray | None] = [None] * len(interfaces)
        self._tangents: dict[int, tuple] = {}
        self.held: list[np.ndarray | None] = [None] * len(interfaces)
        self._start = u.x.array.copy()

    @property
    def vectors(self) -> list[PETSc.Vec]:
        """Every y^a, pair by pair (the order of the layout's tangential fields)."""
        return [y for pair in self.multipliers for y in pair]

    def set_fixed_components(self, fixed: list[np.ndarray]) -> None:
        """Per pair, (owned slave nodes, gdim): the displacement components the Dirichlet
        conditions prescribe (collective). 3D: a tangent direction along a prescribed
        component (a symmetry plane through the coordinate axes, whose frames align with
        it) carries no friction, y^a = 0 (:func:`tangential_rows`); otherwise the mortar
        slip across a symmetry plane, integrated over the half of the neighbourhood the
        model holds, would be held by a spurious stick condition."""
        comm = self.interfaces[0].comm
        any_partial = [comm.allreduce(bool(np.any(f.any(axis=1) & ~f.all(axis=1))), op=MPI.LOR)
                       for f in fixed]
        self.fixed = [f if directions.holds_fixed_components and flag else None
                      for f, flag, directions in zip(fixed, any_partial, self.directions,
                                                     strict=True)]

    def start(self, u: np.ndarray) -> None:
        """Measure slips from the displacement values u (the state a solve starts from, or
        the last converged state when the solve starts from a predicted one)."""
        self._start = np.array(u, copy=True)

    def tangents(self, k: int, rows: np.ndarray) -> PairTangents:
        """Pair k's tangential coefficients of the pairs ``rows`` at the last evaluation
        (kept until the next one: the slip, the force and the Jacobian of an iterate share
        them)."""
        interface = self.interfaces[k]
        q = interface.quantities
        kept = self._tangents.get(k)
        if kept is not None and kept[0] is q and np.array_equal(kept[1], rows):
            return kept[2]
        tangents = self.directions[k].pair_tangents(rows)
        self._tangents[k] = (q, rows.copy(), tangents)
        return tangents

    def node_multipliers(self, k: int) -> list[np.ndarray]:
        """y^a of pair k at its node table, one array per component (collective: ghost
        values are exchanged)."""
        interface = self.interfaces[k]
        return [interface.node_values(y) for y in self.multipliers[k]]

    def pair_multipliers(self, k: int, rows: np.ndarray) -> np.ndarray:
        """(rows, m, j): y^a at the slave nodes of pair k's pairs ``rows`` (collective)."""
        nodes = self.interfaces[k].pair_slave_nodes[rows]
        return np.stack([y[nodes] for y in self.node_multipliers(k)], axis=1)

    def update_slip(self, k: int, u, vector: PETSc.Vec) -> None:
        """u~_j of pair k's owned slave nodes at u, summed over the pairs through the ghosted
        multiplier-layout ``vector`` (collective)."""
        interface = self.interfaces[k]
        table = interface.node_field(u.x.array - self._start)
        self.increments[k] = table
        rows = interface.contributing_pairs()
        stencil = interface.stencil
        du = np.concatenate([table[stencil.slave_nodes[rows]], table[stencil.master_nodes[rows]]],
                            axis=1)
        values = self.tangents(k, rows).slip(du)  # (rows, m, j)
        indices = interface.pair_multipliers[rows].reshape(-1).astype(PETSc.IntType)
        for a in range(self.components):
            vector.zeroEntries()
            vector.setValues(indices, values[:, a].reshape(-1), addv=PETSc.InsertMode.ADD_VALUES)
            vector.assemble()
            self.slips[k][:, a] = vector.getArray(readonly=True)
        if self.fixed[k] is not None:
            aligned = np.abs(self.directions[k].nodal_frames()) > ALIGNED  # (n, a, c)
            self.held[k] = (aligned & self.fixed[k][:, None, :]).any(axis=2)

    def rows(self, k: int, z: np.ndarray, active: np.ndarray, gap: np.ndarray,
             area: np.ndarray) -> TangentialRows:
        """Pair k's owned tangential rows at the current state."""
        y = np.stack([v.getArray(readonly=True) for v in self.multipliers[k]], axis=1)
        if self.laws[k] is not None:
            self.directions[k].check(active)
        rows = tangential_rows(self.laws[k], self.weight, self.c_t, self.c_n, y, z, active,
                               self.slips[k], gap, area, self.held[k])
        rows.pressure = np.array(z, dtype=float, copy=True)
        return rows

    def add_forces(self, vector: PETSc.Vec) -> None:
        """Add -T^T y of every pair to ``vector`` (displacement layout)."""
        for k, interface in enumerate(self.interfaces):
            rows = interface.contributing_pairs()
            force = self.tangents(k, rows).force(self.pair_multipliers(k, rows))
            vector.setValues(interface.pair_force_dofs_of(rows).reshape(-1).astype(PETSc.IntType),
                             force.reshape(-1), addv=PETSc.InsertMode.ADD_VALUES)
            vector.assemble()

    def forces(self, k: int, rows: np.ndarray) -> tuple:
        """(slave, master) friction force T^T y on each side (the load the residual's -T^T y
        balances, as B^T z for the pressure) of pair k's pairs ``rows`` on this rank."""
        force = -self.tangents(k, rows).force(self.pair_multipliers(k, rows))
        ns = self.interfaces[k].stencil.ns
        return force[:, :ns].sum(axis=(0, 1)), force[:, ns:].sum(axis=(0, 1))

    def state(self, k: int, rows: TangentialRows, active: np.ndarray,
              area: np.ndarray) -> dict:
        """Pair k's nodal state (see ContactProblem.friction_state), one row per owned slave
        node in the order of ContactProblem.contact_pressure; in 2D ``traction`` and
        ``slip`` are (n,), in 3D (n, 2) in the nodes' tangent frames, and ``frames``
        (n, 2, 3) holds those (collective in 3D)."""
        y = np.stack([v.getArray(readonly=True) for v in self.multipliers[k]], axis=1)
        safe_area = np.where(active, area, 1.0)
        slip = np.where(active[:, None], self.slips[k] / safe_area[:, None], 0.0)
        squeeze = self.directions[k].per_node
        state = {
            "coordinates": self.interfaces[k].owned_multiplier_coordinates.copy(),
            "pressure": (np.zeros(active.size) if rows.pressure is None
                         else rows.pressure.copy()),
            "traction": squeeze(y.copy()),
            "slip": squeeze(slip),
            "sticking": rows.sticking.copy(),
            "slipping": active & ~rows.sticking,
            "dissipation": np.einsum("na,na->n", y, self.slips[k]),
        }
        state.update(self.directions[k].state())
        return state

    def destroy(self) -> None:
        for y in self.vectors:
            y.destroy()
