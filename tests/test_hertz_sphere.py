"""3D Hertz contact of a sphere on a block (demos/hertz_sphere.py) at refinement 0: the
mesh builder's tags, the load transmitted exactly, the pressure near Hertz's, serial =
parallel, and the same dimensionless answer in other units."""

from __future__ import annotations

import importlib.util
import math
import pathlib

import dolfinx
import numpy as np
import pytest
import ufl
from mpi4py import MPI

from dolfinx_mortar import meshes3d

DEMOS = pathlib.Path(__file__).parents[1] / "demos"
ARGS = ["--refinement", "0", "--steps", "2"]


def hertz_sphere(args, comm=MPI.COMM_SELF) -> dict:
    spec = importlib.util.spec_from_file_location("demo_hertz_sphere", DEMOS / "hertz_sphere.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.main(list(args), comm=comm)


@pytest.fixture(scope="module")
def serial():
    return hertz_sphere(ARGS)


@pytest.mark.parametrize("case", meshes3d.HERTZ_SPHERE_CASES)
def test_mesh_bodies_are_separate_and_tagged(case):
    """Two bodies that share no node (two nodes at the contact point), the quarter load face
    of area pi R^2 / 4 up to its facets, every named facet group present."""
    R = 2.0
    tagged = meshes3d.hertz_sphere(case=case, radius=R, contact_radius=0.2, comm=MPI.COMM_SELF)
    mesh = tagged.mesh
    assert np.count_nonzero(np.linalg.norm(mesh.geometry.x, axis=1) < 1e-12) == 2
    assert tagged.h_contact == pytest.approx(0.2 / meshes3d.ELEMENTS_PER_RADIUS, rel=1e-12)
    for name in ("contact_slave", "contact_master", "load", "support", "symmetry_x",
                 "symmetry_y"):
        assert tagged.facet_tags.find(tagged.markers[name]).size > 0, name
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=tagged.facet_tags)
    area = dolfinx.fem.assemble_scalar(dolfinx.fem.form(
        dolfinx.fem.Constant(mesh, 1.0) * ds(tagged.markers["load"])))
    assert area == pytest.approx(math.pi * R**2 / 4.0, rel=1e-2)
    assert area < math.pi * R**2 / 4.0  # inscribed facets


def test_total_force_equals_the_load(serial):
    """The contact force (times 4 for the quarter) is the applied load F, and slave and
    master forces balance, to rounding (measured 2e-16)."""
    assert serial["total_force"] == pytest.approx(serial["load"], rel=1e-8)
    assert serial["force_balance"] <= 1e-10


def test_pressure_is_near_hertz(serial):
    """Refinement 0 (h = a/4, 2703 dofs), measured: the recovered pressure's peak p_max/p0
    - 1 = -1.1 %, the largest nodal multiplier +3.2 % (gmsh's tetrahedra scatter them),
    the fitted peak p0_fit/p0 - 1 = -0.2 %, a_contact = 0.0945 vs a = 0.1008 (-0.26 slave
    elements), L2 pressure error 9.5 %; one linear problem per active set, so few Newton
    iterations (measured [3, 4] in 2 steps)."""
    assert abs(serial["p_max_error_rel"]) < 0.02
    assert 0.0 < serial["p_max_multiplier_error_rel"] < 0.06
    assert abs(serial["p0_fit_error_rel"]) < 0.02
    assert abs(serial["a_error_in_elements"]) < 1.0
    assert 0.03 < serial["l2_pressure_error_rel"] < 0.12
    assert max(serial["newton_iterations"]) <= 6


@pytest.mark.parametrize("case, slave", [("sphere", "sphere"), ("block", "block")])
def test_two_spheres_and_the_block_as_slave(case, slave):
    """Two equal spheres (R/2 in Hertz's formulas), or the block's top as the slave: the
    load transmitted to rounding; measured p_max/p0 - 1 = -1.0 % and -1.2 % recovered,
    +3.5 % and +3.0 % the largest multiplier (the block's normals, the demo's default for
    a linear material with the block as the slave)."""
    summary = hertz_sphere([*ARGS, "--case", case, "--slave", slave])
    assert summary["total_force"] == pytest.approx(summary["load"], rel=1e-8)
    assert abs(summary["p_max_error_rel"]) < 0.02
    assert 0.0 < summary["p_max_multiplier_error_rel"] < 0.06
    assert abs(summary["a_error_in_elements"]) < 1.0


def test_the_same_problem_in_other_units(serial):
    """Lengths x 8, moduli x 10, force x 640 (= 8^2 x 10): the same mesh (scaled) and the
    same p_max / p0, a_contact / a (measured: equal to 1e-12)."""
    scaled = hertz_sphere([*ARGS, "--radius", "8", "--load", repr(0.15 * 640.0),
                           "--E1", "2000", "--E2", "2000"])
    assert scaled["a_exact"] == pytest.approx(8.0 * serial["a_exact"], rel=1e-12)
    assert scaled["num_dofs"] == serial["num_dofs"]
    for key, exact in (("p_max", "p0_exact"), ("a_contact", "a_exact")):
        ratios = [summary[key] / summary[exact] for summary in (serial, scaled)]
        assert ratios[1] == pytest.approx(ratios[0], rel=1e-6, abs=0.0), key


