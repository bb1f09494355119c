"""Self-contact (dolfinx_mortar/self_contact.py): which facet pairs of one surface face each
other, which side of each zone is the slave, and the self-contact patch test
(demos/self_contact.py): a uniform pressure across a slit whose non-matching lips are one
surface, exact in 2D and 3D, serial and parallel; the linearization (Taylor); Coulomb friction
across the slit (the stick state exact, the slip law, Taylor); a surface far from itself,
whose search and interface are skipped."""

from __future__ import annotations

import dolfinx
import numpy as np
import pytest
import ufl
from friction_states import put_active_nodes_in
from mpi4py import MPI
from petsc4py import PETSc
from test_contact import assert_taylor_second_order, demo

from dolfinx_mortar import (
    ContactPair,
    ContactProblem,
    Coulomb,
    Material,
    compat,
    internal_work,
    meshes,
    newton,
    search,
)
from dolfinx_mortar import self_contact as sc
from dolfinx_mortar.mortar import MortarInterface


def segment(a, b):
    """A 2D facet's nodes (outward normal (t_y, -t_x) for t = b - a)."""
    return np.array([a, b], dtype=float)


def facing_of(pairs):
    """self_contact.facing of 2D facet pairs [(slave blocks, slave x, master blocks,
    master x)]."""
    sb, sx, mb, mx = (np.array([p[i] for p in pairs]) for i in range(4))
    return sc.facing(sb, mb, sx, mx)


def test_facing_pairs_of_one_surface():
    """A facet faces a facet across a gap (opposite normals, each in front of the other);
    not itself, not its smooth neighbour, not the back of a wall (thicker than half a
    facet: a thinner one looks like a penetrated pair), not one facing the same way; the
    two lips of a slit at its tip (a shared node, folded back) do."""
    up = segment([1.0, 0.0], [0.0, 0.0])  # normal +y
    cases = {
        "across a gap": ([0, 1], up, [2, 3], segment([0.2, 0.1], [1.2, 0.1])),
        "itself": ([0, 1], up, [0, 1], up),
        "smooth neighbour": ([0, 1], up, [1, 4], segment([0.0, 0.0], [-1.0, 0.0])),
        "bent neighbour": ([0, 1], up, [1, 4], segment([0.0, 0.0], [-0.6, 0.8])),
        "back of a wall": ([0, 1], up, [5, 6], segment([0.0, -0.8], [1.0, -0.8])),
        "facing the same way": ([0, 1], up, [2, 3], segment([1.2, 0.1], [0.2, 0.1])),
        "slit lips at the tip": ([0, 1], up, [1, 7], segment([0.0, 0.0], [1.0, 0.0])),
        "penetrated a little": ([0, 1], up, [2, 3], segment([0.2, -0.05], [1.2, -0.05])),
    }
    got = dict(zip(cases, facing_of(list(cases.values())), strict=True))
    assert got == {"across a gap": True, "itself": False, "smooth neighbour": False,
                   "bent neighbour": False, "back of a wall": False,
                   "facing the same way": False, "slit lips at the tip": True,
                   "penetrated a little": True}


def zone_pairs():
    """Candidate pairs of two zones, each found from both facets: zone A (facets 0, 1 of
    size 1 facing 2, 3, 4 of size 0.5: the finer side 2-4), zone B (facets 10, 11 of
    equal size facing each other)."""
    one_way = [(0, 2), (0, 3), (1, 3), (1, 4), (10, 11)]
    pairs = one_way + [(b, a) for a, b in one_way]
    size = {0: 1.0, 1: 1.0, 2: 0.5, 3: 0.5, 4: 0.5, 10: 0.3, 11: 0.3}
    blocks = np.array([[[a, 100 + a], [b, 100 + b]] for a, b in pairs])
    sizes = np.array([[size[a], size[b]] for a, b in pairs])
    return pairs, blocks, sizes


def test_each_zone_is_counted_once_from_its_finer_side():
    pairs, blocks, sizes = zone_pairs()
    keep, master_side, slave_side = sc.slave_side(MPI.COMM_SELF, blocks[:, 0], blocks[:, 1],
                                                  sizes[:, 0], sizes[:, 1])
    kept = sorted(p for p, k in zip(pairs, keep, strict=True) if k)
    assert kept == [(2, 0), (3, 0), (3, 1), (4, 1), (10, 11)]
    assert sorted(master_side[:, 0].tolist()) == [0, 1, 11]
    assert sorted(slave_side[:, 0].tolist()) == [2, 3, 4, 10]


