"""Mesh tying of non-matching meshes (demos/mesh_tying.py): patch test and rates."""

from __future__ import annotations

import importlib.util
import pathlib

import pytest

DEMO = pathlib.Path(__file__).parents[1] / "demos" / "mesh_tying.py"


def load_demo():
    spec = importlib.util.spec_from_file_location("mesh_tying_demo", DEMO)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parallel
@pytest.mark.parametrize("basis", ["standard", "dual"])
@pytest.mark.parametrize("cell_type", ["triangle", "quadrilateral"])
@pytest.mark.parametrize("ratio", ["3:4", "1:7", "5:2"])
def test_linear_field_is_reproduced(basis, cell_type, ratio):
    summary = load_demo().main(
        [
            "--solution",
            "linear",
            "--refinements",
            "2",
            "--ratio",
            ratio,
            "--basis",
            basis,
            "--cell-type",
            cell_type,
        ]
    )
    assert summary["max_l2_error"] < 1e-12
    assert summary["max_h1_error"] < 1e-11


@pytest.mark.parallel
@pytest.mark.parametrize("basis", ["standard", "dual"])
def test_optimal_convergence_rates(basis):
    summary = load_demo().main(
        ["--solution", "smooth", "--refinements", "5", "--ratio", "3:4", "--basis", basis]
    )
    assert summary["l2_rate_finest"] == pytest.approx(2.0, abs=0.1)
    assert summary["h1_rate_finest"] == pytest.approx(1.0, abs=0.1)
