"""reaction_force: the force a Dirichlet condition exerts on its boundary, from the bulk
residual summed over that boundary's dofs.

Known answers: a linear-elastic bar under uniaxial strain eps has the reaction
(lambda + 2 mu) eps A on its stretched end and the opposite one on its held end (2D plane
strain and 3D, triangles, quadrilaterals, tetrahedra, hexahedra); a punch pressed into a
block is held by its driven top and the block by its clamped bottom, so each reaction
balances the contact force on its body (2D and 3D, any number of ranks).
"""

from __future__ import annotations

import dolfinx
import numpy as np
import pytest
import ufl

from dolfinx_mortar import (
    ContactPair,
    ContactProblem,
    Material,
    internal_work,
    merge_meshes,
    solve_load_steps,
)
from dolfinx_mortar.reactions import reaction_force

E, NU = 200.0, 0.3
LAMBDA = E * NU / ((1 + NU) * (1 - 2 * NU))
MU = E / (2 * (1 + NU))

CELLS = {
    2: (dolfinx.mesh.CellType.triangle, dolfinx.mesh.CellType.quadrilateral),
    3: (dolfinx.mesh.CellType.tetrahedron, dolfinx.mesh.CellType.hexahedron),
}


def bar(comm, dim: int, cell):
    """[0, 2] x [0, 0.5] (x [0, 0.25]): area A = 0.5 (2D: per unit thickness) or 0.125."""
    if dim == 2:
        mesh = dolfinx.mesh.create_rectangle(comm, [[0.0, 0.0], [2.0, 0.5]], [6, 3], cell)
        return mesh, 0.5
    mesh = dolfinx.mesh.create_box(comm, [[0.0, 0.0, 0.0], [2.0, 0.5, 0.25]], [6, 3, 2], cell)
    return mesh, 0.125


def end_tags(mesh) -> dolfinx.mesh.MeshTags:
    fdim = mesh.topology.dim - 1
    left = dolfinx.mesh.locate_entities_boundary(mesh, fdim, lambda x: np.isclose(x[0], 0.0))
    right = dolfinx.mesh.locate_entities_boundary(mesh, fdim, lambda x: np.isclose(x[0], 2.0))
    indices = np.concatenate([left, right]).astype(np.int32)
    values = np.concatenate([np.full(left.size, 1), np.full(right.size, 2)]).astype(np.int32)
    order = np.argsort(indices)
    return dolfinx.mesh.meshtags(mesh, fdim, indices[order], values[order])


@pytest.mark.parallel
@pytest.mark.parametrize("dim, cell", [(d, c) for d, cells in CELLS.items() for c in cells])
def test_bar_under_uniaxial_strain(comm, dim, cell):
    """u = (eps x, 0, 0) is the exact solution with its ends prescribed and the lateral
    displacement held: sigma_xx = (lambda + 2 mu) eps, the reactions +- sigma_xx A e_x."""
    mesh, area = bar(comm, dim, cell)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (dim,)))
    u = dolfinx.fem.Function(V)
    eps = 1e-3
    u.interpolate(lambda x: np.vstack([eps * x[0]] + [np.zeros(x.shape[1])] * (dim - 1)))
    F = internal_work(u, ufl.TestFunction(V), {0: Material(E, NU, "linear")})
    tags = end_tags(mesh)
    expected = np.zeros(dim)
    expected[0] = (LAMBDA + 2 * MU) * eps * area
    right = reaction_force(F, tags, 2)
    left = reaction_force(F, tags, [1])
    assert right.shape == (dim,)
    assert np.allclose(right, expected, rtol=1e-10, atol=1e-12 * expected[0])
    assert np.allclose(left, -expected, rtol=1e-10, atol=1e-12 * expected[0])
    both = reaction_force(F, tags, (1, 2))  # a self-equilibrated body: the sum is zero
    assert np.linalg.norm(both) <= 1e-12 * expected[0]