def test_a_zone_keeps_its_slave_side_unless_the_other_is_clearly_finer():
    """Zone B (facets 10 and 11 of one size) took 10 as the slave; told that 11 was the
    slave at the last search, it keeps 11; zone A's clearly finer side stays the slave
    whatever the last search said."""
    pairs, blocks, sizes = zone_pairs()
    previous = np.array([[0, 100], [11, 111]])
    keep, _, slave_side = sc.slave_side(MPI.COMM_SELF, blocks[:, 0], blocks[:, 1],
                                        sizes[:, 0], sizes[:, 1], previous_slaves=previous)
    kept = sorted(p for p, k in zip(pairs, keep, strict=True) if k)
    assert kept == [(2, 0), (3, 0), (3, 1), (4, 1), (11, 10)]
    assert sorted(slave_side[:, 0].tolist()) == [2, 3, 4, 11]
    sizes[np.array([a == 11 for a, _ in pairs]), 0] = 0.3 * 1.2  # 11 now clearly coarser
    sizes[np.array([b == 11 for _, b in pairs]), 1] = 0.3 * 1.2
    keep = sc.slave_side(MPI.COMM_SELF, blocks[:, 0], blocks[:, 1], sizes[:, 0],
                         sizes[:, 1], previous_slaves=previous)[0]
    assert (10, 11) in [p for p, k in zip(pairs, keep, strict=True) if k]


def test_odd_cycles_are_dropped():
    """Three facets each facing the other two: no two colours; the pairs whose facets
    share one are dropped, every other pair kept once."""
    pairs = [(0, 1), (1, 2), (2, 0)]
    pairs += [(b, a) for a, b in pairs]
    blocks = np.array([[[a, 100 + a], [b, 100 + b]] for a, b in pairs])
    keep, _, _ = sc.slave_side(MPI.COMM_SELF, blocks[:, 0], blocks[:, 1], np.ones(6),
                               np.ones(6))
    kept = {tuple(sorted(p)) for p, k in zip(pairs, keep, strict=True) if k}
    assert sum(keep) == len(kept) == 2


@pytest.mark.parallel
def test_ranks_agree_on_the_sides():
    """The pairs dealt out to the ranks in turn: the same pairs kept as on one rank."""
    comm = MPI.COMM_WORLD
    pairs, blocks, sizes = zone_pairs()
    mine = np.arange(len(pairs)) % comm.size == comm.rank
    keep = sc.slave_side(comm, blocks[mine, 0], blocks[mine, 1], sizes[mine, 0],
                         sizes[mine, 1])[0]
    serial = sc.slave_side(MPI.COMM_SELF, blocks[:, 0], blocks[:, 1], sizes[:, 0],
                           sizes[:, 1])[0]
    assert np.array_equal(keep, serial[mine])


def test_rows_in():
    table = np.array([[1, 2], [3, 4]])
    assert sc.rows_in(np.array([[3, 4], [2, 1], [1, 2]]), table).tolist() == [True, False, True]
    assert sc.rows_in(np.zeros((0, 2), int), table).size == 0


PATCH_CASES = [(2, "triangle", "5:7"), (2, "triangle", "7:5"), (2, "quadrilateral", "4:9"),
               (2, "triangle", "6:6"), (3, "tetrahedron", "3:4"), (3, "hexahedron", "4:6"),
               (3, "tetrahedron", "5:3")]


