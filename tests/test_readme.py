"""Every ```python block of README.md runs as shown and gives the answers the README states.

Each block is a complete script, executed in-process (exec) in a fresh namespace, inside a
directory that is the same on every rank (the examples write ParaView files with
collective writers). The test is marked ``parallel``: ``make test`` runs it serially and
under ``mpirun -n 2`` and ``-n 3``. With more than one rank, a block that sets
``comm = MPI.COMM_WORLD`` is run a second time with ``comm = MPI.COMM_SELF`` on every
rank (each in its own directory), and its contact results must equal the parallel ones.

Known answers checked on the executed namespace: the contact forces on the two sides
balance; the traction example's contact force equals its load; the driven body's contact
force (the punch's in 2D, the cube's in 3D) balances the reaction at its prescribed top,
summed here independently of ``reaction_force`` and compared with it; in the 3D example's
slip phase every active node slips with a friction traction of mu times its pressure, and
``friction_state`` has ``contact_pressure``'s rows. A block that raises fails the test
with its line number in README.md.
"""

from __future__ import annotations

import logging
import os
import pathlib
import re
import shutil
import tempfile
import traceback

import dolfinx
import numpy as np
import pytest
from mpi4py import MPI

README = pathlib.Path(__file__).parents[1] / "README.md"
WORLD_LINE = "comm = MPI.COMM_WORLD"
LOGGER = logging.getLogger("dolfinx_mortar")


def python_blocks() -> list[tuple[int, str]]:
    """(line of the first code line in README.md, source) of every ```python block."""
    lines = README.read_text().splitlines()
    blocks, start = [], None
    for number, line in enumerate(lines, start=1):
        if start is None and re.fullmatch(r"```python\s*", line):
            start = number + 1
        elif start is not None and line.strip() == "```":
            blocks.append((start, "\n".join(lines[start - 1 : number - 1]) + "\n"))
            start = None
    assert start is None, f"README.md: the ```python block opened at line {start - 1} never closes"
    return blocks


BLOCKS = python_blocks()


def test_readme_has_the_examples():
    """The README keeps its two complete examples (so the checks below have work to do)."""
    sources = [source for _, source in BLOCKS]
    assert any("meshes.hertz(" in s and "traction" in s for s in sources)
    assert any("merge_meshes(" in s and "top_displacement" in s for s in sources)
    assert any("create_box(" in s and "reaction_force(" in s and "Coulomb(" in s for s in sources)
    fences = re.findall(r"^```(\w*)\s*$", README.read_text(), flags=re.MULTILINE)
    openings = fences[0::2]
    assert all(lang in ("python", "sh", "text") for lang in openings), (
        "README.md: code blocks must be ```python (run by this test), ```sh or ```text "
        f"(program output): {openings}"
    )


def shared_directory(comm: MPI.Intracomm) -> pathlib.Path:
    """A new directory, the same path on every rank (made by rank 0)."""
    path = tempfile.mkdtemp(prefix="readme-") if comm.rank == 0 else None
    return pathlib.Path(comm.bcast(path, root=0))


def run_block(line: int, source: str, directory: pathlib.Path) -> dict:
    """Execute one README block in ``directory``; its namespace, or a failure naming the
    block's line (tracebacks point at README.md's own line numbers)."""
    code = compile("\n" * (line - 1) + source, str(README), "exec")
    namespace = {"__name__": "__main__"}
    cwd = os.getcwd()
    handlers = list(LOGGER.handlers)  # configure_logging adds one; keep ranks' logs as they were
    os.chdir(directory)
    try:
        exec(code, namespace)
    except Exception as error:
        pytest.fail(
            f"README.md: the python block at line {line} raised "
            f"{type(error).__name__}: {error}\n{traceback.format_exc()}",
            pytrace=False,
        )
    finally:
        os.chdir(cwd)
        LOGGER.handlers[:] = handlers
    return namespace


def contact_problems(namespace: dict) -> list:
    from dolfinx_mortar import ContactProblem

    return [value for value in namespace.values() if isinstance(value, ContactProblem)]


def results(namespace: dict) -> dict[str, np.ndarray]:
    """What must not depend on the number of ranks (collective calls)."""
    out = {}
    for k, problem in enumerate(contact_problems(namespace)):
        slave, master = problem.contact_forces()
        coordinates, pressure = problem.gathered_pressure()
        out[f"problem {k} slave force"] = slave
        out[f"problem {k} master force"] = master
        out[f"problem {k} pressure"] = pressure
        out[f"problem {k} slave nodes"] = coordinates
        out[f"problem {k} active"] = np.array([problem.num_active()], dtype=float)
    return out


def check_known_answers(line: int, namespace: dict) -> None:
    where = f"README.md block at line {line}"
    for problem in contact_problems(namespace):
        slave, master = problem.contact_forces()
        assert np.linalg.norm(slave) > 0, f"{where}: no contact force at all"
        balance = np.linalg.norm(slave + master) / np.linalg.norm(slave)
        assert balance < 1e-9, f"{where}: slave {slave} and master {master} forces do not balance"
    if "traction" in namespace and "load" in namespace:
        # the cylinder's equilibrium: contact force = applied load (symmetry lines: u_x only)
        slave, _ = namespace["problem"].contact_forces()
        load = namespace["load"]
        assert abs(slave[1] - load) <= 1e-8 * load, (
            f"{where}: contact force {slave} on the cylinder against the load {load}"
        )
    if "top_displacement" in namespace:
        check_punch_reaction(where, namespace)
    if namespace.get("problem") is not None and namespace["problem"].has_friction:
        check_slip(where, namespace)


