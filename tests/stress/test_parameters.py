"""Stress cases 1 and 2: the enforcement parameters over many decades.

1. Penalty eps over six decades around the automatic E/h (patch test, Hertz
   refinement 0): every solve converges, no NaN; the patch test keeps its exact
   uniform pressure with the uniform penetration p / eps, and on Hertz the
   pressure error against Lagrange multipliers falls like 1/eps.
2. The complementarity parameter c_n over four decades: semismooth Newton gives
   the same solution (pressure and displacement) to 1e-8.
"""

from __future__ import annotations

import functools
import warnings

import numpy as np
import pytest

from dolfinx_mortar.diagnostics import ContactWarning

from . import common
from .common import record, record_outcome, relative_difference

PENALTY_FACTORS = [10.0**k for k in range(-3, 4)]  # eps / (E/h): six decades
CN_FACTORS = [1e-2, 1e-1, 10.0, 1e2]  # c_n / (E/h): four decades around 1

# Fixed defects these cases caught (docs/stress.md): the divergence test stopped stiff
# penalty solves (now off by default); penalty from a touching start left every node
# inactive and the punch singular (now ties count as active, null pivots fixed);
# unscaled active rows had rounding floors above the tolerances (rows now force-scaled).
NO_DIVERGENCE_TEST = {"snes_divergence_tolerance": 1e300}


def penetration_times_eps(problem) -> np.ndarray:
    """eps * (-g~_j / A_j) at the active slave nodes (all ranks)."""
    active = problem.active[0]
    depth = -(problem.gaps[0] / np.where(active, problem.areas[0], 1.0))[active]
    return np.concatenate(problem.comm.allgather(problem.penalty * depth))


# ----------------------------------------------------------------------------------------
# 1. penalty sweep


@functools.cache
def patch_lagrange(ratio=(3, 7)):
    setup = common.patch_traction(ratio=ratio)
    outcome = setup.solve()
    scale = setup.problem.penalty  # the automatic E/h
    setup.destroy()
    assert outcome.converged
    return outcome, scale


def run_patch_penalty(factor: float, ratio=(3, 7), **options):
    lagrange, scale = patch_lagrange(ratio)
    setup = common.patch_traction(ratio=ratio, method="penalty", penalty=factor * scale, **options)
    outcome = setup.solve()
    product = penetration_times_eps(setup.problem)
    setup.destroy()
    error = relative_difference(outcome.pressure, lagrange.pressure)
    penetration_error = float(np.max(np.abs(product / common.PATCH_PRESSURE - 1.0), initial=0.0))
    return outcome, error, penetration_error, product


def check_patch_penalty(factor: float, ratio=(3, 7), **options):
    """Converged, no NaN, pressure = Lagrange to 1e-10, penetration x eps = p to 1e-8."""
    outcome, error, penetration_error, product = run_patch_penalty(factor, ratio, **options)
    record_outcome(1, outcome, error=error, penetration_error=penetration_error, eps_factor=factor)
    assert outcome.converged, f"SNES failed at eps = {factor:g} E/h"
    assert not outcome.nan
    assert error <= 1e-10
    assert penetration_error <= 1e-8, product
    return outcome


@pytest.mark.parametrize(
    "factor",
    PENALTY_FACTORS,
)
def test_penalty_patch_test(factor):
    """Any eps: pressure exactly uniform (= Lagrange), penetration exactly p / eps."""
    outcome = check_patch_penalty(factor)
    assert outcome.active == outcome.pressure.size


def test_penalty_stiffest_with_divergence_test_disabled():
    """The same stiffest case converges once SNES's divergence test is off (the fix)."""
    check_patch_penalty(PENALTY_FACTORS[-1], petsc_options=NO_DIVERGENCE_TEST)


def check_first_penalty_iterate(ratio, factor):
    """One Newton iteration of this piecewise linear problem: the displacement must be of
    the order of the solution's (the penetration p / eps plus the elastic part, below 1
    here), not a singular solve's."""
    lagrange, scale = patch_lagrange(ratio)
    setup = common.patch_traction(
        ratio=ratio,
        method="penalty",
        penalty=factor * scale,
        petsc_options={"snes_max_it": 1, **NO_DIVERGENCE_TEST},
    )
    outcome = setup.solve()
    setup.destroy()
    jump = float(np.max(np.abs(outcome.displacement)))
    bound = 100.0 * (1.0 + common.PATCH_PRESSURE / (factor * scale))
    record_outcome(1, outcome, error=jump / bound, jump=jump, bound=bound)
    assert not outcome.nan
    assert jump <= bound, jump


