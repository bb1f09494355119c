"""Coulomb and Tresca friction with tangential multipliers (2D).

Per slave node j the multiplier is the vector lambda_j = z_j n_j + y_j tau_j,
with tau_j = R n_j the nodal normal turned by +90 degrees. The contact force
is -sum_j D_jk lambda_j on slave node k and +sum_j M_jl lambda_j on master
node l, so the displacement rows become

    R_u = F(u) - B^T z - T^T y,   T_j = -(R Dn)_j on slave dofs, +(R Mn)_j on master dofs,

and everything T needs comes from the kernel's Dn and Mn (R is constant):
no new mortar integrals. The weighted slip of the slave against the master
over the current solve is

    u~_j = tau_j . (sum_k D_jk du_k - sum_l M_jl du_l) = -T_j du,   du = u - u_start,

with u_start the state the solve started from (the previous converged step;
a cut-back restores it), and s_j = u~_j / A_j its nodal value (a length). It
is exact for a rigid translation; a rigid rotation by theta within one step
adds theta g~_j, which vanishes on active nodes, where the gap is closed.

The conditions, on active nodes (a projection, or Alart-Curnier, form of the
complementarity function of Hueber, Stadler and Wohlmuth, 2008):

    C_j = y_j - P_b(v_j),   v_j = y_j + c_t s_j,   P_b = projection onto [-b, b],

b_j = mu max(z_j, 0) (Coulomb) or the given bound (Tresca); y_j = 0 on the
other nodes. Stick, |v_j| < b_j: C_j = -c_t s_j, no slip. Slip: y_j = b_j
sign(v_j), parallel to s_j, so the friction traction -y_j on the slave
opposes its slip, and the nodal dissipation y_j u~_j is never negative. The
semismooth Newton derivative is exact in both states. At the kink: a node
that has just come into contact (b = 0, v = 0) starts held instead of sliding
freely for one iteration, except for mu = 0, which always slips: y = 0 with no
coupling at all, the frictionless Newton path; a node at its bound to within
1e-6 (a slipping node at the start of the next step, where s = 0 and y = b
to solver tolerance) slips, instead of dragging the other body along by a
whole load increment in the first iterate (on frictional ironing that
inverted elements). With the penalty method v_j = eps_t s_j
(regularized stick, y = eps_t s while it sticks).

Rows are scaled by h^(d-1), like the normal rows (:mod:`enforcement`).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from petsc4py import PETSc

LAWS = ("coulomb", "tresca")

STICK_BAND = 1e-6
"""|v| within this fraction of the slip bound counts as slipping (see tangential_rows)."""

ROTATION = np.array([[0.0, -1.0], [1.0, 0.0]])
"""R: tau = R n."""


@dataclasses.dataclass(frozen=True)
class FrictionLaw:
    """``("coulomb", mu)``: slip bound mu z_j; ``("tresca", bound)``: a fixed bound (a pressure)."""

    kind: str
    value: float

    @classmethod
    def parse(cls, friction) -> FrictionLaw | None:
        """A law from the user's ``friction`` (None, a (kind, value) pair or a FrictionLaw)."""
        if friction is None or isinstance(friction, FrictionLaw):
            return friction
        try:
            kind, value = friction
        except (TypeError, ValueError):
            raise ValueError(
                f"friction must be None, ('coulomb', mu) or ('tresca', bound); got {friction!r}"
            ) from None
        if kind not in LAWS:
            raise ValueError(f"unknown friction law {kind!r}; expected one of {LAWS}")
        value = float(value)
        if not value >= 0.0:
            raise ValueError(f"the {kind} friction parameter must be >= 0, got {value}")
        return cls(kind, value)


@dataclasses.dataclass
class TangentialRows:
    """Owned tangential rows of one pair: residual C_j and its derivative
    dC_j = slip du~_j + gap dg~_j + area dA_j + normal dz_j + own dy_j; ``sticking``."""

    residual: np.ndarray
    slip: np.ndarray
    gap: np.ndarray
    area: np.ndarray
    normal: np.ndarray
    own: np.ndarray
    sticking: np.ndarray