def test_bad_input_says_what_is_wrong(comm):
    mesh, _ = bar(comm, 2, dolfinx.mesh.CellType.triangle)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    u = dolfinx.fem.Function(V)
    F = internal_work(u, ufl.TestFunction(V), {0: Material(E, NU, "linear")})
    with pytest.raises(ValueError, match="mark no facet"):
        reaction_force(F, end_tags(mesh), 7)
    with pytest.raises(ValueError, match="one argument"):
        reaction_force(ufl.derivative(F, u), end_tags(mesh), 1)
    scalar = dolfinx.fem.functionspace(mesh, ("Lagrange", 1))
    w = dolfinx.fem.Function(scalar)
    form = ufl.inner(ufl.grad(w), ufl.grad(ufl.TestFunction(scalar))) * ufl.dx
    with pytest.raises(ValueError, match="vector-valued"):
        reaction_force(form, end_tags(mesh), 1)


@pytest.mark.parallel
@pytest.mark.parametrize("dim", [2, 3])
def test_reactions_balance_the_contact_forces(comm, dim):
    """Punch pressed into a block: the driven top's reaction is minus the contact force on
    the punch, the clamped bottom's minus that on the block."""
    if dim == 2:
        punch = dolfinx.mesh.create_rectangle(comm, [[0.5, 1.0], [1.5, 1.5]], [8, 4])
        block = dolfinx.mesh.create_rectangle(comm, [[0.0, 0.0], [2.0, 1.0]], [10, 5])
    else:
        hexahedron = dolfinx.mesh.CellType.hexahedron
        punch = dolfinx.mesh.create_box(comm, [[0.5, 0.5, 1.0], [1.5, 1.5, 1.5]], [4, 4, 2],
                                        hexahedron)
        block = dolfinx.mesh.create_box(comm, [[0.0, 0.0, 0.0], [2.0, 2.0, 1.0]], [3, 3, 2],
                                        hexahedron)

    def height(value):
        return lambda x: np.isclose(x[dim - 1], value)

    tagged = merge_meshes({"punch": (punch, {"contact": height(1.0), "top": height(1.5)}),
                           "block": (block, {"contact": height(1.0), "bottom": height(0.0)})})
    mesh, markers, facet_tags = tagged.mesh, tagged.markers, tagged.facet_tags
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (dim,)))
    u = dolfinx.fem.Function(V)
    F = internal_work(u, ufl.TestFunction(V),
                      {markers["punch"]: Material(100.0, 0.3, "neo-hookean"),
                       markers["block"]: Material(1000.0, 0.3, "neo-hookean")},
                      tagged.cell_tags)
    fdim = mesh.topology.dim - 1
    top = dolfinx.fem.locate_dofs_topological(V, fdim, facet_tags.find(markers["punch_top"]))
    bottom = dolfinx.fem.locate_dofs_topological(
        V, fdim, facet_tags.find(markers["block_bottom"]))
    drive = dolfinx.fem.Constant(mesh, np.zeros(dim))
    bcs = [dolfinx.fem.dirichletbc(drive, top, V),
           dolfinx.fem.dirichletbc(np.zeros(dim), bottom, V)]
    pair = ContactPair(facet_tags, markers["punch_contact"], markers["block_contact"])
    problem = ContactProblem(F, u, bcs, [pair])

    def press(t):
        value = np.zeros(dim)
        value[0], value[-1] = 0.05 * t, -0.04 * t
        drive.value[:] = value

    solve_load_steps(problem, press, num_steps=2)
    slave, master = problem.contact_forces()
    on_top = reaction_force(problem, facet_tags, markers["punch_top"])
    on_bottom = reaction_force(F, facet_tags, markers["block_bottom"])
    scale = np.linalg.norm(slave)
    assert slave.shape == on_top.shape == (dim,) and scale > 0.0
    assert np.linalg.norm(on_top + slave) <= 1e-8 * scale
    assert np.linalg.norm(on_bottom + master) <= 1e-8 * scale
    problem.destroy()