def test_penalty_first_iterate_from_touching_is_sane():
    check_first_penalty_iterate((1, 1), 1.0)


@pytest.mark.slow
@pytest.mark.parametrize("factor", PENALTY_FACTORS)
def test_penalty_first_iterate_from_touching_aligned_full(factor):
    check_first_penalty_iterate((1, 1), factor)


@pytest.mark.slow
@pytest.mark.parametrize("factor", PENALTY_FACTORS)
def test_penalty_first_iterate_from_touching_2_2_full(factor):
    check_first_penalty_iterate((2, 2), factor)


@functools.cache
def hertz_lagrange(refinement=0, steps=2):
    setup = common.hertz(refinement=refinement)
    outcome = setup.steps(steps) if steps else setup.solve()
    scale = setup.problem.penalty
    setup.destroy()
    assert outcome.converged and outcome.cutbacks == 0
    return outcome, scale


def run_hertz_penalty(factor: float, refinement=0, steps=2, **options):
    lagrange, scale = hertz_lagrange(refinement, steps)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ContactWarning)
        setup = common.hertz(refinement=refinement, method="penalty", penalty=factor * scale,
                             **options)
        outcome = setup.steps(steps) if steps else setup.solve()
    outcome.extra["warnings"] = [str(w.message) for w in caught
                                 if issubclass(w.category, ContactWarning)]
    setup.destroy()
    error = relative_difference(outcome.pressure, lagrange.pressure)
    return outcome, error


@pytest.mark.parametrize(
    "factor",
    PENALTY_FACTORS,
)
def test_penalty_hertz_every_solve_converges(factor):
    """Hertz in the demo's two load steps: every Newton solve converges (no cut-back); a
    penalty of 1e-2 E/h or softer lets the block's nodes end more than half a facet inside
    the cylinder, and the user is told so, with the soft penalty among the causes."""
    outcome, error = run_hertz_penalty(factor)
    if factor <= 1e-2:
        assert outcome.extra["warnings"], "no penetration warning for a soft penalty"
        assert all("penalty parameter too soft" in m for m in outcome.extra["warnings"])
    else:
        assert outcome.extra["warnings"] == []
    record_outcome(
        1,
        outcome,
        error=error,
        eps_factor=factor,
    )
    assert outcome.converged and not outcome.nan
    assert outcome.cutbacks == 0
    assert (
        float(np.linalg.norm(outcome.slave_force + outcome.master_force))
        <= 1e-10 * common.HERTZ_LOAD
    )


def check_one_over_eps(factors, errors, floor=1e-9):
    """Monotone decrease; from 10 E/h on, error * eps constant within 15 % until the floor."""
    errors = np.asarray(errors)
    assert np.all(np.diff(errors) < 0.0), errors
    stiff = [(f, e) for f, e in zip(factors, errors, strict=True) if f >= 10.0 and e > floor]
    assert len(stiff) >= 2
    products = np.array([f * e for f, e in stiff])
    assert np.ptp(products) <= 0.15 * products.max(), products


def test_penalty_hertz_error_falls_like_one_over_eps():
    """The load stepper's accepted results (cut-backs allowed): |p_eps - p_lagrange| ~ 1/eps."""
    errors, iterations = [], []
    for factor in PENALTY_FACTORS:
        outcome, error = run_hertz_penalty(factor)
        assert outcome.converged and not outcome.nan
        errors.append(error)
        iterations.append(sum(outcome.iterations))
    record(
        1,
        converged=True,
        iterations=iterations,
        error=errors[-1],
        errors=errors,
        factors=PENALTY_FACTORS,
    )
    check_one_over_eps(PENALTY_FACTORS, errors)


@pytest.mark.slow
@pytest.mark.parametrize("refinement", [1, 2])
def test_penalty_hertz_refined_error_falls_like_one_over_eps(refinement):
    errors, iterations, cutbacks = [], [], 0
    for factor in PENALTY_FACTORS:
        outcome, error = run_hertz_penalty(factor, refinement=refinement)
        assert outcome.converged and not outcome.nan
        errors.append(error)
        iterations.append(sum(outcome.iterations))
        cutbacks += outcome.cutbacks
    record(
        1,
        converged=True,
        iterations=iterations,
        cutbacks=cutbacks,
        error=errors[-1],
        errors=errors,
        factors=PENALTY_FACTORS,
    )
    check_one_over_eps(PENALTY_FACTORS, errors)


