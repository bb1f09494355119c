"""Static condensation of dual multipliers, as a preconditioner of the monolithic system.

The Newton system of :class:`~dolfinx_mortar.problem.ContactProblem` is, per
rank [u | z] (all multiplier fields together),

    A du + G dz = r_u          (u rows; A = K + d(-B^T z)/du, G = -B^T)
    C du + diag(d) dz = r_z    (multiplier rows; d_j is 0 or 1)

Rows with d_j != 0 (inactive Lagrange, penalty, augmented) are eliminated
exactly: dz_j = (r_z - C du)_j / d_j. The rows with d_j = 0 (active Lagrange)
are condensed after Popp et al. with the unit normal n_j of slave node j:
T (rows n_j^T on node j's dofs) turns the u rows into T A' du + T G dz_a =
T r', and with P = diag(T G) (exact when T G is diagonal, i.e. when the dual
basis decouples the nodes) dz_a = P^-1 T (r' - A' du). The u rows then become
(I - G P^-1 T)(A' du - r') = 0, whose components along the active normals
vanish; those rows are replaced by the constraints C_a du = r_za:

    K_r = (I - T^T T)(I - G P^-1 T) A' - T^T C_a,    A' = A - G d^-1 C

(the constraint rows negated, so that their diagonal is positive).

The other rows of K_r still hold the slave normal displacements: the master rows
near the contact took, through G P^-1 T, the slave body's normal stiffness as
couplings to them. Where the slave body is the stiffer one these couplings are
its stiffness, far above the master rows' own diagonal, and algebraic multigrid
does not converge on such rows (the inner solve's error then kept the outer
method from converging; docs/benchmarks.md, "Iterative solver under contrast").
So every other row takes the slave normal displacements out with the constraint
rows (T K_r = -C_a), i.e. n_j^T du_j is replaced by what constraint j says it
is, in terms of the master nodes:

    K_c = (I - E Q^-1 T) K_r,    E = (I - T^T T) K_r T^T,    Q = diag(T K_r T^T)

and the right-hand side takes the same row operation. The master rows then hold the
slave body's normal stiffness on their own (master) columns, as in the elimination
of the slave normal displacements by the mortar projection D^-1 M. The row operation
is invertible (T (I - T^T T) = 0), so K_c du = (I - E Q^-1 T) rc has K_r's solution.

K_c has the displacement size only. Our mortar integrals carry the
interpolated normal (Dn_jk = int Phi_j N_k n_h), so T G is not exactly
diagonal in general and the condensation is approximate; it is therefore
used as the preconditioner of an outer Krylov method (fgmres) on the full
monolithic matrix, which makes the Newton steps exact to the Krylov
tolerance: the solution does not change, only how the linear systems are
solved. When T G is diagonal the outer method converges in one iteration.

The normal n_j is the direction of G's column j at node j's own dofs (the
diagonal Dn_jj), so that P_jj = |Dn_jj| > 0.

K_c differs from A only in the rows of G (the pairs' slave and master dofs), of T^T
(the slave nodes') and in the rows with an entry in a slave node's column (E's): the
products are computed on those rows only, and the inner matrix is A's rows elsewhere.
No product then has the size of A, which is what the condensation cost when every
product ran over all rows.

Friction (``node_groups``): a slave node j has d multipliers lambda_j = (z_j, y_j^1 ..
y_j^(d-1)), and their rows' own block Z_j (d x d: the normal row's delta, a tangential
row's own entries and its coupling to z_j) is not diagonal: a slipping node's rows tie
y_j to mu z_j along the slip (Z_j has rank 1 in 2D), a sticking node's rows are
constraints on du (Z_j = 0 on them), a node at its slip bound in 3D has a tangential
direction whose own entry nearly vanishes. Each node's rows and multipliers are turned
by the singular value decomposition Z_j = U_j diag(sigma_j) V_j^T (rows U_j^T, unknowns
mu_j = V_j^T lambda_j; Gitterle, Popp, Gee and Wall 2010 condense the same rows node by
node with the dual basis), which makes the multiplier block diagonal, sigma. A node
whose rows all have their own diagonal entry (inactive, penalty: Z_j triangular) is
eliminated whole, exactly, as the d_j != 0 rows above; at the others (active Lagrange
nodes) a rotated multiplier whose sigma is at least ELIMINATION_RATIO of its node's
largest is eliminated through it, and the others are condensed through the
slave node's rows, T's rows then the orthonormalized directions of their columns of
G V at the node (a Gram-Schmidt factorization G V = T^T P on the node, P upper
triangular, so P^-1 is a d x d block per node), and a small sigma kept in their rows:

    K_r = (I - T^T T)(I - G P^-1 T) A' - T^T (C_a - S P^-1 T A'),   S = diag(sigma_a).

Eliminating a row with a small sigma instead would add the stiffness G sigma^-1 C,
about c_t r / (1 - r) at a node whose slip ratio r = b/|v| nears 1 (a stick condition
as a penalty); condensing it keeps every entry bounded. A sticking node condenses like
an active normal row, along its normal and tangent frame; a 2D slipping node condenses
its tilted force direction n +- mu tau (the tangential row eliminated through its
diagonal).
"""

from __future__ import annotations

import hashlib

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from . import diagnostics
from .inner_matrix import DisplacementBlock, InnerMatrix, row_reduce
from .petsc_c import local_blocks

ELIMINATION_RATIO = 0.03
"""With friction, a rotated multiplier whose singular value sigma is at least this
fraction of its node's largest is eliminated through it; below, it is condensed (module
docstring). Elimination is exact; the condensation of a tangential direction is not (its
frame is G's columns at the node only), so the fewer condensed, the fewer outer
iterations. But at a 3D node at its slip bound the tangential direction across the slip
has sigma/max = (1 - r)/sqrt(1 + mu^2), r = b/|v|: eliminating it adds a penalty of
about r/(1 - r) c_t to K_c, at most about 30 c_t here; eliminating every nonzero sigma
made the linear solves fail, even with an exact inner solve (docs/benchmarks.md, "The
elimination ratio of the frictional condensation")."""

