"""Every demo runs in a small configuration, and N ranks give the serial answer to 1e-8.

Under ``make test`` these run serially and under ``mpirun -n 2`` and ``-n 3``
(marker ``parallel``); each rank also computes the serial answer on
COMM_SELF, so the comparison happens inside one run. pytest-timeout turns a
hang into a failure.
"""

from __future__ import annotations

import importlib.util
import json
import math
import pathlib

import pytest
from mpi4py import MPI

DEMOS = pathlib.Path(__file__).parents[1] / "demos"

CONFIGURATIONS = {
    "hertz": (
        ["--refinement", "0", "--steps", "2"],
        ["p_max", "a_contact", "total_force", "l2_pressure_error_rel", "newton_iterations"],
    ),
    "patch_test": (
        ["--ratio", "3:7", "--slave", "bottom"],
        ["max_pressure_deviation_rel", "pressure_max", "newton_iterations"],
    ),
    "ironing": (
        ["--steps", "20", "--end-time", "0.3"],
        ["steps_completed", "newton_iterations", "max_force_balance_rel"],
    ),
    "mesh_tying": (["--refinements", "3"], ["l2_rate", "h1_rate", "max_l2_error"]),
}


def load(name: str):
    spec = importlib.util.spec_from_file_location(f"demo_{name}", DEMOS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def assert_close(serial, parallel, key, tolerance=1e-8):
    if isinstance(serial, list):
        assert len(serial) == len(parallel), key
        for a, b in zip(serial, parallel, strict=True):
            assert_close(a, b, key, tolerance)
    elif isinstance(serial, int | float):
        scale = max(abs(serial), 1e-300)
        assert math.isclose(serial, parallel, rel_tol=tolerance, abs_tol=tolerance * scale) or abs(
            serial - parallel
        ) <= tolerance * max(1.0, scale), (key, serial, parallel)
    else:
        assert serial == parallel, key


@pytest.mark.parallel
@pytest.mark.timeout(600)
@pytest.mark.parametrize("name", sorted(CONFIGURATIONS))
def test_demo_serial_equals_parallel(name, tmp_path_factory):
    args, keys = CONFIGURATIONS[name]
    module = load(name)
    serial = module.main(list(args), comm=MPI.COMM_SELF)
    parallel = module.main(list(args), comm=MPI.COMM_WORLD)
    json.dumps(parallel)  # the summary is JSON-serialisable
    for key in keys:
        assert_close(serial[key], parallel[key], key)


def test_demo_outputs(tmp_path):
    """JSON, PNG and ParaView files where the options say."""
    output = tmp_path / "hertz"
    load("hertz").main(
        [
            "--refinement",
            "0",
            "--steps",
            "1",
            "--output",
            str(output),
            "--json",
            str(output / "summary.json"),
        ],
        comm=MPI.COMM_SELF,
    )
    summary = json.loads((output / "summary.json").read_text())
    for key in (
        "p_max",
        "a_contact",
        "total_force",
        "p0_exact",
        "a_exact",
        "l2_pressure_error_rel",
        "newton_iterations",
        "num_dofs",
        "wall_time_s",
        "timings",
    ):
        assert key in summary
    assert (output / "hertz_pressure.png").stat().st_size > 1000
    assert (output / "paraview" / "displacement.bp").exists()
    assert (output / "paraview" / "contact_pressure.bp").exists()
    iron = tmp_path / "ironing"
    load("ironing").main(
        ["--steps", "40", "--end-time", "0.3", "--output", str(iron)], comm=MPI.COMM_SELF
    )
    assert (iron / "ironing_forces.csv").read_text().count("\n") >= 3
    assert (iron / "ironing_forces.png").stat().st_size > 1000


@pytest.mark.parallel
def test_ironing_die_top_reaction_equals_contact_force():
    """The die is in equilibrium: the force of the drive on its top (the bulk residual
    summed over the die-top nodes) is the contact force of the die on the block."""
    summary = load("ironing").main(["--steps", "20", "--end-time", "0.4"])
    pressing = [h for h in summary["history"] if h["t"] >= 0.3]
    assert pressing and all(h["active"] > 0 and h["die_top_force_y"] < 0.0 for h in pressing)
    assert -pressing[-1]["die_top_force_y"] > 1e7
    assert summary["max_reaction_mismatch_rel"] <= 1e-8