def check_punch_reaction(where: str, namespace: dict) -> None:
    """The driven body's equilibrium: the bulk residual summed over its prescribed top (the
    drive's reaction) plus the contact force on the body is zero; ``reaction_force`` gives
    the same sum."""
    from dolfinx_mortar.reactions import reaction_force

    problem, V = namespace["problem"], namespace["V"]
    slave, _ = problem.contact_forces()
    gdim = V.mesh.geometry.dim
    residual = dolfinx.fem.assemble_vector(dolfinx.fem.form(namespace["F"]))
    residual.scatter_reverse(dolfinx.la.InsertMode.add)
    top = namespace["top"]
    top = top[top < V.dofmap.index_map.size_local]
    reaction = problem.comm.allreduce(
        residual.array.reshape(-1, gdim)[top].sum(axis=0), op=MPI.SUM
    )
    assert reaction.shape == slave.shape == (gdim,)
    assert np.linalg.norm(reaction + slave) <= 1e-8 * np.linalg.norm(slave), (
        f"{where}: reaction {reaction} at the driven top against contact force {slave}"
    )
    markers, facet_tags = namespace["markers"], namespace["facet_tags"]
    name = next(n for n in ("punch_top", "cube_top") if n in markers)
    helper = reaction_force(problem, facet_tags, markers[name])
    assert np.linalg.norm(helper - reaction) <= 1e-12 * np.linalg.norm(reaction), (
        f"{where}: reaction_force {helper} against the residual's sum {reaction}"
    )
    if "reaction" in namespace:  # the block's own reaction_force call
        assert np.allclose(namespace["reaction"], helper, rtol=1e-12, atol=0.0)


def check_slip(where: str, namespace: dict) -> None:
    """After sliding, every active node slips with |y_j| = mu z_j, and friction_state's rows
    are contact_pressure's (coordinates and the multipliers, raw=True, equal row by row)."""
    problem, mu = namespace["problem"], namespace["mu"]
    state = problem.friction_state()
    coordinates, pressure = problem.contact_pressure(raw=True)
    assert np.array_equal(state["coordinates"], coordinates), f"{where}: rows differ"
    assert np.array_equal(state["pressure"], pressure), f"{where}: pressures differ"
    active = pressure > 0.0
    assert problem.comm.allreduce(int(np.count_nonzero(state["sticking"])), op=MPI.SUM) == 0
    assert np.all(state["slipping"] == active), f"{where}: an active node does not slip"
    traction = np.abs(state["traction"]) if state["traction"].ndim == 1 else np.linalg.norm(
        state["traction"], axis=1)
    assert np.allclose(traction[active], mu * pressure[active], rtol=1e-8, atol=0.0), (
        f"{where}: slipping nodes' friction traction is not mu times their pressure"
    )
    # the total force's ratio is mu up to the tilt of the deformed surface's normals
    slave, _ = problem.contact_forces()
    ratio = np.linalg.norm(slave[:-1]) / abs(slave[-1])
    assert abs(ratio - mu) <= 0.01 * mu, f"{where}: tangential / normal force {ratio}"


def destroy(namespace: dict) -> None:
    for problem in contact_problems(namespace):
        problem.destroy()


@pytest.mark.parallel
@pytest.mark.timeout(600)
@pytest.mark.parametrize("line, source", BLOCKS, ids=[f"line{line}" for line, _ in BLOCKS])
def test_readme_block(line, source):
    comm = MPI.COMM_WORLD
    directory = shared_directory(comm)
    try:
        namespace = run_block(line, source, directory)
        check_known_answers(line, namespace)
        if contact_problems(namespace):
            assert WORLD_LINE in source.splitlines(), (
                f"README.md block at line {line}: write `{WORLD_LINE}` and pass comm on, so "
                "that this test can compare the block with a serial run"
            )
        if contact_problems(namespace) and comm.size > 1:
            parallel = results(namespace)
            serial_dir = directory / f"serial-rank{comm.rank}"
            serial_dir.mkdir()
            serial_source = "\n".join(
                "comm = MPI.COMM_SELF" if s == WORLD_LINE else s for s in source.splitlines()
            )
            serial_namespace = run_block(line, serial_source + "\n", serial_dir)
            for problem in contact_problems(serial_namespace):
                assert problem.comm.size == 1, "the serial run must not use COMM_WORLD"
            serial = results(serial_namespace)
            destroy(serial_namespace)
            assert serial.keys() == parallel.keys()
            for key, value in serial.items():
                scale = max(float(np.max(np.abs(value), initial=0.0)), 1e-300)
                difference = float(np.max(np.abs(parallel[key] - value), initial=0.0))
                assert parallel[key].shape == value.shape and difference <= 1e-8 * scale, (
                    f"README.md block at line {line}: {key} on {comm.size} ranks differs from "
                    f"the serial run by {difference:.3g} (scale {scale:.3g})"
                )
        destroy(namespace)
    finally:
        comm.Barrier()
        if comm.rank == 0:
            shutil.rmtree(directory, ignore_errors=True)
