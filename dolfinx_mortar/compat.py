"""Every difference between the dolfinx versions we support (0.9, 0.10, 0.11).

No other module of dolfinx_mortar looks at a version number: whatever differs
between releases is wrapped here once, behind a function with one signature.
"""

from __future__ import annotations

import typing

import dolfinx
import dolfinx.fem.petsc

DOLFINX_VERSION: tuple[int, int] = tuple(int(v) for v in dolfinx.__version__.split(".")[:2])  # type: ignore[assignment]
"""(major, minor) of the running dolfinx."""

MINIMUM_DOLFINX_VERSION = (0, 9)

if DOLFINX_VERSION < MINIMUM_DOLFINX_VERSION:  # pragma: no cover
    raise ImportError(
        "dolfinx_mortar needs dolfinx >= "
        f"{MINIMUM_DOLFINX_VERSION[0]}.{MINIMUM_DOLFINX_VERSION[1]}, "
        f"found {dolfinx.__version__}"
    )

if DOLFINX_VERSION >= (0, 10):
    from dolfinx.io import gmsh as _gmshio
else:
    from dolfinx.io import gmshio as _gmshio


class MeshWithTags(typing.NamedTuple):
    """A mesh and its cell and facet tags, as every gmsh builder returns it."""

    mesh: dolfinx.mesh.Mesh
    cell_tags: dolfinx.mesh.MeshTags
    facet_tags: dolfinx.mesh.MeshTags


def model_to_mesh(model, comm, rank: int, gdim: int) -> MeshWithTags:
    """Convert the gmsh model held on `rank` into a distributed dolfinx mesh.

    dolfinx 0.9 returns a tuple, 0.10 onwards a ``MeshData`` object.
    """
    data = _gmshio.model_to_mesh(model, comm, rank, gdim=gdim)
    if DOLFINX_VERSION >= (0, 10):
        return MeshWithTags(data.mesh, data.cell_tags, data.facet_tags)
    mesh, cell_tags, facet_tags = data
    return MeshWithTags(mesh, cell_tags, facet_tags)


def gmsh_mesh_data(value):
    """(mesh, facet tags, {physical name: (dim, tag)}) if ``value`` is the ``MeshData`` that
    dolfinx 0.10 onwards returns from ``model_to_mesh``, else None (0.9 returns a tuple)."""
    if DOLFINX_VERSION >= (0, 10) and isinstance(value, _gmshio.MeshData):
        return value.mesh, value.facet_tags, dict(value.physical_groups or {})
    return None


def geometry_dofmap(mesh: dolfinx.mesh.Mesh):
    """The (num_cells, nodes_per_cell) array of geometry node indices.

    dolfinx 0.10 onwards keeps one dofmap per cell type (``dofmaps``).
    """
    if DOLFINX_VERSION >= (0, 10):
        return mesh.geometry.dofmaps[0]
    return mesh.geometry.dofmap


def create_matrix(form):
    """A PETSc matrix (AIJ) with the sparsity of a compiled bilinear form."""
    return dolfinx.fem.petsc.create_matrix(form)


def create_vector(form):
    """A ghosted PETSc vector for the test space of a compiled linear form.

    dolfinx 0.10 onwards takes the function space, 0.9 the form.
    """
    if DOLFINX_VERSION >= (0, 10):
        return dolfinx.fem.petsc.create_vector(form.function_spaces[0])
    return dolfinx.fem.petsc.create_vector(form)


def coordinate_element_degree(mesh: dolfinx.mesh.Mesh) -> int:
    """Polynomial degree of the mesh geometry."""
    cmap = mesh.geometry.cmaps[0] if DOLFINX_VERSION >= (0, 10) else mesh.geometry.cmap
    return int(cmap.degree)


def is_linear_lagrange(V: dolfinx.fem.FunctionSpace) -> bool:
    """Whether V is a continuous Lagrange space of degree 1 (scalar or blocked)."""
    import basix

    element = V.ufl_element()
    scalar = getattr(element, "sub_elements", None)
    if scalar:
        element = scalar[0]
    basix_element = getattr(element, "basix_element", None)
    if basix_element is None:
        return False
    return (
        basix_element.family == basix.ElementFamily.P
        and basix_element.degree == 1
        and not basix_element.discontinuous
    )


def set_bc(b, bcs, x0=None, alpha: float = 1.0) -> None:
    """Set Dirichlet values in a PETSc vector: b = alpha (g - x0) on constrained dofs."""
    if x0 is None:
        dolfinx.fem.petsc.set_bc(b, bcs, alpha=alpha)
    else:
        dolfinx.fem.petsc.set_bc(b, bcs, x0, alpha)


def set_bc_values(u: dolfinx.fem.Function, bcs) -> None:
    """Write the Dirichlet values into the dofs of ``u`` they constrain."""
    for bc in bcs:
        bc.set(u.x.array)
    u.x.scatter_forward()


def interpolation_points(V: dolfinx.fem.FunctionSpace):
    """Reference points for interpolating an Expression into V (a method until 0.9)."""
    points = V.element.interpolation_points
    return points if DOLFINX_VERSION >= (0, 10) else points()


def add_matrix_local(A, form, bcs) -> None:
    """Add a bilinear form into A through A's local-to-global map, dof by dof.

    The form's local dofs (owned and ghost, unrolled: block * bs + component)
    are A's local indices (MatSetValuesLocal), as dolfinx assembles the
    blocks of a block matrix. Rows and columns of the dofs in ``bcs`` get
    zeros, their diagonal nothing. dolfinx 0.10 onwards packs constants and
    coefficients from the Python form, 0.9 from the C++ one.
    """
    import dolfinx.cpp as _cpp

    if DOLFINX_VERSION >= (0, 10):
        constants = dolfinx.fem.pack_constants(form)
        coefficients = dolfinx.fem.pack_coefficients(form)
    else:
        constants = _cpp.fem.pack_constants(form._cpp_object)
        coefficients = _cpp.fem.pack_coefficients(form._cpp_object)
    _cpp.fem.petsc.assemble_matrix(A, form._cpp_object, constants, coefficients,
                                   [bc._cpp_object for bc in bcs], True)
