"""The recovered contact pressure (dolfinx_mortar.recovery): exact for linear pressures on
irregular flat surfaces, equal to an independent least-squares fit over each node's
patch, the multipliers where no fit applies, and the same on any number of ranks; on by
default in 3D only."""

from __future__ import annotations

import dolfinx
import numpy as np
import pytest
import ufl
from mpi4py import MPI

from dolfinx_mortar import ContactPair, ContactProblem, Material, internal_work, meshes

CASES = [(2, "triangle"), (2, "quadrilateral"), (3, "tetrahedron"), (3, "hexahedron")]


def _irregular(tagged) -> None:
    """Move the nodes within the planes of the blocks' faces (deterministically, by their
    coordinates), so that the contact surfaces are flat but their facets irregular."""
    x = tagged.mesh.geometry.x
    gdim = tagged.mesh.geometry.dim
    if gdim == 2:
        bump = (x[:, 0] - 4.0) * (6.0 - x[:, 0])
        x[:, 0] += 0.08 * np.where(bump > 0, bump, 0.0) * np.sin(37.0 * x[:, 0] + 11.0 * x[:, 1])
        return
    bump = x[:, 0] * (1.0 - x[:, 0]) * x[:, 1] * (1.0 - x[:, 1])
    x[:, 0] += 0.6 * bump * np.sin(37.0 * x[:, 0] + 11.0 * x[:, 1] + 5.0 * x[:, 2])
    x[:, 1] += 0.6 * bump * np.cos(23.0 * x[:, 0] - 7.0 * x[:, 1] + 3.0 * x[:, 2])


def _problem(dim: int, cell: str, slave: str, comm, recovery: bool | None = True,
             irregular: bool = True) -> ContactProblem:
    build = meshes.patch_test if dim == 2 else meshes.patch_test_3d
    tagged = build(ratio=(3, 2), slave=slave, refinement=1, cell_type=cell, comm=comm)
    if irregular:
        _irregular(tagged)
    mesh, markers = tagged.mesh, tagged.markers
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (dim,)))
    u = dolfinx.fem.Function(V)
    F = internal_work(u, ufl.TestFunction(V), {0: Material(1000.0, 0.3, "linear")})
    fdim = mesh.topology.dim - 1
    held = np.concatenate([tagged.facet_tags.find(markers[name])
                           for name in ("foundation_bottom", "punch_top")])
    dofs = dolfinx.fem.locate_dofs_topological(V, fdim, held)
    bcs = [dolfinx.fem.dirichletbc(np.zeros(dim), dofs, V)]
    pair = ContactPair(tagged.facet_tags, markers["contact_slave"], markers["contact_master"])
    return ContactProblem(F, u, bcs, [pair], pressure_recovery=recovery)


def _scatter(coordinates: np.ndarray) -> np.ndarray:
    """A node-to-node scatter in [0.7, 1.3], uncorrelated between neighbours (a hash of the
    coordinates: the same on every rank)."""
    phase = coordinates @ np.array([12.9898, 78.233, 37.719][: coordinates.shape[1]])
    return 1.0 + 0.6 * (np.modf(np.abs(np.sin(phase)) * 43758.5453)[0] - 0.5)


def _set_multipliers(problem: ContactProblem, values: np.ndarray, active: np.ndarray) -> None:
    problem.multipliers[0].getArray()[:] = values
    problem.active[0][:] = active


def _patch_fit(problem: ContactProblem, values: np.ndarray, active: np.ndarray) -> np.ndarray:
    """The fit computed independently (serial): at each active node, the linear function of
    the in-plane coordinates minimizing the sum over sample points of each fully active
    facet of its patch (a 7 x 7 tensor Gauss rule on the facet's parametrization, exact for
    the squared error) of (p - lambda_h)^2, by weighted least squares."""
    interface = problem.interfaces[0]
    slave = interface.slave
    node_values = values[interface.node_multipliers - interface.multiplier_offset]
    node_active = active[interface.node_multipliers - interface.multiplier_offset]
    x = slave.reference_coordinates
    gdim = x.shape[1]
    points, weights = np.polynomial.legendre.leggauss(7)
    points, weights = 0.5 * (points + 1.0), 0.5 * weights
    result = values.copy()
    for node in range(slave.num_nodes):
        row = interface.node_multipliers[node] - interface.multiplier_offset
        if not node_active[node]:
            continue
        rows, rhs = [], []
        for facet in slave.facets:
            if node not in facet or not node_active[facet].all():
                continue
            corners, z = x[facet], node_values[facet]
            for s, ws in zip(points, weights, strict=True):
                samples = [(t, ws * wt) for t, wt in zip(points, weights, strict=True)] \
                    if gdim == 3 else [(None, ws)]
                for t, w in samples:
                    if gdim == 2:
                        shape = np.array([1 - s, s])
                        jacobian = np.linalg.norm(corners[1] - corners[0])
                    elif len(facet) == 3:  # collapsed square: (s, t) -> (s (1 - t), s t)
                        shape = np.array([1 - s, s * (1 - t), s * t])
                        jacobian = s * np.linalg.norm(np.cross(corners[1] - corners[0],
                                                               corners[2] - corners[0]))
                    else:
                        shape = np.array([(1 - s) * (1 - t), s * (1 - t), s * t, (1 - s) * t])
                        d_s = np.array([-(1 - t), 1 - t, t, -t]) @ corners
                        d_t = np.array([-(1 - s), -s, s, 1 - s]) @ corners
                        jacobian = np.linalg.norm(np.cross(d_s, d_t))
                    point = shape @ corners
                    scale = np.sqrt(w * jacobian)
                    in_plane = (point - x[node])[: gdim - 1]
                    rows.append(scale * np.concatenate([[1.0], in_plane]))
                    rhs.append(scale * (shape @ z))
        if rows:
            coefficients, *_ = np.linalg.lstsq(np.array(rows), np.array(rhs), rcond=None)
            result[row] = coefficients[0]
    return result