RELAXATIONS = {
    "symmetric": ("symmetric-SOR/Jacobi", "symmetric-SOR/Jacobi"),
    "forward-backward": ("SOR/Jacobi", "backward-SOR/Jacobi"),
    "l1": ("l1scaled-SOR/Jacobi", "l1scaled-SOR/Jacobi"),
}
"""BoomerAMG's smoothers of the inner solve, (down, up): PETSc's default, hybrid
symmetric Gauss-Seidel (2D); hybrid Gauss-Seidel forward down and backward up, a
symmetric V-cycle of half the sweeps (3D, :data:`~dolfinx_mortar.solvers.
BOOMERAMG_3D_RELAXATION`); and the l1-scaled hybrid symmetric Gauss-Seidel, to which an
inner solve that breaks down switches (and from it back). A hybrid smoother broke down on
condensed 3D systems on which the l1 form converged and the other way round, and neither
is the faster everywhere (docs/benchmarks.md, "The inner AMG's smoother" and "Forward
down, backward up")."""

FALLBACK_RELAXATION = "l1"

SINGULAR_COARSE_RELAXATION = "l1scaled-SOR/Jacobi"
"""BoomerAMG's relaxation on its coarsest level while the inner matrix has a null space
(a body that only frictionless contact holds, free to slide), instead of hypre's Gaussian
elimination: eliminating the singular coarsest matrix made every V-cycle garbage and the
inner GMRES broke down (3D Cattaneo-Mindlin's normal phase on 3 ranks), where these sweeps
converge in as many iterations as the factorization did elsewhere (docs/benchmarks.md,
"A singular coarsest level")."""