@pytest.mark.parallel
def test_serial_equals_parallel():
    serial = hertz_sphere(ARGS, comm=MPI.COMM_SELF)
    parallel = hertz_sphere(ARGS, comm=MPI.COMM_WORLD)
    assert parallel["num_ranks"] == MPI.COMM_WORLD.size
    assert parallel["num_dofs"] == serial["num_dofs"]
    assert parallel["active_nodes"] == serial["active_nodes"]
    for key in ("p_max", "total_force", "a_contact", "l2_pressure_error_rel",
                "l2_multiplier_error_rel"):
        assert parallel[key] == pytest.approx(serial[key], rel=1e-8), key
    assert parallel["total_force"] == pytest.approx(parallel["load"], rel=1e-8)


def _demo_module():
    spec = importlib.util.spec_from_file_location("demo_hertz_sphere", DEMOS / "hertz_sphere.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("n0, refinement, steps", [(4, 0, 1), (4, 1, 2), (4, 2, 3), (2, 3, 3),
                                                    (5, 2, 4), (5, 3, 7)])
def test_automatic_steps_move_the_contact_edge_at_most_three_elements(n0, refinement, steps):
    """From a/2 to a is n0 2^k / 2 slave elements: the fewest steps of at most 3 each."""
    module = _demo_module()
    assert module.automatic_steps(n0, refinement) == steps
    distance = (1.0 - module.INITIAL_RADIUS) * n0 * 2**refinement
    assert distance / steps <= module.EDGE_ELEMENTS_PER_STEP
    assert steps == 1 or distance / (steps - 1) > module.EDGE_ELEMENTS_PER_STEP


def test_the_answer_does_not_depend_on_the_load_steps(serial):
    """Frictionless linear elasticity has no load path: 1 and 4 steps (the default at
    refinement 0 is 1) end at the 2-step answer to 1e-8; the iterations per step fall with
    the distance the contact edge moves in a step (measured [5], [3, 4] and [3, 2, 1, 2])."""
    runs = {n: hertz_sphere(["--refinement", "0", "--steps", str(n)]) for n in (1, 4)}
    for n, summary in runs.items():
        for key in ("p_max", "a_contact", "l2_pressure_error_rel"):
            assert summary[key] == pytest.approx(serial[key], rel=1e-8), (n, key)
        assert summary["load_steps"] == n
    assert max(runs[4]["newton_iterations"]) < runs[1]["newton_iterations"][0]


@pytest.mark.parametrize(
    "option", [["--load", "-1"], ["--E2", "0"], ["--nu1", "0.5"], ["--load", "100"]]
)
def test_demo_rejects_bad_physical_input(option, capsys):
    """Before any mesh is built; a load of 100 gives a = 0.88 R, beyond the contact cap."""
    with pytest.raises(SystemExit) as exit_info:
        hertz_sphere(option)
    assert exit_info.value.code == 2
    assert ("R/3" if option[1] == "100" else option[0]) in capsys.readouterr().err


HEX_ARGS = ["--cell", "hexahedron", "--elements-per-radius", "2", "--steps", "2",
            "--material", "linear"]


def test_graded_nodes_are_uniform_then_grow_to_the_end():
    """h_fine up to the zone, then each cell at most ratio times its neighbour and at most
    h_max (the graded part is only shrunk to fit), the last node exactly at the length."""
    nodes = meshes3d.graded_nodes(1.0, 0.025, 0.15, 1.5, 0.25)
    sizes = np.diff(nodes)
    assert nodes[0] == 0.0 and nodes[-1] == 1.0
    np.testing.assert_allclose(sizes[:6], 0.025, rtol=1e-14)
    assert np.all(sizes[6:] > 0.025) and np.all(sizes[6:] <= 0.25 + 1e-14)
    assert np.all(sizes[1:] / sizes[:-1] <= 1.5 + 1e-12)
    short = meshes3d.graded_nodes(0.1, 0.025, 0.15, 1.5, 0.25)
    np.testing.assert_allclose(short, np.linspace(0.0, 0.1, 7), rtol=1e-14)