def tangential_rows(law: FrictionLaw | None, weight: float, c_t: float, c_n: float | None,
                    y: np.ndarray, z: np.ndarray, active: np.ndarray, slip: np.ndarray,
                    gap: np.ndarray, area: np.ndarray) -> TangentialRows:
    """The rows of the module docstring at the current state (weight = h^(d-1)).

    ``c_n`` given (Lagrange multipliers): the Coulomb bound is mu max(0, z_j - c_n g^_j),
    the normal complementarity quantity (equal to mu z_j once the gap is closed), as in
    Hueber, Stadler and Wohlmuth and Gitterle et al.; None (penalty): mu max(0, z_j).
    """
    n = y.size
    residual = weight * y
    d_slip, d_gap, d_area, d_normal = (np.zeros(n) for _ in range(4))
    d_own = np.full(n, weight)
    sticking = np.zeros(n, dtype=bool)
    if law is None or not np.any(active):
        return TangentialRows(residual, d_slip, d_gap, d_area, d_normal, d_own, sticking)
    lagrange = c_n is not None
    a = np.where(active, area, 1.0)
    s = slip / a
    v = (y if lagrange else 0.0) + c_t * s
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
    # a node that just came into contact (b = 0, nothing slipped: v = 0) starts held, not
    # free to slide; one at its slip bound to rounding (a slipping node at the start of
    # the next step) keeps slipping instead of dragging the other body along for an iterate
    new = (bound == 0.0) & (v == 0.0) & (law.value > 0.0)
    sticking = active & ((np.abs(v) < (1.0 - STICK_BAND) * bound) | new)
    slipping = active & ~sticking
    sign = np.sign(v)
    residual[sticking] = weight * (y - v)[sticking]
    d_slip[sticking] = -weight * c_t / a[sticking]
    d_area[sticking] = weight * c_t * (slip / a**2)[sticking]
    d_own[sticking] = 0.0 if lagrange else weight
    residual[slipping] = weight * (y - bound * sign)[slipping]
    d_normal[slipping] = -weight * (db_dz * sign)[slipping]
    d_gap[slipping] = -weight * (db_dgap * sign)[slipping]
    d_area[slipping] = -weight * (db_darea * sign)[slipping]
    return TangentialRows(residual, d_slip, d_gap, d_area, d_normal, d_own, sticking)


def tangential_coefficients(force_coefficients: np.ndarray) -> np.ndarray:
    """T's values (rows, j, nodes, 2) from B's (-Dn slave, +Mn master): R applied to each."""
    return force_coefficients @ ROTATION.T


def pair_slip(force_coefficients: np.ndarray, du: np.ndarray) -> np.ndarray:
    """(rows, j): each pair's part of u~_j = -T_j du, du (rows, facet nodes, 2)."""
    return -np.einsum("njkc,nkc->nj", tangential_coefficients(force_coefficients), du)


def slip_terms(stencil, j: int, du_slave: np.ndarray, du_master: np.ndarray,
               weight: np.ndarray) -> list:
    """Combined-gradient terms of weight * u~_j over the pair's kernel outputs at fixed du.

    u~_j = sum_k Dn_jk . (R^T du_k) - sum_l Mn_jl . (R^T du_l); du_* are (rows, nodes, 2).
    """
    rotated_slave = du_slave @ ROTATION
    rotated_master = du_master @ ROTATION
    terms = [(stencil.dn(j, k, c), weight * rotated_slave[:, k, c])
             for k in range(stencil.ns) for c in range(2)]
    terms += [(stencil.mn(j, m, c), -weight * rotated_master[:, m, c])
              for m in range(stencil.nm) for c in range(2)]
    return terms


def add_tangential_force(interface, y: PETSc.Vec, vector: PETSc.Vec) -> None:
    """Add -T^T y to ``vector`` (displacement layout), as ``contact_force`` adds -B^T z."""
    q = interface._require()
    rows = interface._rows(q)
    y_pair = interface.node_values(y)[interface.pair_slave_nodes[rows]]
    tangent = tangential_coefficients(interface._force_coefficient_values(q, rows))
    force = -np.einsum("nj,njkc->nkc", y_pair, tangent)
    vector.setValues(interface._force_columns()[rows].reshape(-1).astype(PETSc.IntType),
                     force.reshape(-1), addv=PETSc.InsertMode.ADD_VALUES)
    vector.assemble()


def laws_per_pair(friction, num_pairs: int) -> list[FrictionLaw | None]:
    """One law (or None) per pair from the user's ``friction``: one for all, or a list."""
    if isinstance(friction, list):
        if len(friction) != num_pairs:
            raise ValueError(f"friction: got {len(friction)} laws for {num_pairs} contact pairs")
        return [FrictionLaw.parse(f) for f in friction]
    law = FrictionLaw.parse(friction)
    return [law] * num_pairs


