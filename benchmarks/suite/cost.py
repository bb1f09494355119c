"""Section ``cost``: the contact share of a Newton iteration at >= 1e5 dofs, mortar time
against slave facets, the far-apart A/B and the run on 1 and 2 MPI ranks."""

from __future__ import annotations

import contextlib
import json
import os
import pathlib
import shlex
import subprocess
import sys
import time

from mpi4py import MPI

from .common import REPOSITORY, RUN, log, loglog_slope
from .far_apart import far_apart
from .runner import contact_share_record, hertz_runs, run_demo


def parallel_worker(refinement: int, repeats: int, path: pathlib.Path) -> None:
    """Under mpirun: the Hertz B demo (linear) at ``refinement``; rank 0 writes ``path``."""
    comm = MPI.COMM_WORLD
    run_demo("hertz", ["--case", "B", "--refinement", "0"], comm=comm)  # warm-up
    runs = hertz_runs(refinement, repeats, "linear", comm=comm, tag=f"parallel n={comm.size}")
    record = contact_share_record(runs, f"{comm.size} ranks")
    record.update(num_ranks=comm.size, p_max=runs[0]["p_max"], a_contact=runs[0]["a_contact"],
                  total_force=runs[0]["total_force"])
    if comm.rank == 0:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(record, indent=1))


def parallel_runs(refinement: int, repeats: int, ranks: list[int]) -> dict:
    """Start ``mpirun -n N python3 benchmarks/run.py --only parallel ...`` per N."""
    import tempfile

    results, commands = [], []
    scratch = pathlib.Path(tempfile.mkdtemp(prefix="dolfinx_mortar_parallel_"))
    env = dict(os.environ)
    for key in list(env):  # this process's singleton MPI must not leak into mpirun
        if key.startswith(("PMIX_", "OMPI_COMM_", "OMPI_MCA_orte_", "OMPI_FILE_LOCATION")):
            del env[key]
    for n in ranks:
        path = scratch / f"parallel_{n}.json"
        command = ["mpirun", "-n", str(n), sys.executable, str(RUN),
                   "--only", "parallel", "--worker-json", str(path),
                   "--parallel-refinement", str(refinement), "--repeats", str(repeats)]
        commands.append(shlex.join(["mpirun", "-n", str(n), "python3", "benchmarks/run.py"]
                                   + command[5:7] + ["--worker-json", f"parallel_{n}.json"]
                                   + command[9:]))
        log(f"[parallel] {shlex.join(command)}")
        start = time.perf_counter()
        completed = subprocess.run(command, env=env, cwd=REPOSITORY, capture_output=True,
                                   text=True)
        sys.stderr.write(completed.stderr)
        if completed.returncode != 0 or not path.exists():
            results.append({"num_ranks": n, "failed": True, "returncode": completed.returncode,
                            "error": completed.stderr[-2000:]})
            continue
        record = json.loads(path.read_text())
        path.unlink()
        record["process_wall_s"] = time.perf_counter() - start
        results.append(record)
    with contextlib.suppress(OSError):
        scratch.rmdir()
    ok = [r for r in results if not r.get("failed")]
    reference = next((r for r in ok if r["num_ranks"] == 1), None)
    for record in ok:
        if reference is not None:
            record["speedup_solve"] = reference["timings"]["total"] / record["timings"]["total"]
            record["speedup_wall"] = reference["wall_time_s"] / record["wall_time_s"]
            record["p_max_difference_rel"] = abs(record["p_max"] / reference["p_max"] - 1.0)
    return {"refinement": refinement, "repeats": repeats, "commands": commands, "runs": results}


def cost_of_contact(quick: bool, repeats: int, ranks: list[int],
                    big_refinement: int | None, far_apart_repeats: int | None = None) -> dict:
    """``repeats`` for every Hertz run (the scaling, the share and the ranks); the
    far-apart A/B takes at least 5 (3 quick): it measures a difference of a few %."""
    # mortar time against slave facets (Neo-Hookean: integrals in every iteration); the
    # last refinement is the first with >= 1e5 dofs (quick: 3)
    run_demo("hertz", ["--case", "B", "--refinement", "0", "--material", "neo-hookean"])
    scaling, runs_at = [], {}
    refinement = 0
    while True:
        runs = hertz_runs(refinement, repeats, "neo-hookean", tag="cost scaling")
        runs_at[refinement] = runs
        scaling.append(contact_share_record(runs, f"Neo-Hookean r{refinement}"))
        dofs = runs[0]["num_dofs"]
        if big_refinement is not None:
            if refinement >= big_refinement:
                break
        elif (quick and refinement >= 3) or (not quick and dofs >= 1e5) or refinement >= 7:
            break
        refinement += 1
    big = refinement
    facets = [r["slave_facets"] for r in scaling]
    slopes = {
        "kernel_per_evaluation": loglog_slope(facets, [r["kernel_time_per_evaluation"]
                                                       for r in scaling]),
        "kernel_per_evaluation_finest_3": loglog_slope(
            facets[-3:], [r["kernel_time_per_evaluation"] for r in scaling[-3:]]),
        "pairs": loglog_slope(facets, [r["contact_statistics"].get("pairs", 0) for r in scaling]),
        "mortar_phase_per_iteration": loglog_slope(
            facets, [r["per_iteration"]["mortar integration"] for r in scaling]),
        "mortar_phase_per_iteration_vs_dofs": loglog_slope(
            [r["num_dofs"] for r in scaling],
            [r["per_iteration"]["mortar integration"] for r in scaling]),
        "mortar_phase_other_per_iteration_vs_dofs": loglog_slope(
            [r["num_dofs"] for r in scaling],
            [r["mortar_phase_other"] / max(r["iterations_total"], 1) for r in scaling]),
    }
    linear = contact_share_record(hertz_runs(big, repeats, "linear", tag="cost share"),
                                  f"linear r{big}")
    share = {"linear": linear, "neo-hookean": scaling[-1]}
    far = far_apart(big, far_apart_repeats or (3 if quick else max(repeats, 5)))
    parallel = parallel_runs(big, repeats, ranks)
    return {"big_refinement": big, "share": share, "scaling": scaling, "slopes": slopes,
            "far_apart": far, "parallel": parallel}