@pytest.mark.parallel
@pytest.mark.parametrize("dim, cell, ratio", PATCH_CASES)
@pytest.mark.parametrize("basis", ["dual", "standard"])
def test_self_contact_patch_test_is_exact(dim, cell, ratio, basis):
    summary = demo("self_contact").main(
        ["--dim", str(dim), "--cell", cell, "--ratio", ratio, "--multipliers", basis])
    assert summary["converged"]
    assert summary["max_pressure_deviation_rel"] < 1e-10
    assert summary["max_multiplier_deviation_rel"] < 1e-10
    assert summary["force_balance"] < 1e-10
    assert summary["max_penetration_rel"] < 1e-10
    # the finer lip carries the multipliers, all but the tip's
    n_left, n_right = (int(n) for n in ratio.split(":"))
    layers = 1 if dim == 2 else max(1, min(n_left, n_right) // 2) + 1
    assert summary["slave_nodes"] == max(n_left, n_right) * layers


@pytest.mark.parallel
@pytest.mark.parametrize("dim, cell", [(2, "quadrilateral"), (3, "hexahedron")])
def test_self_contact_patch_test_neo_hookean_is_uniform(dim, cell):
    """Uniform to Newton's tolerance (the default relative 1e-10 leaves a spread of 3.5e-10
    in 3D): solved to 1e-13 relative and 1e-11 absolute here, through the options database
    as a user would, in 3 Newton iterations on any number of ranks. The lips' edges
    coincide on the roller planes; while the 3D clip made vertices at the intersection of
    such edges, the Jacobian carried entries of 2e17 decided by rounding, and 3 ranks took
    4 to 12 iterations from run to run (tests/test_compiled_surface3.py,
    test_edges_that_coincide_under_rotation)."""
    options = PETSc.Options()
    options["dolfinx_mortar_snes_rtol"] = 1e-13
    options["dolfinx_mortar_snes_atol"] = 1e-11
    try:
        summary = demo("self_contact").main(
            ["--dim", str(dim), "--cell", cell, "--ratio", "4:6", "--material", "neo-hookean"])
    finally:
        options.delValue("dolfinx_mortar_snes_rtol")
        options.delValue("dolfinx_mortar_snes_atol")
    assert summary["converged"] and summary["newton_iterations"] <= 3
    assert summary["max_pressure_deviation_rel"] < 1e-10  # (max - min) / mean
    assert summary["force_balance"] < 1e-10


def pressed_slit(dim: int, cell: str, comm=MPI.COMM_WORLD, noise: float = 1e-3,
                 **options) -> ContactProblem:
    """The slit block (Neo-Hookean, current configuration) with its lips pushed 0.02 into
    each other and sheared by waves plus ``noise`` (1e-3), random multipliers in [0.5, 1.5]
    (without noise: all 1, the same state on any number of ranks): a
    state for a Taylor test in which no active set and no clip polygon's shape changes
    within the steps (at most 1e-4: with noise as small as the steps, the lips' aligned
    layers leave edges of slave and master facets crossing within a step in 3D)."""
    tagged = meshes.slit_block((4, 6), cell, comm)
    markers = tagged.markers
    V = dolfinx.fem.functionspace(tagged.mesh, ("Lagrange", 1, (dim,)))
    u = dolfinx.fem.Function(V)
    F = internal_work(u, ufl.TestFunction(V), {markers["block"]: Material(1000.0, 0.3,
                                                                           "neo-hookean")},
                      tagged.cell_tags)
    bcs = []
    for name, component, value in (("bottom", 1, 0.0),):
        dofs = dolfinx.fem.locate_dofs_topological(
            V.sub(component), dim - 1, tagged.facet_tags.find(markers[name]))
        bcs.append(dolfinx.fem.dirichletbc(dolfinx.default_scalar_type(value), dofs,
                                           V.sub(component)))
    pair = ContactPair(tagged.facet_tags, markers["slit"], markers["slit"])
    problem = ContactProblem(F, u, bcs, [pair], configuration="current", **options)
    rng = np.random.default_rng(5 + comm.rank)

    def pushed(towards: float):
        def field(x):
            # zero from the tip up, where the halves share their nodes
            depth = towards * np.clip((meshes.SLIT_TIP - x[1]) / meshes.SLIT_TIP, 0.0, 1.0)
            wave = 0.01 * np.sin(3.0 * x[1])
            return np.vstack([depth, wave]
                             + ([0.005 * np.cos(2.0 * x[1])] if dim == 3 else []))
        return field

    # by cells: the two lips' nodes share their coordinates
    for side, towards in ((lambda x: x[0] <= 1.0 + 1e-12, 0.01),
                          (lambda x: x[0] >= 1.0 - 1e-12, -0.01)):
        u.interpolate(pushed(towards), dolfinx.mesh.locate_entities(tagged.mesh, dim, side))
    u.x.array[:] += noise * rng.standard_normal(u.x.array.size)
    u.x.scatter_forward()
    compat.set_bc_values(u, problem.bcs)
    for z in problem.multipliers:
        if noise:
            z.setArray(rng.uniform(0.5, 1.5, z.getLocalSize()))
        else:
            z.set(1.0)
    problem.equations.read_state(problem.x)
    return problem


@pytest.mark.parallel
@pytest.mark.parametrize("dim, cell", [(2, "triangle"), (3, "tetrahedron"), (3, "hexahedron")])
def test_self_contact_jacobian_taylor(dim, cell):
    """|R(x + e h) - R(x) - e J h| = O(e^2) with the lips pressed into each other: the
    facets of one surface in both roles, the tip's node in both."""
    problem = pressed_slit(dim, cell)
    assert_taylor_second_order(problem, seed=11)
    problem.destroy()


@pytest.mark.parallel
@pytest.mark.parametrize("dim, cell", [(2, "triangle"), (3, "tetrahedron")])
def test_self_contact_serial_equals_parallel(dim, cell):
    """The Neo-Hookean patch test on one rank and on all: the same pressures and forces.
    (Not the same Newton path in 3D: the lips' edges on the block's faces lie on each
    other, so which side of a clip a sliver falls on is rounding, and with it the
    Jacobian's branch; measured the same for two bodies, demos/patch_test.py --dim 3
    --material neo-hookean: 3 Newton iterations on 1 and 3 ranks, the second residual
    7.8e-4 against 4.1e-4.)"""
    results = []
    for communicator in (MPI.COMM_SELF, MPI.COMM_WORLD):
        summary = demo("self_contact").main(
            ["--dim", str(dim), "--cell", cell, "--ratio", "3:5", "--material",
             "neo-hookean"], comm=communicator)
        assert summary["converged"]
        results.append(np.hstack([summary["pressure_min"], summary["pressure_max"],
                                  summary["slave_force"]]))
    serial, parallel = results
    np.testing.assert_allclose(parallel, serial, rtol=1e-8, atol=1e-8 * np.abs(serial).max())


@pytest.mark.parallel
@pytest.mark.parametrize("dim, cell", [(2, "triangle"), (3, "tetrahedron")])
def test_self_contact_system_serial_equals_parallel(dim, cell):
    """At one pressed state (no noise: the same on any number of ranks) the residual and
    the Jacobian's action on a smooth direction have the same norms on one rank and on
    all."""
    norms = []
    for communicator in (MPI.COMM_SELF, MPI.COMM_WORLD):
        problem = pressed_slit(dim, cell, comm=communicator, noise=0.0)
        residual = problem.b.duplicate()
        problem.equations.residual(problem.snes, problem.x, residual)
        J = problem.equations.assemble_system()
        direction = problem.x.copy()
        applied = residual.duplicate()
        J.mult(direction, applied)
        norms.append([residual.norm(), applied.norm(), problem.num_active()])
        problem.destroy()
    np.testing.assert_allclose(norms[1], norms[0], rtol=1e-12)


def test_a_slit_pulled_open_carries_nothing():
    """The lips pulled apart: no pressure, the pair's facets are found but hold nothing."""
    comm = MPI.COMM_WORLD
    tagged = meshes.slit_block((5, 7), "triangle", comm)
    markers = tagged.markers
    V = dolfinx.fem.functionspace(tagged.mesh, ("Lagrange", 1, (2,)))
    u = dolfinx.fem.Function(V)
    F = internal_work(u, ufl.TestFunction(V), {markers["block"]: Material(1000.0, 0.3)},
                      tagged.cell_tags)
    bcs = []
    for name, component, value in (("left", 0, -0.01), ("right", 0, 0.01), ("bottom", 1, 0.0)):
        dofs = dolfinx.fem.locate_dofs_topological(
            V.sub(component), 1, tagged.facet_tags.find(markers[name]))
        bcs.append(dolfinx.fem.dirichletbc(dolfinx.default_scalar_type(value), dofs,
                                           V.sub(component)))
    pair = ContactPair(tagged.facet_tags, markers["slit"], markers["slit"])
    with ContactProblem(F, u, bcs, [pair], configuration="reference") as problem:
        report = problem.solve()
        assert report.converged
        assert np.abs(problem.gathered_pressure()[1]).max() < 1e-12
        assert problem.num_active() == 0


@pytest.mark.parallel
def test_crushed_ring_closes_and_carries_the_plates():
    """The ring crushed until its inner walls flatten on each other (demos/self_contact.py
    --case crush, its defaults): every step converges without a cut-back in at most 10
    Newton iterations, the walls come into contact only near the end, the plates' forces
    balance, no node of either wall is deeper than 0.01 facet lengths behind the other
    (the issue's bound; measured 1.8e-6 on the mirror-symmetric mesh, 0.026 on the former
    asymmetric one), and one rank and all ranks give the same forces."""
    comm = MPI.COMM_WORLD
    serial = demo("self_contact").main(["--case", "crush"], comm=MPI.COMM_SELF)
    assert serial["converged"] and sum(serial["cutbacks"]) == 0
    assert max(serial["newton_iterations"]) <= 10
    active = np.array(serial["inner_active"])
    assert active[: len(active) * 4 // 5].max() == 0 and active[-1] > 10
    assert serial["force_balance"] < 1e-9
    assert serial["max_penetration_rel"] < 0.01
    if comm.size > 1:
        parallel = demo("self_contact").main(["--case", "crush"], comm=comm)
        assert parallel["newton_iterations"] == serial["newton_iterations"]
        np.testing.assert_allclose(parallel["plate_force"], serial["plate_force"], rtol=1e-8)


def test_crush_without_the_self_contact_pair():
    """--no-self-contact leaves the inner walls unpaired (the demo's baseline for what
    self-contact costs); while the walls are apart the plates' forces are the same as with
    the pair, to the Newton tolerance."""
    arguments = ["--case", "crush", "--depth", "0.5", "--steps", "5"]
    without = demo("self_contact").main(arguments + ["--no-self-contact"], comm=MPI.COMM_SELF)
    with_pair = demo("self_contact").main(arguments, comm=MPI.COMM_SELF)
    assert without["converged"] and not without["self_contact"]
    assert max(without["inner_active"]) == 0 == max(with_pair["inner_active"])
    np.testing.assert_allclose(without["plate_force"], with_pair["plate_force"], rtol=1e-8)


# -- friction on a self-contact surface ---------------------------------------------------

SHEAR = 0.002
"""gamma of the sheared slit's displacement (-squeeze (x - 1), gamma (x - 1), 0)."""


def sheared_slit(dim: int, cell: str, basis: str, mu: float, comm=MPI.COMM_WORLD):
    """The slit block (linear material), its whole outer boundary held at the uniform strain
    u = (-0.01 (x - 1), SHEAR (x - 1), 0): without the slit this is the solution, sigma_xx =
    -p = -(lambda + 2 G) 0.01 and sigma_xy = G SHEAR everywhere. With Coulomb friction mu
    across the slit the lips stick if G SHEAR < mu p (then nothing changes: the exact
    state), else they slip. Returns the solved problem, its report, (p, sigma) and the
    exact displacement."""
    E, nu, squeeze = 1000.0, 0.3, 0.01
    tagged = meshes.slit_block((4, 6) if dim == 3 else (5, 7), cell, comm)
    mesh, markers = tagged.mesh, tagged.markers
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (dim,)))
    u = dolfinx.fem.Function(V)
    F = internal_work(u, ufl.TestFunction(V), {markers["block"]: Material(E, nu, "linear")},
                      tagged.cell_tags)

    def uniform(x):
        return np.vstack([-squeeze * (x[0] - 1.0), SHEAR * (x[0] - 1.0)]
                         + ([np.zeros_like(x[0])] if dim == 3 else []))

    def outer(x):
        on = np.isclose(x[0], 0.0) | np.isclose(x[0], 2.0) | np.isclose(x[1], 0.0)
        on |= np.isclose(x[1], 2.0)
        return on | (np.isclose(x[2], 0.0) | np.isclose(x[2], 0.5) if dim == 3 else False)

    exact = dolfinx.fem.Function(V)
    exact.interpolate(uniform)
    facets = dolfinx.mesh.locate_entities_boundary(mesh, dim - 1, outer)
    bc = dolfinx.fem.dirichletbc(exact, dolfinx.fem.locate_dofs_topological(V, dim - 1, facets))
    pair = ContactPair(tagged.facet_tags, markers["slit"], markers["slit"])
    problem = ContactProblem(F, u, [bc], [pair], configuration="reference", basis=basis,
                             friction=Coulomb(mu))
    report = problem.solve()
    lam, shear = E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))
    sigma = np.zeros((dim, dim))
    sigma[0, 0], sigma[0, 1] = -(lam + 2 * shear) * squeeze, shear * SHEAR
    sigma[1, 0] = sigma[0, 1]
    return problem, report, (lam + 2 * shear) * squeeze, sigma, exact


