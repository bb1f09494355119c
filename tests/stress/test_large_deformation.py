"""Stress cases 10, 11 and 12: large sliding, large strain, too large load steps.

10. Ironing (demos/ironing.py): the die slides over many block elements; every step
    converges (the stepper may cut back) and the contact forces on die and block
    balance to 1e-8.
11. Two Neo-Hookean rings (meshes.rings, holes of radius 0.3) squeezed together by
    moving their inner boundaries rigidly towards each other over several load
    steps: 10 % of the outer diameter (fast), 35 % and 40 % (full); converges, force
    balance 1e-8 at every step, no inverted element, no NaN.
12. Load steps that are too large: Hertz (Neo-Hookean) with 40 times the nominal load
    in one step must be cut back and still reach the full load, with the answer of
    a finely stepped run; with max_cutbacks=0 it raises a clear LoadSteppingError
    and leaves the problem in its initial state. Ironing in one step (die down by
    1.0 at once, far more than the search margin in one Newton iterate) must be
    cut back and end in the state of eight small steps, not inside the block.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_mortar import LoadSteppingError

from . import common
from .common import record, record_outcome, relative_difference

# ----------------------------------------------------------------------------------------
# 10. large sliding


def check_ironing(args: list[str]):
    summary = common.demo("ironing").main(args)
    history = summary["history"]
    forces = np.array(
        [
            [h["slave_force_x"], h["slave_force_y"], h["master_force_x"], h["master_force_y"]]
            for h in history
        ]
    )
    nan = not np.all(np.isfinite(forces))
    end = float(args[args.index("--end-time") + 1])
    record(
        10,
        converged=summary["end_time"] >= end - 1e-12,
        iterations=summary["newton_iterations"],
        cutbacks=summary["cutbacks"],
        nan=nan,
        error=summary["max_force_balance_rel"],
        end_time=summary["end_time"],
        steps=summary["steps_completed"],
        max_iterations=summary["max_newton_iterations"],
        vertical_force_at_t1=summary["vertical_force_at_t1"],
        plateau=summary["vertical_force_plateau_mean"],
    )
    assert summary["end_time"] == pytest.approx(end, abs=1e-12)
    assert not nan
    assert summary["max_force_balance_rel"] <= 1e-8
    assert max(summary["newton_iterations"]) < 30
    # the die is in contact and pushes the block down once it has crossed the gap of 0.2
    pressing = [h for h in history if h["t"] >= 0.3]
    assert all(h["active"] > 0 and h["master_force_y"] < 0.0 for h in pressing)
    return summary


def test_ironing_large_sliding():
    check_ironing(["--steps", "40", "--end-time", "1.1"])


@pytest.mark.slow
@pytest.mark.parametrize(
    "args",
    [
        ["--steps", "100", "--end-time", "1.3"],
        ["--steps", "100", "--end-time", "1.3", "--refinement", "1"],
        ["--steps", "100", "--end-time", "1.3", "--cell-type", "triangle"],
        ["--steps", "60", "--end-time", "1.3", "--method", "penalty"],
    ],
    ids=["quadrilateral", "refined", "triangle", "penalty"],
)
def test_ironing_large_sliding_full(args):
    check_ironing(args)


# ----------------------------------------------------------------------------------------
# 11. rings at large strain


def check_rings(squeeze: float, steps: int, refinement: int, **options):
    setup = common.rings(squeeze=squeeze, refinement=refinement, **options)
    problem = setup.problem
    balances, inverted = [], []

    def on_step(_record):
        slave, master = problem.contact_forces()
        balances.append(float(np.linalg.norm(slave + master) / max(np.linalg.norm(slave), 1e-300)))
        inverted.append(common.inverted_cells(problem.u))

    outcome = setup.steps(steps, on_step=on_step)
    fraction = squeeze / setup.info["outer_diameter"]
    setup.destroy()
    record_outcome(
        11,
        outcome,
        error=max(balances),
        squeeze_fraction=fraction,
        active=outcome.active,
        inverted=max(inverted),
        contact_force=outcome.slave_force.tolist(),
    )
    assert outcome.converged and not outcome.nan
    assert max(balances) <= 1e-8
    assert max(inverted) == 0 and outcome.inverted == 0
    assert outcome.active > 0 and outcome.slave_force[1] > 0.0  # the bottom ring pushes up
    assert outcome.extra["records"][-1].load == pytest.approx(1.0)


def test_rings_moderate_squeeze():
    check_rings(squeeze=0.2, steps=4, refinement=0)  # 10 % of the outer diameter


@pytest.mark.slow
@pytest.mark.parametrize(
    "squeeze,steps,refinement,options",
    [
        (0.7, 14, 1, {}),  # 35 %: the material between the holes (1.4) compressed to 0.7
        (0.8, 16, 2, {}),  # 40 %
        (0.7, 14, 1, {"cell_type": "quadrilateral"}),
        (0.7, 14, 1, {"method": "penalty"}),
        (0.3, 15, 1, {"inner_radius": 0.8}),  # thin rings: 0.4 of material crushed to 0.1
    ],
    ids=["35%", "40%-refined", "35%-quadrilateral", "35%-penalty", "thin-15%"],
)
def test_rings_large_squeeze(squeeze, steps, refinement, options):
    check_rings(squeeze, steps, refinement, **options)


# ----------------------------------------------------------------------------------------
# 12. load steps that are too large

BIG_LOAD = 40.0 * common.HERTZ_LOAD


@functools.cache
def hertz_finely_stepped(load: float, steps: int = 8):
    setup = common.hertz(load=load, material="neo-hookean")
    outcome = setup.steps(steps)
    setup.destroy()
    assert outcome.converged and outcome.cutbacks == 0
    return outcome


def test_too_large_step_is_cut_back():
    setup = common.hertz(load=BIG_LOAD, material="neo-hookean")
    outcome = setup.steps(1)
    setup.destroy()
    reference = hertz_finely_stepped(BIG_LOAD)
    records = outcome.extra["records"]
    difference = relative_difference(outcome.pressure, reference.pressure)
    record_outcome(
        12,
        outcome,
        error=difference,
        final_load=records[-1].load,
        force=float(outcome.slave_force[1]),
    )
    assert outcome.cutbacks > 0
    assert records[-1].load == pytest.approx(1.0)
    assert outcome.converged and not outcome.nan and outcome.inverted == 0
    assert outcome.slave_force[1] == pytest.approx(BIG_LOAD, rel=1e-9)
    assert difference <= 1e-8  # the same equilibrium as eight small steps


def test_no_cutback_allowed_raises_a_clear_error():
    setup = common.hertz(load=BIG_LOAD, material="neo-hookean")
    initial = setup.problem.u.x.array.copy()
    with pytest.raises(
        LoadSteppingError,
        match=r"no convergence from t = 0 to 1 after 0 cut-backs "
        r"\(last SNES reason -?\d+",
    ) as error:
        setup.steps(1, max_cutbacks=0)
    restored = np.array_equal(setup.problem.u.x.array, initial)
    multipliers = [z.getArray(readonly=True).copy() for z in setup.problem.multipliers]
    setup.destroy()
    record(12, converged=False, error=0.0, message=str(error.value), restored=restored)
    assert restored  # the failed step is undone
    assert all(np.all(z == 0.0) for z in multipliers)


@functools.cache
def ironing_finely_stepped(steps: int = 8):
    """Displacement and die force of the ironing problem at t = 1 (die down by 1.0)."""
    setup = common.ironing()
    outcome = setup.steps(steps, end=1.0)
    u = setup.problem.u.x.array.copy()
    setup.destroy()
    assert outcome.converged and outcome.cutbacks == 0
    return u, outcome.slave_force.copy()


def test_ironing_in_one_step_is_cut_back_or_solved():
    """The first Newton iterate moves the die down by 1.0 at once (its arc from y in [4.2, 4.5]
    to [3.2, 3.5], the block top is at y = 4): far more than the search margin (0.087) in one
    update. The swept search still pairs the die with the block facets it crossed, the
    penetrated nodes are active, the step fails (inverted elements) and is cut back, and
    the end state is the one of eight small steps. The block is 10 times softer than the
    die, so it is indented by 0.76: the die's lowest point (3.237) is on the indented
    block surface, not inside it."""
    setup = common.ironing()
    outcome = setup.steps(1, end=1.0)
    problem = setup.problem
    interface = problem.interfaces[0]
    lowest, block_lowest, smallest_gap = (
        problem.comm.allreduce(float(np.min(values, initial=np.inf)), op=MPI.MIN)
        for values in (
            interface.slave.current_coordinates(problem.u)[:, 1],
            interface.master.current_coordinates(problem.u)[:, 1],
            problem.gaps[0],
        )
    )
    u = problem.u.x.array.copy()
    setup.destroy()
    reference_u, reference_force = ironing_finely_stepped()
    squares = problem.comm.allreduce(
        np.array([np.sum((u - reference_u) ** 2), np.sum(reference_u**2)])
    )
    difference = float(np.sqrt(squares[0] / squares[1]))
    force_difference = relative_difference(outcome.slave_force, reference_force)
    record_outcome(
        12,
        outcome,
        active=outcome.active,
        lowest_die_point=lowest,
        lowest_block_point=block_lowest,
        error=difference,
        force_error=force_difference,
    )
    assert outcome.converged and not outcome.nan
    assert outcome.active > 0, "no contact found"
    assert outcome.cutbacks > 0
    assert outcome.extra["records"][-1].load == pytest.approx(1.0)
    assert outcome.force_balance <= 1e-8
    assert smallest_gap >= -1e-12
    # the die is on the indented block surface, not inside the block
    assert block_lowest < 3.5 and lowest >= block_lowest
    assert difference <= 1e-10 and force_difference <= 1e-10


@pytest.mark.slow
def test_ironing_sliding_jump_is_cut_back():
    """From the state at t = 1 (20 steps), jump to t = 1.1 (the die slides 1.0, ten block
    elements) in one step: cut back, reach t = 1.1, forces balance, and the same
    vertical force as a run in steps of 0.01 (the cut-backs end in steps of 0.0125)."""
    setup = common.ironing()
    setup.steps(20, end=1.0)
    outcome = setup.steps(1, start=1.0, end=1.1)
    jumped = outcome.slave_force.copy()
    setup.destroy()
    fine = common.ironing()
    fine.steps(20, end=1.0)
    reference = fine.steps(10, start=1.0, end=1.1)
    fine.destroy()
    difference = float(
        np.linalg.norm(jumped - reference.slave_force) / np.linalg.norm(reference.slave_force)
    )
    record_outcome(
        12,
        outcome,
        error=difference,
        balance=outcome.force_balance,
    )
    assert outcome.cutbacks > 0
    assert outcome.extra["records"][-1].load == pytest.approx(1.1)
    assert outcome.converged and not outcome.nan
    assert outcome.force_balance <= 1e-8
    assert difference <= 1e-6
