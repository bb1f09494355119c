"""Coulomb and Tresca friction in 2D (3D: test_friction3d): patch tests, Taylor tests, mu = 0."""

from __future__ import annotations

import numpy as np
import pytest
from friction_states import put_active_nodes_in
from mpi4py import MPI
from test_contact import assert_taylor_second_order, built_problem, penetrating_blocks

from dolfinx_mortar import ContactProblem, Coulomb, Tresca, compat


def load_demo(name: str):
    import importlib.util
    import pathlib

    path = pathlib.Path(__file__).parents[1] / "demos" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(f"demo_{name}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


PATCH = load_demo("friction_patch")
sheared_blocks = PATCH.sheared_blocks
E, NU, PRESSURE, SHEAR_MODULUS = PATCH.E, PATCH.NU, PATCH.PRESSURE, PATCH.SHEAR_MODULUS


def solved(problem):
    report = problem.solve()
    assert report.converged, report
    return report


@pytest.mark.parallel
@pytest.mark.parametrize("slave", ["upper", "lower"])
@pytest.mark.parametrize("ratio", ["3:7", "7:3"])
@pytest.mark.parametrize("cell", ["triangle", "quadrilateral"])
def test_full_slip_gives_mu_times_pressure_at_every_node(ratio, slave, cell):
    """demos/friction_patch.py, R = 3: every slave node slips with y_j = mu z_j = 2,
    z_j = 10 and the slip 2 mu p H / G (measured deviations <= 1e-13)."""
    summary = PATCH.main(["--ratio", ratio, "--slave", slave, "--shear-ratio", "3",
                          "--cell-type", cell])
    assert summary["num_slipping"] == summary["num_active"] == summary["num_slave_nodes"]
    for key in ("pressure", "traction", "slip"):
        assert summary[f"max_{key}_deviation_rel"] < 1e-10, key
    assert summary["newton_iterations"] <= 10


@pytest.mark.parallel
@pytest.mark.parametrize("slave", ["upper", "lower"])
@pytest.mark.parametrize("ratio", ["3:7", "7:3"])
def test_below_the_limit_the_blocks_stick(ratio, slave):
    """R = 0.6: every node sticks, slip 0 to rounding, y_j = 0.6 mu p, z_j = p."""
    summary = PATCH.main(["--ratio", ratio, "--slave", slave, "--shear-ratio", "0.6"])
    assert summary["num_sticking"] == summary["num_active"] == summary["num_slave_nodes"]
    for key in ("pressure", "traction", "slip"):
        assert summary[f"max_{key}_deviation_rel"] < 1e-10, key


def test_tresca_bound_is_the_slip_traction():
    """Tresca with bound 1.5: full slip with y_j = 1.5 whatever the pressure."""
    problem = sheared_blocks((3, 7), "upper", Tresca(1.5), top_shift=0.02, side_shear=1.5)
    solved(problem)
    state = problem.friction_state()
    np.testing.assert_allclose(state["traction"], 1.5, rtol=1e-10)
    assert state["slipping"].all()


def test_penalty_friction_sticks_with_an_elastic_slip():
    """Penalty friction (regularized stick): y = eps_t s while it sticks, so the nodes
    creep by shear / eps_t; full slip still gives mu p exactly."""
    eps = 1e4
    problem = sheared_blocks((3, 7), "upper", Coulomb(0.5), top_shift=0.0078,
                             side_shear=0.0078 * SHEAR_MODULUS, method="penalty",
                             penalty=1e5, c_t=eps)
    solved(problem)
    state = problem.friction_state()
    assert state["sticking"].all()
    np.testing.assert_allclose(state["traction"], eps * state["slip"], rtol=1e-10)
    problem = sheared_blocks((3, 7), "upper", Coulomb(0.2), top_shift=0.02,
                             side_shear=2.0, method="penalty", penalty=1e5, c_t=eps)
    solved(problem)
    z = problem.multipliers[0].getArray(readonly=True)
    np.testing.assert_allclose(problem.friction_state()["traction"], 0.2 * z, rtol=1e-10)


@pytest.mark.parametrize("mu", [0.0, 0.3])
def test_zero_friction_is_the_frictionless_problem(mu):
    """Hertz (demos/hertz.py): mu = 0 gives the frictionless Newton path and answer; the
    Coulomb problem with mu = 0.3 differs (similar materials: only slightly)."""
    argv = ["--refinement", "0"]
    frictionless = built_problem("hertz", argv)
    frictional = built_problem("hertz", argv + ["--mu", str(mu)])
    reports = [ContactProblem.solve(p) for p in (frictionless, frictional)]
    u0, u1 = (p.u.x.array for p in (frictionless, frictional))
    change = np.max(np.abs(u1 - u0)) / np.max(np.abs(u0))
    if mu == 0.0:
        assert reports[0].iterations == reports[1].iterations
        assert change < 1e-10
        assert not np.any(frictional.tangential[0].getArray(readonly=True))
    else:
        assert change > 1e-8


def frictional_blocks(mu: float, method: str = "lagrange"):
    """penetrating_blocks (test_contact) with friction and random tangential multipliers
    1 <= |y_j| <= 2."""
    import test_contact

    original = test_contact.ContactProblem

    class Frictional(original):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, friction=Coulomb(mu), **kwargs)

    test_contact.ContactProblem = Frictional
    try:
        problem = penetrating_blocks("averaged", method)
    finally:
        test_contact.ContactProblem = original
    return with_random_tangential_multipliers(problem, seed=3)


