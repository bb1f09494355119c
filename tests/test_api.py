"""The curated top level and the options: what users import and pass.

The names users need import from ``dolfinx_mortar`` itself (the kernels still import
without dolfinx); the options are frozen and Literal-typed, friction laws are small
dataclasses; the old spellings (import paths that moved, friction tuples,
``multipliers=``, ``enforcement.Solver``) keep working for one release with a
DeprecationWarning that names the user's line.
"""

from __future__ import annotations

import dataclasses
import inspect
import os
import pathlib
import subprocess
import sys
import typing
import warnings

import pytest

import dolfinx_mortar
from dolfinx_mortar import ContactOptions, Coulomb, Tresca
from dolfinx_mortar.options import contact_options

REPOSITORY = pathlib.Path(__file__).parents[1]


def test_the_entry_points_import_from_the_top_level():
    from dolfinx_mortar import (  # noqa: F401
        ContactPair,
        ContactProblem,
        Material,
        merge_meshes,
        solve_load_steps,
    )
    from dolfinx_mortar.problem import ContactProblem as defined

    assert ContactProblem is defined
    for name in dolfinx_mortar.__all__:
        assert getattr(dolfinx_mortar, name) is not None
    assert set(dolfinx_mortar.__all__) <= set(dir(dolfinx_mortar))
    assert dolfinx_mortar.__doc__.index("ContactProblem") < dolfinx_mortar.__doc__.index(
        "MortarInterface")


def test_the_kernels_and_the_options_import_without_dolfinx():
    code = ("import sys; import dolfinx_mortar.kernels, dolfinx_mortar.dual; "
            "from dolfinx_mortar import ContactOptions, Coulomb, Tresca; "
            "assert 'dolfinx' not in sys.modules, sorted(sys.modules)")
    environment = dict(os.environ, PYTHONPATH=str(REPOSITORY))
    subprocess.run([sys.executable, "-c", code], check=True, env=environment,
                   cwd=REPOSITORY)


def test_options_are_frozen_and_their_choices_literal_typed():
    options = ContactOptions(method="penalty", friction=Coulomb(0.2))
    with pytest.raises(dataclasses.FrozenInstanceError):
        options.method = "lagrange"
    hints = typing.get_type_hints(ContactOptions)
    literal = {name for name, hint in hints.items() if typing.get_origin(hint) is typing.Literal}
    assert literal == {"method", "integration", "normals", "active_set", "basis",
                       "configuration", "linear_solver", "slave_side"}
    for name in literal:
        allowed = typing.get_args(hints[name])
        assert getattr(ContactOptions(), name) in allowed
        with pytest.raises(ValueError, match=f"unknown {name} 'nonsense'; expected one of"):
            ContactOptions(**{name: "nonsense"})
    assert ContactOptions(friction=[Coulomb(0.1), None]).friction == (Coulomb(0.1), None)
    assert ContactOptions(friction=[Coulomb(0.1), None]).friction_laws(2)[1] is None
    assert (Coulomb(0.3).kind, Coulomb(0.3).value) == ("coulomb", 0.3)
    assert (Tresca(2.0).kind, Tresca(2.0).value) == ("tresca", 2.0)


def test_friction_tuples_are_deprecated_and_mean_the_laws():
    with pytest.warns(DeprecationWarning, match=r"pass Coulomb\(0.2\)") as caught:
        options = ContactOptions(friction=("coulomb", 0.2))
    assert options.friction == Coulomb(0.2)
    assert all(w.filename == __file__ for w in caught)
    with pytest.warns(DeprecationWarning, match=r"pass Tresca\(1.5\)"):
        options = ContactOptions(friction=[("tresca", 1.5), None])
    assert options.friction == (Tresca(1.5), None)


