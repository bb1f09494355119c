"""Set-up checks that name the cause before the first load step (ContactProblem): bodies
that start overlapping, bodies that share nodes, a body free to move as a rigid body.

A cube on a block, each from create_box and joined by merge_meshes (the README's scene),
in 3D, and a punch on a foundation in 2D; serially and on 2 and 3 ranks.
"""

from __future__ import annotations

import warnings

import dolfinx
import numpy as np
import pytest
import ufl
from contact_warnings import warns_on_rank_zero
from mpi4py import MPI

from dolfinx_mortar import (
    ContactPair,
    ContactProblem,
    ContactWarning,
    LoadSteppingError,
    Material,
    compat,
    internal_work,
    merge_meshes,
    solve_load_steps,
)
from dolfinx_mortar.surface import SurfaceError


def cube_on_block(bottom: float, gdim: int = 3, held: tuple = ("cube_top", "block_bottom"),
                  spring: float = 0.0, held_vertically: tuple = ()):
    """A cube of side 0.5 with its bottom at height ``bottom`` over the middle of a unit
    block (2D: a square on a rectangle); Dirichlet conditions u = 0 on the ``held`` groups
    and u_z = 0 (2D: u_y) on the ``held_vertically`` ones; optionally a spring of stiffness
    ``spring`` per area on the cube's top (a Robin term)."""
    comm = MPI.COMM_WORLD
    up = gdim - 1

    def box(lower, upper, n):
        if gdim == 2:
            return dolfinx.mesh.create_rectangle(comm, [lower[:2], upper[:2]], n[:2])
        return dolfinx.mesh.create_box(comm, [lower, upper], n,
                                       dolfinx.mesh.CellType.hexahedron)

    lower, upper = [0.25, 0.25, 0.25][:gdim], [0.75, 0.75, 0.75][:gdim]
    lower[up], upper[up] = bottom, bottom + 0.5
    cube = box(lower + [0.0] * (3 - gdim), upper + [0.0] * (3 - gdim), [2, 2, 2])
    block = box([0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [3, 3, 2])
    tagged = merge_meshes({
        "cube": (cube, {"bottom": lambda x: np.isclose(x[up], bottom),
                        "top": lambda x: np.isclose(x[up], bottom + 0.5)}),
        "block": (block, {"top": lambda x: np.isclose(x[up], 1.0),
                          "bottom": lambda x: np.isclose(x[up], 0.0)})})
    tags, markers = tagged.facet_tags, tagged.markers
    V = dolfinx.fem.functionspace(tagged.mesh, ("Lagrange", 1, (gdim,)))
    u = dolfinx.fem.Function(V)
    F = internal_work(u, ufl.TestFunction(V), {0: Material(100.0, 0.3, "neo-hookean")})
    if spring:
        ds = ufl.Measure("ds", tagged.mesh, subdomain_data=tags)
        F += spring * ufl.inner(u, ufl.TestFunction(V)) * ds(markers["cube_top"])
    bcs = [dolfinx.fem.dirichletbc(np.zeros(gdim), dolfinx.fem.locate_dofs_topological(
        V, gdim - 1, tags.find(markers[name])), V) for name in held]
    bcs += [dolfinx.fem.dirichletbc(0.0, dolfinx.fem.locate_dofs_topological(
        V.sub(up), gdim - 1, tags.find(markers[name])), V.sub(up)) for name in held_vertically]
    return F, u, bcs, ContactPair(tags, markers["cube_bottom"], markers["block_top"],
                                  name="cube-block")


def build(F, u, bcs, pair):
    problem = ContactProblem(F, u, bcs, [pair])
    problem.destroy()


@pytest.mark.parallel
@pytest.mark.parametrize("gdim", [2, 3])
def test_bodies_that_start_overlapping_are_reported_with_depth_and_place(gdim):
    """The cube's bottom 0.2 inside the block (0.8 of the cube's facet length 0.25)."""
    with warns_on_rank_zero(r"'cube-block'.*the bodies overlap at the start: \d+ surface "
                            r"node\(s\).*deepest a (slave|master) node 0.8 facet lengths behind"
                            r".*interference fit") as shown:
        build(*cube_on_block(0.8, gdim))
    assert len(shown) == (1 if MPI.COMM_WORLD.rank == 0 else 0)


@pytest.mark.parallel
@pytest.mark.parametrize("gdim", [2, 3])
@pytest.mark.parametrize("bottom", [1.0, 1.1])
def test_touching_or_apart_bodies_held_by_dirichlet_conditions_give_no_message(gdim, bottom):
    with warnings.catch_warnings():
        warnings.simplefilter("error", ContactWarning)
        build(*cube_on_block(bottom, gdim))


@pytest.mark.parallel
@pytest.mark.parametrize("gdim", [2, 3])
def test_a_free_body_apart_from_the_other_is_reported(gdim):
    """No Dirichlet condition on the cube, 0.1 above the block: free along every axis."""
    axes = "x, y, z" if gdim == 3 else "x, y"
    with warns_on_rank_zero(r"the body with nodes in \(0.25(, 0.25)?, 1.1\) .. "
                            rf"\(0.75(, 0.75)?, 1.6\) is free to move as a rigid body "
                            rf"along {axes}: .*smallest nodal gap .*'cube-block'.* is 0.1\b"):
        build(*cube_on_block(1.1, gdim, held=("block_bottom",)))


@pytest.mark.parallel
def test_a_body_held_by_touching_contact_a_spring_or_one_component_is_not_reported():
    """Touching at the start (the first iterate's contact is active), a spring on the cube's
    top (the form holds it), or the cube's vertical component alone fixed on its top (the
    horizontal translations are free: reported along x, y only)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", ContactWarning)
        build(*cube_on_block(1.0, held=("block_bottom",)))
        build(*cube_on_block(1.1, held=("block_bottom",), spring=1.0))
    with warns_on_rank_zero(r"free to move as a rigid body along x, y: no Dirichlet condition "
                            r"holds it in those directions"):
        build(*cube_on_block(1.1, held=("block_bottom",), held_vertically=("cube_top",)))


@pytest.mark.parallel
def test_a_failed_load_step_repeats_the_set_up_warning():
    """The free cube pushed down by a traction on its top: the step fails, and the error
    says that the cube was free to move, which is why."""
    F, u, bcs, pair = cube_on_block(1.1, gdim=2, held=("block_bottom",))
    V = u.function_space
    push = dolfinx.fem.Constant(V.mesh, 0.0)
    ds = ufl.Measure("ds", V.mesh, subdomain_data=pair.facet_tags)
    F += push * ufl.TestFunction(V)[1] * ds(pair.slave + 1)  # cube_top
    with warns_on_rank_zero(r"free to move as a rigid body"):
        problem = ContactProblem(F, u, bcs, [pair])
    assert len(problem.setup_warnings) == 1

    def apply_load(t):
        push.value = 10.0 * t

    with pytest.raises(LoadSteppingError, match=r"Warned when the problem was built: the body "
                       r"with nodes in .* is free to move as a rigid body"):
        solve_load_steps(problem, apply_load, 1, max_cutbacks=1)
    problem.destroy()


def two_boxes_from_one_gmsh_model(comm):
    """A block [0, 1]^3 and a box [1, 1.5] x [0, 1]^2 beside it, fragmented in one gmsh model
    (they share the nodes of the face x = 1); groups: 1 the block's top, 2 the box's top,
    3 the block's bottom, 4 the shared face."""
    gmsh = pytest.importorskip("gmsh")
    gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    try:
        if comm.rank == 0:
            occ = gmsh.model.occ
            occ.fragment([(3, occ.addBox(0, 0, 0, 1, 1, 1))], [(3, occ.addBox(1, 0, 0, 0.5, 1, 1))])
            occ.synchronize()
            for i, (_, volume) in enumerate(gmsh.model.getEntities(3)):
                gmsh.model.addPhysicalGroup(3, [volume], i + 1)
            e = 1e-6

            def faces(x0, y0, z0, x1, y1, z1):
                return [t for _, t in gmsh.model.getEntitiesInBoundingBox(
                    x0 - e, y0 - e, z0 - e, x1 + e, y1 + e, z1 + e, 2)]

            for tag, box in enumerate([(0, 0, 1, 1, 1, 1), (1, 0, 1, 1.5, 1, 1),
                                       (0, 0, 0, 1, 1, 0), (1, 0, 0, 1, 1, 1)], start=1):
                gmsh.model.addPhysicalGroup(2, faces(*box), tag)
            gmsh.option.setNumber("Mesh.MeshSizeMax", 0.5)
            gmsh.model.mesh.generate(3)
        return compat.model_to_mesh(gmsh.model, comm, 0, 3)
    finally:
        gmsh.finalize()


@pytest.mark.parallel
def test_bodies_that_share_nodes_are_refused_with_the_cause():
    comm = MPI.COMM_WORLD
    data = two_boxes_from_one_gmsh_model(comm)
    V = dolfinx.fem.functionspace(data.mesh, ("Lagrange", 1, (3,)))
    u = dolfinx.fem.Function(V)
    F = internal_work(u, ufl.TestFunction(V), {0: Material(100.0, 0.3, "linear")})
    tags = data.facet_tags
    bcs = [dolfinx.fem.dirichletbc(np.zeros(3), dolfinx.fem.locate_dofs_topological(
        V, 2, tags.find(3)), V)]
    with pytest.raises(ValueError, match=r"lie on one connected mesh \(cells joined through "
                       r"shared nodes; the two surfaces share \d+ node\(s\), one at \(1, .*"
                       r"wrong body.*two bodies share nodes.*fragment.*merge_meshes"):
        build(F, u, bcs, ContactPair(tags, 2, 1))
    # a surface on the shared face itself is made of interior facets
    with pytest.raises(SurfaceError, match=r"interior facets.*must not share nodes"):
        build(F, u, bcs, ContactPair(tags, 4, 1))