def with_random_tangential_multipliers(problem, seed: int):
    """``problem`` with random tangential multipliers 1 <= |y^a_j| <= 2 (per-rank seed)."""
    rng = np.random.default_rng(seed + problem.comm.rank)
    for y in problem.tangential:
        size = y.getLocalSize()
        y.setArray(rng.choice([-1.0, 1.0], size) * rng.uniform(1.0, 2.0, size))
    problem.equations.read_state(problem.x)
    return problem


@pytest.mark.parallel
@pytest.mark.parametrize("method", ["lagrange", "penalty"])
@pytest.mark.parametrize("state", ["slipping", "sticking"])
def test_frictional_jacobian_taylor(state, method):
    """Residual of the whole frictional system: slope 2 in the stick and in the slip state.
    mu is set from the state, so that every active node is in ``state`` with a margin of
    2 from the kink: bound = mu (z_j - c_n g^_j) (penalty: mu z_j) against |v_j| (module
    docstring of friction)."""
    problem = frictional_blocks(1.0, method)
    put_active_nodes_in(problem, state, method)
    assert_taylor_second_order(problem, seed=11)


def test_bad_friction_input():
    """Unknown laws, negative coefficients, wrong counts, unsupported options: clear errors."""
    args = ((3, 7), "upper")
    for law, value in ((Coulomb, -0.1), (Tresca, -1.0)):
        with pytest.raises(ValueError, match="must be >= 0"):
            law(value)
    for friction, message in [(("viscous", 0.1), "unknown friction law"),
                              (0.3, "friction must be None"),
                              ([Coulomb(0.1)] * 2, "2 laws for 1 contact pairs")]:
        with pytest.raises(ValueError, match=message):
            sheared_blocks(*args, friction, 0.0, 0.0)
    for options, message in [({"method": "augmented"}, "method='lagrange' or 'penalty'"),
                             ({"active_set": "fixed-point"}, "active_set='semismooth'")]:
        with pytest.raises(ValueError, match=message):
            sheared_blocks(*args, Coulomb(0.1), 0.0, 0.0, **options)


def test_state_is_saved_and_restored_with_the_tangential_multipliers():
    problem = sheared_blocks((3, 7), "upper", Coulomb(0.2), top_shift=0.02, side_shear=2.0)
    saved = problem.save_state()
    solved(problem)
    y = problem.tangential[0].getArray(readonly=True).copy()
    assert np.any(y)
    problem.restore_state(saved)
    assert not np.any(problem.tangential[0].getArray(readonly=True))
    compat.set_bc_values(problem.u, problem.bcs)
    solved(problem)
    np.testing.assert_allclose(problem.tangential[0].getArray(readonly=True), y, rtol=1e-12)



@pytest.mark.parametrize("ratio", [0.3, 0.7])
def test_cattaneo_mindlin_stick_zone_and_tangential_force(ratio):
    """Refinement 1 (5,286 dofs): the stick half-width within one slave element of
    a sqrt(1 - Q/(mu P)) (measured 0.46 and 0.53 elements), the friction force on the
    cylinder -Q to 1e-8, at most 10 Newton iterations per step, the L2 traction error
    below 15 % (measured 14.1 and 5.5 %; it falls at rate ~1, docs/benchmarks.md)."""
    summary = load_demo("cattaneo_mindlin").main(
        ["--refinement", "1", "--tangential-ratio", str(ratio)], comm=MPI.COMM_SELF)
    assert summary["stick_error_in_elements"] < 1.0
    assert summary["total_tangential_force_error_rel"] < 1e-8
    assert summary["total_force_error_rel"] < 1e-8
    assert max(summary["newton_iterations"]) <= 10
    assert summary["l2_traction_error_rel"] < 0.15
    assert summary["num_sticking"] > 0 and summary["num_slipping"] > 0
    assert summary["min_nodal_dissipation_rel"] > -1e-10


