"""How the contact conditions enter the multiplier rows: one strategy per method.

A strategy decides, per pair and owned slave node j, the active set and the
multiplier row C_j with its coefficients (alpha on the weighted gap g~_j, beta
on the nodal weight A_j, delta on z_j), and runs a solve: one Newton solve in
SNES, or an outer loop of them, through the :class:`NewtonSolver` protocol. The
problem owns the state (u, multipliers, gaps) and its solver the SNES; a strategy only
knows the scales and the rules.

* :class:`SemismoothLagrange`: C_j = z_j - max(0, z_j - c_n g^_j), g^_j = g~_j / A_j;
  the active set is decided in every Newton iteration.
* :class:`FixedPointLagrange`: the active set is frozen during a Newton
  solve, then updated from the averaged pressure and the nodal gap.
* :class:`Penalty`: z_j = max(0, -eps g^_j).
* :class:`AugmentedLagrange`: z_j = max(0, lam_j - eps g^_j) with Uzawa updates
  lam <- z until lam settles.

Rows are in force units (E x length in plane strain, E x area in 3D), whatever
the strategy: active Lagrange rows are s g~_j, inactive rows h^(d-1) z_j,
penalty rows w (z_j - lam_j + eps g^_j), with s ~ E/h, h the mean slave facet
length and w = h^(d-1) min(1, s/eps). The scaling is constant per row, so it changes no Newton
step; it makes SNES' tolerances independent of units, c_n and eps.
"""

from __future__ import annotations

import dataclasses
import typing

import numpy as np
from mpi4py import MPI

from . import diagnostics
from .deprecation import moved
from .options import ActiveSet, Method
from .solvers import SolveReport

METHODS = typing.get_args(Method)
ACTIVE_SET_STRATEGIES = typing.get_args(ActiveSet)


@dataclasses.dataclass(frozen=True)
class Scales:
    """The problem's stiffness and length scales (see the module docstring)."""

    row: float
    """s: about E/h of the slave side."""
    length: float
    """h: the mean slave facet length in the reference configuration."""
    dim: int = 2
    """The geometric dimension d."""

    @property
    def face(self) -> float:
        """h^(d-1): the size of a slave facet (a length in 2D, an area in 3D)."""
        return self.length ** (self.dim - 1)

    @property
    def dirichlet(self) -> float:
        """k = s h^(d-1): the scale of Dirichlet rows (force per displacement)."""
        return self.row * self.face

    @property
    def pressure(self) -> float:
        """s h: about E."""
        return self.row * self.length


class NewtonSolver(typing.Protocol):
    """What a strategy drives: the Newton solver of a contact problem
    (:class:`~dolfinx_mortar.newton.ContactNewton` implements it)."""

    comm: MPI.Intracomm
    interfaces: list
    """The pairs' mortar interfaces."""
    multipliers: list
    """The pairs' normal multiplier vectors z (owned slave nodes)."""

    def newton(self) -> SolveReport:
        """One Newton solve from the current iterate, into the state. Collective."""

    def nodal_gaps(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """(covered, g^) of pair k's owned slave nodes at the last contact update."""

    def update_contact(self) -> None:
        """The state from the current iterate, then gaps, areas and active sets at it."""


__getattr__ = moved(__name__, {"Solver": "dolfinx_mortar.enforcement.NewtonSolver"})

Rows = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]
"""(residual C_j, alpha, beta, delta) of the owned multiplier rows of one pair."""


class Enforcement:
    """Base class: the rules of one method (see the module docstring)."""

    name = ""

    def __init__(self, scales: Scales, num_multipliers: typing.Sequence[int]):
        self.scales = scales
        self.num_multipliers = list(num_multipliers)

    def decide_active(self, k: int, z: np.ndarray, covered: np.ndarray,
                      gap: np.ndarray) -> np.ndarray:
        """Active owned slave nodes of pair k from the multipliers and nodal gaps g^."""
        raise NotImplementedError

    def rows(self, k: int, z: np.ndarray, active: np.ndarray, gap: np.ndarray,
             area: np.ndarray) -> Rows:
        raise NotImplementedError

    def solve(self, solver: NewtonSolver) -> SolveReport:
        return solver.newton()

    def save_state(self) -> list[np.ndarray]:
        return []

    def restore_state(self, state: list[np.ndarray]) -> None:
        pass