@pytest.mark.parallel
@pytest.mark.parametrize("dim, cell, basis", [(2, "triangle", "dual"),
                                              (2, "quadrilateral", "standard"),
                                              (3, "tetrahedron", "dual"),
                                              (3, "hexahedron", "standard")])
def test_frictional_self_contact_stick_is_exact(dim, cell, basis):
    """The sheared slit with mu = 0.5 (G SHEAR / p = 0.057): the lips stick, the displacement
    is the uniform strain, every carrying node has z = p and the tangential multipliers of
    the slave side's traction sigma n, y^a = -(sigma n) . tau^a (2D: tau = R n, so y =
    -G SHEAR whichever lip is the slave; 3D: on the nodes' frames), the slips zero."""
    comm = MPI.COMM_WORLD
    problem, report, p, sigma, exact = sheared_slit(dim, cell, basis, mu=0.5)
    with problem:
        assert report.converged
        error = np.abs(problem.u.x.array - exact.x.array).max(initial=0.0)
        assert comm.allreduce(error, op=MPI.MAX) < 1e-14
        active = problem.active[0]
        # the finer lip's nodes but those at the held boundary and the tip (no multiplier)
        expected_active = 6 if dim == 2 else 5
        assert comm.allreduce(int(active.sum()), op=MPI.SUM) == expected_active
        z = problem.multipliers[0].getArray(readonly=True)[active]
        np.testing.assert_allclose(z, p, rtol=1e-10)
        state = problem.friction_state()
        y = state["traction"][active]
        if dim == 2:
            expected = np.full(z.size, -sigma[0, 1])
        else:
            frames = state["frames"][active]  # (n, a, c)
            normal = np.cross(frames[:, 0], frames[:, 1])
            expected = -np.einsum("nac,nc->na", frames, normal @ sigma)
        np.testing.assert_allclose(y, expected, rtol=0.0, atol=1e-10 * p)
        assert state["sticking"][active].all()
        assert np.abs(state["slip"][active]).max(initial=0.0) < 1e-14


