"""Coulomb friction in 3D: nodal tangent frames, Taylor tests in stick and slip, the friction
patch test, mu = 0, serial = parallel."""

import numpy as np
import pytest
from friction_states import put_active_nodes_in
from mpi4py import MPI
from test_contact import assert_taylor_second_order
from test_contact3d import curved_punch, penetrating_punch
from test_friction import load_demo, with_random_tangential_multipliers

from dolfinx_mortar import Coulomb, Tresca
from dolfinx_mortar.friction import tangent_frames


def test_tangent_frames_are_orthonormal_with_exact_derivatives():
    """tau^1, tau^2, n orthonormal and right-handed; d tau / d n against central
    differences of the unit normal (the frame is used only on the sphere |n| = 1, so the
    derivative is checked along tangent directions of n)."""
    rng = np.random.default_rng(0)
    normals = rng.standard_normal((50, 3))
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    axis = np.array([1.0, 0.0, 0.0])
    normals = normals[np.abs(normals @ axis) < 0.95]
    tau, dtau = tangent_frames(normals, axis)
    frame = np.concatenate([tau, normals[:, None]], axis=1)
    np.testing.assert_allclose(frame @ frame.transpose(0, 2, 1),
                               np.broadcast_to(np.eye(3), frame.shape), atol=1e-14)
    np.testing.assert_allclose(np.linalg.det(frame), 1.0, rtol=1e-14)
    direction = rng.standard_normal(normals.shape)
    direction -= np.einsum("nc,nc->n", direction, normals)[:, None] * normals
    h = 1e-6
    plus, minus = (tangent_frames(normals + s * h * direction, axis)[0] for s in (1, -1))
    difference = (plus - minus) / (2 * h)
    exact = np.einsum("nace,ne->nac", dtau, direction)
    np.testing.assert_allclose(difference, exact, atol=1e-8)


def frictional_punch(method: str, mu: float = 1.0, normals: str = "averaged"):
    """The 3D contact Taylor test's state (test_contact3d.penetrating_punch, curvature
    0.02: every slave node 0.03 to 0.04 deep) with Coulomb friction, slips from the
    undeformed state and random tangential multipliers 1 <= |y^a_j| <= 2."""
    problem = penetrating_punch(0.02, method=method, friction=Coulomb(mu),
                                normals=normals)
    return with_random_tangential_multipliers(problem, seed=5)


@pytest.mark.parallel
@pytest.mark.parametrize("normals", ["averaged", "slave", "master"])
@pytest.mark.parametrize("method", ["lagrange", "penalty"])
@pytest.mark.parametrize("state", ["slipping", "sticking"])
def test_frictional_jacobian_taylor_3d(state, method, normals):
    """The whole 3D frictional system: slope 2 in the stick and in the slip state, with
    mu set so that every active node is in ``state`` with a margin of 2 from the kink
    (bound mu (z_j - c_n g^_j), penalty mu z_j, against |v_j|). Slip exercises the
    coupled 2 x 2 derivative of the projection onto the disc; both exercise d D, d M and
    the frames' derivative through the averaged normals (with every normal option: the
    frames always come from the averaged normals)."""
    problem = frictional_punch(method, normals=normals)
    put_active_nodes_in(problem, state, method)
    assert_taylor_second_order(problem, seed=11)
    problem.destroy()


@pytest.mark.parametrize("integration, basis",
                         [("element", "standard"), ("segment", "dual"), ("element", "dual")])
def test_frictional_jacobian_taylor_3d_integration_and_basis(integration, basis):
    """The 3D frictional Taylor test (slip, Lagrange) with element-based integration and
    the dual basis: D and M keep their exact gradients on every kernel path."""
    problem = penetrating_punch(0.02, method="lagrange", friction=Coulomb(1.0),
                                integration=integration, basis=basis)
    with_random_tangential_multipliers(problem, seed=5)
    put_active_nodes_in(problem, "slipping", "lagrange")
    assert_taylor_second_order(problem, seed=11)
    problem.destroy()


PATCH = load_demo("friction_patch")