class SemismoothLagrange(Enforcement):
    """Lagrange multipliers with the active set decided in every Newton iteration.

    Ties (z - c_n g^ = 0, e.g. touching at zero pressure) count as active: a
    valid choice of the generalized derivative at the kink of max(0, .), which
    keeps a body held only by contact attached when it starts exactly touching.
    The Jacobian is the exact generalized derivative, so Newton converges
    quadratically once the set has settled, and the solution does not depend on c_n.
    """

    name = "lagrange"

    def __init__(self, scales: Scales, num_multipliers, c_n: float):
        super().__init__(scales, num_multipliers)
        self.c_n = float(c_n)

    def decide_active(self, k, z, covered, gap):
        return covered & (z - self.c_n * gap >= 0.0)

    def rows(self, k, z, active, gap, area) -> Rows:
        weight = self.scales.face
        alpha = np.zeros_like(z)
        beta = np.zeros_like(z)
        delta = np.full_like(z, weight)
        residual = weight * z
        residual[active] = self.scales.row * gap[active]
        alpha[active] = self.scales.row
        delta[active] = 0.0
        return residual, alpha, beta, delta


class FixedPointLagrange(SemismoothLagrange):
    """Lagrange multipliers with the active set frozen during each Newton solve (paper,
    section 5): rows g~_j = 0 if active, z_j = 0 if not; then the set is updated from the
    averaged nodal pressure and the weighted gap, until it stops changing."""

    def __init__(self, scales: Scales, num_multipliers, c_n: float, max_outer_iterations: int):
        super().__init__(scales, num_multipliers, c_n)
        self.max_outer_iterations = max_outer_iterations
        self.frozen: list[np.ndarray] | None = None

    def decide_active(self, k, z, covered, gap):
        if self.frozen is None:
            return super().decide_active(k, z, covered, gap)
        return self.frozen[k] & covered

    def solve(self, solver: NewtonSolver) -> SolveReport:
        self.frozen = None
        solver.update_contact()
        self.frozen = []
        for k, z in enumerate(solver.multipliers):
            covered, gap = solver.nodal_gaps(k)
            self.frozen.append(covered & ((z.getArray(readonly=True) > 0) | (gap <= 0)))
        return outer_loop(solver, lambda: self._update(solver), self.max_outer_iterations,
                          diagnostics.FIXED_POINT_NOT_SETTLED)

    def _update(self, solver: NewtonSolver) -> bool:
        """One fixed-point update; True when no node changed on any rank.

        A node leaves the set when its averaged pressure is negative beyond
        rounding (1e-10 of the largest), and joins it when its nodal gap is
        negative beyond rounding: a node at zero pressure and zero gap must not
        flip in and out forever.
        """
        comm = solver.comm
        changed = 0
        new_sets = []
        for k in range(len(solver.interfaces)):
            pressure = averaged_pressure(solver.interfaces[k], solver.multipliers[k])
            largest = comm.allreduce(float(np.max(np.abs(pressure), initial=0.0)), op=MPI.MAX)
            covered, gap = solver.nodal_gaps(k)
            frozen = self.frozen[k]
            active = frozen.copy()
            active[frozen & (pressure < -1e-10 * largest)] = False
            active[~frozen & (gap < 0.0) & covered] = True
            changed += int(np.count_nonzero(active != frozen))
            new_sets.append(active)
        self.frozen = new_sets
        return comm.allreduce(changed, op=MPI.SUM) == 0


class Penalty(Enforcement):
    """z_j = max(0, lam_j - eps g~_j / A_j) with lam = 0 (A_j = int Phi_j, so that a uniform
    penetration d gives the pressure eps d), written as the row z_j - max(0, ...) and
    linearized exactly."""

    name = "penalty"

    def __init__(self, scales: Scales, num_multipliers, eps: float):
        super().__init__(scales, num_multipliers)
        self.eps = float(eps)
        self.lam = [np.zeros(n) for n in self.num_multipliers]

    def decide_active(self, k, z, covered, gap):
        return covered & (self.lam[k] - self.eps * gap >= 0.0)

    def rows(self, k, z, active, gap, area) -> Rows:
        eps = self.eps
        weight = self.scales.face * min(1.0, self.scales.row / eps)
        alpha = np.zeros_like(z)
        beta = np.zeros_like(z)
        delta = np.full_like(z, weight)
        residual = weight * z
        safe_area = np.where(active, area, 1.0)
        residual[active] = weight * (z - self.lam[k] + eps * gap / safe_area)[active]
        alpha[active] = (weight * eps / safe_area)[active]
        beta[active] = (-weight * eps * gap / safe_area**2)[active]
        return residual, alpha, beta, delta

    def solve(self, solver: NewtonSolver) -> SolveReport:
        self.lam = [np.zeros(n) for n in self.num_multipliers]
        return solver.newton()

    def save_state(self) -> list[np.ndarray]:
        return [lam.copy() for lam in self.lam]

    def restore_state(self, state: list[np.ndarray]) -> None:
        self.lam = [lam.copy() for lam in state]