@pytest.mark.parametrize("case", meshes3d.HERTZ_SPHERE_CASES)
def test_hexahedral_mesh_bodies_are_separate_and_tagged(case):
    """Two nodes at the contact point, the slave nodes on the sphere's surface, the load
    face the square (R/2)^2 exactly, every named group present."""
    R = 2.0
    tagged = meshes3d.hertz_sphere_hexahedral(case=case, radius=R, contact_radius=0.2,
                                              elements_per_radius=2, comm=MPI.COMM_SELF)
    mesh = tagged.mesh
    x = mesh.geometry.x
    assert np.count_nonzero(np.linalg.norm(x, axis=1) < 1e-12) == 2
    assert tagged.h_contact == pytest.approx(0.1, rel=1e-12)
    for name in ("contact_slave", "contact_master", "load", "support", "symmetry_x",
                 "symmetry_y"):
        assert tagged.facet_tags.find(tagged.markers[name]).size > 0, name
    slave = tagged.facet_tags.find(tagged.markers["contact_slave"])
    nodes = np.unique(dolfinx.mesh.entities_to_geometry(mesh, 2, slave, False))
    sphere = R - np.sqrt(R**2 - x[nodes, 0] ** 2 - x[nodes, 1] ** 2)
    np.testing.assert_allclose(x[nodes, 2], sphere, atol=1e-14 * R)
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=tagged.facet_tags)
    area = dolfinx.fem.assemble_scalar(dolfinx.fem.form(
        dolfinx.fem.Constant(mesh, 1.0) * ds(tagged.markers["load"])))
    assert area == pytest.approx((R / 2.0) ** 2, rel=1e-12)


@pytest.mark.parametrize("case, refinement", [("block", 0), ("block", 1), ("sphere", 0)])
def test_hexahedral_pressure_peak_is_within_two_percent(case, refinement):
    """On the structured hexahedral grids the nodal multipliers do not scatter as on gmsh's
    tetrahedra: their maximum within 2 % of p0 (measured +1.16 % and -0.10 % for the block
    at h = a/2 and a/4, +1.38 % for two spheres at h = a/2); the recovered pressure's peak
    differs from it by the linear fit's curvature error, O(p0 h^2 / a^2) (a node on the
    symmetry planes has a one-sided patch; measured +2.40 %, -0.08 %, +2.63 %); the
    contact radius within one slave element, the load transmitted to rounding. The same
    fit lowers the concave pressure at every node with a full patch
    (test_recovery.test_uniform_quadrilaterals_recover_the_nine_point_average), so the
    recovered pressure's L2 error is the larger of the two here."""
    summary = hertz_sphere([*HEX_ARGS, "--case", case, "--refinement", str(refinement)])
    assert abs(summary["p_max_multiplier_error_rel"]) < 0.02
    assert summary["l2_multiplier_error_rel"] < summary["l2_pressure_error_rel"]
    h_over_a = summary["h_slave_measured"] / summary["a_exact"]
    assert abs(summary["p_max_error_rel"]) < 0.15 * h_over_a**2
    assert abs(summary["a_error_in_elements"]) < 1.0
    assert summary["total_force"] == pytest.approx(summary["load"], rel=1e-8)
    assert summary["force_balance"] <= 1e-10
    assert max(summary["newton_iterations"]) <= 8


@pytest.mark.parallel
def test_hexahedral_serial_equals_parallel():
    args = [*HEX_ARGS, "--refinement", "0"]
    serial = hertz_sphere(args, comm=MPI.COMM_SELF)
    parallel = hertz_sphere(args, comm=MPI.COMM_WORLD)
    assert parallel["num_dofs"] == serial["num_dofs"]
    assert parallel["active_nodes"] == serial["active_nodes"]
    for key in ("p_max", "total_force", "a_contact", "l2_pressure_error_rel",
                "l2_multiplier_error_rel"):
        assert parallel[key] == pytest.approx(serial[key], rel=1e-8), key


def _contact_edge_length(tagged, name: str, within: float) -> float:
    """Mean edge length of the facets ``name`` whose midpoints lie within ``within`` of
    the z axis (serial mesh)."""
    mesh = tagged.mesh
    facets = tagged.facet_tags.find(tagged.markers[name])
    points = mesh.geometry.x[dolfinx.mesh.entities_to_geometry(mesh, 2, facets, False)]
    near = np.hypot(*points.mean(axis=1)[:, :2].T) < within
    ring = points[near]
    return float(np.linalg.norm(np.roll(ring, -1, axis=1) - ring, axis=2).mean())


@pytest.mark.parametrize("ratio", [0.5, 2.0])
def test_lower_size_ratio_scales_the_lower_contact_mesh(ratio):
    """The lower body's contact facets are ``ratio`` times the upper body's (within 15 %
    for gmsh's sizes), the upper body's unchanged."""
    a = 0.1
    meshes = {r: meshes3d.hertz_sphere(case="sphere", contact_radius=a, lower_size_ratio=r,
                                       comm=MPI.COMM_SELF) for r in (1.0, ratio)}
    upper = {r: _contact_edge_length(m, "sphere_surface", 1.5 * a) for r, m in meshes.items()}
    lower = {r: _contact_edge_length(m, "block_top", 1.5 * a) for r, m in meshes.items()}
    assert upper[ratio] == pytest.approx(upper[1.0], rel=0.05)
    assert lower[ratio] / upper[ratio] == pytest.approx(ratio, rel=0.15)
    assert lower[1.0] / upper[1.0] == pytest.approx(1.0, rel=0.1)
