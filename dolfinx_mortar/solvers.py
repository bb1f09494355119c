"""SNES and linear solver set-up: our defaults, the user's options the PETSc way.

Defaults are Newton with full steps and MUMPS LU on the monolithic [u | z] system,
or, with condensation, fgmres on it preconditioned by a condensed displacement-only
solve (:mod:`dolfinx_mortar.condensation`): MUMPS LU (``linear_solver="direct"``) or
GMRES with algebraic multigrid whose near-nullspace is the rigid-body modes of each
body (``linear_solver="iterative"``; BoomerAMG, with :data:`BOOMERAMG_3D_OPTIONS` in
3D and :data:`BOOMERAMG_HEXAHEDRON_OPTIONS` on hexahedra). ``linear_solver="auto"``,
the problem's default, is one of the two by dimension and size
(:func:`automatic_linear_solver`), and falls back to the direct solver for the rest of
the run where the iterative one fails a linear solve. The option
``condensed_keep_products`` (default true) keeps the condensation's sub-matrices and
products between Newton iterations, so that a Jacobian of the same pattern only
recomputes values; false frees them after each set-up (less memory, every product
built anew); with friction ``condensed_elimination_ratio`` is
:data:`~dolfinx_mortar.condensation.ELIMINATION_RATIO`. ``ksp_newton_fraction``
(default :data:`KSP_NEWTON_FRACTION`; 0 turns it off) stops the outer linear solve of the
condensed path where its residual is that fraction of the Newton tolerance
(:class:`NewtonLinearTolerance`).
``petsc_options`` given to the problem override the defaults, and the user's options
database under the problem's prefix overrides both.

Our defaults and ``petsc_options`` are in the global options database only while a
problem sets its solver up and while it solves (:func:`inserted_options`: PETSc reads the
factorization options at every symbolic factorization), and removed after either, also
when it fails: a problem leaves no option behind, alive, destroyed or collected.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import typing

import numpy as np
from petsc4py import PETSc

from . import diagnostics
from .options import LinearSolver

DEFAULT_OPTIONS = {
    "snes_type": "newtonls",
    "snes_linesearch_type": "basic",
    "snes_rtol": 1e-10,
    "snes_stol": 0.0,
    "snes_max_it": 30,
    # PETSc's default, stated (PETSc >= 3.22 reads -1 as it): an iterate whose residual
    # grows 1e4-fold is cut back (docs/benchmarks.md, "3D Cattaneo-Mindlin at refinement 2")
    "snes_divergence_tolerance": 1e4,
    # at least one Newton step per solve: an increment whose residual is below
    # the absolute tolerance (a 1e-12 push) must still be applied
    "snes_force_iteration": True,
    "ksp_type": "preonly",
    "pc_type": "lu",
    "pc_factor_mat_solver_type": "mumps",
    # null pivots (|pivot| <= 1e-8 ||A||): the rigid mode of a body held
    # only by contact that lost every active node; its step is set to 0
    "mat_mumps_icntl_24": 1,
    # relative pivot threshold 0.1 (MUMPS' default 0.01): the LU solve of the
    # saddle point system (condition ~1e6 on the patch test) was otherwise only
    # accurate to about eps ||J|| ||dx||, which left the patch test's pressure
    # 5e-10 off uniform after its one Newton step (now 2e-12)
    "mat_mumps_cntl_1": 0.1,
    "mat_mumps_cntl_3": 1e-8,
}

LINEAR_SOLVERS = typing.get_args(LinearSolver)

REFERENCE_BLAS_DIRECTORY = "/blas/"
"""Where Debian installs the reference (netlib) BLAS, ``/usr/lib/<triplet>/blas/libblas.so.3``:
the optimized ones (OpenBLAS, BLIS, ATLAS) live in directories of their own names."""

_blas_advised = False


def reference_blas(maps: str = "/proc/self/maps") -> str | None:
    """The path of the reference BLAS if this process has it loaded (from the memory map:
    the library the loader resolved the ``libblas.so.3`` alternative to), else None (also
    where there is no ``/proc``)."""
    try:
        with open(maps) as lines:
            paths = {line.split()[-1] for line in lines if "libblas.so" in line}
    except OSError:
        return None
    found = sorted(path for path in paths if REFERENCE_BLAS_DIRECTORY in path)
    return found[0] if found else None


def advise_blas(comm, maps: str = "/proc/self/maps") -> None:
    """Once per process, on rank 0: a WARNING on the ``dolfinx_mortar`` logger (printed by
    Python where no handler is set) when MUMPS would factorize with the reference BLAS,
    which makes its dense frontal matrices several times slower (docs/benchmarks.md,
    "The BLAS under MUMPS"). Not a ContactWarning: nothing is wrong with the answer."""
    global _blas_advised
    if _blas_advised or comm.rank != 0:
        return
    _blas_advised = True
    path = reference_blas(maps)
    if path is not None:
        logging.getLogger("dolfinx_mortar").warning(
            "the direct solver (MUMPS) runs on the reference BLAS (%s), several times slower "
            "than an optimized one: install one (Debian: apt install libopenblas0-serial, "
            "single-threaded, for MPI runs) and start the program again", path)


AUTO_ITERATIVE_MIN_DOFS = 50_000
"""``linear_solver="auto"`` takes the iterative solver from this many displacement dofs
(global) in 3D; see :func:`automatic_linear_solver`."""


def automatic_linear_solver(gdim: int, num_dofs: int, multipliers: str,
                            has_friction: bool) -> str:
    """What ``linear_solver="auto"`` (the default) means for a problem: ``iterative`` in
    3D from :data:`AUTO_ITERATIVE_MIN_DOFS` displacement dofs on, with dual multipliers
    (what the iterative path supports), with or without friction (``has_friction``: the
    tangential rows condense with the normal ones, node by node); ``direct`` otherwise.

    Why, as measured on the Hertz problems (benchmarks/README.md, "Direct or iterative
    by default"): in 2D MUMPS was faster than the condensed GMRES + BoomerAMG solve at
    every size measured, serial and on 2 ranks; in 3D the LU factor fills in far
    faster with the dofs: with an optimized BLAS under MUMPS the iterative solve was
    faster per Newton iteration from about this size on (serial tetrahedra: LU 1.7x
    faster at 34k dofs, 1.4x slower at 85k; on the reference BLAS LU was 2.5x slower
    already at 13k), by an order of magnitude a few refinements later, and its memory
    grows about linearly with the dofs (at 85k: 2.2 GB against LU's 3.8 GB). Below the
    threshold LU is faster and the more robust. Both give the same Newton iterates (the
    iterative solve preconditions FGMRES on the full system, rtol 1e-12). Where the iterative solve
    fails, the problem falls back to the direct one
    (:meth:`~dolfinx_mortar.problem.ContactProblem.solve`): a linear solve that only
    the iterative solver fails does not stop an ``auto`` run.
    """
    del has_friction  # the same rule with friction
    if gdim == 3 and num_dofs >= AUTO_ITERATIVE_MIN_DOFS and multipliers == "dual":
        return "iterative"
    return "direct"

ITERATIVE_OPTIONS = {
    # the inner solve only preconditions fgmres on [u | z] (which makes the Newton
    # step exact to its rtol), so a loose inner tolerance is enough
    "condensed_ksp_type": "gmres",
    "condensed_ksp_rtol": 1e-3,
    "condensed_ksp_max_it": 200,
    "condensed_ksp_gmres_restart": 100,
    # hypre's BoomerAMG: on the condensed Hertz systems it kept 6-8 inner steps
    # from 5e3 to 2e4 dofs where GAMG (even with SOR smoothing and a symmetrized
    # graph, K_c not being symmetric) grew from 6 to 155 (docs/benchmarks.md)
    "condensed_pc_type": "hypre",
    "condensed_pc_hypre_type": "boomeramg",
}

BOOMERAMG_3D_OPTIONS = {
    # added (under condensed_, unless the user set them) when the displacement has 3
    # components: HMIS coarsening, extended+i interpolation of at most 4 entries a row,
    # and one level of aggressive coarsening. hypre's defaults (Falgout, classical) made
    # coarse levels of 200-400 entries a row on the condensed 3D Hertz systems; without
    # the aggressive level the hierarchy took twice the set-up and about three times
    # the time per V-cycle for half the inner steps, which stay flat with it from 2e5
    # to 9e5 dofs. In 2D the defaults stay: there HMIS took 16.5 inner steps at 77k dofs
    # against 6.9 (docs/benchmarks.md, "One level of aggressive coarsening";
    # benchmarks/README.md, "Iterative linear solver in 3D")
    "pc_hypre_boomeramg_coarsen_type": "HMIS",
    "pc_hypre_boomeramg_interp_type": "ext+i",
    "pc_hypre_boomeramg_P_max": 4,
    "pc_hypre_boomeramg_agg_nl": 1,
}

BOOMERAMG_3D_RELAXATION = "forward-backward"
"""The inner BoomerAMG's smoother in 3D (a key of :data:`~dolfinx_mortar.condensation.
RELAXATIONS`), unless the user sets ``condensed_pc_hypre_boomeramg_relax_type_*``: hybrid
Gauss-Seidel forward on the way down and backward on the way up, one sweep each, instead
of PETSc's symmetric sweep both ways: more inner iterations at half the sweeps each,
less time per Newton iteration on every 3D case measured (docs/benchmarks.md, "Forward
down, backward up")."""

BOOMERAMG_HEXAHEDRON_OPTIONS = {
    # added (under condensed_, unless the user set them) on hexahedral meshes, after
    # BOOMERAMG_3D_OPTIONS: the graded hexahedral Hertz grids (cells up to 20:1) took 16.5
    # inner steps per application at the default threshold 0.25 and 6.3 at 0.7 (50,526
    # dofs, serial; inner steps per Newton iteration 87 -> 28, outer 5.3 -> 4.4, the same
    # Newton iterates). On tetrahedra 0.7 cost steps (6.1 -> 9.7), so there it stays
    # (docs/benchmarks.md, "Contact vs bonded elasticity (issue 26)")
    "pc_hypre_boomeramg_strong_threshold": 0.7,
}

KSP_NEWTON_FRACTION = 1e-2
"""With condensation, the outer Krylov solve also stops where its residual is this fraction
of the Newton tolerance (:class:`NewtonLinearTolerance`)."""


class NewtonLinearTolerance:
    """An SNES update that sets the outer KSP's absolute tolerance, before each Newton step,
    to ``fraction`` of the Newton tolerance max(atol, rtol ||r_0||) (``||r_0||``: the first
    norm ``monitored`` holds), and never below ``atol``, the KSP's own.

    Why: the relative tolerance (1e-12 of the step's residual) is what makes the iterative
    Newton iterates those of a direct solve, but once the residual is far below its start
    it asks for digits no Newton test can see: a step whose linear residual is 1e-2 of
    the Newton tolerance leaves the next residual within 1 % of the tolerance plus the
    quadratic term, so the Newton iterations stay the same and the iterates differ by
    that residual through J^-1. Holds ``monitored`` (a list the SNES monitor appends to)
    only: the SNES keeps its update callback."""

    def __init__(self, monitored: list[float], fraction: float, atol: float):
        self.monitored = monitored
        self.fraction = fraction
        self.atol = atol

    def __call__(self, snes: PETSc.SNES, iteration: int) -> None:
        rtol, atol, _, _ = snes.getTolerances()
        first = self.monitored[0] if self.monitored else 0.0
        target = max(atol, rtol * first)
        snes.getKSP().setTolerances(atol=max(self.atol, self.fraction * target))


GAMG_OPTIONS = {
    # selectable with petsc_options={"condensed_pc_type": "gamg"}: the near-nullspace
    # (rigid-body modes) is set on K_c for it; SOR smoothing needs no eigenvalue
    # estimate on the non-symmetric K_c
    "condensed_pc_gamg_threshold": 0.01,
    "condensed_pc_gamg_sym_graph": True,
    "condensed_mg_levels_ksp_type": "richardson",
    "condensed_mg_levels_pc_type": "sor",
}


@dataclasses.dataclass
class SolveReport:
    """What one call of :meth:`~dolfinx_mortar.problem.ContactProblem.solve` did."""

    converged: bool
    reason: int
    iterations: int
    residuals: list[float]
    active: int
    outer_iterations: int = 1
    linear_iterations: int = 0
    timings: dict[str, float] = dataclasses.field(default_factory=dict)
    inversion: diagnostics.Inversion = dataclasses.field(default_factory=diagnostics.Inversion)
    """Inverted cells of the Newton iterate that stopped a failed solve (count 0 otherwise)."""
    linear_solver_failure: str = ""
    """Why the linear solver failed (reason DIVERGED_LINEAR_SOLVE), in PETSc's words."""

    def cause(self) -> str:
        """Why the solve failed, in words ("converged" if it did not fail)."""
        if self.converged:
            return "converged"
        parts = [f"SNES reason {diagnostics.describe_snes_reason(self.reason)}"]
        if self.inversion.count:
            parts.append(f"{self.inversion.describe()} in a Newton iterate")
        if self.linear_solver_failure:
            parts.append(self.linear_solver_failure)
        return "; ".join(parts)



def default_options(condensation: bool, linear_solver: str = "direct") -> dict:
    """Our defaults (see :data:`DEFAULT_OPTIONS`), for the monolithic or the condensed solve."""
    defaults = dict(DEFAULT_OPTIONS)
    if condensation:
        # fgmres on [u | z], preconditioned by the condensed solve (a python PC);
        # its inner solver takes the defaults (and the user's options) under condensed_
        for key in ("pc_type", "pc_factor_mat_solver_type"):
            del defaults[key]
        defaults.update(ksp_type="fgmres", ksp_rtol=1e-12, ksp_atol=1e-50, ksp_max_it=200)
        defaults.update({f"condensed_{key}": value for key, value in defaults.items()
                         if key.startswith("mat_mumps")})
        if linear_solver == "iterative":
            defaults.update(ITERATIVE_OPTIONS)
            defaults.update(GAMG_OPTIONS)
        else:
            defaults.update(condensed_ksp_type="preonly", condensed_pc_type="lu",
                            condensed_pc_factor_mat_solver_type="mumps")
    return defaults


@contextlib.contextmanager
def inserted_options(prefix: str, values: dict) -> typing.Iterator[None]:
    """``values`` (names without ``prefix``) in the global options database for the block,
    each under ``prefix`` unless the database already has that name (the user's own wins);
    the names put there are removed after the block, also when it raises, so that no
    problem leaves an option behind for the next one to take for the user's."""
    options = PETSc.Options()
    added = []
    try:
        for key, value in values.items():
            name = f"{prefix}{key}"
            if not options.hasName(name):
                options[name] = value
                added.append(name)
        yield
    finally:
        for name in added:
            options.delValue(name)


def configure_snes(
    snes: PETSc.SNES,
    prefix: str,
    petsc_options: dict,
    condensation: bool,
    default_atol: float,
    before_options: typing.Callable[[], None],
    after_options: typing.Callable[[PETSc.KSP], None],
    linear_solver: str = "direct",
) -> dict:
    """Set ``snes`` up from our defaults, ``petsc_options`` and the options database.

    ``before_options`` runs with the options in the database and before
    ``setFromOptions`` (set the function, Jacobian and monitor there);
    ``after_options`` runs after it, still with the options in the database
    (a python preconditioner that reads its own options). The absolute
    tolerance is ``default_atol`` unless the user gave one.

    Returns:
        The options (our defaults and ``petsc_options``) to put into the database again
        for each solve (:func:`inserted_options`): PETSc reads the factorization ones
        (``mat_*``) at every symbolic factorization.
    """
    snes.setOptionsPrefix(prefix)
    values = default_options(condensation, linear_solver)
    values.update(petsc_options)
    user_atol = "snes_atol" in petsc_options or PETSc.Options().hasName(f"{prefix}snes_atol")
    with inserted_options(prefix, values):
        before_options()
        snes.setFromOptions()
        snes.getKSP().setFromOptions()
        if not user_atol:
            snes.setTolerances(atol=default_atol)
        after_options(snes.getKSP())
    return values


def rigid_body_modes(V) -> list[np.ndarray]:
    """Rigid-body modes of each body (connected set of cells) of ``V``'s mesh, orthonormal.

    Translations and rotations (1 in 2D, 3 in 3D) about the body's centre,
    restricted to the body's dofs, as arrays over this rank's owned dofs (in
    ``V``'s order, the order of the displacement rows of the condensed
    matrix). They are the near-nullspace algebraic multigrid needs for
    elasticity; per body, because a body held only by contact may move
    rigidly without straining its neighbours. Collective.
    """
    from mpi4py import MPI

    from .surface import body_labels

    mesh = V.mesh
    comm = mesh.comm
    gdim = mesh.geometry.dim
    bs = V.dofmap.index_map_bs
    index_map = V.dofmap.index_map
    owned = index_map.size_local
    x = V.tabulate_dof_coordinates()[:owned, :gdim]
    labels = body_labels(mesh)
    node_label = np.full(index_map.size_local + index_map.num_ghosts, -1, dtype=np.int64)
    cell_dofs = V.dofmap.list
    node_label[cell_dofs.reshape(-1)] = np.repeat(labels, cell_dofs.shape[1])
    node_label = node_label[:owned]
    bodies = np.unique(np.concatenate(comm.allgather(np.unique(node_label))))
    modes = []
    for body in bodies:
        mask = node_label == body
        count = comm.allreduce(int(mask.sum()), op=MPI.SUM)
        centre = comm.allreduce(x[mask].sum(axis=0), op=MPI.SUM) / max(count, 1)
        r = x - centre
        fields = [np.eye(gdim)[c][None, :].repeat(owned, axis=0) for c in range(gdim)]
        if gdim == 2:
            fields.append(np.column_stack([-r[:, 1], r[:, 0]]))
        else:
            zero = np.zeros(owned)
            fields += [np.column_stack([-r[:, 1], r[:, 0], zero]),
                       np.column_stack([zero, -r[:, 2], r[:, 1]]),
                       np.column_stack([r[:, 2], zero, -r[:, 0]])]
        for field in fields:
            values = np.zeros((owned, bs))
            values[mask, :gdim] = field[mask]
            modes.append(values.reshape(-1))
    # modified Gram-Schmidt with global dot products
    basis: list[np.ndarray] = []
    for mode in modes:
        for other in basis:
            mode = mode - comm.allreduce(float(mode @ other), op=MPI.SUM) * other
        norm = np.sqrt(comm.allreduce(float(mode @ mode), op=MPI.SUM))
        if norm > 1e-10:
            basis.append(mode / norm)
    return basis


def condensed_preconditioner(ksp: PETSc.KSP, layout, interfaces, block_size: int, prefix: str,
                             near_nullspace: list[np.ndarray] | None = None,
                             cell_name: str = "", components: int = 0):
    """Make the condensed solve the (python) preconditioner of the monolithic KSP.

    ``cell_name`` (the mesh's cell type) selects BoomerAMG's options beyond the
    dimension's: :data:`BOOMERAMG_HEXAHEDRON_OPTIONS` on hexahedra. ``components``:
    the tangential multiplier fields per pair (d - 1 with friction, fields P + 1 ..
    of the layout, pair by pair), condensed with their node's normal multiplier."""
    from .condensation import ELIMINATION_RATIO, RELAXATIONS, CondensedPreconditioner

    comm = layout.comm
    first = int(layout.offsets[comm.rank])
    u_rows = first + np.arange(layout.owned_u.start, layout.owned_u.stop)
    z_rows = first + np.arange(layout.owned_z.start, layout.owned_z.stop)
    # per layout field after u: each pair's normal multipliers, then (friction) each
    # pair's tangential ones; a multiplier's position in z_rows and its node's dofs
    fields = [(k, 1 + k) for k in range(len(interfaces))] + [
        (k, 1 + len(interfaces) + k * components + a)
        for k in range(len(interfaces)) for a in range(components)]
    node_dofs = np.zeros((z_rows.size, block_size), dtype=np.int64)
    positions = {}
    for k, field in fields:
        owned = layout.owned(field)
        # (a pair left out of the layout has no rows: newton.ContactNewton.fit_layout)
        blocks = interfaces[k].owned_multiplier_blocks[:owned.stop - owned.start]
        node_dofs[owned.start - layout.owned_z.start:owned.stop - layout.owned_z.start] = (
            blocks[:, None] * block_size + np.arange(block_size))
        positions.setdefault(k, []).append(
            np.arange(owned.start, owned.stop) - layout.owned_z.start)
    node_groups = (np.concatenate([np.stack(positions[k], axis=1)
                                   for k in range(len(interfaces))])
                   if components else None)
    options = PETSc.Options()
    added = []
    # a smoother the user chose is kept, also after a breakdown
    relaxation = None if any(
        options.hasName(f"{prefix}condensed_pc_hypre_boomeramg_relax_type_{which}")
        for which in ("all", "down", "up")) else "symmetric"
    if block_size == 3:
        defaults = dict(BOOMERAMG_3D_OPTIONS)
        if cell_name == "hexahedron":
            defaults.update(BOOMERAMG_HEXAHEDRON_OPTIONS)
        if relaxation is not None:
            relaxation = BOOMERAMG_3D_RELAXATION
            down, up = RELAXATIONS[relaxation]
            defaults.update({"pc_hypre_boomeramg_relax_type_down": down,
                             "pc_hypre_boomeramg_relax_type_up": up})
        for key, value in defaults.items():
            name = f"{prefix}condensed_{key}"
            if not options.hasName(name):
                options[name] = value
                added.append(name)
    keep_products = options.getBool(f"{prefix}condensed_keep_products", True)
    elimination_ratio = options.getReal(f"{prefix}condensed_elimination_ratio",
                                        ELIMINATION_RATIO)
    try:
        condenser = CondensedPreconditioner(comm, u_rows, z_rows, node_dofs,
                                            prefix=f"{prefix}condensed_",
                                            near_nullspace=near_nullspace,
                                            keep_products=keep_products,
                                            elimination_ratio=elimination_ratio,
                                            node_groups=node_groups, relaxation=relaxation)
    finally:
        for name in added:
            options.delValue(name)
    pc = ksp.getPC()
    pc.setType(PETSc.PC.Type.PYTHON)
    pc.setPythonContext(condenser)
    return condenser