@pytest.mark.timeout(300)
def test_cattaneo_mindlin_3d_stick_radius_and_coulomb_law(tmp_path):
    """3D (--dim 3), refinement 0 (4,320 dofs, half model): a stick core and a slip ring;
    the stick radius within one element of Mindlin's a (1 - Q/(mu P))^(1/3) (measured
    0.32); the friction force on the sphere -Q and the normal force P to 1e-8 (the loads
    are exact on the faceted top); the traction |y_j| = mu z_j at every slipping node to
    1e-8 and below it at the sticking ones; no negative frictional work; the recovered
    traction (problem.tangential_traction) closer to Mindlin's than the multipliers
    (L2 29.2 % against 46.5 %); the outputs."""
    summary = load_demo("cattaneo_mindlin").main(
        ["--dim", "3", "--output", str(tmp_path), "--json", str(tmp_path / "cm3d.json")],
        comm=MPI.COMM_SELF)
    assert summary["num_sticking"] > 0 and summary["num_slipping"] > 0
    assert summary["stick_error_in_elements"] < 1.0
    assert summary["total_tangential_force_error_rel"] < 1e-8
    assert summary["total_force_error_rel"] < 1e-8
    assert summary["force_balance"] < 1e-10
    low, high = summary["coulomb_ratio_slipping"]
    assert 1.0 - 1e-8 < low <= high < 1.0 + 1e-8
    assert summary["coulomb_ratio_sticking_max"] < 1.0
    assert summary["min_nodal_dissipation_rel"] > -1e-8
    assert max(summary["newton_iterations"]) <= 10 and summary["cutbacks"] == 0
    assert summary["l2_traction_error_rel"] < 0.7 * summary["l2_multiplier_traction_error_rel"]
    for name in ("cattaneo_mindlin_3d.png", "cattaneo_mindlin_3d.csv", "cm3d.json",
                 "paraview/tangential_traction.bp"):
        assert (tmp_path / name).exists(), name


@pytest.mark.parallel
@pytest.mark.timeout(300)
def test_cattaneo_mindlin_3d_iterative_solver_equals_the_direct_one():
    """The 3D Cattaneo-Mindlin at refinement 0 with the iterative solver and with MUMPS: the
    same Newton iterations and tractions (to 1e-8 of mu p0). Its frictionless normal phase
    leaves the sphere free to slide along x (a flat master, the reference configuration):
    the Newton matrix is singular there, and without that null space in the iterative path
    the slide took any value and the tractions came out 200 times too large."""
    module = load_demo("cattaneo_mindlin")
    runs = [module.main(["--dim", "3", "--linear-solver", solver], comm=MPI.COMM_WORLD)
            for solver in ("direct", "iterative")]
    assert [r["linear_solver"] for r in runs] == ["direct", "iterative"]
    assert runs[0]["newton_iterations"] == runs[1]["newton_iterations"]
    assert runs[0]["cutbacks"] == runs[1]["cutbacks"] == 0
    scale = runs[0]["mu"] * runs[0]["p0_exact"]
    for key in ("traction_x", "recovered_traction_x"):
        q = [np.array(r["profile"][key]) for r in runs]
        assert np.max(np.abs(q[0] - q[1])) < 1e-8 * scale, key
    assert runs[0]["stick_radius"] == runs[1]["stick_radius"]


def test_cattaneo_mindlin_outputs(tmp_path):
    """PNG, CSV, JSON and the ParaView files of the frictional state."""
    load_demo("cattaneo_mindlin").main(
        ["--refinement", "0", "--tangential-steps", "1", "--output", str(tmp_path),
         "--json", str(tmp_path / "cm.json")], comm=MPI.COMM_SELF)
    for name in ("cattaneo_mindlin.png", "cattaneo_mindlin.csv", "cm.json",
                 "paraview/tangential_traction.bp", "paraview/friction_status.bp"):
        assert (tmp_path / name).exists(), name


def test_a_monotone_pull_does_not_depend_on_the_number_of_steps():
    """Cattaneo-Mindlin at refinement 0 pulled in 2 and in 8 steps: the same tractions
    (to 1e-8 of mu p0: partial slip under a monotone load has no path dependence)."""
    module = load_demo("cattaneo_mindlin")
    runs = [module.main(["--refinement", "0", "--tangential-steps", str(n)],
                        comm=MPI.COMM_SELF) for n in (2, 8)]
    q = [np.array(r["profile"]["traction"]) for r in runs]
    scale = 0.2 * runs[0]["p0_exact"]
    assert np.max(np.abs(q[0] - q[1])) < 1e-8 * scale