@pytest.mark.parallel
@pytest.mark.parametrize("dim, cell", [(2, "triangle"), (3, "tetrahedron")])
def test_frictional_self_contact_slips_by_coulomb(dim, cell):
    """The sheared slit with mu = 0.02 (below G SHEAR / p = 0.057): the lips slip; at every
    slipping node |y| = mu z (the gap closed: the bound mu max(0, z - c_n g^) is mu z), at
    every sticking node |y| <= mu z, and the friction dissipates (y . u~ > 0 where slipping).
    """
    comm = MPI.COMM_WORLD
    mu = 0.02
    problem, report, p, _, _ = sheared_slit(dim, cell, "dual", mu=mu)
    with problem:
        assert report.converged
        active = problem.active[0]
        z = problem.multipliers[0].getArray(readonly=True)[active]
        state = problem.friction_state()
        y = state["traction"][active].reshape(z.size, problem.friction.components)
        size = np.linalg.norm(y, axis=1)
        slipping = state["slipping"][active]
        assert comm.allreduce(int(slipping.sum()), op=MPI.SUM) > 0
        np.testing.assert_allclose(size[slipping], mu * z[slipping], rtol=1e-8)
        assert np.all(size[~slipping] <= mu * z[~slipping] * (1 + 1e-8))
        assert np.all(state["dissipation"][active][slipping] > 0.0)


def tangential_multipliers_along_the_slips(problem: ContactProblem, seed: int) -> None:
    """Random tangential multipliers 5 <= |y^a_j| <= 10 (per-rank seed) of the sign of
    the slip u~^a_j, so that |v| = |y + c_t s| >= 5 at every node: a Taylor step (at
    most 1e-4 in a random direction) changes c_t s by about 1 at a small corner node of
    the slit (c_t ~ 2300), which, with y of the other sign (test_friction's
    with_random_tangential_multipliers), took v through 0 (the kink) on 3 ranks."""
    problem.equations.residual(problem.snes, problem.x, problem.b)
    m = problem.friction.components
    slip = problem.friction_state()["slip"].reshape(-1, m)
    rng = np.random.default_rng(seed + problem.comm.rank)
    for a, y in enumerate(problem.tangential):
        y.setArray(np.where(slip[:, a] < 0.0, -1.0, 1.0)
                   * rng.uniform(5.0, 10.0, y.getLocalSize()))
    problem.equations.read_state(problem.x)


