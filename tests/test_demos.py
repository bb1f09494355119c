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

import numpy as np
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
    "friction_patch": (
        ["--ratio", "3:7", "--slave", "lower", "--shear-ratio", "2"],
        ["max_pressure_deviation_rel", "num_slipping", "newton_iterations"],
    ),
    "cattaneo_mindlin": (
        ["--refinement", "0", "--tangential-ratio", "0.7"],
        ["stick_half_width", "q_max", "l2_traction_error_rel", "total_tangential_force",
         "p_max", "newton_iterations"],
    ),
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


HELP_DEFAULTS = {
    "friction_patch": ["(default: 3:7)", "(default: upper)", "(default: 2.0)", "(default: 0.2)"],
    "cattaneo_mindlin": ["(default: 0.5)", "(default: 0.2)", "(default: master)"],
    "hertz": ["(default: B)", "(default: 8.0)", "(default: 2)"],
    "patch_test": ["(default: 3:2)", "(default: top)", "(default: lagrange)"],
    "ironing": ["(default: 500)", "(default: quadrilateral)", "(default: 2.0)",
                "(default: frictionless)", "None: averaged in 2D, slave in 3D"],
    "mesh_tying": [
        "(None: 5 in 2D, 4 in 3D)",
        "(None: 3:4 in 2D, 2:3 in 3D)",
        "(default: smooth)",
        "(default: 2)",
    ],
}


@pytest.mark.parametrize("name", sorted(CONFIGURATIONS))
def test_demo_help_shows_defaults_and_the_output_options(name, capsys):
    with pytest.raises(SystemExit) as exit_info:
        load(name).main(["--help"], comm=MPI.COMM_SELF)
    assert exit_info.value.code == 0
    text = " ".join(capsys.readouterr().out.split())
    for option in ("--output DIR", "--json FILE", *HELP_DEFAULTS[name]):
        assert option in text, option


@pytest.mark.parallel
@pytest.mark.timeout(600)
@pytest.mark.parametrize("cell", ["tetrahedron", "hexahedron"])
def test_mesh_tying_3d_serial_equals_parallel(cell):
    """Two 3D meshes, 2:3 and 4:6 elements per unit length: 3 (n + 1)^2 (round(n/2) + 1)
    displacements per box (3 (9 * 2 + 16 * 3) = 198, 3 (25 * 3 + 49 * 4) = 813) and one
    multiplier per slave node, 4^2 and 7^2; N ranks give the serial errors and rates."""
    args = ["--dim", "3", "--cell", cell, "--refinements", "2"]
    module = load("mesh_tying")
    serial = module.main(list(args), comm=MPI.COMM_SELF)
    parallel = module.main(list(args), comm=MPI.COMM_WORLD)
    json.dumps(parallel)
    for summary in (serial, parallel):
        assert [r["num_dofs"] for r in summary["runs"]] == [198, 813]
        assert [r["num_multipliers"] for r in summary["runs"]] == [16, 49]
    for key in ("l2_rate", "h1_rate", "max_l2_error", "max_h1_error"):
        assert_close(serial[key], parallel[key], key)


@pytest.mark.parallel
@pytest.mark.parametrize("basis", ["standard", "dual"])
@pytest.mark.parametrize("cell", ["tetrahedron", "hexahedron"])
def test_mesh_tying_3d_reproduces_a_linear_field(cell, basis):
    """The demo's 3D patch test: P1 reproduces a linear field, so the tied solution is exact."""
    summary = load("mesh_tying").main(
        [
            *("--dim", "3", "--cell", cell, "--basis", basis),
            *("--solution", "linear", "--refinements", "2", "--ratio", "3:4"),
        ]
    )
    assert summary["max_l2_error"] < 1e-12
    assert summary["max_h1_error"] < 1e-11


@pytest.mark.parametrize(
    "option",
    [
        ["--dim", "3", "--cell", "triangle"],
        ["--cell-type", "hexahedron"],
        ["--dim", "3", "--ratio", "0:3"],
    ],
)
def test_mesh_tying_demo_rejects_bad_3d_input(option, capsys):
    """A cell of the other dimension or an empty block is a usage error, not a traceback."""
    with pytest.raises(SystemExit) as exit_info:
        load("mesh_tying").main(option, comm=MPI.COMM_SELF)
    assert exit_info.value.code == 2
    assert option[-2] in capsys.readouterr().err


@pytest.mark.parametrize(
    "option", [["--load", "-1"], ["--E-block", "0"], ["--radius", "nan"], ["--nu-block", "0.5"]]
)
def test_hertz_demo_rejects_bad_physical_input(option, capsys):
    with pytest.raises(SystemExit) as exit_info:
        load("hertz").main(option, comm=MPI.COMM_SELF)
    assert exit_info.value.code == 2
    assert option[0] in capsys.readouterr().err