def test_multipliers_is_the_deprecated_name_of_basis():
    with pytest.warns(DeprecationWarning, match="multipliers= is deprecated") as caught:
        options = contact_options(None, {"multipliers": "standard"})
    assert options.basis == "standard"
    assert all(w.filename == __file__ for w in caught)
    with pytest.raises(TypeError, match="basis= only"):
        contact_options(None, {"multipliers": "standard", "basis": "dual"})
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert contact_options(ContactOptions(method="penalty"), {"basis": "standard"}) == \
            ContactOptions(method="penalty", basis="standard")


@pytest.mark.parametrize("module, name, now", [
    ("dolfinx_mortar.problem", "SolveReport", "dolfinx_mortar.solvers"),
    ("dolfinx_mortar.problem", "ContactWarning", "dolfinx_mortar.diagnostics"),
    ("dolfinx_mortar.problem", "INITIAL_OVERLAP", "dolfinx_mortar.checks"),
    ("dolfinx_mortar.problem", "STIFF_SLAVE_RATIO", "dolfinx_mortar.checks"),
])
def test_names_that_moved_still_import_with_a_warning(module, name, now):
    import importlib

    with pytest.warns(DeprecationWarning, match=f"{module}.{name} is deprecated"):
        old = getattr(importlib.import_module(module), name)
    assert old is getattr(importlib.import_module(now), name)


def test_the_enforcement_protocol_has_a_public_name():
    from dolfinx_mortar import enforcement

    with pytest.warns(DeprecationWarning, match="use dolfinx_mortar.enforcement.NewtonSolver"):
        assert enforcement.Solver is enforcement.NewtonSolver
    public = [name for name in dir(enforcement.NewtonSolver) if not name.startswith("_")]
    assert {"newton", "nodal_gaps", "update_contact"} <= set(public)


def test_slave_marker_is_the_deprecated_name_of_slave(tmp_path):
    """MortarInterface and MeshTying take ``slave=`` and ``master=`` as ContactPair does;
    the old keywords still work with a warning at the caller's line."""
    import dolfinx
    import numpy as np
    from mpi4py import MPI

    from dolfinx_mortar import MeshTying, MortarInterface

    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 2, 2)
    fdim = mesh.topology.dim - 1
    left = dolfinx.mesh.locate_entities_boundary(mesh, fdim, lambda x: np.isclose(x[0], 0.0))
    right = dolfinx.mesh.locate_entities_boundary(mesh, fdim, lambda x: np.isclose(x[0], 1.0))
    facets = np.concatenate([left, right])
    order = np.argsort(facets)
    values = np.concatenate([np.full(left.size, 1), np.full(right.size, 2)]).astype(np.int32)
    tags = dolfinx.mesh.meshtags(mesh, fdim, facets[order], values[order])
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    by_name = MortarInterface(V, tags, slave=1, master=2)
    with pytest.warns(DeprecationWarning, match="(slave|master)_marker= is deprecated") as caught:
        old = MortarInterface(V, tags, slave_marker=1, master_marker=2)
    assert all(w.filename == __file__ for w in caught)
    assert np.array_equal(old.slave.facets, by_name.slave.facets)
    assert np.array_equal(old.master.facets, by_name.master.facets)
    with pytest.raises(TypeError, match="pass slave= only"):
        MortarInterface(V, tags, slave=1, slave_marker=1, master=2)
    signature = inspect.signature(MeshTying.__init__)
    assert "slave" in signature.parameters and "slave_marker" not in signature.parameters


def test_a_deprecation_reaches_the_screen_of_a_plain_script(tmp_path):
    """FFCx routes warnings to an unconfigured logger (logging.captureWarnings): a user's
    script must still see the deprecation on stderr, at its own line."""
    script = tmp_path / "user.py"
    script.write_text(
        "import ffcx  # noqa: F401 (captures warnings into logging)\n"
        "from dolfinx_mortar.options import contact_options\n"
        "contact_options(None, {'multipliers': 'standard'})\n")
    result = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                            check=True)
    assert f"{script}:3: DeprecationWarning: the option multipliers= is deprecated" in result.stderr