@pytest.mark.parallel
@pytest.mark.parametrize("slave", ["upper", "lower"])
@pytest.mark.parametrize("cell", ["tetrahedron", "hexahedron"])
@pytest.mark.parametrize("shear_ratio", [0.5, 2.0])
def test_friction_patch_test_3d(shear_ratio, cell, slave):
    """demos/friction_patch.py --dim 3, non-matching 3:7 (tetrahedra) or 2:3 (hexahedra):
    R = 2 every node slips with the traction vector mu p along the slip and the slip
    (R - 1) mu p H / G; R = 0.5 every node sticks with the traction R mu p and slip 0
    (measured deviations <= 2.4e-13)."""
    ratio = "3:7" if cell == "tetrahedron" else "2:3"
    summary = PATCH.main(["--dim", "3", "--cell-type", cell, "--ratio", ratio, "--slave", slave,
                          "--shear-ratio", str(shear_ratio)])
    state = "num_slipping" if shear_ratio > 1 else "num_sticking"
    assert summary[state] == summary["num_active"] == summary["num_slave_nodes"]
    for key in ("pressure", "traction", "slip"):
        assert summary[f"max_{key}_deviation_rel"] < 1e-10, key
    assert summary["newton_iterations"] <= 10


def test_tresca_and_penalty_friction_in_3d():
    """Tresca with bound 1.5: full slip with |y_j| = 1.5 along the slip; penalty Coulomb
    while sticking: y = eps_t s as vectors."""
    problem = PATCH.sheared_blocks_3d((3, 7), "upper", Tresca(1.5), 0.02, 1.5)
    assert problem.solve().converged
    state = problem.friction_state()
    assert state["slipping"].all()
    np.testing.assert_allclose(np.linalg.norm(state["traction"], axis=1), 1.5, rtol=1e-10)
    np.testing.assert_allclose(state["traction"][:, 1], 0.0, atol=1e-10)
    problem.destroy()
    eps = 1e4
    shift = 0.0078
    problem = PATCH.sheared_blocks_3d((3, 7), "upper", Coulomb(0.5), shift,
                                      shift * PATCH.SHEAR_MODULUS, method="penalty",
                                      penalty=1e5, c_t=eps)
    assert problem.solve().converged
    state = problem.friction_state()
    assert state["sticking"].all()
    np.testing.assert_allclose(state["traction"], eps * state["slip"], rtol=1e-10, atol=1e-12)
    problem.destroy()


def test_zero_friction_is_the_frictionless_problem_3d():
    """The curved punch of test_contact3d, 2 load steps: mu = 0 gives the frictionless
    Newton iterations and displacement (y stays exactly 0)."""
    from test_contact3d import solve_curved_punch

    frictionless = solve_curved_punch(MPI.COMM_SELF, steps=2)
    frictional = solve_curved_punch(MPI.COMM_SELF, steps=2, friction=Coulomb(0.0))
    assert frictional["iterations"] == frictionless["iterations"]
    np.testing.assert_allclose(frictional["pressure"], frictionless["pressure"], rtol=1e-10,
                               atol=1e-12 * np.max(frictionless["pressure"]))
    force = frictionless["slave_force"]
    np.testing.assert_allclose(frictional["slave_force"], force, rtol=1e-10,
                               atol=1e-12 * np.linalg.norm(force))


def test_disc_projection_rows_against_finite_differences():
    """tangential_rows in 3D (one node at a time): the derivatives of C_j with respect to
    y_j, u~_j, z_j, g~_j and A_j against central differences, in stick and in slip,
    Lagrange and penalty, with and without held components (y^a = 0 along a prescribed
    displacement): the 2 x 2 blocks of the projection onto the disc."""
    from dolfinx_mortar.friction import tangential_rows

    rng = np.random.default_rng(5)
    law = Coulomb(0.4)
    n = 40
    y = rng.standard_normal((n, 2))
    slip = 0.3 * rng.standard_normal((n, 2))
    z = rng.uniform(1.0, 3.0, n)
    gap = -0.05 * rng.uniform(0.0, 1.0, n)
    area = rng.uniform(0.5, 1.5, n)
    active = np.ones(n, dtype=bool)
    h = 1e-7
    held_some = np.zeros((n, 2), dtype=bool)
    held_some[::5, 0] = True
    held_some[::7, 1] = True
    for c_n, held in ((2.0, None), (None, None), (2.0, held_some), (None, held_some)):
        def rows(y=y, slip=slip, z=z, gap=gap, area=area, c_n=c_n, held=held):
            return tangential_rows(law, 1.3, 1.7, c_n, y, z, active, slip, gap, area, held)

        base = rows()
        assert 0 < base.sticking.sum() < n
        for a in range(2):
            dy = np.zeros((n, 2))
            dy[:, a] = h
            np.testing.assert_allclose((rows(y=y + dy).residual - rows(y=y - dy).residual)
                                       / (2 * h), base.own[:, :, a], atol=1e-6)
            np.testing.assert_allclose((rows(slip=slip + dy).residual
                                        - rows(slip=slip - dy).residual) / (2 * h),
                                       base.slip[:, :, a], atol=1e-6)
        for name, value in (("normal", "z"), ("gap", "gap"), ("area", "area")):
            plus = rows(**{value: locals()[value] + h}).residual
            minus = rows(**{value: locals()[value] - h}).residual
            np.testing.assert_allclose((plus - minus) / (2 * h), getattr(base, name),
                                       atol=1e-6, err_msg=name)