class CondensedPreconditioner:
    """A petsc4py ``python`` PC: the condensed solve of the monolithic [u | z] system.

    Args:
        comm: communicator.
        u_rows: this rank's monolithic rows of the displacements (global indices).
        z_rows: this rank's monolithic rows of all multipliers (global indices).
        z_node_dofs: (len(z_rows), gdim) global displacement dofs of the slave
            node of each owned multiplier (owned by this rank too).
        node_groups: with friction, (owned slave nodes, d) the positions in z_rows of
            each node's normal and tangential multipliers (every position once), whose
            rows are condensed node by node (module docstring); None: one multiplier per
            node.
        prefix: options prefix of the inner solver of K_c (ContactProblem puts
            its defaults, MUMPS LU or GMRES + AMG, into the options database).
        near_nullspace: this rank's part (owned displacement dofs, in order) of
            the vectors K_c is given as near-nullspace (the rigid-body modes of
            each body, for algebraic multigrid); orthonormal.
        keep_products: keep every sub-matrix and product between set-ups, so that
            a Jacobian of the same pattern only recomputes their values (the
            default). False keeps only what ``apply`` needs (G, C, T, E Q^-1
            and the inner solver's matrix) and frees the rest as soon as it is used: the
            products (of the rows near the contact) are then built anew at every
            set-up.
        elimination_ratio: with friction, the fraction of its node's largest singular value
            above which a rotated multiplier is eliminated (:data:`ELIMINATION_RATIO`).
    """

    def __init__(self, comm: MPI.Intracomm, u_rows, z_rows, z_node_dofs, prefix: str,
                 near_nullspace: list[np.ndarray] | None = None, keep_products: bool = True,
                 node_groups: np.ndarray | None = None,
                 elimination_ratio: float = ELIMINATION_RATIO,
                 relaxation: str | None = "symmetric"):
        if not 0.0 < elimination_ratio < 1.0:
            raise ValueError(f"elimination_ratio must lie in (0, 1), got {elimination_ratio}")
        self.comm = comm
        self.keep_products = keep_products
        self.elimination_ratio = elimination_ratio
        self.is_u = PETSc.IS().createGeneral(np.asarray(u_rows, dtype=PETSc.IntType), comm=comm)
        self.is_z = PETSc.IS().createGeneral(np.asarray(z_rows, dtype=PETSc.IntType), comm=comm)
        self.num_u = len(u_rows)
        self.num_z = len(z_rows)
        z_node_dofs = np.asarray(z_node_dofs, dtype=np.int64)
        self.block_size = z_node_dofs.shape[1] if z_node_dofs.ndim == 2 else 2
        self.z_node_dofs = z_node_dofs.reshape(self.num_z, self.block_size)
        self.rotate = node_groups is not None and np.shape(node_groups)[1] > 1
        self.node_groups = (np.asarray(node_groups, dtype=np.int64) if self.rotate
                            else np.arange(self.num_z, dtype=np.int64)[:, None])
        if np.any(np.sort(self.node_groups.reshape(-1)) != np.arange(self.num_z)):
            raise ValueError("node_groups must hold every multiplier position once")
        # the first of this rank's columns of the z space in the sub-matrices G, Z
        self.z_first = comm.exscan(self.num_z) or 0  # (None on rank 0)
        self.near_nullspace = near_nullspace
        self.inner_iterations: list[int] = []
        self.inner_failure = ""
        """Why an inner solve broke down (empty if none did since the owner last cleared it)."""
        self.ksp = PETSc.KSP().create(comm)
        self.ksp.setOptionsPrefix(prefix)
        self.ksp.setFromOptions()
        self.prefix = prefix
        self._initial_relaxation = self._relaxation = self._switchable(relaxation)
        options = PETSc.Options()
        # the coarsest level's solve follows the null space unless the user set it
        self._coarse_switchable = self._switchable("symmetric") is not None and not any(
            options.hasName(f"{prefix}pc_hypre_boomeramg_relax_type_{which}")
            for which in ("all", "coarse"))
        self._singular_coarse = False
        self.relaxation_switches = 0
        """inner solves that broke down and were retried with the other smoother"""
        self._matrices: dict[str, PETSc.Mat] = {}
        self._vectors: dict[str, PETSc.Vec] = {}
        self._index_sets: dict[str, PETSc.IS] = {}
        self._products: dict[str, PETSc.Mat] = {}
        self._scratch: dict[str, PETSc.Mat] = {}
        self._inputs_kept: dict[str, tuple] = {}
        self._sets: tuple | None = None
        self._inner = InnerMatrix(comm, self.block_size)
        self._a: DisplacementBlock | None = None
        self._fingerprint = None
        self._null_space: PETSc.NullSpace | None = None
        self.num_active = 0
        self.rebuilds = 0
        """set-ups that built every matrix (J's pattern was new)"""
        self.reuses = 0
        """set-ups that only recomputed values (J's pattern had not changed)"""

    # -- PC interface ------------------------------------------------------

    def setUp(self, pc: PETSc.PC) -> None:  # noqa: N802 (petsc4py's name)
        # The sub-matrices of J follow J's pattern; the products run over the condensed
        # multipliers and the eliminated ones with a nonzero C row only, so their
        # patterns follow those sets. While J's pattern stays, the sub-matrices and the
        # rows near the contact are reused; while the sets stay too, the products (their
        # symbolic part) and the inner matrix's layout, and only values are computed.
        J = pc.getOperators()[0]
        self._J = J
        try:
            self._set_up(J)
        finally:
            self._J = None  # (a reference would keep an old Newton matrix alive)

    def _set_up(self, J: PETSc.Mat) -> None:
        self._take_null_space(J)
        fingerprint = _pattern_fingerprint(J, self.comm)
        reuse = (self.keep_products and fingerprint == self._fingerprint
                 and bool(self._matrices))
        if not reuse:
            self._release_matrices()
        self._fingerprint = fingerprint
        active = self._split(J, reuse)
        if not reuse:
            self._choose_rows()
        same_sets = self._choose_multipliers(active) and reuse
        if not same_sets:
            for matrix in (*self._products.values(), *self._scratch.values(),
                           *(kept[0] for kept in self._inputs_kept.values())):
                matrix.destroy()
            self._products, self._scratch, self._inputs_kept = {}, {}, {}
            self._inner.forget_layout()
        K_rows = self._condensed_rows()
        if reuse:
            self.reuses += 1
        else:
            self.rebuilds += 1
        m = self._matrices
        inner = self._inner.fill(J, self._a, self._rows, K_rows, m.get("K_inner"),
                                 "hypre" if self.ksp.getPC().getType() == "hypre" else "aij")
        if inner is not m.get("K_inner"):
            if "K_inner" in m:
                m["K_inner"].destroy()
            m["K_inner"] = inner
            self._set_near_nullspace(inner)
            self.ksp.setOperators(inner)
        self._set_inner_null_space(inner)
        _MatrixStore(self._products, self.keep_products).release("K_rows")
        self.ksp.setUp()

    def postSolve(self, pc: PETSc.PC, ksp: PETSc.KSP, b: PETSc.Vec,  # noqa: N802
                  x: PETSc.Vec) -> None:
        self.release_inner()

    def release_inner(self) -> None:
        """Free K_c and the inner preconditioner's data while the Newton iteration has no
        use for them (the next set-up makes K_c anew from J, its layout kept while it
        holds). Algebraic multigrid is set up anew at every set-up anyway, so keeping them
        through the residual and Jacobian assembly and into the next fill only raises the
        peak (docs/benchmarks.md). A factorization keeps them (MUMPS reuses its analysis
        while the pattern holds)."""
        inner = self._matrices.get("K_inner")
        if inner is None or self.ksp.getPC().getType() in (PETSc.PC.Type.LU,
                                                           PETSc.PC.Type.CHOLESKY):
            return
        self.ksp.reset()  # (the preconditioner's references to K_c)
        inner.destroy()
        del self._matrices["K_inner"]

    def apply(self, pc: PETSc.PC, x: PETSc.Vec, y: PETSc.Vec) -> None:
        if "K_inner" not in self._matrices:  # (released, and J is the same)
            self.setUp(pc)
        m, v = self._matrices, self._vectors
        source = x.getArray(readonly=True)
        v["ru"].getArray()[:] = source[: self.num_u]
        if self.rotate:  # the multiplier rows turned node by node: U^T r_z
            v["rz_raw"].getArray()[:] = source[self.num_u:]
            m["R_U_t"].mult(v["rz_raw"], v["rz"])
        else:
            v["rz"].getArray()[:] = source[self.num_u:]
        # r' = r_u - G d^-1 r_z
        v["sz"].pointwiseMult(v["inverse_d"], v["rz"])
        m["G"].mult(v["sz"], v["rp"])
        v["rp"].aypx(-1.0, v["ru"])
        # rc = (I - G P^-1 T) r', then rc - T^T (T rc + r_za [- S P^-1 T r'])
        m["T"].mult(v["rp"], v["tr"])
        if self.rotate:
            m["P_inv"].mult(v["tr"], v["sz"])
        else:
            v["sz"].pointwiseMult(v["inverse_p"], v["tr"])
        m["G"].mult(v["sz"], v["rc"])
        v["rc"].aypx(-1.0, v["rp"])
        m["T"].mult(v["rc"], v["tz"])
        v["sz"].pointwiseMult(v["active"], v["rz"])
        v["tz"].axpy(1.0, v["sz"])
        if self.rotate:
            m["S_P_inv"].mult(v["tr"], v["sz"])
            v["tz"].axpy(-1.0, v["sz"])
        m["T"].multTranspose(v["tz"], v["tu"])
        v["rc"].axpy(-1.0, v["tu"])
        # the column elimination's row operation: rc - E Q^-1 T rc
        m["T"].mult(v["rc"], v["tz"])
        if "E_q" in self._products:
            v["tz_a"].getArray()[:] = v["tz"].getArray(readonly=True)[self._condensed]
            self._products["E_q"].mult(v["tz_a"], v["t_rows"])
            v["rc"].getArray()[self._rows] -= v["t_rows"].getArray(readonly=True)
        failure = self._inner_solve(v["rc"], v["du"])
        if failure and self._switch_relaxation():
            retried = self._inner_solve(v["rc"], v["du"])
            failure = retried and (f"{failure}; with {self._relaxation} "
                                   f"smoothing: {retried}")
        if failure:
            # a NaN makes the outer Krylov method fail (DIVERGED_NANORINF), and SNES stops
            # before it applies the step
            self.inner_failure = failure
            y.set(np.nan)
            return
        # dz = d^-1 (r_z - C du) on the eliminated rows, P^-1 T (r' - A' du) on the active ones
        m["C"].mult(v["du"], v["sz"])
        v["sz"].aypx(-1.0, v["rz"])
        v["sz"].pointwiseMult(v["sz"], v["inverse_d"])
        # r' - A' du = r_u - A du - G d^-1 (r_z - C du); A du = (J [du; 0])_u
        v["x_mono"].getArray()[: self.num_u] = v["du"].getArray(readonly=True)
        pc.getOperators()[0].mult(v["x_mono"], v["y_mono"])
        v["tu"].getArray()[:] = v["y_mono"].getArray(readonly=True)[: self.num_u]
        v["tu"].aypx(-1.0, v["ru"])
        m["G"].mult(v["sz"], v["rp"])
        v["tu"].axpy(-1.0, v["rp"])
        m["T"].mult(v["tu"], v["tz"])
        if self.rotate:
            m["P_inv"].multAdd(v["tz"], v["sz"], v["sz"])
            m["R_V"].mult(v["sz"], v["rz_raw"])  # lambda = V mu
            result = v["rz_raw"]
        else:
            v["tz"].pointwiseMult(v["tz"], v["inverse_p"])
            v["sz"].axpy(1.0, v["tz"])
            result = v["sz"]
        target = y.getArray()
        target[: self.num_u] = v["du"].getArray(readonly=True)
        target[self.num_u:] = result.getArray(readonly=True)
        del target
        if self._null_space is not None:
            # fgmres preconditions from the right: its steps are the outputs
            self._null_space.remove(y)

    def _inner_solve(self, rhs: PETSc.Vec, solution: PETSc.Vec) -> str:
        """Solve K_c du = rc; why it broke down, or "" (also at its iteration limit: an
        iterative inner solve stopped there is still a preconditioner, which fgmres
        allows to vary)."""
        self.ksp.solve(rhs, solution)
        self.inner_iterations.append(self.ksp.getIterationNumber())
        reason = self.ksp.getConvergedReason()
        if reason >= 0 or reason == PETSc.KSP.ConvergedReason.DIVERGED_MAX_IT:
            return ""
        return (f"{diagnostics.describe_ksp_failure(self.ksp)} after "
                f"{self.ksp.getIterationNumber()} iterations")

    def _switchable(self, relaxation: str | None) -> str | None:
        """``relaxation`` (a key of :data:`RELAXATIONS`: the smoother the options set up),
        or None if the inner preconditioner is not BoomerAMG or the user chose its
        smoother (then a breakdown is not retried)."""
        pc = self.ksp.getPC()
        if (relaxation is None or pc.getType() != PETSc.PC.Type.HYPRE
                or pc.getHYPREType() != "boomeramg"):
            return None
        if relaxation not in RELAXATIONS:
            raise ValueError(f"relaxation must be one of {sorted(RELAXATIONS)}, got {relaxation!r}")
        return relaxation

    def _switch_relaxation(self) -> bool:
        """After an inner breakdown: BoomerAMG set up anew with :data:`FALLBACK_RELAXATION`
        (from it, with the smoother it started with), which it keeps for later set-ups;
        False if there is none to switch to. Collective (every rank's inner solve fails
        together)."""
        if self._relaxation is None:
            return False
        self._relaxation = (FALLBACK_RELAXATION if self._relaxation != FALLBACK_RELAXATION
                            else self._initial_relaxation)
        options = PETSc.Options()
        names = [f"{self.prefix}pc_hypre_boomeramg_relax_type_{which}"
                 for which in ("down", "up")]
        for name, value in zip(names, RELAXATIONS[self._relaxation], strict=True):
            options[name] = value
        try:
            self.ksp.getPC().setFromOptions()
        finally:
            for name in names:
                options.delValue(name)
        # the same matrix: a new state makes the PC set hypre up again (the l1 norms)
        self._matrices["K_inner"].stateIncrease()
        self.ksp.setUp()
        self.relaxation_switches += 1
        return True

    def _take_null_space(self, J: PETSc.Mat) -> None:
        """J's null space (:meth:`~dolfinx_mortar.equations.ContactEquations.set_null_space`),
        if it has one with vectors: removed from every output (so from fgmres' step) and,
        by its displacement parts, given to the inner matrix."""
        if self._null_space is not None:
            self._null_space.destroy()
            self._null_space = None
        space = J.getNullSpace()
        if space and space.getVecs():
            self._null_space = space  # (getNullSpace took a reference for it)

    def _set_inner_null_space(self, inner: PETSc.Mat) -> None:
        """The displacement parts of J's null vectors as K_c's null space (none: an empty
        one), which the inner Krylov method removes from its preconditioner's output and
        its right-hand side (the condensed residual of a slide that no force drives)."""
        vectors = []
        for vector in self._null_space.getVecs() if self._null_space is not None else []:
            part = inner.createVecRight()
            part.getArray()[:] = vector.getArray(readonly=True)[: self.num_u]
            part.normalize()
            vectors.append(part)
        self._set_coarse_relaxation(bool(vectors), inner)
        space = PETSc.NullSpace().create(vectors=vectors, comm=self.comm)
        inner.setNullSpace(space)
        # and from its right-hand side: with the null space only in the output, the inner
        # GMRES broke down on the 3D Cattaneo-Mindlin at refinement 1 (2 ranks)
        inner.setTransposeNullSpace(space)
        space.destroy()
        for part in vectors:
            part.destroy()

    def _set_coarse_relaxation(self, singular: bool, inner: PETSc.Mat) -> None:
        """BoomerAMG's coarsest level: :data:`SINGULAR_COARSE_RELAXATION` while the inner
        matrix is singular, hypre's Gaussian elimination otherwise (the PC is set up anew
        where it changes). Collective (the null space is the same on every rank)."""
        if not self._coarse_switchable or singular == self._singular_coarse:
            return
        self._singular_coarse = singular
        options = PETSc.Options()
        name = f"{self.prefix}pc_hypre_boomeramg_relax_type_coarse"
        options[name] = SINGULAR_COARSE_RELAXATION if singular else "Gaussian-elimination"
        try:
            self.ksp.getPC().setFromOptions()
        finally:
            options.delValue(name)
        inner.stateIncrease()

    def view(self, pc: PETSc.PC, viewer: PETSc.Viewer) -> None:
        viewer.printfASCII(f"static condensation of the multipliers ({self.num_active} active)\n")
        self.ksp.view(viewer)

    # -- pieces ------------------------------------------------------------

    def _split(self, J: PETSc.Mat, reuse: bool) -> np.ndarray:
        """J's blocks G, C (with friction turned node by node: G V, U^T C), the
        scalings d^-1 and P^-1 and T from them; returns which (rotated) multipliers are
        condensed (d_j = 0 or, with friction, a small sigma)."""
        m, v = self._matrices, self._vectors
        if not reuse:
            self._a = DisplacementBlock(self.comm, J, self.is_u.getIndices())
        raw = "_raw" if self.rotate else ""
        G = m["G" + raw] = J.createSubMatrix(self.is_u, self.is_z, submat=m.get("G" + raw))
        m["C" + raw] = J.createSubMatrix(self.is_z, self.is_u, submat=m.get("C" + raw))
        if self.rotate:
            d = self._rotate(J)
            G = m["G"]
            active = ~(d > 0.0)
        else:
            diagonal = J.getDiagonal()
            d = diagonal.getArray(readonly=True)[self.num_u:].copy()
            diagonal.destroy()
            active = d == 0.0
        self.num_active = self.comm.allreduce(int(active.sum()), op=MPI.SUM)
        if not reuse:
            for name in ("inverse_d", "inverse_p", "active", "rz", "sz", "tz",
                         "tr", "rz_raw"):
                v[name] = G.createVecRight()
            for name in ("ru", "rp", "rc", "du", "tu"):
                v[name] = G.createVecLeft()
            v["x_mono"], v["y_mono"] = J.createVecs()
            v["x_mono"].zeroEntries()
        v["inverse_d"].getArray()[:] = np.where(active, 0.0, 1.0 / np.where(active, 1.0, d))
        v["active"].getArray()[:] = active
        if self.rotate:
            frames, inverse_p = self._frames(G, active)
            m["P_inv"] = self._block_matrix(inverse_p, m.get("P_inv"))
            scaled = inverse_p * self._sigma[self.node_groups][:, :, None]
            m["S_P_inv"] = self._block_matrix(scaled, m.get("S_P_inv"))
        else:
            frames, lengths = self._normals(G, active)
            v["inverse_p"].getArray()[:] = np.where(active,
                                                    1.0 / np.where(active, lengths, 1.0), 0.0)
        self._normal_values = frames
        m["T"] = self._normal_matrix(frames, self._a.sizes, m.get("T"))
        return active

    def _rotate(self, J: PETSc.Mat) -> np.ndarray:
        """With friction: each node's block Z_j of J turned into its singular values,
        G V into "G" and U^T C into "C" (and the turns R_V, R_U^T kept for ``apply``);
        returns the singular values of the eliminated rotated multipliers, 0 at the
        condensed ones (their own values, possibly nonzero, in ``_sigma``)."""
        m = self._matrices
        store = _MatrixStore(m, self.keep_products)
        Z = m["Z"] = J.createSubMatrix(self.is_z, self.is_z, submat=m.get("Z"))
        groups = self.node_groups
        g = groups.shape[1]
        columns = self.z_first + groups
        blocks = _entries(Z, np.repeat(groups, g, axis=1).reshape(-1, g, g),
                          np.tile(columns, (1, g)).reshape(-1, g, g))
        store.release("Z")
        U, sigma, Vh = np.linalg.svd(blocks)
        # a node whose every row has its own entry (inactive, penalty: Z_j triangular and
        # invertible) is eliminated whole, as without friction
        whole = np.all(np.diagonal(blocks, axis1=1, axis2=2) != 0.0, axis=1)
        eliminated = whole[:, None] | (sigma > self.elimination_ratio * sigma[:, :1])
        self._sigma = np.zeros(self.num_z)
        self._sigma[groups] = np.where(eliminated, 0.0, sigma)
        d = np.zeros(self.num_z)
        d[groups] = np.where(eliminated, sigma, 0.0)
        # R_V[group i, group k] = V[i, k]; R_U^T[group k, group i] = U[i, k]
        m["R_V"] = self._block_matrix(np.swapaxes(Vh, 1, 2), m.get("R_V"))
        m["R_U_t"] = self._block_matrix(np.swapaxes(U, 1, 2), m.get("R_U_t"))
        store.product("G", m["G_raw"], m["R_V"])
        store.product("C", m["R_U_t"], m["C_raw"])
        store.release("G_raw", "C_raw")
        return d

    def _choose_rows(self) -> None:
        """The displacement rows where K_c differs from A: those of G (the slave and master
        dofs of the pairs), the slave nodes' (T^T) and every row with an entry in a slave
        node's column (K_r T^T). Elsewhere K_c = A, so the products need these rows only.
        From the patterns (zeros included), so they hold while J's pattern does."""
        G = self._matrices["G"]
        A = self._a
        first = A.first
        slave_u = np.zeros(A.sizes[1], dtype=bool)
        slave_u[np.concatenate(self.comm.allgather(self.z_node_dofs.reshape(-1)))] = True
        slave = np.zeros(A.column.size, dtype=bool)  # over J's columns
        is_u = A.column >= 0
        slave[is_u] = slave_u[A.column[is_u]]
        near = np.zeros(self.num_u, dtype=bool)
        with A.blocks(self._J) as blocks:
            for block in blocks:
                near |= row_reduce(np.logical_or, slave[block.columns][block.indices],
                                   block.indptr)
        near[np.diff(G.getValuesCSR()[0]) > 0] = True
        near[self.z_node_dofs.reshape(-1) - first] = True
        self._rows = np.flatnonzero(near)
        index_sets = self._index_sets
        for index_set in index_sets.values():
            index_set.destroy()
        index_sets.clear()
        index_sets["rows"] = PETSc.IS().createGeneral(
            (first + self._rows).astype(PETSc.IntType), comm=self.comm)
        index_sets["rows_of_J"] = PETSc.IS().createGeneral(
            (A.j_first + self._rows).astype(PETSc.IntType), comm=self.comm)
        index_sets["columns"] = PETSc.IS().createStride(self.num_u, first, 1, comm=self.comm)
        rows_first = self.comm.exscan(self._rows.size) or 0
        position = np.full(self.num_u, -1, dtype=np.int64)
        position[self._rows] = rows_first + np.arange(self._rows.size)
        self._t_row_columns = position[self.z_node_dofs - first].astype(PETSc.IntType)

    def _choose_multipliers(self, active: np.ndarray) -> bool:
        """The multipliers the products run over: the condensed ones (``active``) and the
        eliminated ones whose C row holds a nonzero (penalty, augmented; an inactive
        Lagrange row is z_j = 0, C_j = 0); returns whether both sets are the last
        set-up's on every rank. Collective."""
        m, v = self._matrices, self._vectors
        indptr, _, values = m["C"].getValuesCSR()
        coupled = np.bincount(np.repeat(np.arange(self.num_z), np.diff(indptr)),
                              weights=values != 0.0, minlength=self.num_z) > 0
        condensed = np.flatnonzero(active)
        eliminated = np.flatnonzero(~active & coupled)
        sets = (condensed.tobytes(), eliminated.tobytes())
        same = self.comm.allreduce(sets == self._sets, op=MPI.LAND)
        if same:
            return True
        self._sets = sets
        self._condensed, self._eliminated = condensed, eliminated
        self._set_sizes = tuple(self.comm.allreduce(part.size, op=MPI.SUM)
                                for part in (condensed, eliminated))
        index_sets = self._index_sets
        for name, part in (("condensed", condensed), ("eliminated", eliminated)):
            if name in index_sets:
                index_sets.pop(name).destroy()
            index_sets[name] = PETSc.IS().createGeneral(
                (self.z_first + part).astype(PETSc.IntType), comm=self.comm)
        for name in ("tz_a", "t_rows"):
            if name in v:
                v.pop(name).destroy()
        v["tz_a"] = PETSc.Vec().createMPI((condensed.size, PETSc.DETERMINE), comm=self.comm)
        return False

    def _inputs(self) -> dict[str, PETSc.Mat]:
        """The products' factors, their stored zeros dropped: A, G and C on the rows near
        the contact and the multipliers of ``_choose_multipliers``, T (in the columns of
        A and of the rows near the contact), with friction P^-1 and S P^-1. J's pattern
        holds every candidate pair's entries, most of them zero (pairs that do not
        overlap, inactive nodes), which the products would carry as stored zeros into
        K_c and algebraic multigrid into its coarse levels. When a factor's pattern
        changed on any rank, the products are released (built anew). Collective."""
        m, v, sets = self._matrices, self._vectors, self._index_sets
        num_condensed, num_eliminated = self._set_sizes
        wanted = [("A_rows", self._J, sets["rows_of_J"], self.is_u, None)]
        if num_eliminated:
            inverse_d = v["inverse_d"].getArray(readonly=True)[self._eliminated]
            wanted += [("G_e", m["G"], sets["rows"], sets["eliminated"], None),
                       ("C_e", m["C"], sets["eliminated"], sets["columns"], inverse_d)]
        if num_condensed:
            wanted += [("G_a", m["G"], sets["rows"], sets["condensed"], None),
                       ("C_a", m["C"], sets["condensed"], sets["columns"], None)]
            if self.rotate:
                wanted += [("P_inv_a", m["P_inv"], sets["condensed"], sets["condensed"], None),
                           ("S_P_inv_a", m["S_P_inv"], sets["condensed"], sets["condensed"],
                            None)]
        scratch = self._scratch
        parts = {}
        for name, source, rows, columns, row_scaling in wanted:
            sub = scratch[name] = source.createSubMatrix(rows, columns,
                                                         submat=scratch.get(name))
            indptr, indices, values = sub.getValuesCSR()
            if row_scaling is not None:
                values = values * np.repeat(row_scaling, np.diff(indptr))
            parts[name] = (indptr, indices, values, sub.getSizes())
        if num_condensed:
            condensed = self._condensed
            normals = self._normal_values[condensed]
            width = normals.shape[1]
            indptr = np.arange(0, width * condensed.size + 1, width)
            row_sizes, column_sizes = parts["A_rows"][3]
            for name, columns, sizes in (("T_rows", self._t_row_columns, row_sizes),
                                         ("T_cols", self.z_node_dofs, column_sizes)):
                parts[name] = (indptr, columns[condensed].reshape(-1), normals.reshape(-1),
                               ((condensed.size, PETSc.DETERMINE), sizes))
        kept = self._inputs_kept
        nonzero = {name: _nonzero_csr(*part[:3]) for name, part in parts.items()}
        same = set(kept) == set(parts) and all(
            np.array_equal(kept[name][1], nonzero[name][0])
            and np.array_equal(kept[name][2], nonzero[name][1]) for name in parts)
        if not self.comm.allreduce(same, op=MPI.LAND):
            for matrix in (*self._products.values(), *(k[0] for k in kept.values())):
                matrix.destroy()
            self._products, kept = {}, {}
            self._inputs_kept = kept
            self._inner.forget_layout()
            for name, (indptr, indices, values) in nonzero.items():
                matrix = PETSc.Mat().createAIJ(size=parts[name][3], csr=(indptr, indices, values),
                                               comm=self.comm)
                matrix.assemble()
                kept[name] = (matrix, indptr, indices)
        else:
            for name, (indptr, indices, values) in nonzero.items():
                kept[name][0].setValuesCSR(indptr, indices, values)
                kept[name][0].assemble()
        return {name: kept[name][0] for name in parts}

    def _condensed_rows(self) -> PETSc.Mat:
        """K_c's rows near the contact (``self._rows``; the module docstring's products
        restricted to them and to the multipliers of ``_choose_multipliers``, in order;
        what ``apply`` needs stays in the products)."""
        v = self._vectors
        inputs = self._inputs()
        store = _MatrixStore(self._products, self.keep_products)
        A = inputs["A_rows"]
        if "t_rows" not in v:
            v["t_rows"] = A.createVecLeft()
        num_condensed, num_eliminated = self._set_sizes
        # A' = A - G d^-1 C: the exact elimination of the rows with d != 0
        if num_eliminated:
            A_prime = store.combination(
                "A_prime", [(1.0, A), (-1.0, store.product("G_C", inputs["G_e"], inputs["C_e"]))])
            store.release("G_C")
        else:
            A_prime = A
        if not num_condensed:
            return A_prime
        T_rows, C_a = inputs["T_rows"], inputs["C_a"]
        # B1 = (I - G P^-1 T) A'
        if self.rotate:
            G_p = store.product("G_p", inputs["G_a"], inputs["P_inv_a"])
        else:
            G_p = inputs["G_a"]
            _scale(G_p, right=v["inverse_p"].getArray(readonly=True)[self._condensed])
        T_A = store.product("T_A", T_rows, A_prime)
        correction = store.product("G_p_T_A", G_p, T_A)
        B1 = store.combination("B1", [(1.0, A_prime), (-1.0, correction)])
        store.release("A_prime", "G_p", "G_p_T_A")
        # K_r = B1 - T^T (T B1 + C_a [- S P^-1 T A']): the normal rows at active nodes
        # become the constraints, negated so that their diagonal (c_n D_jj) is positive
        # as the stiffness is (the constraints row C_a is -c_n D n on the slave node)
        terms = [(1.0, store.product("T_B1", T_rows, B1)), (1.0, C_a)]
        if self.rotate:
            terms.append((-1.0, store.product("S_P_inv_T_A", inputs["S_P_inv_a"], T_A)))
        normal_rows = store.combination("normal_rows", terms)
        store.release("T_B1", "T_A", "S_P_inv_T_A")
        replaced = store.product("replaced", T_rows, normal_rows, transpose=True)
        store.release("normal_rows")
        K_r = store.combination("K_r", [(1.0, B1), (-1.0, replaced)])
        store.release("B1", "replaced")
        # K_c = (I - E Q^-1 T) K_r = K_r + E Q^-1 C_a, E = (I - T^T T) K_r T^T,
        # Q = diag(T K_r T^T): the slave normal displacements taken out of every other
        # row with the constraint rows (T K_r = -C_a)
        p = self._products
        T_t = p["T_t"] = inputs["T_cols"].transpose(p["T_t"] if "T_t" in p else PETSc.Mat())
        K_T = store.product("K_T", K_r, T_t)
        normal_block = store.product("T_K_T", T_rows, K_T)
        q = normal_block.getDiagonal()
        q_values = q.getArray(readonly=True)
        q.setArray(np.where(q_values != 0.0, 1.0 / np.where(q_values != 0.0, q_values, 1.0),
                            0.0))
        E = store.combination("E", [(1.0, K_T),
                                    (-1.0, store.product("T_t_T_K_T", T_rows, normal_block,
                                                         transpose=True))])
        store.release("K_T", "T_K_T", "T_t_T_K_T", "T_t")
        E_q = store.scaled_copy("E_q", E, right=q)
        q.destroy()
        store.release("E")
        K_rows = store.combination("K_rows", [(1.0, K_r),
                                              (1.0, store.product("E_q_C_a", E_q, C_a))])
        store.release("K_r", "E_q_C_a")
        return K_rows

    def _normals(self, G: PETSc.Mat, active: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Unit normals (n_z, gdim) and |G[node j dofs, j]| of the active multipliers (0
        elsewhere)."""
        first_row = G.getOwnershipRange()[0]
        first_col = G.getOwnershipRangeColumn()[0]
        num_cols = G.getSize()[1]
        indptr, indices, values = G.getValuesCSR()
        # AIJ rows are sorted by column: the keys row * num_cols + col are sorted
        keys = np.repeat(np.arange(self.num_u, dtype=np.int64), np.diff(indptr)) * num_cols
        keys += indices
        normals = np.zeros((self.num_z, self.block_size))
        selected = np.flatnonzero(active)
        wanted = (self.z_node_dofs[selected] - first_row) * num_cols
        wanted += (first_col + selected)[:, None]
        position = np.minimum(np.searchsorted(keys, wanted), max(keys.size - 1, 0))
        found = keys[position] == wanted if keys.size else np.zeros(wanted.shape, dtype=bool)
        normals[selected] = np.where(found, values[position] if keys.size else 0.0, 0.0)
        lengths = np.linalg.norm(normals, axis=1)
        if np.any(lengths[selected] == 0.0):
            raise RuntimeError("an active multiplier has no coupling to its own slave node")
        normals[selected] /= lengths[selected, None]
        return normals, lengths

    def _frames(self, G: PETSc.Mat, active: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """With friction: T's rows (num_z, gdim), per node the orthonormalized directions of
        its condensed multipliers' columns of G at the node's dofs (Gram-Schmidt in the
        order of the node's multipliers: G = T^T P on the node), zero at the eliminated
        ones; and P^-1 per node (nodes, d, d), zero outside the condensed ones."""
        groups = self.node_groups
        num_nodes, g = groups.shape
        first_row = G.getOwnershipRange()[0]
        rows = np.broadcast_to((self.z_node_dofs[groups[:, 0]] - first_row)[:, None, :],
                               (num_nodes, g, self.block_size))
        columns = np.broadcast_to((self.z_first + groups)[:, :, None], rows.shape)
        condensed = active[groups]
        columns_at_node = _entries(G, rows, columns) * condensed[:, :, None]
        Q = np.zeros_like(columns_at_node)
        R = np.zeros((num_nodes, g, g))
        for k in range(g):
            column = columns_at_node[:, k]
            R[:, :k, k] = np.einsum("nic,nc->ni", Q[:, :k], column)
            rest = column - np.einsum("ni,nic->nc", R[:, :k, k], Q[:, :k])
            length = np.linalg.norm(rest, axis=1)
            R[:, k, k] = length
            usable = condensed[:, k] & (length > 0.0)
            Q[usable, k] = rest[usable] / length[usable, None]
        if np.any(condensed & (np.diagonal(R, axis1=1, axis2=2) == 0.0)):
            raise RuntimeError("a condensed multiplier has no coupling to its own slave node "
                               "independent of its node's other ones")
        diagonal = np.arange(g)
        R[:, diagonal, diagonal] += ~condensed  # identity on the eliminated ones
        inverse_p = np.linalg.inv(R)
        inverse_p[:, diagonal, diagonal] *= condensed
        frames = np.zeros((self.num_z, self.block_size))
        frames[groups] = Q
        return frames, inverse_p

    def _block_matrix(self, values: np.ndarray, existing: PETSc.Mat | None) -> PETSc.Mat:
        """The z x z matrix with values[j, r, c] at (node_groups[j, r], node_groups[j, c])
        (a d x d block per node, every entry in the pattern); an ``existing`` one only
        gets the new values."""
        groups = self.node_groups
        num_nodes, g = groups.shape
        order = np.argsort(groups, axis=1)
        sorted_columns = np.take_along_axis(groups, order, axis=1) + self.z_first
        sorted_values = np.take_along_axis(values, order[:, None, :], axis=2)
        columns = np.zeros((self.num_z, g), dtype=PETSc.IntType)
        entries = np.zeros((self.num_z, g))
        columns[groups] = sorted_columns[:, None, :]
        entries[groups] = sorted_values
        indptr = np.arange(0, g * self.num_z + 1, g, dtype=PETSc.IntType)
        if existing is not None:
            existing.setValuesCSR(indptr, columns.reshape(-1), entries.reshape(-1))
            existing.assemble()
            return existing
        matrix = PETSc.Mat().createAIJ(size=((self.num_z, PETSc.DETERMINE),) * 2,
                                       csr=(indptr, columns.reshape(-1), entries.reshape(-1)),
                                       comm=self.comm)
        matrix.assemble()
        return matrix

    def _normal_matrix(self, normals: np.ndarray, column_sizes: tuple,
                       existing: PETSc.Mat | None = None) -> PETSc.Mat:
        """T: row j holds n_j^T on the dofs of slave node j (zeros when j is not active);
        its pattern is fixed, so an ``existing`` T only gets the new values."""
        return _sparse_rows(normals, self.z_node_dofs, column_sizes, self.comm, existing)

    def _set_near_nullspace(self, matrix: PETSc.Mat) -> None:
        if not self.near_nullspace:
            return
        vectors = []
        for values in self.near_nullspace:
            vector = matrix.createVecRight()
            vector.getArray()[:] = values
            vectors.append(vector)
        nullspace = PETSc.NullSpace().create(vectors=vectors, comm=self.comm)
        matrix.setNearNullSpace(nullspace)
        nullspace.destroy()
        for vector in vectors:
            vector.destroy()

    def _release_matrices(self) -> None:
        for matrix in (*self._matrices.values(), *self._products.values(),
                       *self._scratch.values(), *(kept[0] for kept in self._inputs_kept.values())):
            matrix.destroy()
        self._products, self._scratch, self._inputs_kept = {}, {}, {}
        self._sets = None
        self._inner.reset()
        for vector in self._vectors.values():
            vector.destroy()
        self._matrices, self._vectors = {}, {}

    def destroy(self, pc: PETSc.PC | None = None) -> None:
        self._release_matrices()
        if self._null_space is not None:
            self._null_space.destroy()
            self._null_space = None
        for index_set in self._index_sets.values():
            index_set.destroy()
        self.ksp.destroy()
        self.is_u.destroy()
        self.is_z.destroy()


def _entries(matrix: PETSc.Mat, rows: np.ndarray, columns: np.ndarray) -> np.ndarray:
    """The values of ``matrix`` at (local row, global column) pairs of any shape, 0 where
    its pattern has no entry."""
    indptr, indices, values = matrix.getValuesCSR()
    num_columns = matrix.getSize()[1]
    # AIJ rows are sorted by column: the keys row * num_columns + column are sorted
    keys = np.repeat(np.arange(indptr.size - 1, dtype=np.int64), np.diff(indptr))
    keys = keys * num_columns + indices
    wanted = np.asarray(rows, dtype=np.int64) * num_columns + np.asarray(columns)
    if not keys.size:
        return np.zeros(wanted.shape)
    position = np.minimum(np.searchsorted(keys, wanted), keys.size - 1)
    return np.where(keys[position] == wanted, values[position], 0.0)


def _pattern_fingerprint(J: PETSc.Mat, comm: MPI.Intracomm) -> tuple:
    """Collective: a key of J's layout and nonzero pattern on every rank (read in place)."""
    digest = hashlib.blake2b(digest_size=16)
    with local_blocks(J) as blocks:
        for block in blocks:
            for array in (block.indptr, block.indices, block.columns):
                digest.update(np.ascontiguousarray(array).data)
    local = (J.getOwnershipRange(), digest.hexdigest())
    return tuple(comm.allgather(local))


class _MatrixStore:
    """The named matrices of a set-up: each result is written into the matrix of its
    name if there is one (its pattern reused), and freed after its last use unless
    the products are kept between set-ups."""

    def __init__(self, matrices: dict[str, PETSc.Mat], keep: bool):
        self.matrices, self.keep = matrices, keep

    def scaled_copy(self, name, source, left=None, right=None) -> PETSc.Mat:
        m = self.matrices
        if name in m:
            source.copy(m[name], structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        else:
            m[name] = source.copy()
        m[name].diagonalScale(L=left, R=right)
        return m[name]

    def combination(self, name, terms) -> PETSc.Mat:
        """sum of factor * matrix over ``terms`` in one matrix of their joint pattern."""
        m, structure = self.matrices, PETSc.Mat.Structure
        if name not in m:
            first_factor, first = terms[0]
            m[name] = first.copy()
            m[name].scale(first_factor)
            for factor, matrix in terms[1:]:
                m[name].axpy(factor, matrix, structure=structure.DIFFERENT_NONZERO_PATTERN)
            return m[name]
        m[name].zeroEntries()
        for factor, matrix in terms:
            m[name].axpy(factor, matrix, structure=structure.SUBSET_NONZERO_PATTERN)
        return m[name]

    def product(self, name, left, right, transpose=False) -> PETSc.Mat:
        multiply = left.transposeMatMult if transpose else left.matMult
        self.matrices[name] = multiply(right, result=self.matrices.get(name))
        return self.matrices[name]

    def release(self, *names) -> None:
        """Without kept products: free what the rest of the set-up and apply do not need."""
        if not self.keep:
            for name in names:
                if name in self.matrices:
                    self.matrices.pop(name).destroy()


def _sparse_rows(values: np.ndarray, columns: np.ndarray, column_sizes, comm: MPI.Intracomm,
                 existing: PETSc.Mat | None = None) -> PETSc.Mat:
    """The matrix with this rank's row i holding ``values[i]`` at ``columns[i]`` (the same
    number per row, columns ascending); an ``existing`` one only gets the new values."""
    num_rows, width = values.shape
    indptr = np.arange(0, width * num_rows + 1, width, dtype=PETSc.IntType)
    columns = np.asarray(columns).reshape(-1).astype(PETSc.IntType)
    if existing is None:
        existing = PETSc.Mat().createAIJ(size=((num_rows, PETSc.DETERMINE), column_sizes),
                                         csr=(indptr, columns, values.reshape(-1)), comm=comm)
    else:
        existing.setValuesCSR(indptr, columns, values.reshape(-1))
    existing.assemble()
    return existing


def _nonzero_csr(indptr, indices, values) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The CSR rows without their zero entries."""
    rows = np.repeat(np.arange(indptr.size - 1), np.diff(indptr))
    keep = values != 0.0
    kept_indptr = np.zeros(indptr.size, dtype=PETSc.IntType)
    np.cumsum(np.bincount(rows[keep], minlength=indptr.size - 1), out=kept_indptr[1:])
    return kept_indptr, np.asarray(indices)[keep].astype(PETSc.IntType), values[keep]


def _scale(matrix: PETSc.Mat, left: np.ndarray | None = None,
           right: np.ndarray | None = None) -> None:
    """diag(left) matrix diag(right), from this rank's parts of the two diagonals."""
    vectors = []
    for values in (left, right):
        if values is None:
            vectors.append(None)
            continue
        vector = PETSc.Vec().createMPI((values.size, PETSc.DETERMINE), comm=matrix.getComm())
        vector.getArray()[:] = values
        vectors.append(vector)
    matrix.diagonalScale(L=vectors[0], R=vectors[1])
    for vector in vectors:
        if vector is not None:
            vector.destroy()
