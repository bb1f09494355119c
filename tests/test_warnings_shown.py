"""A ContactWarning reaches the user's screen: a plain script that imports dolfinx first
(FFCx then routes every warning to a logger that prints nothing) sees it on stderr,
once, however many ranks run it; a warnings filter set to "error" raises on every rank.

Each case runs a fresh Python process (serially, or under mpirun -n 2), so that nothing
pytest did to warnings or logging is in the way.
"""

from __future__ import annotations

import os
import pathlib
import re
import shutil
import subprocess
import sys

import pytest

REPOSITORY = pathlib.Path(__file__).parents[1]

# a cube whose slave tag is on its top, facing away from the block: the user's report
SCRIPT = """
import dolfinx
import logging
import sys
import warnings

import numpy as np
import ufl
from mpi4py import MPI

from dolfinx_mortar import (ContactPair, ContactProblem, ContactWarning, Material,
                            internal_work, merge_meshes)

mode = sys.argv[1]
if mode in ("captured", "logging"):
    logging.captureWarnings(True)  # what FFCx 0.9 does at import (trixie)
if mode == "logging":
    logging.basicConfig()
elif mode == "error":
    warnings.simplefilter("error", ContactWarning)
comm = MPI.COMM_WORLD
hexahedron = dolfinx.mesh.CellType.hexahedron
cube = dolfinx.mesh.create_box(comm, [[0.25, 0.25, 1.0], [0.75, 0.75, 1.5]], [2, 2, 1], hexahedron)
block = dolfinx.mesh.create_box(comm, [[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]], [3, 3, 1], hexahedron)
tagged = merge_meshes({
    "cube": (cube, {"top": lambda x: np.isclose(x[2], 1.5)}),
    "block": (block, {"top": lambda x: np.isclose(x[2], 1.0),
                      "bottom": lambda x: np.isclose(x[2], 0.0)})})
tags, markers = tagged.facet_tags, tagged.markers
V = dolfinx.fem.functionspace(tagged.mesh, ("Lagrange", 1, (3,)))
u = dolfinx.fem.Function(V)
F = internal_work(u, ufl.TestFunction(V), {0: Material(100.0, 0.3, "neo-hookean")})
bcs = [dolfinx.fem.dirichletbc(np.zeros(3), dolfinx.fem.locate_dofs_topological(
    V, 2, tags.find(markers[name])), V) for name in ("cube_top", "block_bottom")]
pair = ContactPair(tags, markers["cube_top"], markers["block_top"], name="cube-block")
try:
    problem = ContactProblem(F, u, bcs, [pair])
except ContactWarning:
    print(f"raised on rank {comm.rank}", flush=True)
else:
    problem.destroy()
    print(f"built on rank {comm.rank}", flush=True)
"""

WARNING = "ContactWarning: contact pair 'cube-block' (slave tag"


def run(tmp_path, mode: str, ranks: int) -> subprocess.CompletedProcess:
    script = tmp_path / "wrong_face.py"
    script.write_text(SCRIPT)
    command = [sys.executable, str(script), mode]
    if ranks > 1:
        if shutil.which("mpirun") is None:
            pytest.skip("no mpirun")
        command = ["mpirun", "-n", str(ranks), *command]
    # a child of this (singleton MPI) process must start as a new MPI job
    environment = {k: v for k, v in os.environ.items()
                   if not k.startswith(("OMPI_COMM_WORLD", "PMIX_", "PMI_", "OMPI_MCA_ess",
                                        "OMPI_MCA_orte", "OMPI_MCA_pmix", "PYTEST"))}
    environment["PYTHONPATH"] = os.pathsep.join(
        [str(REPOSITORY), *filter(None, [os.environ.get("PYTHONPATH")])])
    result = subprocess.run(command, capture_output=True, text=True, timeout=300,
                            env=environment, cwd=tmp_path)
    assert result.returncode == 0, result.stdout + result.stderr
    return result


@pytest.mark.parametrize("mode", ["plain", "captured"])
@pytest.mark.parametrize("ranks", [1, 2])
def test_the_warning_reaches_stderr_once(tmp_path, ranks, mode):
    """Whatever importing dolfinx did to warnings and logging ("plain"), and with warnings
    captured by an unconfigured logging module ("captured")."""
    result = run(tmp_path, mode, ranks)
    assert result.stderr.count(WARNING) == 1, result.stderr
    assert "looks away from its master" in result.stderr
    # it points at the user's line, not at the library
    assert f"wrong_face.py:{SCRIPT.count(chr(10), 0, SCRIPT.index('problem = Contact')) + 1}:" \
        in result.stderr
    assert sorted(re.findall(r"built on rank \d", result.stdout)) == [
        f"built on rank {r}" for r in range(ranks)]


def test_configured_logging_shows_it_once(tmp_path):
    """With warnings captured and logging configured by the user, the warning takes the
    logging path, once."""
    result = run(tmp_path, "logging", 1)
    assert result.stderr.count("looks away from its master") == 1, result.stderr
    assert "WARNING:py.warnings:" in result.stderr


@pytest.mark.parametrize("ranks", [1, 2])
def test_an_error_filter_raises_on_every_rank(tmp_path, ranks):
    result = run(tmp_path, "error", ranks)
    # mpirun may join the ranks' lines: find the words, not the lines
    assert sorted(re.findall(r"raised on rank \d", result.stdout)) == [
        f"raised on rank {r}" for r in range(ranks)]
    assert WARNING not in result.stderr
