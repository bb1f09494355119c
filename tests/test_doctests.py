"""The examples in the docstrings of the small public functions run and give what they show.

Each module listed here has at least one ``>>>`` example (materials' Lame parameters,
normals and search on numpy arrays, the monolithic layout's index maps, the mesh
builders' size helpers, a solver reason in words); a failing example fails the suite.
"""

from __future__ import annotations

import doctest
import importlib

import pytest

MODULES = ("materials", "normals", "search", "layout", "meshes", "meshes3d", "diagnostics")


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    module = importlib.import_module(f"dolfinx_mortar.{name}")
    result = doctest.testmod(module, optionflags=doctest.NORMALIZE_WHITESPACE, report=True)
    assert result.attempted > 0, f"{module.__name__} has no examples"
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples failed"
