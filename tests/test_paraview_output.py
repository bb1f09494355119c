"""The demos' ParaView files (VTX, ADIOS2 BP) read back: the fields, time steps and values
written are the ones computed.

Serial only: one ADIOS2 block per variable, so the file's points are the rank's nodes.
Debian's ADIOS2 Python package loads its serial bindings unless it sees mpirun, while
dolfinx links the MPI library; ADIOS2_ALWAYS_USE_MPI makes it load the MPI ones.
"""

from __future__ import annotations

import importlib.util
import os
import pathlib
import xml.etree.ElementTree as ElementTree

os.environ.setdefault("ADIOS2_ALWAYS_USE_MPI", "1")

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from mpi4py import MPI  # noqa: E402

adios2 = pytest.importorskip("adios2")

DEMOS = pathlib.Path(__file__).parents[1] / "demos"

POINT_ARRAYS_OF_VTX = {"TIME", "vtkOriginalPointIds", "vtkGhostType"}


def load(name: str):
    spec = importlib.util.spec_from_file_location(f"paraview_demo_{name}", DEMOS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def read_vtx(path) -> dict:
    """Fields, times and per-step point data of a VTX file written by dolfinx.

    Returns:
        {"fields": names of the point fields, "times": one per step,
        "geometry": [steps of (N, 3) arrays], name: [steps of (N, components) arrays]}.
    """
    with adios2.FileReader(str(path)) as reader:
        text = reader.read_attribute_string("vtk.xml")
        xml = ElementTree.fromstring(text if isinstance(text, str) else text[0])
        arrays = xml.findall("./UnstructuredGrid/Piece/PointData/DataArray")
        time_name = next(a.text.strip() for a in arrays if a.get("Name") == "TIME")
        fields = [a.get("Name") for a in arrays if a.get("Name") not in POINT_ARRAYS_OF_VTX]
        steps = reader.num_steps()
        data: dict = {"fields": fields, "times": [], "geometry": []}
        for name in fields:
            data[name] = []
        for step in range(steps):
            selection = [step, 1]
            time = reader.read(time_name, step_selection=selection)
            data["times"].append(float(np.ravel(time)[0]))
            data["geometry"].append(reader.read("geometry", step_selection=selection))
            for name in fields:
                values = reader.read(name, step_selection=selection)
                data[name].append(values.reshape(len(data["geometry"][-1]), -1))
    return data


def sorted_rows(points: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Rows (x, y, values...) in lexicographic order: a point set with its values, free of
    node numbering (bodies that touch have distinct nodes at equal coordinates)."""
    rows = np.column_stack([points[:, :2], values])
    return rows[np.lexsort(rows.T[::-1])]


class Capture:
    """Wraps a demo module's ContactProblem and solve_load_steps to keep what they computed."""

    def __init__(self, module):
        self.module = module
        self.state: dict = {}
        self.loads: list[float] | None = None

    def __enter__(self):
        module, state = self.module, self.state
        self.original = module.ContactProblem, getattr(module, "solve_load_steps", None)

        class Recording(module.ContactProblem):
            def destroy(self):
                V = self.u.function_space
                state["points"] = V.tabulate_dof_coordinates()
                state["u"] = self.u.x.array.reshape(-1, 2).copy()
                state["pressure"] = self.pressure_function().x.array.copy()
                state["multiplier"] = self.pressure_function(raw=True).x.array.copy()
                state["pressure_points"] = (
                    self.pressure_function().function_space.tabulate_dof_coordinates()
                )
                super().destroy()

        module.ContactProblem = Recording
        if self.original[1] is not None:
            solve = self.original[1]

            def recorded(*args, **kwargs):
                records = solve(*args, **kwargs)
                self.loads = [r.load for r in records]
                return records

            module.solve_load_steps = recorded
        return self

    def __exit__(self, *exc):
        self.module.ContactProblem = self.original[0]
        if self.original[1] is not None:
            self.module.solve_load_steps = self.original[1]


def check_contact_output(directory, state, times):
    displacement = read_vtx(directory / "displacement.bp")
    pressure = read_vtx(directory / "contact_pressure.bp")
    assert displacement["fields"] == ["displacement"]
    assert pressure["fields"] == ["contact_pressure", "contact_multiplier"]
    for data in (displacement, pressure):
        assert data["times"] == pytest.approx(times, rel=1e-14, abs=0.0)
        assert len(data["geometry"]) == len(times)
    # last step: the file's values at its points are the computed ones at theirs
    u = displacement["displacement"][-1]
    assert u.shape[1] == 3 and np.all(u[:, 2] == 0.0)
    last = sorted_rows(displacement["geometry"][-1], u[:, :2])
    computed = sorted_rows(state["points"], state["u"])
    np.testing.assert_array_equal(last, computed)
    for name, key in (("contact_pressure", "pressure"), ("contact_multiplier", "multiplier")):
        written = sorted_rows(pressure["geometry"][-1], pressure[name][-1])
        computed = sorted_rows(state["pressure_points"], state[key])
        np.testing.assert_array_equal(written, computed)
        assert computed[:, 2].max() > 0.0  # the pressure is not all zero
    # each step written, not the last one repeated
    if len(times) > 1:
        first = sorted_rows(displacement["geometry"][0], displacement["displacement"][0][:, :2])
        assert np.abs(first[:, 2:] - last[:, 2:]).max() > 0.0


def test_hertz_paraview_output_holds_every_load_step(tmp_path):
    module = load("hertz")
    with Capture(module) as capture:
        summary = module.main(
            ["--refinement", "0", "--steps", "3", "--output", str(tmp_path)], comm=MPI.COMM_SELF
        )
    assert capture.loads == pytest.approx([1 / 3, 2 / 3, 1.0], rel=1e-14)
    assert len(summary["newton_iterations"]) == 3
    check_contact_output(tmp_path / "paraview", capture.state, capture.loads)


def test_patch_test_paraview_output_holds_the_solution(tmp_path):
    module = load("patch_test")
    with Capture(module) as capture:
        module.main(["--ratio", "3:7", "--output", str(tmp_path)], comm=MPI.COMM_SELF)
    check_contact_output(tmp_path / "paraview", capture.state, [1.0])
    # the exact solution: contact pressure 10 on the slave surface
    pressure = capture.state["pressure"]
    assert np.abs(pressure[pressure > 0] - 10.0).max() <= 1e-9


def test_mesh_tying_paraview_output_is_the_exact_linear_field(tmp_path):
    """``--solution linear`` is reproduced exactly: the file must hold it at its points."""
    load("mesh_tying").main(
        ["--refinements", "2", "--solution", "linear", "--output", str(tmp_path)],
        comm=MPI.COMM_SELF,
    )
    data = read_vtx(tmp_path / "paraview" / "displacement.bp")
    assert data["fields"] == ["displacement"]
    assert data["times"] == [0.0]
    x, y = data["geometry"][0][:, 0], data["geometry"][0][:, 1]
    exact = np.column_stack([0.1 + 0.2 * x - 0.3 * y, -0.05 + 0.15 * x + 0.25 * y])
    u = data["displacement"][0]
    assert len(x) > 50
    assert np.abs(u[:, :2] - exact).max() <= 1e-10