@pytest.mark.parallel
@pytest.mark.parametrize("state", ["slipping", "sticking"])
@pytest.mark.parametrize("dim, cell", [(2, "triangle"), (3, "tetrahedron")])
def test_frictional_self_contact_jacobian_taylor(dim, cell, state):
    """|R(x + e h) - R(x) - e J h| = O(e^2) with Coulomb friction on the pressed slit (the
    lips pushed into each other, sheared, random normal and tangential multipliers),
    every active node slipping or every one sticking: the tangents of the slave side's
    normals (2D: turned; 3D: the frames through the averaged normals' stars, which leave
    the master side out), the slips between the lips, the tip's node in both roles."""
    problem = pressed_slit(dim, cell, friction=Coulomb(1.0))
    tangential_multipliers_along_the_slips(problem, seed=5)
    put_active_nodes_in(problem, state)
    assert_taylor_second_order(problem, seed=11)
    problem.destroy()


# -- a surface far from itself costs (almost) nothing -------------------------------------

def stadium_hole(gap: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The boundary of a stadium-shaped hole: walls y = +-gap/2 for -1 <= x <= 1 joined by
    half circles, facets about 0.1 long, the nodes jittered by 0.002; as nodes and facets
    oriented as the body around the hole orients them (self_contact.facet_frames' normal
    (t_y, -t_x) into the hole: clockwise)."""
    radius = 0.5 * gap
    wall = np.linspace(1.0, -1.0, 20, endpoint=False)
    turn = np.linspace(0.5 * np.pi, 1.5 * np.pi, max(4, int(np.pi * radius / 0.1)),
                       endpoint=False)
    x = np.concatenate([np.column_stack([wall, np.full(wall.size, radius)]),
                        np.column_stack([radius * np.cos(turn) - 1.0, radius * np.sin(turn)]),
                        np.column_stack([-wall, np.full(wall.size, -radius)]),
                        np.column_stack([1.0 - radius * np.cos(turn), -radius * np.sin(turn)])])
    x += 0.002 * np.random.default_rng(seed).standard_normal(x.shape)
    n = x.shape[0]
    return x, np.column_stack([(np.arange(n) + 1) % n, np.arange(n)])


def test_the_far_surface_precheck_misses_no_pair():
    """self_contact.may_face is False only where the search against itself keeps no facing
    pair: a hole whose walls are ``gap`` apart, the margin 0.1, with and without a sweep
    and a search depth; both answers occur."""
    answers = set()
    for gap in (0.05, 0.15, 0.21, 0.3, 0.6):
        for seed in range(3):
            x, facets = stadium_hole(gap, seed=seed)
            for origin, depth in ((None, 0.0), (x + 0.03, 0.0), (None, 0.05)):
                pairs = search.candidate_pairs(x, facets, x, facets, 0.1,
                                               slave_previous=origin, master_previous=origin,
                                               depth=depth)
                kept = sc.facing(facets[pairs[:, 0]], facets[pairs[:, 1]],
                                 x[facets[pairs[:, 0]]], x[facets[pairs[:, 1]]], depth)
                may = sc.may_face(x, np.arange(x.shape[0]), facets, facets, 0.1, origin,
                                  depth)
                assert may or not kept.any(), (gap, seed, origin is None, depth)
                answers.add(may)
    assert answers == {True, False}


@pytest.mark.parallel
def test_a_ring_far_from_itself_skips_its_interface_until_it_closes():
    """The crushed ring's inner surface (demos/self_contact.py --case crush) undeformed and
    squeezed to 0.9 and 0.8 of its height: the search finds no facing pair on any rank, so
    the interface holds no pair (``without_pairs``, the same on every rank), evaluates
    nothing after the first update, keeps its pattern through new searches and adds no
    force; squeezed to 0.02 of its height, the walls face each other and the next search
    finds the same pairs as an interface that was never apart."""
    comm = MPI.COMM_WORLD
    tagged = meshes.crushed_ring(0, comm=comm)
    V = dolfinx.fem.functionspace(tagged.mesh, ("Lagrange", 1, (2,)))
    inner = tagged.markers["ring_inner"]
    interface = MortarInterface(V, tagged.facet_tags, inner, inner)
    u = dolfinx.fem.Function(V)

    def squeezed(height: float) -> None:
        u.interpolate(lambda x: np.vstack([0.0 * x[0], (height - 1.0) * x[1]]))

    interface.update(u)
    assert interface.without_pairs and interface.stencil.num_pairs == 0
    version, evaluations = interface._pattern_version, interface.statistics.evaluations
    for height in (0.9, 0.8):
        squeezed(height)
        interface.reuse.invalidate()  # a new search, which finds nothing again
        interface.update(u)
        assert interface.without_pairs
    assert interface.statistics.searches_done == 3
    assert interface._pattern_version == version
    assert interface.statistics.evaluations == evaluations
    force = dolfinx.fem.Function(V)  # (kept: its PETSc vector wraps its array)
    z = interface.create_multiplier_vector()
    z.set(1.0)
    interface.contact_force(z, force.x.petsc_vec)
    assert force.x.petsc_vec.norm() == 0.0
    squeezed(0.02)
    interface.update(u)
    fresh = MortarInterface(V, tagged.facet_tags, inner, inner)
    fresh.update(u)
    assert not interface.without_pairs
    found = [comm.allreduce(i.stencil.num_pairs, op=MPI.SUM) for i in (interface, fresh)]
    assert found[0] == found[1] > 0
    np.testing.assert_array_equal(interface.contributing_pairs(), fresh.contributing_pairs())
    np.testing.assert_array_equal(interface.quantities.gap.value, fresh.quantities.gap.value)
    z.destroy()
    interface.destroy()
    fresh.destroy()


@pytest.mark.parallel
def test_a_surface_coming_into_contact_enters_the_layout(monkeypatch):
    """The ring crushed to 1.45 in 10 steps: its inner walls, apart until the last steps,
    have no rows in the layout from the first solve on; a search inside a later Newton
    solve finds them facing, and that solve goes on from that iterate with their rows.
    The run equals, step by step (Newton iterations, forces, active nodes), the run that
    keeps the rows throughout (``ContactNewton.compact_layout = False``), to 1e-10 on all
    ranks, and serially."""
    comm = MPI.COMM_WORLD
    arguments = ["--case", "crush", "--depth", "1.45", "--steps", "10"]
    events = []
    fit = newton.ContactNewton.fit_layout

    def recorded(self) -> None:
        before = list(self.equations.in_layout)
        fit(self)
        if self.equations.in_layout != before:
            events.append((list(self.equations.in_layout), len(self.equations.residual_history),
                           self.equations.layout.num_global))
    monkeypatch.setattr(newton.ContactNewton, "fit_layout", recorded)
    compact = demo("self_contact").main(arguments, comm=comm)
    layouts = list(events)
    monkeypatch.setattr(newton.ContactNewton, "compact_layout", False)
    kept = demo("self_contact").main(arguments, comm=comm)
    assert events == layouts  # (none while every pair keeps its rows)
    assert [e[0] for e in layouts] == [[True, True, False], [True, True, True]]
    assert layouts[1][1] > 0  # within a Newton solve, after a step
    assert layouts[1][2] - layouts[0][2] == interface_multipliers(comm)
    assert compact["converged"] and max(compact["inner_active"]) > 0
    for key in ("newton_iterations", "cutbacks", "inner_active"):
        assert compact[key] == kept[key], key
    for key in ("plate_force", "inner_force"):
        np.testing.assert_allclose(compact[key], kept[key], rtol=1e-10,
                                   atol=1e-10 * max(kept[key]))
    if comm.size > 1:
        monkeypatch.setattr(newton.ContactNewton, "compact_layout", True)
        serial = demo("self_contact").main(arguments, comm=MPI.COMM_SELF)
        assert serial["newton_iterations"] == compact["newton_iterations"]
        np.testing.assert_allclose(serial["plate_force"], compact["plate_force"], rtol=1e-8)


def test_a_frictional_surface_coming_into_contact_enters_the_layout(monkeypatch):
    """The same with Coulomb friction (mu = 0.1, crushed to 1.4 in 10 steps, which takes
    cut-backs): each new layout's matrix is assembled from gaps, active sets and slips of
    the current state (friction's slips restart at each solve; a pair that was out was
    not updated), and the run equals the one that keeps the rows, step by step."""
    arguments = ["--case", "crush", "--depth", "1.4", "--steps", "10", "--mu", "0.1"]
    compact = demo("self_contact").main(arguments, comm=MPI.COMM_SELF)
    monkeypatch.setattr(newton.ContactNewton, "compact_layout", False)
    kept = demo("self_contact").main(arguments, comm=MPI.COMM_SELF)
    assert compact["converged"] and max(compact["inner_active"]) > 0
    for key in ("newton_iterations", "cutbacks", "inner_active"):
        assert compact[key] == kept[key], key
    np.testing.assert_allclose(compact["plate_force"], kept["plate_force"], rtol=1e-10)


def interface_multipliers(comm) -> int:
    """The number of multipliers of the crushed ring's inner surface (its nodes)."""
    tagged = meshes.crushed_ring(0, comm=comm)
    V = dolfinx.fem.functionspace(tagged.mesh, ("Lagrange", 1, (2,)))
    inner = tagged.markers["ring_inner"]
    interface = MortarInterface(V, tagged.facet_tags, inner, inner)
    try:
        return interface.num_global_multipliers
    finally:
        interface.destroy()

# --- the crushed tube (3D) and the walls' facing history (issue 29) --------------------


def test_a_pair_that_faced_keeps_facing_while_penetrated():
    """A facet pushed through the other deeper than the reach (half a facet: the back of a
    wall would look the same) faces it only if it faced it at the last search; a pair
    whose normals no longer oppose does not, whatever it did before."""
    up = segment([1.0, 0.0], [0.0, 0.0])  # normal +y
    cases = [([0, 1], up, [2, 3], segment([0.2, -0.8], [1.2, -0.8])),  # 0.8 deep
             ([0, 1], up, [2, 3], segment([1.2, 0.1], [0.2, 0.1]))]  # facing the same way
    sb, sx, mb, mx = (np.array([c[i] for c in cases]) for i in range(4))
    assert sc.facing(sb, mb, sx, mx).tolist() == [False, False]
    assert sc.facing(sb, mb, sx, mx, faced=np.array([False, True])).tolist() == [False, False]
    assert sc.facing(sb, mb, sx, mx, faced=np.array([True, True])).tolist() == [True, False]


def test_crush_in_half_the_steps():
    """The ring crushed in 30 steps instead of 60: the closing step carries the walls
    through each other by more than half a facet within one Newton update; the pairs that
    faced before keep facing, so the contact pushes them back: no cut-back, and no node
    deeper than 0.01 facet lengths (measured 5.9e-8; before the facing history, the walls
    went through each other and the step failed with inverted elements after 6
    cut-backs)."""
    summary = demo("self_contact").main(["--case", "crush", "--steps", "30"],
                                        comm=MPI.COMM_SELF)
    assert summary["converged"] and sum(summary["cutbacks"]) == 0
    assert max(summary["newton_iterations"]) <= 10
    assert summary["max_penetration_rel"] < 0.01


@pytest.mark.parallel
def test_crushed_tube_mesh():
    """meshes3d.crushed_tube: the ring's volume and its surfaces' areas are the half
    tube's (to the chords' error), the plates' faces 1.6 x length, and no facet is in two
    groups."""
    from dolfinx_mortar import meshes3d

    tagged = meshes3d.crushed_tube(comm=MPI.COMM_WORLD)
    mesh, markers = tagged.mesh, tagged.markers
    dx = ufl.Measure("dx", domain=mesh, subdomain_data=tagged.cell_tags)
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=tagged.facet_tags)

    def integral(measure) -> float:
        value = dolfinx.fem.assemble_scalar(dolfinx.fem.form(1.0 * measure))
        return mesh.comm.allreduce(value)

    L = 0.3
    np.testing.assert_allclose(integral(dx(markers["ring"])), np.pi / 2 * 0.51 * L, rtol=1e-2)
    np.testing.assert_allclose(integral(ds(markers["ring_inner"])), np.pi * 0.7 * L, rtol=1e-2)
    for name in ("ring_outer_top", "ring_outer_bottom"):
        np.testing.assert_allclose(integral(ds(markers[name])), np.pi / 2 * L, rtol=1e-2)
    for name in ("plate_top_contact", "plate_bottom_contact", "plate_top_load",
                 "plate_bottom_support"):
        np.testing.assert_allclose(integral(ds(markers[name])), 1.6 * L, rtol=1e-12)
    np.testing.assert_allclose(integral(ds(markers["symmetry"])), 2 * 0.3 * L + 2 * 0.2 * L,
                               rtol=1e-12)
    ends = 2 * (np.pi / 2 * 0.51 + 2 * 1.6 * 0.2)
    np.testing.assert_allclose(integral(ds(markers["ends"])), ends, rtol=1e-2)
    tags = tagged.facet_tags
    assert np.unique(tags.indices).size == tags.indices.size