@pytest.mark.parallel
@pytest.mark.parametrize("shear_ratio", [0.6, 2.0])
def test_a_predicted_start_measures_slips_from_the_converged_state(shear_ratio):
    """The friction patch test in stick (R = 0.6) and in slip (R = 2), solved; then the same
    load again from a guess (that state extrapolated as from u = 0, twice its displacement
    and multipliers, as ``ContactProblem.predict`` makes them): the solve must come back
    to the solved state, because slips are measured from the last converged state and
    not from the guess."""
    limit = 0.5 * PATCH.PRESSURE
    problem = sheared_blocks((3, 7), "upper", Coulomb(0.5),
                             shear_ratio * limit / PATCH.SHEAR_MODULUS,
                             min(shear_ratio, 1.0) * limit)
    start = problem.save_state()
    solved(problem)
    converged = problem.save_state()
    problem.predict(start, 1.0)
    guess = problem.save_state()
    comm = problem.comm
    for key in ("u", "z", "y"):
        a, b = (np.ravel(state[key]) for state in (converged, guess))
        scale = comm.allreduce(np.abs(a).max(initial=0.0), op=MPI.MAX)
        moved = comm.allreduce(np.abs(a - b).max(initial=0.0), op=MPI.MAX)
        assert moved > 0.5 * scale > 0.0, key
    solved(problem)
    for key in ("u", "z", "y"):
        a, b = (np.ravel(state[key]) for state in (converged, problem.save_state()))
        scale = comm.allreduce(np.abs(a).max(initial=0.0), op=MPI.MAX)
        difference = comm.allreduce(np.abs(a - b).max(initial=0.0), op=MPI.MAX)
        assert difference <= 1e-9 * scale, (key, difference, scale)


def test_the_predictor_does_not_change_a_frictional_answer():
    """Cattaneo-Mindlin at refinement 0 pulled in 8 steps, each started from the last two
    converged states extrapolated (``--predictor extrapolate``) and from the last one: the
    same tractions (to 1e-8 of mu p0) and fewer Newton iterations with the guess. (Under a
    monotone pull the stick nodes keep their relative position, so slips measured from the
    guess would pass here too: test_a_predicted_start_measures_slips_from_the_converged_state
    is the check of that.)"""
    module = load_demo("cattaneo_mindlin")
    runs = [module.main(["--refinement", "0", "--tangential-steps", "8", "--predictor", p],
                        comm=MPI.COMM_SELF) for p in ("none", "extrapolate")]
    q = [np.array(r["profile"]["traction"]) for r in runs]
    scale = 0.2 * runs[0]["p0_exact"]
    assert np.max(np.abs(q[0] - q[1])) < 1e-8 * scale
    assert sum(runs[1]["newton_iterations"]) < sum(runs[0]["newton_iterations"])


@pytest.mark.parallel
@pytest.mark.timeout(600)
def test_frictional_ironing_serial_equals_parallel():
    """Shallow ironing with mu = 0.3 into the sliding phase (250 steps over [0, 2], twice
    the benchmark's step, to t = 1.08): at most 10 Newton iterations per step (measured 9
    and 8 on trixie and sid; with 100 steps 12 on sid), forces balance to 1e-8, the
    frictional work is >= 0 at every node (to rounding), and N ranks give the serial
    forces to 1e-8."""
    module = load_demo("ironing")
    args = ["--mu", "0.3", "--steps", "250", "--end-time", "1.08"]
    serial = module.main(list(args), comm=MPI.COMM_SELF)
    parallel = module.main(list(args), comm=MPI.COMM_WORLD)
    for summary in (serial, parallel):
        assert summary["end_time"] == pytest.approx(1.08)
        assert summary["max_force_balance_rel"] < 1e-8
        assert max(summary["newton_iterations"]) <= 10
        largest = max(h["dissipation"] for h in summary["history"])
        assert largest > 0.0 and summary["min_nodal_dissipation"] > -1e-10 * largest
    assert serial["newton_iterations"] == parallel["newton_iterations"]
    for a, b in zip(serial["history"], parallel["history"], strict=True):
        for key in ("block_force_x", "block_force_y"):
            assert b[key] == pytest.approx(a[key], rel=1e-8, abs=1e-8 * abs(a["block_force_y"]))