@pytest.mark.parametrize("dim, cell", CASES)
@pytest.mark.parametrize("slave", ["top", "bottom"])
def test_linear_pressure_is_reproduced(dim, cell, slave):
    """A pressure linear in the surface coordinates is its own recovery, on irregular
    facets, either slave side; raw=True gives the multipliers themselves."""
    problem = _problem(dim, cell, slave, MPI.COMM_SELF)
    coordinates = problem.interfaces[0].owned_multiplier_coordinates
    linear = 2.0 + 0.3 * coordinates[:, 0] - (0.7 * coordinates[:, 1] if dim == 3 else 0.0)
    _set_multipliers(problem, linear, np.ones(linear.size, dtype=bool))
    _, recovered = problem.contact_pressure()
    assert np.abs(recovered - linear).max() <= 1e-12 * np.abs(linear).max()
    _, raw = problem.contact_pressure(raw=True)
    assert np.array_equal(raw, linear)
    problem.destroy()


@pytest.mark.parametrize("dim, cell", CASES)
def test_recovery_is_the_patch_least_squares_fit(dim, cell):
    """Scattered multipliers, some nodes inactive: each active node's value is the L2 fit
    over its fully active facets (computed independently), the others keep z_j."""
    problem = _problem(dim, cell, "top", MPI.COMM_SELF)
    coordinates = problem.interfaces[0].owned_multiplier_coordinates
    values = _scatter(coordinates)
    active = coordinates[:, 0] < (5.5 if dim == 2 else 0.7)
    _set_multipliers(problem, np.where(active, values, 0.0), active)
    _, recovered = problem.contact_pressure()
    expected = _patch_fit(problem, np.where(active, values, 0.0), active)
    assert np.abs(recovered - expected).max() <= 1e-12
    assert np.array_equal(recovered[~active], np.zeros(np.count_nonzero(~active)))
    fitted = active & (recovered != values)
    assert fitted.sum() >= 0.5 * active.sum()
    problem.destroy()


def test_uniform_quadrilaterals_recover_the_nine_point_average():
    """On a flat uniform grid of squares (side h) the fit at a node with its four facets
    active is the patch's mean, (4 z_C + 2 (edge neighbours) + (corner neighbours)) / 16;
    so a concave pressure is lowered at every such node, by exactly h^2 |laplacian| / 4
    for a quadratic one: what makes the recovered Hertz pressure on hexahedra lower, and
    its L2 error larger, than the multipliers' (docs/benchmarks.md, "Contrast sweep in 3D
    on hexahedra")."""
    problem = _problem(3, "hexahedron", "top", MPI.COMM_SELF, irregular=False)
    coordinates = problem.interfaces[0].owned_multiplier_coordinates
    h = 1.0 / 6.0  # the punch's 3 * 2 elements per side
    index = np.rint(coordinates[:, :2] / h).astype(int)
    np.testing.assert_allclose(index * h, coordinates[:, :2], atol=1e-14)
    row = {tuple(ij): k for k, ij in enumerate(index)}
    interior = np.flatnonzero(np.all((index > 0) & (index < 6), axis=1))
    assert interior.size == 25
    everywhere = np.ones(coordinates.shape[0], dtype=bool)

    values = _scatter(coordinates)
    _set_multipliers(problem, values, everywhere)
    _, recovered = problem.contact_pressure()
    for k in interior:
        i, j = index[k]
        stencil = sum((2 - abs(di)) * (2 - abs(dj)) * values[row[i + di, j + dj]]
                      for di in (-1, 0, 1) for dj in (-1, 0, 1)) / 16.0
        assert recovered[k] == pytest.approx(stencil, abs=1e-12)

    q = 3.0  # p = 2 - q r^2 around the centre: laplacian -4 q
    r2 = np.sum((coordinates[:, :2] - 0.5) ** 2, axis=1)
    _set_multipliers(problem, 2.0 - q * r2, everywhere)
    _, recovered = problem.contact_pressure()
    expected = 2.0 - q * r2[interior] - h**2 * q
    assert np.abs(recovered[interior] - expected).max() <= 1e-12
    problem.destroy()