@pytest.mark.slow
def test_penalty_hertz_eleven_decades_single_step():
    """One Newton solve to the full load, eps from 1e-3 to 1e8 E/h (divergence test off):
    the error keeps falling like 1/eps down to about 3e-9."""
    factors = [10.0**k for k in range(-3, 9)]
    errors, iterations = [], []
    for factor in factors:
        outcome, error = run_hertz_penalty(factor, steps=0, petsc_options=NO_DIVERGENCE_TEST)
        assert outcome.converged and not outcome.nan, factor
        errors.append(error)
        iterations.append(outcome.iterations[0])
    record(
        1, converged=True, iterations=iterations, error=errors[-1], errors=errors, factors=factors
    )
    check_one_over_eps(factors, errors, floor=1e-12)


def penalty_ratio_params():
    for ratio in [(1, 1), (2, 3), (1, 7), (7, 1)]:
        for factor in PENALTY_FACTORS:
            yield pytest.param(ratio, factor, id=f"{ratio[0]}:{ratio[1]}-{factor:g}")


@pytest.mark.slow
@pytest.mark.parametrize("ratio,factor", list(penalty_ratio_params()))
def test_penalty_patch_test_ratios(ratio, factor):
    check_patch_penalty(factor, ratio, petsc_options=NO_DIVERGENCE_TEST)


# ----------------------------------------------------------------------------------------
# 2. c_n sweep

CONFIGURATIONS = {
    # name: (builder, options, number of load steps (0: one plain solve))
    "hertz": (common.hertz, {}, 2),
    "patch-linear": (common.patch_traction, {"ratio": (3, 7)}, 0),
    "patch-neo-hookean-punch": (
        common.patch_traction,
        {"ratio": (3, 7), "material": "neo-hookean", "pressure_on": "punch", "pressure": 40.0},
        2,
    ),
    "hertz-refined": (common.hertz, {"refinement": 1}, 2),
    "hertz-neo-hookean": (common.hertz, {"material": "neo-hookean"}, 2),
    "patch-slave-bottom-quadrilateral": (
        common.patch_traction,
        {
            "ratio": (3, 7),
            "slave": "bottom",
            "cell_type": "quadrilateral",
            "material": "neo-hookean",
            "pressure_on": "punch",
            "pressure": 40.0,
        },
        2,
    ),
    "hertz-fixed-point": (common.hertz, {"active_set": "fixed-point"}, 2),
    "hertz-standard-multipliers": (common.hertz, {"basis": "standard"}, 2),
}
FAST_CONFIGURATIONS = ["hertz", "patch-linear", "patch-neo-hookean-punch"]


def run_configuration(name: str, **options):
    builder, base, steps = CONFIGURATIONS[name]
    setup = builder(**base, **options)
    outcome = setup.steps(steps) if steps else setup.solve()
    c_n = setup.problem.c_n
    setup.destroy()
    return outcome, c_n


@functools.cache
def cn_reference(name: str):
    outcome, c_n = run_configuration(name)
    assert outcome.converged and not outcome.nan
    return outcome, c_n


def check_cn(name: str, factor: float):
    reference, c_n = cn_reference(name)
    outcome, _ = run_configuration(name, c_n=factor * c_n)
    pressure_difference = relative_difference(outcome.pressure, reference.pressure)
    displacement_difference = relative_difference(outcome.displacement, reference.displacement)
    record_outcome(
        2,
        outcome,
        error=max(pressure_difference, displacement_difference),
        reference_iterations=reference.iterations,
    )
    # c_n changes the Newton path (the active-set guesses), not the solution: cut-backs
    # are recorded, not forbidden
    assert outcome.converged and not outcome.nan
    assert pressure_difference <= 1e-8
    assert displacement_difference <= 1e-8


@pytest.mark.parametrize("factor", CN_FACTORS)
@pytest.mark.parametrize("name", FAST_CONFIGURATIONS)
def test_cn_independence(name, factor):
    check_cn(name, factor)


def cn_params(names, factors):
    for name in names:
        for factor in factors:
            yield pytest.param(name, factor, id=f"{name}-{factor:g}")


@pytest.mark.slow
@pytest.mark.parametrize(
    "name,factor",
    list(
        cn_params(sorted(set(CONFIGURATIONS) - set(FAST_CONFIGURATIONS)), [1e-3, *CN_FACTORS, 1e3])
    ),
)
def test_cn_independence_full(name, factor):
    check_cn(name, factor)


@pytest.mark.slow
@pytest.mark.parametrize("name,factor", list(cn_params(FAST_CONFIGURATIONS, [1e-3, 1e3])))
def test_cn_independence_six_decades(name, factor):
    check_cn(name, factor)