def hertz_in_units(length: float, modulus: float, case: str) -> dict:
    """The demo's Hertz case with lengths times ``length`` and moduli times ``modulus``:
    the force per unit thickness scales like modulus x length."""
    E_block = {"A": 2e12, "B": 200.0, "C": 200.0}[case]
    load_ = {"A": 3.2032, "B": 10.0, "C": 10.0}[case]
    return load("hertz").main(
        [
            *("--case", case, "--refinement", "0", "--steps", "2"),
            *("--radius", repr(8.0 * length), "--load", repr(load_ * modulus * length)),
            *("--E-cylinder", repr(200.0 * modulus), "--E-block", repr(E_block * modulus)),
        ],
        comm=MPI.COMM_SELF,
    )


@pytest.mark.parametrize("case", ["B", "C"])
def test_hertz_demo_is_scale_free(case):
    """The same dimensionless Hertz problem in two unit systems (lengths x 1e3, moduli
    x 1e-6, force x 1e-3) gives the same p_max / p0 and a / a_exact (measured: equal to
    2e-15), and the mesh scales with the lengths: its refined zone follows the Hertz a."""
    base = hertz_in_units(1.0, 1.0, case)
    scaled = hertz_in_units(1e3, 1e-6, case)
    assert scaled["a_exact"] == pytest.approx(1e3 * base["a_exact"], rel=1e-12)
    assert scaled["h_contact"] == pytest.approx(1e3 * base["h_contact"], rel=1e-12)
    assert scaled["num_dofs"] == base["num_dofs"]
    for key, exact in (("p_max", "p0_exact"), ("a_contact", "a_exact")):
        ratios = [summary[key] / summary[exact] for summary in (base, scaled)]
        assert ratios[1] == pytest.approx(ratios[0], rel=1e-6, abs=0.0), key
    assert scaled["newton_iterations"] == base["newton_iterations"]


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
    rows = [line.split(",") for line in (iron / "ironing_forces.csv").read_text().splitlines()]
    assert rows[0][:3] == ["t", "newton_iterations", "active"] and len(rows) >= 4
    assert all(len(row) == len(rows[0]) for row in rows)
    float_cells = np.array(rows[1:], dtype=float)  # one number a cell (no per-step lists)
    assert float_cells[-1, 0] == pytest.approx(0.3)
    assert (iron / "ironing_forces.png").stat().st_size > 1000
    assert (iron / "paraview" / "displacement.bp").exists()
    profile = (output / "hertz_pressure.csv").read_text().splitlines()
    assert profile[0] == "x,pressure,pressure_hertz"
    assert len(profile) == 1 + summary["num_slave_nodes"]

    patch = tmp_path / "patch"
    load("patch_test").main(
        ["--ratio", "3:7", "--output", str(patch), "--json", str(patch / "patch.json")],
        comm=MPI.COMM_SELF,
    )
    assert "max_pressure_deviation_rel" in json.loads((patch / "patch.json").read_text())
    assert (patch / "patch_test_pressure.png").stat().st_size > 1000
    assert (patch / "paraview" / "displacement.bp").exists()
    assert (patch / "paraview" / "contact_pressure.bp").exists()

    tying = tmp_path / "tying"
    summary = load("mesh_tying").main(
        ["--refinements", "2", "--output", str(tying), "--json", str(tying / "tying.json")],
        comm=MPI.COMM_SELF,
    )
    assert json.loads((tying / "tying.json").read_text())["runs"] == summary["runs"]
    rows = (tying / "mesh_tying_errors.csv").read_text().splitlines()
    assert rows[0].split(",")[:2] == ["refinement", "h"] and len(rows) == 3
    assert (tying / "mesh_tying_convergence.png").stat().st_size > 1000
    assert (tying / "paraview" / "displacement.bp").exists()

    tying3d = tmp_path / "tying3d"
    load("mesh_tying").main(
        [
            *("--dim", "3", "--refinements", "2"),
            *("--output", str(tying3d), "--json", str(tying3d / "tying.json")),
        ],
        comm=MPI.COMM_SELF,
    )
    summary = json.loads((tying3d / "tying.json").read_text())
    assert summary["dim"] == 3 and summary["cell_type"] == "tetrahedron"
    assert {"l2_rate", "h1_rate", "max_l2_error"} <= set(summary)
    rows = (tying3d / "mesh_tying_errors.csv").read_text().splitlines()
    assert rows[0].split(",")[:2] == ["refinement", "h"] and len(rows) == 3
    assert (tying3d / "mesh_tying_convergence.png").stat().st_size > 1000
    assert (tying3d / "paraview" / "displacement.bp").exists()


@pytest.mark.parallel
def test_ironing_die_top_reaction_equals_contact_force():
    """The die is in equilibrium: the force of the drive on its top (the bulk residual
    summed over the die-top nodes) is the contact force of the die on the block."""
    summary = load("ironing").main(["--steps", "20", "--end-time", "0.4"])
    pressing = [h for h in summary["history"] if h["t"] >= 0.3]
    assert pressing and all(h["active"] > 0 and h["die_top_force_y"] < 0.0 for h in pressing)
    assert -pressing[-1]["die_top_force_y"] > 1e7
    assert summary["max_reaction_mismatch_rel"] <= 1e-8
