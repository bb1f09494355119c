"""Reaction forces: the total force a Dirichlet condition exerts on a boundary.

The reaction on a boundary Gamma_D with a prescribed displacement is the bulk residual
F(u; w) tested with a function w equal to a unit vector e_c at the degrees of freedom on
Gamma_D and 0 at all others, one component c at a time: F = internal minus external
virtual work, so at an equilibrium state F(u; w) is the force the prescribed
displacement must exert on the body to hold it there. With a lifted w that is the sum of
the residual's rows at Gamma_D's dofs of component c, which is what is computed here
(one vector assembly, no extra form).
"""

from __future__ import annotations

import dolfinx
import numpy as np
from mpi4py import MPI

__all__ = ["reaction_force"]


def reaction_force(residual, facet_tags: dolfinx.mesh.MeshTags, tag) -> np.ndarray:
    """Total force the Dirichlet condition on the facets ``tag`` exerts on the body.

    Collective: every rank of the mesh's communicator must call it; each gets the sum over
    all ranks.

    Args:
        residual: a :class:`~dolfinx_mortar.problem.ContactProblem` (its bulk residual F
            at its current state) or a UFL residual form F(u; v) with one argument, the
            test function of a vector-valued space.
        facet_tags: facet tags of the mesh (e.g. ``TaggedMesh.facet_tags``).
        tag: the value (int) or values (iterable of int) of the facets of the boundary.

    Returns:
        The force, shape (value size of the space,): gdim components in 2D and 3D, the same
        on every rank. At an equilibrium state it balances every other force on the body;
        e.g. for a body held only by that boundary and pressed by contact it equals minus
        the contact force on that body (:meth:`ContactProblem.contact_forces`).

    Raises:
        ValueError: on every rank, for a residual that is neither, a scalar test space, or
            a tag that marks no facet on any rank.

    Note:
        Only the bulk residual F is summed, not the contact terms: a node of the boundary
        that is also a slave or master node would miss its share of the contact force, so
        keep the driven boundary away from contact surfaces (as in the examples).
    """
    if hasattr(residual, "F_form") and hasattr(residual, "V"):  # a ContactProblem
        form, V = residual.F_form, residual.V
    else:
        arguments = residual.arguments() if hasattr(residual, "arguments") else ()
        if len(arguments) != 1:
            raise ValueError(
                "reaction_force needs a ContactProblem or a UFL residual form with one "
                f"argument (the test function), got {type(residual).__name__} with "
                f"{len(arguments)} arguments"
            )
        form, V = dolfinx.fem.form(residual), arguments[0].ufl_function_space()
    block = V.dofmap.index_map_bs
    if block == 1 and V.num_sub_spaces == 0:
        raise ValueError("reaction_force needs a vector-valued test space (a displacement)")
    mesh = V.mesh
    fdim = mesh.topology.dim - 1
    values = np.atleast_1d(np.asarray(tag, dtype=np.int32))
    facets = facet_tags.indices[np.isin(facet_tags.values, values)]
    if mesh.comm.allreduce(facets.size, op=MPI.SUM) == 0:
        raise ValueError(f"reaction_force: the tag(s) {values.tolist()} mark no facet")
    mesh.topology.create_connectivity(fdim, mesh.topology.dim)
    blocks = dolfinx.fem.locate_dofs_topological(V, fdim, facets)
    blocks = blocks[blocks < V.dofmap.index_map.size_local]  # owned: each node counted once
    vector = dolfinx.fem.assemble_vector(form)
    vector.scatter_reverse(dolfinx.la.InsertMode.add)
    local = vector.array[: V.dofmap.index_map.size_local * block].reshape(-1, block)
    return mesh.comm.allreduce(local[blocks].sum(axis=0), op=MPI.SUM)
