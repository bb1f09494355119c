"""Mesh tying in 3D: non-matching tetrahedral and hexahedral blocks reproduce linear fields,
on one rank and several."""

from __future__ import annotations

import dolfinx
import numpy as np
import pytest
import ufl
from mpi4py import MPI
from test_mortar3d import two_blocks

from dolfinx_mortar import MeshTying


def linear_field(x):
    return np.vstack([0.1 + 0.2 * x[0] - 0.3 * x[1] + 0.1 * x[2], 0.05 * x[0] + 0.2 * x[2],
                      -0.1 + 0.3 * x[1] - 0.2 * x[2]])


@pytest.mark.parallel
@pytest.mark.parametrize("cell", ["tetrahedron", "hexahedron"])
@pytest.mark.parametrize("basis", ["standard", "dual"])
def test_linear_field_is_reproduced_on_non_matching_blocks(cell, basis):
    """Dirichlet data of a linear field on the outer boundary: the tied solution is that
    field to rounding (the mortar patch test in 3D)."""
    tagged = two_blocks(cell, 3, 4, gap=0.0)
    mesh = tagged.mesh
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (3,)))
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)

    def strain(w):
        return ufl.sym(ufl.grad(w))

    a = ufl.inner(2.0 * strain(u) + ufl.tr(strain(u)) * ufl.Identity(3), strain(v)) * ufl.dx
    L = ufl.inner(dolfinx.fem.Constant(mesh, np.zeros(3)), v) * ufl.dx
    exact = dolfinx.fem.Function(V)
    exact.interpolate(linear_field)
    mesh.topology.create_connectivity(2, 3)
    outer = dolfinx.mesh.exterior_facet_indices(mesh.topology)
    outer = outer[~np.isclose(dolfinx.mesh.compute_midpoints(mesh, 2, outer)[:, 2], 0.5)]
    bc = dolfinx.fem.dirichletbc(exact, dolfinx.fem.locate_dofs_topological(V, 2, outer))
    uh = dolfinx.fem.Function(V)
    tying = MeshTying(a, L, uh, [bc], tagged.facet_tags, tagged.markers["upper_bottom"],
                      tagged.markers["lower_top"], basis=basis)
    tying.solve()
    error = mesh.comm.allreduce(np.abs(uh.x.array - exact.x.array).max(), op=MPI.MAX)
    assert error < 1e-12
    assert tying.interface.num_global_multipliers == 5 * 5  # the slave grid's nodes


def test_mumps_options_reach_the_factor():
    """mat_mumps_* options (ours and the user's) are set on the factor, which exists only
    once the KSP is set up: the 3D saddle point needs a larger workspace (ICNTL(14))."""
    tagged = two_blocks("hexahedron", 2, 3, gap=0.0, comm=MPI.COMM_SELF)
    V = dolfinx.fem.functionspace(tagged.mesh, ("Lagrange", 1, (3,)))
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    a = ufl.inner(ufl.grad(u), ufl.grad(v)) * ufl.dx
    L = ufl.inner(dolfinx.fem.Constant(tagged.mesh, np.zeros(3)), v) * ufl.dx
    bottom = dolfinx.mesh.locate_entities_boundary(tagged.mesh, 2, lambda x: np.isclose(x[2], 0))
    bc = dolfinx.fem.dirichletbc(np.zeros(3), dolfinx.fem.locate_dofs_topological(V, 2, bottom), V)
    markers = (tagged.markers["upper_bottom"], tagged.markers["lower_top"])
    for options, expected in (({}, 200), ({"mat_mumps_icntl_14": 300}, 300)):
        uh = dolfinx.fem.Function(V)
        tying = MeshTying(a, L, uh, [bc], tagged.facet_tags, *markers, petsc_options=options)
        assert tying.solver.getPC().getFactorMatrix().getMumpsIcntl(14) == expected
