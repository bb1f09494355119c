"""Mesh tying: couple two non-matching subdomains with the mortar matrices D and M.

The interface condition u^(1) = u^(2) is imposed weakly with a vector
multiplier per slave node (paper, section 1):

    sum_k D_jk u_k^(1) - sum_l M_jl u_l^(2) = 0    for every slave node j,

and the multipliers enter the equilibrium as D^T lambda on the slave side and
-M^T lambda on the master side. The saddle-point system is assembled into one
AIJ matrix (:mod:`layout`) and solved with a direct solver (MUMPS by default;
PETSc options with a prefix, the dolfinx way).
"""

from __future__ import annotations

import dolfinx
import dolfinx.fem.petsc
import numpy as np
from petsc4py import PETSc

from . import compat
from .deprecation import renamed_keywords
from .layout import BlockLayout, csr_to_coo, dirichlet_dofs
from .mortar import MortarInterface


class MeshTying:
    """Tie the slave and master surfaces of ``facet_tags`` in a linear problem.

    Args:
        a, L: bilinear and linear UFL forms on the displacement space ``V``.
        u: the Function that receives the solution.
        bcs: Dirichlet conditions.
        facet_tags, slave, master: the two sides of the interface.
        basis: ``standard`` or ``dual`` multipliers.
        petsc_options: options for the KSP (default: direct solve with MUMPS).
        petsc_options_prefix: prefix for those options.

    A slave node whose displacement is fully prescribed (a crosspoint with a
    Dirichlet boundary) gets no multiplier: its basis function is merged into
    its neighbour's (constants stay in the multiplier space, so the patch test
    holds), and its multiplier row is an identity row.
    """

    @renamed_keywords(slave_marker="slave", master_marker="master")
    def __init__(
        self,
        a,
        L,
        u: dolfinx.fem.Function,
        bcs: list,
        facet_tags: dolfinx.mesh.MeshTags,
        slave: int,
        master: int,
        *,
        basis: str = "standard",
        integration: str = "segment",
        num_gauss_points: int | None = None,
        petsc_options: dict | None = None,
        petsc_options_prefix: str = "dolfinx_mortar_tying_",
    ):
        self.u = u
        self.V = u.function_space
        self.bcs = bcs
        self.a = dolfinx.fem.form(a)
        self.L = dolfinx.fem.form(L)
        self.interface = MortarInterface(
            self.V,
            facet_tags,
            slave,
            master,
            normals="slave",
            integration=integration,
            basis=basis,
            num_gauss_points=num_gauss_points,
        )
        comm = self.V.mesh.comm
        interface = self.interface
        bs = self.V.dofmap.index_map_bs
        fixed = dirichlet_dofs(bcs, self.V)
        fixed_blocks = np.unique(fixed // bs)
        fully_fixed = fixed_blocks[
            np.all([np.isin(fixed_blocks * bs + c, fixed) for c in range(bs)], axis=0)
        ]
        interface.set_crosspoints(fully_fixed)
        interface.update(None)
        self.layout = BlockLayout(
            comm, interface.num_owned_dofs, bs * interface.num_owned_multipliers
        )
        self.A = self._assemble_saddle_point(fixed)
        self.solver = self._create_solver(petsc_options, petsc_options_prefix)

    def _assemble_saddle_point(self, fixed: np.ndarray) -> PETSc.Mat:
        """[[K, B^T], [B, 0]] with B = [D, -M] per displacement component; identity rows
        for the crosspoints' multipliers and the prescribed dofs (``fixed``)."""
        interface, bs, bcs = self.interface, self.V.dofmap.index_map_bs, self.bcs
        D_mat, M_mat = interface.mortar_matrices()
        constraint = []
        for matrix in (D_mat, M_mat):
            rows, cols, values = csr_to_coo(matrix)
            constraint.append((rows, cols, values if matrix is D_mat else -values))
        rows = np.concatenate([c[0] for c in constraint])
        cols = np.concatenate([c[1] for c in constraint])
        values = np.concatenate([c[2] for c in constraint])
        # rows: multiplier j -> (j, component); cols: node block -> (block, component)
        component = np.arange(bs)
        z_rows = (rows[:, None] * bs + component).reshape(-1)
        u_cols = (cols[:, None] * bs + component).reshape(-1)
        b_values = np.repeat(values, bs)
        crosspoints = interface.owned_crosspoint_multipliers
        self._fixed_multipliers = (crosspoints[:, None] * bs + np.arange(bs)).reshape(-1)

        self.K = dolfinx.fem.petsc.assemble_matrix(self.a, bcs=bcs)
        self.K.assemble()
        k_rows, k_cols, k_values = csr_to_coo(self.K)
        mono = self.layout
        fixed_z = mono.z(self._fixed_multipliers)
        all_rows = np.concatenate([mono.u(k_rows), mono.z(z_rows), mono.u(u_cols), fixed_z])
        all_cols = np.concatenate([mono.u(k_cols), mono.u(u_cols), mono.z(z_rows), fixed_z])
        all_values = np.concatenate([k_values, b_values, b_values, np.ones(fixed_z.size)])
        self._system = mono.create_matrix(all_rows, all_cols)
        A = self._system.assemble(all_values)
        # rows of prescribed dofs stay identity rows: no multiplier force there
        A.zeroRows(mono.u(fixed).astype(PETSc.IntType), diag=1.0)
        return A

    def _create_solver(self, petsc_options: dict | None, petsc_options_prefix: str) -> PETSc.KSP:
        """The KSP of :attr:`A`, set up with the options (inserted for the set-up only)."""
        solver = PETSc.KSP().create(self.V.mesh.comm)
        solver.setOperators(self.A)
        solver.setOptionsPrefix(petsc_options_prefix)
        options = {
            "ksp_type": "preonly",
            "pc_type": "lu",
            "pc_factor_mat_solver_type": "mumps",
            # the saddle point's delayed pivots outgrow MUMPS' default workspace
            # estimate (+20 %) in 3D: INFOG(1) = -8 on 3 ranks, 1803 hexahedral dofs
            "mat_mumps_icntl_14": 200,
        }
        options.update(petsc_options or {})
        opts = PETSc.Options()
        for key, value in options.items():
            opts[f"{petsc_options_prefix}{key}"] = value
        try:
            solver.setFromOptions()
            # the factor (and its mat_mumps_* options) exists once the KSP is set up
            solver.setUp()
        finally:
            # also when the set-up fails: no option left for the next solver to read
            for key in options:
                del opts[f"{petsc_options_prefix}{key}"]
        return solver

    def solve(self) -> dolfinx.fem.Function:
        """Assemble the right-hand side, solve, and write the displacement into ``u``."""
        b_u = dolfinx.fem.petsc.assemble_vector(self.L)
        dolfinx.fem.petsc.apply_lifting(b_u, [self.a], bcs=[self.bcs])
        b_u.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        compat.set_bc(b_u, self.bcs)
        rhs = self.layout.create_vector()
        rhs.getArray()[self.layout.owned_u] = b_u.getArray(readonly=True)
        solution = self.layout.create_vector()
        self.solver.solve(rhs, solution)
        reason = self.solver.getConvergedReason()
        if reason < 0:
            raise RuntimeError(f"mesh tying solve failed: KSP converged reason {reason}")
        owned = self.interface.num_owned_dofs
        self.u.x.array[:owned] = solution.getArray(readonly=True)[self.layout.owned_u]
        self.u.x.scatter_forward()
        self.multipliers = solution.getArray(readonly=True)[self.layout.owned_z].copy()
        b_u.destroy()
        rhs.destroy()
        solution.destroy()
        return self.u