def test_frictional_semismooth_newton_converges_quadratically():
    """Neo-Hookean Hertz (refinement 1) with mu = 0.3: at most 10 Newton iterations per
    step, and once the contact and stick/slip sets have settled r_{k+1}/r_0 <= 10
    (r_k/r_0)^2."""
    summary = load_demo("hertz").main(
        ["--refinement", "1", "--steps", "2", "--material", "neo-hookean", "--mu", "0.3"],
        comm=MPI.COMM_SELF)
    assert max(summary["newton_iterations"]) <= 10
    for residuals in summary["residuals_per_step"]:
        q = np.array(residuals) / residuals[0]
        asymptotic = [(a, b) for a, b, rb in zip(q[:-1], q[1:], residuals[1:], strict=True)
                      if a < 0.1 and rb > 1e-11]
        assert asymptotic, residuals
        for a, b in asymptotic:
            assert b <= 10.0 * a**2, residuals


@pytest.mark.parallel
def test_friction_per_pair():
    """The slave surface as two pairs (cut at x = 0.5). The same law on both: the one-pair
    full-slip answer, y_j = mu p at every node of both pairs. Coulomb on the right pair
    only: the left pair's tangential multipliers stay exactly 0, the right pair's slipping
    nodes carry y_j = mu z_j.

    The node at the cut carries a multiplier in each pair. Their area-weighted mean is the
    physical traction and is checked like every other node; how it splits between the two
    pairs is a nearly singular direction of the system (a self-equilibrated pair of master
    forces): solved to 3e-15 of the first residual, the split still moved 2.5e-11 ..
    1.2e-10 of mu p with the partition (serial, 2 and 3 ranks, trixie and sid), so it is
    held to 1e-8."""
    mu, shift = 0.2, 3 * 0.2 * PRESSURE / SHEAR_MODULUS
    law = Coulomb(mu)
    both = sheared_blocks((3, 7), "upper", [law, law], shift, mu * PRESSURE, split_at=0.5)
    solved(both)
    comm = both.comm
    # friction_state is collective: every rank gathers its states before any assert
    states = [both.friction_state(k) for k in range(2)]
    nodes = []
    for k, state in enumerate(states):
        assert comm.allreduce(int(both.active[k].sum()), op=MPI.SUM) > 0
        all_slip = comm.allreduce(bool(state["slipping"].all()), op=MPI.LAND)
        assert all_slip, f"pair {k}: a node sticks"
        rows = np.column_stack([state["coordinates"][:, 0], state["traction"], both.areas[k]])
        nodes.append(np.concatenate(comm.allgather(rows)))
    deviation = {}
    for rows in nodes:
        for x, traction, area in rows:
            deviation.setdefault(round(x, 12), []).append((traction / (mu * PRESSURE) - 1.0, area))
    shared = {x: v for x, v in deviation.items() if len(v) == 2}
    assert len(shared) == 1, sorted(shared)
    for x, values in deviation.items():
        devs, areas = np.array(values).T
        mean = float(np.dot(devs, areas) / areas.sum())
        assert abs(mean) <= 1e-10, f"x = {x}: traction off mu p by {mean:.3e}"
        assert np.max(np.abs(devs)) <= (1e-8 if len(values) == 2 else 1e-10), (x, devs)
    mixed = sheared_blocks((3, 7), "upper", [None, law], shift, mu * PRESSURE, split_at=0.5)
    solved(mixed)
    left, right = mixed.friction_state(0), mixed.friction_state(1)
    assert not comm.allreduce(bool(np.any(left["traction"])), op=MPI.LOR)
    z = mixed.multipliers[1].getArray(readonly=True)
    slipping = right["slipping"]
    assert comm.allreduce(int(slipping.sum()), op=MPI.SUM) > 0
    local = np.abs(np.abs(right["traction"][slipping]) / (mu * z[slipping]) - 1.0)
    error = comm.allreduce(float(np.max(local, initial=0.0)), op=MPI.MAX)
    assert error <= 1e-10, f"|y| / (mu z) off 1 by {error:.3e}"


@pytest.mark.parametrize("demo", ["cattaneo_mindlin", "friction_patch"])
def test_coulomb_demos_refuse_tresca(demo, capsys):
    """A Tresca bound given to a Coulomb demo is a usage error, not silently ignored."""
    with pytest.raises(SystemExit) as exit_info:
        load_demo(demo).main(["--tresca", "1.0"], comm=MPI.COMM_SELF)
    assert exit_info.value.code == 2
    assert "--tresca" in capsys.readouterr().err