@pytest.mark.parallel
def test_crushed_tube_closes_and_carries_the_plates():
    """A coarse, short 3D crush (demos/self_contact.py --dim 3 --case crush, a slice one
    tetrahedron long, 30 steps): every step converges without a cut-back in at most 10
    Newton iterations, the inner walls meet only near the end, the plates' forces balance,
    no node of either wall deeper than 0.02 facet lengths behind the other (measured
    0.0090; the issue asks for 0.01), and one rank and all ranks give the same forces. The
    slice's ends are held in z (plane strain): the end force is the 2D ring's, 0.265 to
    0.267 per unit length (two meshes; 0.01989 / 0.075 = 0.2652 measured here)."""
    arguments = ["--dim", "3", "--case", "crush", "--length", "0.075", "--steps", "30"]
    comm = MPI.COMM_WORLD
    serial = demo("self_contact").main(arguments, comm=MPI.COMM_SELF)
    assert serial["converged"] and sum(serial["cutbacks"]) == 0
    assert max(serial["newton_iterations"]) <= 10
    active = np.array(serial["inner_active"])
    assert active[: len(active) * 4 // 5].max() == 0 and active[-1] > 20
    assert serial["force_balance"] < 1e-9
    assert serial["max_penetration_rel"] < 0.02
    np.testing.assert_allclose(serial["plate_force"][-1] / 0.075, 0.265, rtol=0.01)
    if comm.size > 1:
        parallel = demo("self_contact").main(arguments, comm=comm)
        assert parallel["converged"] and sum(parallel["cutbacks"]) == 0
        np.testing.assert_allclose(parallel["plate_force"], serial["plate_force"], rtol=1e-8)