def check_options(gdim: int, method: str, active_set: str, condensation: bool,
                  linear_solver: str) -> None:
    """Raise for the combinations friction does not support (yet)."""
    if gdim != 2:
        raise ValueError("friction is implemented in 2D only; 3D contact is frictionless for now")
    if method not in ("lagrange", "penalty"):
        raise ValueError(f"friction works with method='lagrange' or 'penalty', got {method!r}")
    if active_set != "semismooth":
        raise ValueError("friction needs active_set='semismooth' (the stick and slip sets are "
                         "decided in the Newton iterations)")
    if condensation or linear_solver != "direct":
        raise ValueError("friction needs linear_solver='direct' without condensation (the "
                         "condensed system does not hold the tangential rows yet)")


class Friction:
    """The frictional part of a contact problem: per pair a law, the tangential multipliers
    y (one ghosted vector, laid out like the normal ones), the weighted slips u~ of the
    owned slave nodes since the solve started, and du = u - u_start at each node table.

    Args:
        laws: one :class:`FrictionLaw` or None (frictionless) per pair.
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
        self.multipliers = [i.create_multiplier_vector() for i in interfaces]
        self.slips = [np.zeros(i.num_owned_multipliers) for i in interfaces]
        self.increments: list[np.ndarray | None] = [None] * len(interfaces)
        self._start = u.x.array.copy()

    def start(self, u) -> None:
        """Measure slips from u (the state a solve starts from)."""
        self._start = u.x.array.copy()

    def update_slip(self, k: int, u, vector: PETSc.Vec) -> None:
        """u~_j of pair k's owned slave nodes at u, summed over the pairs through the ghosted
        multiplier-layout ``vector`` (collective)."""
        interface = self.interfaces[k]
        q = interface.quantities
        table = interface.node_field(u.x.array - self._start)
        self.increments[k] = table
        rows = interface._rows(q)
        stencil = interface.stencil
        du = np.concatenate([table[stencil.slave_nodes[rows]], table[stencil.master_nodes[rows]]],
                            axis=1)
        values = pair_slip(interface._force_coefficient_values(q, rows), du)
        vector.zeroEntries()
        vector.setValues(interface.pair_multipliers[rows].reshape(-1).astype(PETSc.IntType),
                         values.reshape(-1), addv=PETSc.InsertMode.ADD_VALUES)
        vector.assemble()
        self.slips[k] = vector.getArray(readonly=True).copy()

    def rows(self, k: int, z: np.ndarray, active: np.ndarray, gap: np.ndarray,
             area: np.ndarray) -> TangentialRows:
        """Pair k's owned tangential rows at the current state."""
        return tangential_rows(self.laws[k], self.weight, self.c_t, self.c_n,
                               self.multipliers[k].getArray(readonly=True), z, active,
                               self.slips[k], gap, area)

    def add_forces(self, vector: PETSc.Vec) -> None:
        """Add -T^T y of every pair to ``vector`` (displacement layout)."""
        for interface, y in zip(self.interfaces, self.multipliers, strict=True):
            add_tangential_force(interface, y, vector)

    def forces(self, k: int, rows: np.ndarray, coefficients: np.ndarray) -> tuple:
        """(slave, master) friction force of pair k's pairs ``rows`` on this rank, from B's
        coefficients of those rows."""
        interface = self.interfaces[k]
        y = interface.node_values(self.multipliers[k])[interface.pair_slave_nodes[rows]]
        tangent = tangential_coefficients(coefficients)
        ns = interface.stencil.ns
        return (np.einsum("nj,njkc->c", y, tangent[:, :, :ns]),
                np.einsum("nj,njlc->c", y, tangent[:, :, ns:]))

    def state(self, k: int, rows: TangentialRows, active: np.ndarray,
              area: np.ndarray) -> dict:
        """Pair k's nodal state (see ContactProblem.friction_state)."""
        y = self.multipliers[k].getArray(readonly=True).copy()
        safe_area = np.where(active, area, 1.0)
        return {
            "coordinates": self.interfaces[k].owned_multiplier_coordinates.copy(),
            "traction": y,
            "slip": np.where(active, self.slips[k] / safe_area, 0.0),
            "sticking": rows.sticking.copy(),
            "slipping": active & ~rows.sticking,
            "dissipation": y * self.slips[k],
        }

    def destroy(self) -> None:
        for y in self.multipliers:
            y.destroy()
