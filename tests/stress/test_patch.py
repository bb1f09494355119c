"""Stress cases 3 and 6: the contact patch test at extreme mesh ratios and node positions.

3. Mesh ratios 1:1 to 1:10 (punch : foundation elements along the interface), and
   the 10:1 direction by putting the slave on the other side (``--slave``): segment
   Lagrange multipliers must pass the uniform pressure exactly (deviation <= 1e-10),
   through demos/patch_test.py.
6. Aligned nodes (ratios 1:1 and 2:2: every slave node exactly opposite a master
   node) and tiny overlaps (the punch moved horizontally by 1e-14, so that slave and
   master facets overlap over 1e-14): Newton converges and the pressure is uniform,
   p in the small-strain reference configuration, p / a in the Neo-Hookean current
   configuration (a = the exact lateral stretch: the traction is a dead load per
   reference length, the multiplier a force per current length).
"""

from __future__ import annotations

import numpy as np
import pytest

from . import common
from .common import record, record_outcome


def patch_demo(ratio: str, slave: str, *extra: str) -> dict:
    return common.demo("patch_test").main(["--ratio", ratio, "--slave", slave, *extra])


def check_patch_summary(summary: dict) -> None:
    forces = np.array(summary["slave_force"]) + np.array(summary["master_force"])
    values = [
        summary["max_pressure_deviation_rel"],
        summary["max_stress_deviation_rel"],
        summary["pressure_min"],
        summary["pressure_max"],
        *summary["residuals"],
    ]
    nan = not np.all(np.isfinite(values))
    record(
        3,
        converged=summary["converged"],
        iterations=summary["newton_iterations"],
        nan=nan,
        error=summary["max_pressure_deviation_rel"],
        stress_error=summary["max_stress_deviation_rel"],
        active=summary["active_nodes"],
    )
    assert summary["converged"] and not nan
    assert summary["max_pressure_deviation_rel"] <= 1e-10
    assert summary["max_stress_deviation_rel"] <= 1e-10
    assert np.linalg.norm(forces) <= 1e-10 * summary["total_force_expected"]


FAST_RATIOS = ["1:1", "1:2", "1:5", "1:10"]


@pytest.mark.parametrize("slave", ["top", "bottom"])
@pytest.mark.parametrize("ratio", FAST_RATIOS)
def test_patch_test_mesh_ratio(ratio, slave):
    """slave top: the coarse punch is the slave (1 : k); bottom: the fine foundation (k : 1)."""
    check_patch_summary(patch_demo(ratio, slave))


@pytest.mark.slow
@pytest.mark.parametrize("cell_type", ["triangle", "quadrilateral"])
@pytest.mark.parametrize("slave", ["top", "bottom"])
@pytest.mark.parametrize(
    "ratio",
    [f"1:{k}" for k in range(1, 11)] + [f"{k}:1" for k in range(2, 11)] + ["3:10", "10:3", "7:9"],
)
def test_patch_test_mesh_ratio_full(ratio, slave, cell_type):
    check_patch_summary(patch_demo(ratio, slave, "--cell-type", cell_type))


@pytest.mark.slow
@pytest.mark.parametrize(
    "options",
    [
        ["--multipliers", "standard"],
        ["--normals", "slave"],
        ["--normals", "master"],
        ["--active-set", "fixed-point"],
        ["--method", "augmented"],
    ],
)
@pytest.mark.parametrize("ratio,slave", [("1:10", "top"), ("1:10", "bottom")])
def test_patch_test_mesh_ratio_options(ratio, slave, options):
    # (the demo's --material neo-hookean is no exact patch test: its corner condition uses
    # the small-strain lateral strain; case 6 runs the exact Neo-Hookean one)
    check_patch_summary(patch_demo(ratio, slave, *options))


# ----------------------------------------------------------------------------------------
# 6. aligned nodes and tiny overlaps


def check_aligned(ratio, slave, material, shift, cell_type="triangle", tolerance=1e-10):
    setup = common.patch_traction(
        ratio=ratio, slave=slave, material=material, cell_type=cell_type, punch_shift=shift
    )
    outcome = setup.solve()
    strain = setup.info["strain_xx"]
    setup.destroy()
    # the multiplier is a force per current length: p / a with a = 1 + lateral strain
    expected = (
        common.PATCH_PRESSURE / (1.0 + strain) if material != "linear" else common.PATCH_PRESSURE
    )
    deviation = float(np.max(np.abs(outcome.pressure / expected - 1.0)))
    record_outcome(
        6,
        outcome,
        error=deviation,
        active=outcome.active,
        shift=shift,
    )
    assert outcome.converged and not outcome.nan
    assert outcome.active == outcome.pressure.size  # every slave node in contact
    assert deviation <= tolerance
    assert outcome.force_balance <= 1e-12


@pytest.mark.parametrize("shift", [0.0, 1e-14, -1e-14])
@pytest.mark.parametrize("material", ["linear", "neo-hookean"])
@pytest.mark.parametrize("slave", ["top", "bottom"])
@pytest.mark.parametrize("ratio", [(1, 1), (2, 2)])
def test_aligned_nodes_and_tiny_overlaps(ratio, slave, material, shift):
    check_aligned(ratio, slave, material, shift)


@pytest.mark.slow
@pytest.mark.parametrize("shift", [0.0, 1e-15, -1e-15, 1e-14, -1e-14, 1e-12, -1e-12])
@pytest.mark.parametrize("cell_type", ["triangle", "quadrilateral"])
@pytest.mark.parametrize("material", ["linear", "neo-hookean"])
@pytest.mark.parametrize("slave", ["top", "bottom"])
@pytest.mark.parametrize("ratio", [(1, 1), (2, 2), (3, 3), (4, 4), (2, 4), (4, 2)])
def test_aligned_nodes_and_tiny_overlaps_full(ratio, slave, material, cell_type, shift):
    """(2, 4) and (4, 2): every second node aligned. A shift of 1e-12 leaves a slave end
    uncovered by 1e-12, which moves its pressure by O(1e-12) (still within 1e-10)."""
    check_aligned(ratio, slave, material, shift, cell_type)