@pytest.mark.parallel
@pytest.mark.parametrize("dim, cell", [(2, "triangle"), (3, "tetrahedron"), (3, "hexahedron")])
def test_recovery_in_parallel_equals_serial(dim, cell):
    """The recovered pressure gathered from all ranks equals the serial one (the patches
    of nodes on a partition boundary are summed on their owners)."""
    values = {}
    for name, comm in (("serial", MPI.COMM_SELF), ("parallel", MPI.COMM_WORLD)):
        problem = _problem(dim, cell, "bottom", comm)
        coordinates = problem.interfaces[0].owned_multiplier_coordinates
        active = coordinates[:, 0] < (5.5 if dim == 2 else 0.7)
        _set_multipliers(problem, np.where(active, _scatter(coordinates), 0.0), active)
        values[name] = problem.gathered_pressure()
        problem.destroy()
    assert np.array_equal(values["serial"][0], values["parallel"][0])
    assert np.abs(values["serial"][1] - values["parallel"][1]).max() <= 1e-13


@pytest.mark.parametrize("dim, cell", [(2, "triangle"), (3, "tetrahedron")])
def test_recovery_is_the_default_in_3d_only(dim, cell):
    """pressure_recovery=None: the recovered pressure in 3D, the multipliers in 2D."""
    problem = _problem(dim, cell, "top", MPI.COMM_SELF, recovery=None)
    assert problem.pressure_recovery == (dim == 3)
    values = _scatter(problem.interfaces[0].owned_multiplier_coordinates)
    _set_multipliers(problem, values, np.ones(values.size, dtype=bool))
    _, pressure = problem.contact_pressure()
    assert np.array_equal(pressure, values) == (dim == 2)
    problem.destroy()


@pytest.mark.parametrize("dim, cell", [(2, "triangle"), (3, "tetrahedron"), (3, "hexahedron")])
def test_uniform_slip_traction_is_its_own_recovery(dim, cell):
    """The friction patch test at slip (every node slides, traction mu p along the slip):
    the recovered tangential traction is the uniform multipliers' own, to 1e-12 (the
    fit, in 3D of the traction vectors and their projection back onto the tangent
    frames, keeps constants); raw=True gives the multipliers; pressure_recovery=False
    too."""
    from test_friction import load_demo

    from dolfinx_mortar import Coulomb

    patch = load_demo("friction_patch")
    limit = 0.2 * patch.PRESSURE
    build = patch.sheared_blocks if dim == 2 else patch.sheared_blocks_3d
    ratio = (3, 7) if cell != "hexahedron" else (2, 3)
    for recovery in (True, False):
        problem = build(ratio, "upper", Coulomb(0.2), 2.0 * limit / patch.SHEAR_MODULUS, limit,
                        cell, MPI.COMM_SELF, pressure_recovery=recovery)
        assert problem.solve().converged
        state = problem.friction_state()
        assert state["slipping"].all()
        coordinates, traction = problem.tangential_traction()
        assert np.array_equal(coordinates, state["coordinates"])
        assert np.abs(traction - state["traction"]).max() <= 1e-12 * limit
        assert np.array_equal(problem.tangential_traction(raw=True)[1], state["traction"])
        if not recovery:
            assert np.array_equal(traction, state["traction"])
        problem.destroy()


def test_scattered_3d_traction_is_the_componentwise_patch_fit():
    """Scattered tangential multipliers on the flat (irregular) 3D patch: the recovered
    traction is the independent patch fit (as for the pressure) of each component of
    y_j . tau_j, back in the node's frame; the nodes without a fit keep y_j."""
    from dolfinx_mortar import recovery

    problem = _problem(3, "tetrahedron", "top", MPI.COMM_SELF)
    interface = problem.interfaces[0]
    coordinates = interface.owned_multiplier_coordinates
    active = coordinates[:, 0] < 0.7
    vectors = np.stack([_scatter(coordinates), -0.5 * _scatter(coordinates[:, ::-1]),
                        np.zeros(coordinates.shape[0])], axis=1) * active[:, None]
    recovered = recovery.recovered_traction(interface, vectors, active)
    for c in range(2):
        expected = _patch_fit(problem, vectors[:, c], active)
        assert np.abs(recovered[:, c] - expected).max() <= 1e-12
    assert np.abs(recovered[:, 2]).max() <= 1e-14  # tangential to the plane z = const
    assert np.array_equal(recovered[~active], vectors[~active])
    problem.destroy()
