"""The Newton solver of a contact problem: PETSc SNES on its equations.

:class:`ContactNewton` owns the SNES, its linear solver (with condensation its python
preconditioner) and the iterate x; the SNES calls the residual and Jacobian of a
:class:`~dolfinx_mortar.equations.ContactEquations`, which knows neither the solver nor
the problem, and the SNES holds it only weakly: no reference cycle through the SNES, and
nothing kept alive by an SNES that outlives its problem. It is what the enforcement strategies
drive (:class:`~dolfinx_mortar.enforcement.NewtonSolver`). Our PETSc options are in the
global options database only while the solver is set up and while it solves
(:func:`~dolfinx_mortar.solvers.inserted_options`).
"""

from __future__ import annotations

import numpy as np
from petsc4py import PETSc

from . import diagnostics, solvers
from .equations import ContactEquations
from .layout import BlockLayout
from .solvers import SolveReport


class ContactNewton:
    """SNES with our defaults (:mod:`dolfinx_mortar.solvers`) on ``equations``.

    Args:
        equations: the contact equations (state, residual, Jacobian).
        x, b: the iterate and the residual vector of the [u | z] layout.
        prefix: the options prefix.
        petsc_options: the user's options; they and then the options database win over
            our defaults.
        linear_solver: ``direct`` or ``iterative`` (not ``auto``: chosen by the problem).
        condensation: whether the multipliers are condensed.
        default_atol: SNES' absolute tolerance unless the user gave one.
        automatic: whether ``linear_solver="auto"`` chose the linear solver (then a
            failed iterative solve reports no advice: the direct solver takes over).
    """

    def __init__(self, equations: ContactEquations, x: PETSc.Vec, b: PETSc.Vec, prefix: str,
                 petsc_options: dict, linear_solver: str, condensation: bool,
                 default_atol: float, automatic: bool = False):
        self.equations = equations
        self.comm = equations.layout.comm
        self.interfaces = equations.interfaces
        self.multipliers = equations.multipliers
        self.x, self.b = x, b
        self.prefix = prefix
        self.petsc_options = dict(petsc_options)
        self.linear_solver = linear_solver
        self.condensation = condensation
        self.default_atol = default_atol
        self.automatic = automatic
        self.condenser = None
        self.snes: PETSc.SNES | None = None
        try:
            self.setup()
        except BaseException:
            self.destroy()  # the SNES holds the equations' callbacks
            raise

    def setup(self) -> None:
        """Create and set up the SNES (and with condensation its preconditioner)."""
        snes = PETSc.SNES().create(self.comm)
        equations = self.equations

        def callbacks() -> None:
            snes.setFunction(equations.callbacks.residual, self.b)
            equations.assemble_system()  # creates the matrix with its pattern
            snes.setJacobian(equations.callbacks.jacobian, equations.system.mat)
            snes.setMonitor(equations.callbacks.monitor)

        def condensation(ksp: PETSc.KSP) -> None:
            if self.condensation:
                V = equations.V
                near_nullspace = (solvers.rigid_body_modes(V)
                                  if self.linear_solver == "iterative" else None)
                self.condenser = solvers.condensed_preconditioner(
                    ksp, equations.layout, self.interfaces, V.dofmap.index_map_bs,
                    self.prefix, near_nullspace, V.mesh.topology.cell_name(),
                    components=equations.system.components)

        self.snes = snes
        self.solve_options = solvers.configure_snes(
            snes, self.prefix, self.petsc_options, self.condensation, self.default_atol,
            callbacks, condensation, self.linear_solver)
        if self.condensation:
            with solvers.inserted_options(self.prefix, self.solve_options):
                fraction = PETSc.Options().getReal(f"{self.prefix}ksp_newton_fraction",
                                                   solvers.KSP_NEWTON_FRACTION)
            if fraction > 0.0:
                atol = snes.getKSP().getTolerances()[1]
                snes.setUpdate(solvers.NewtonLinearTolerance(
                    equations.residual_history, fraction, atol))

    def fall_back_to_direct(self, condensation: bool, failure: str, warn) -> None:
        """Replace the iterative linear solver that ``auto`` chose, which failed a linear
        solve (``failure``), by MUMPS LU (of the condensed system with ``condensation``)
        for the rest of the run; ``warn(cause, message)`` says why. Collective.

        ``auto`` promises a solver that works where the direct one would: the direct one
        is the more robust, and a problem whose iterative solve failed once (a contrast
        or a geometry its preconditioner does not handle) would likely fail again."""
        warn(
            ("linear solver fallback",),
            "linear_solver='auto' chose the iterative solver (GMRES + AMG on the condensed "
            f"system) for this problem, and a linear solve failed: {failure}. The direct "
            "solver (MUMPS LU) solves this load step again and every later one. Pass "
            "linear_solver='direct' to skip the iterative attempt, or "
            "linear_solver='iterative' to keep it (the load stepping then cuts the step "
            "back).",
        )
        self.equations.null_space_candidates = []
        self.equations.set_null_space(self.equations.system.mat)
        self.destroy()
        self.linear_solver = "direct"
        self.condensation = condensation
        self.setup()

    def fit_layout(self) -> None:
        """Leave the multiplier rows of each pair without pairs on any rank (at its last
        search) out of the layout, and put those of a pair with pairs back: a new layout,
        x, b, matrix and SNES when either changes. Collective (every rank has the same
        interfaces without pairs).

        Why: a self-contact surface far from itself has multipliers but no pair; its rows
        (z_j = 0, decoupled from the rest) are unknowns that each factorization orders
        and factors (docs/benchmarks.md, "Self-contact far from itself: the rows taken
        out"). Taking them out changes no solution: the multipliers of a pair without
        pairs are zero and enter no other row."""
        equations = self.equations
        wanted = [not self.compact_layout or not i.without_pairs for i in self.interfaces]
        if wanted == equations.in_layout:
            return
        equations.write_state(self.x)
        equations.in_layout = wanted
        counts = [i.num_owned_multipliers if present else 0
                  for i, present in zip(self.interfaces, wanted, strict=True)]
        components = equations.system.components
        layout = BlockLayout(self.comm, self.interfaces[0].num_owned_dofs,
                             counts + [c for c in counts for _ in range(components)])
        self.destroy()
        for vector in (self.x, self.b):
            vector.destroy()
        equations.layout = layout
        equations.system.set_layout(layout, wanted)
        self.x, self.b = layout.create_vector(), layout.create_vector()
        equations.read_state(self.x)
        # the gaps, active sets and slips at this state (a pair back in the layout was not
        # updated while out; friction's slips are reset at each solve's start), for the
        # matrix the set-up assembles
        equations.update_contact()
        self.setup()

    compact_layout = True
    """Whether :meth:`fit_layout` leaves pairs without pairs out of the layout (False: every
    pair's rows stay, as before; for comparisons)."""

    def newton(self) -> SolveReport:
        """One Newton solve from the state in x, into the state. Collective.

        The layout is fitted first (:meth:`fit_layout`). Where a pair left out of it
        finds pairs at an iterate, the SNES stops there and the solve goes on from that
        iterate in a layout with the pair's rows: the same iterates as with the rows
        throughout (the tolerances and the iteration limit of the whole solve hold)."""
        equations = self.equations
        equations.stale_state = None
        self.fit_layout()
        report = self._snes_solve()
        while equations.stale_state is not None:
            done, history = report.iterations, report.residuals
            linear = report.linear_iterations
            state, equations.stale_state = equations.stale_state, None
            equations.restore_state(state)
            equations.read_state(self.x)
            self.fit_layout()
            report = self._snes_solve(done, history)
            report.linear_iterations += linear
        return report

    def _snes_solve(self, done: int = 0, history: list[float] | None = None) -> SolveReport:
        """One SNES solve from the state in x, into the state; ``done`` Newton iterations
        with the residual norms ``history`` went before it in this solve (then its
        relative tolerance is of history[0], and no step is forced)."""
        equations = self.equations
        equations.residual_history.clear()
        equations.last_inversion = diagnostics.Inversion()
        if self.condenser is not None:
            self.condenser.inner_failure = ""
        tolerances = self.snes.getTolerances()
        with solvers.inserted_options(self.prefix, self.solve_options):
            force = PETSc.Options().getBool(f"{self.prefix}snes_force_iteration", False)
            try:
                if history:
                    rtol, atol, _, max_it = tolerances
                    self.snes.setTolerances(rtol=0.0, atol=max(atol, rtol * history[0]),
                                            max_it=max(max_it - done, 1))
                    self.snes.setForceIteration(False)
                self.snes.solve(None, self.x)
            finally:
                if history:
                    rtol, atol, _, max_it = tolerances
                    self.snes.setTolerances(rtol=rtol, atol=atol, max_it=max_it)
                    self.snes.setForceIteration(force)
        reason = self.snes.getConvergedReason()
        residuals = (history or []) + list(equations.residual_history)
        if equations.stale_state is not None:  # (its own iterate, whichever the SNES holds)
            return SolveReport(converged=False, reason=reason, iterations=len(residuals),
                               residuals=residuals, active=0,
                               linear_iterations=self.snes.getLinearSolveIterations())
        equations.write_state(self.x)
        report = SolveReport(
            converged=reason > 0, reason=reason,
            iterations=done + self.snes.getIterationNumber(), residuals=residuals, active=0,
            linear_iterations=self.snes.getLinearSolveIterations())
        if reason <= 0:
            report.inversion = equations.last_inversion
        if reason == PETSc.SNES.ConvergedReason.DIVERGED_LINEAR_SOLVE:
            # SNES stops before the step is applied (a NaN step included): x is the last
            # iterate, and the load stepping cuts the step back
            ksp = self.snes.getKSP()
            if self.linear_solver == "iterative":
                # with ``auto`` the direct solver takes over: no advice
                report.linear_solver_failure = diagnostics.describe_iterative_failure(
                    ksp, self.prefix, self.condenser.inner_failure, advice=not self.automatic)
            else:
                report.linear_solver_failure = diagnostics.describe_ksp_failure(ksp)
        return report

    def update_contact(self) -> None:
        """u and the multipliers from the iterate x, then the gaps, areas and active sets
        there. Collective."""
        self.equations.write_state(self.x)
        self.equations.update_contact()

    def nodal_gaps(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """(covered, g^) of pair k's owned slave nodes at the last contact update."""
        return self.equations.nodal_gaps(k)

    def destroy(self) -> None:
        """Free the SNES and the condensation's preconditioner. Collective."""
        if self.snes is not None:
            self.snes.destroy()
            self.snes = None
        if self.condenser is not None:
            self.condenser.destroy()
            self.condenser = None