def sheared_punch(comm, steps: int = 4) -> dict:
    """The curved punch (test_contact3d) pressed 0.02 (t in [0, 1]) then its top moved
    0.02 along x (t in [1, 2]) with Coulomb mu = 0.3: a circular contact zone with a
    sticking centre and a slipping rim, then gross sliding."""
    from dolfinx_mortar import solve_load_steps

    problem, press = curved_punch(comm, cell="hexahedron", ratio=(6, 5), curvature=0.1,
                                  friction=Coulomb(0.3))
    drive = problem.bcs[0].g.x.array.reshape(-1, 3)

    def apply_load(t):
        press(min(t, 1.0))
        drive[:, 0] = 0.02 * max(t - 1.0, 0.0)

    history = []

    def record(step):
        state = problem.friction_state()
        z = problem.multipliers[0].getArray(readonly=True)
        slave, master = problem.contact_forces()
        history.append({
            "iterations": step.iterations,
            "slave": slave, "master": master,
            "slipping": comm.allreduce(int(state["slipping"].sum()), op=MPI.SUM),
            "sticking": comm.allreduce(int(state["sticking"].sum()), op=MPI.SUM),
            "dissipation": comm.allreduce(float(state["dissipation"].sum()), op=MPI.SUM),
            "min_dissipation": comm.allreduce(float(state["dissipation"].min(initial=0.0)),
                                              op=MPI.MIN),
            # |y_j| - mu z_j on the slipping nodes, relative to the largest pressure
            "slip_bound_deviation": comm.allreduce(float(np.max(np.abs(
                np.linalg.norm(state["traction"], axis=1) - 0.3 * z)[state["slipping"]],
                initial=0.0)), op=MPI.MAX) / comm.allreduce(float(z.max(initial=0.0)),
                                                            op=MPI.MAX),
        })

    records = solve_load_steps(problem, apply_load, 2 * steps, on_step=record, end=2.0)
    problem.destroy()
    assert all(r.cutbacks == 0 for r in records)
    return {"history": history}


@pytest.mark.parallel
def test_sheared_punch_sticks_then_slides_and_dissipates():
    """3D frictional sliding (curved punch, hexahedra, mu = 0.3): at most 10 Newton
    iterations a step, a stick zone inside a slip rim on the first shear step and gross
    slip at the end; on slipping nodes |y_j| = mu z_j (the gap closed to solver
    tolerance); slave and master forces balance; the nodal frictional work is never
    negative (to rounding); N ranks give the serial forces to 1e-8."""
    result = sheared_punch(MPI.COMM_WORLD)
    history = result["history"]
    assert max(h["iterations"] for h in history) <= 10
    first_shear, last = history[4], history[-1]
    assert first_shear["sticking"] > 0 and first_shear["slipping"] > 0
    assert last["sticking"] == 0 and last["slipping"] > 0
    for h in history:
        assert h["slip_bound_deviation"] < 1e-8
        np.testing.assert_allclose(h["slave"], -h["master"], atol=1e-12 * abs(h["slave"][2]))
        assert h["min_dissipation"] >= -1e-12 * max(g["dissipation"] for g in history)
    if MPI.COMM_WORLD.size > 1:
        serial = sheared_punch(MPI.COMM_SELF)["history"]
        for a, b in zip(history, serial, strict=True):
            np.testing.assert_allclose(a["slave"], b["slave"], rtol=1e-8,
                                       atol=1e-8 * abs(b["slave"][2]))


def test_hertz_sphere_with_friction_on_symmetry_planes():
    """demos/hertz_sphere.py --mu 0.3 (quarter model: slave nodes on the symmetry planes
    have one or two prescribed components, their tangent directions along those carry no
    friction): both load steps converge without cut-back in at most 8 Newton iterations
    and the total force is the load. Without the held components the stick rows there
    constrain the half neighbourhood's mortar slip and Newton stalls (measured: refinement
    1 failed in every cut-back)."""
    summary = load_demo("hertz_sphere").main(
        ["--elements-per-radius", "2", "--refinement", "1", "--steps", "2", "--mu", "0.3"],
        comm=MPI.COMM_SELF)
    assert len(summary["newton_iterations"]) == 2
    assert max(summary["newton_iterations"]) <= 8
    assert summary["total_force"] == pytest.approx(summary["load"], rel=1e-10)