class AugmentedLagrange(Penalty):
    """Penalty rows around lam, with Uzawa updates lam <- z after each Newton solve until
    max|lam_new - lam| <= tolerance max(max|lam|, 1e-4 k): the limit is the Lagrange
    solution at any fixed eps."""

    name = "augmented"

    def __init__(self, scales: Scales, num_multipliers, eps: float, tolerance: float,
                 max_outer_iterations: int):
        super().__init__(scales, num_multipliers, eps)
        self.tolerance = tolerance
        self.max_outer_iterations = max_outer_iterations

    def solve(self, solver: NewtonSolver) -> SolveReport:
        return outer_loop(solver, lambda: self._update(solver), self.max_outer_iterations,
                          diagnostics.UZAWA_NOT_SETTLED)

    def _update(self, solver: NewtonSolver) -> bool:
        change, size = 0.0, 0.0
        for k, z in enumerate(solver.multipliers):
            new = z.getArray(readonly=True).copy()
            change = max(change, float(np.max(np.abs(new - self.lam[k]), initial=0.0)))
            size = max(size, float(np.max(np.abs(new), initial=0.0)))
            self.lam[k] = new
        change = solver.comm.allreduce(change, op=MPI.MAX)
        size = solver.comm.allreduce(size, op=MPI.MAX)
        # floor: pressures of 1e-4 E are "zero" for the relative test, so
        # rounding noise in z at zero load does not keep Uzawa going forever
        return change <= self.tolerance * max(size, 1e-4 * self.scales.pressure)


def default_parameters(method: str, scales: Scales, master_scale: float, c_n: float | None,
                       penalty: float | None, c_t: float | None) -> tuple[float, float, float]:
    """(c_n, eps, c_t): the user's, or the defaults from the slave's (``scales``) and the
    master's stiffness scales."""
    if c_n is None:
        # the two sides in series: the compliance of the contact, so that a stiff
        # slave on a soft master (ironing's die) does not get an overly stiff c_n
        c_n = 1.0 / (1.0 / scales.row + 1.0 / master_scale)
    if penalty is None:
        # Uzawa contracts like 1 / (1 + eps * contact compliance): a stiffer
        # eps makes augmented Lagrange converge in far fewer updates
        penalty = scales.row * (10.0 if method == "augmented" else 1.0)
    if c_t is None:
        c_t = penalty if method == "penalty" else c_n
    return float(c_n), float(penalty), float(c_t)


def create(method: str, active_set: str, scales: Scales, num_multipliers, *, c_n: float,
           penalty: float, augmented_tolerance: float, max_outer_iterations: int) -> Enforcement:
    """The strategy for ``method`` and ``active_set`` (checked by the caller)."""
    if method == "lagrange" and active_set == "semismooth":
        return SemismoothLagrange(scales, num_multipliers, c_n)
    if method == "lagrange":
        return FixedPointLagrange(scales, num_multipliers, c_n, max_outer_iterations)
    if method == "penalty":
        return Penalty(scales, num_multipliers, penalty)
    return AugmentedLagrange(scales, num_multipliers, penalty, augmented_tolerance,
                             max_outer_iterations)


def outer_loop(solver: NewtonSolver, settled: typing.Callable[[], bool],
               max_outer_iterations: int, failure_reason: int) -> SolveReport:
    """Newton solves until ``settled()`` (called after each converged one) says so."""
    total_iterations, residuals, linear_iterations = 0, [], 0
    for outer in range(1, max_outer_iterations + 1):
        report = solver.newton()
        total_iterations += report.iterations
        residuals += report.residuals
        linear_iterations += report.linear_iterations
        report.iterations, report.residuals, report.outer_iterations = (
            total_iterations, residuals, outer)
        report.linear_iterations = linear_iterations
        if not report.converged or settled():
            return report
    return SolveReport(converged=False, reason=failure_reason, iterations=total_iterations,
                       residuals=residuals, active=0, outer_iterations=max_outer_iterations,
                       linear_iterations=linear_iterations)


def averaged_pressure(interface, z) -> np.ndarray:
    """p_j = int N_j lambda / int N_j = (D^T z)_j / (D^T 1)_j at owned slave nodes."""
    D, _ = interface.mortar_matrices()
    ones = z.duplicate()
    ones.set(1.0)
    weighted, weights = D.createVecRight(), D.createVecRight()
    D.multTranspose(z, weighted)
    D.multTranspose(ones, weights)
    local = interface.owned_multiplier_blocks - interface.V.dofmap.index_map.local_range[0]
    numerator = weighted.getArray(readonly=True)[local]
    denominator = weights.getArray(readonly=True)[local]
    for vector in (ones, weighted, weights):
        vector.destroy()
    return np.where(
        np.abs(denominator) > 0, numerator / np.where(denominator != 0, denominator, 1), 0.0
    )
