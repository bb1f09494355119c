"""The 3D sections: the patch test (``patch3d``), Hertz's sphere over refinements
(``hertz3d``) and the direct against the iterative linear solver on growing Hertz meshes,
serial and on MPI ranks (``scaling3d``).

``patch3d`` and ``hertz3d`` run the demos in-process like the 2D sections; every
``scaling3d`` run is a process of its own (``python3 benchmarks/run.py
--worker-demo hertz_sphere ...``, under ``mpirun -n N`` for N > 1), so that its peak
resident memory (ru_maxrss, per rank) is its own.
"""

from __future__ import annotations

import datetime
import json
import math
import os
import pathlib
import resource
import shlex
import signal
import statistics
import subprocess
import sys
import tempfile
import time

from mpi4py import MPI

from .common import REPOSITORY, RUN, log, loglog_slope
from .runner import median_timings, run_demo

PATCH_CELLS = ("tetrahedron", "hexahedron")
PATCH_RATIOS = ("1:1", "2:3", "3:7")
PATCH_SLAVES = ("top", "bottom")
PATCH_KEYS = ("max_pressure_deviation_rel", "max_pressure_deviation_interior_rel",
              "max_stress_deviation_rel", "pressure_nonuniformity_rel")
PATCH_TOLERANCE = 1e-10

HERTZ3D_VARIANTS: list[dict] = [
    {"name": "direct", "args": [],
     "label": "segment-based, Lagrange (dual, semismooth), MUMPS LU of the monolithic system"},
    {"name": "iterative", "args": ["--linear-solver", "iterative"],
     "label": "segment-based, Lagrange (dual, semismooth), condensed system, GMRES + BoomerAMG"},
    {"name": "hex-direct", "args": ["--cell", "hexahedron"],
     "label": "as direct, on the structured hexahedral grids (--cell hexahedron)"},
    {"name": "hex-iterative", "args": ["--cell", "hexahedron", "--linear-solver", "iterative"],
     "label": "as iterative, on the structured hexahedral grids (--cell hexahedron)"},
]
HERTZ3D_ERRORS = ("l2_pressure_error_rel", "p_max_error_rel", "p0_fit_error_rel",
                  "a_error_in_elements", "total_force_error_rel")
SCALING3D_SOLVERS = ("direct", "iterative")
# (elements per radius, refinement): 13,407 / 33,846 / 84,726 / 225,975 / 1,642,887 dofs
SCALING3D_MESHES = ((4, 1), (2, 2), (4, 2), (2, 3), (2, 4))
# growth of the run time with the dofs, to estimate a run from the last one of its kind
SCALING3D_EXPONENT = {"direct": 2.0, "iterative": 1.3}


def parse_mesh(text: str) -> tuple[int, int]:
    """``"N:R"`` -> (elements per radius N, refinement R)."""
    n0, refinement = text.split(":")
    return int(n0), int(refinement)


# -- patch test -----------------------------------------------------------------------------


def patch3d_argv(cell: str, ratio: str, slave: str) -> list[str]:
    return ["--dim", "3", "--cell-type", cell, "--ratio", ratio, "--slave", slave]


def patch3d(repeats: int, cells=PATCH_CELLS, ratios=PATCH_RATIOS, slaves=PATCH_SLAVES,
            warm_up: bool = True) -> dict:
    """Every cell type x ratio x slave side, ``repeats`` times (timings: medians)."""
    if warm_up:
        run_demo("patch_test", patch3d_argv(cells[0], ratios[0], slaves[0]))
    runs = []
    for cell in cells:
        for ratio in ratios:
            for slave in slaves:
                argv = patch3d_argv(cell, ratio, slave)
                samples = [run_demo("patch_test", argv) for _ in range(repeats)]
                first = samples[0]
                deviations = {key: float(first[key]) for key in PATCH_KEYS}
                record = {
                    "cell": cell, "ratio": ratio, "slave": slave, "argv": argv,
                    "num_dofs": first["num_dofs"], "converged": bool(first["converged"]),
                    "newton_iterations": first["newton_iterations"],
                    "linear_iterations": first["linear_iterations"],
                    "active_nodes": first["active_nodes"],
                    "deviations": deviations,
                    "exact": max(deviations.values()) < PATCH_TOLERANCE,
                    "timings": median_timings([s["timings"] for s in samples]),
                    "solve_cpu_s": statistics.median(s["probe"]["solve_cpu_s"] for s in samples),
                    "wall_time_s": statistics.median(s["wall_time_s"] for s in samples),
                    "repeats": len(samples),
                }
                runs.append(record)
                log(f"[patch3d] {cell} {ratio} slave {slave}: pressure deviation "
                    f"{deviations['max_pressure_deviation_rel']:.2e}, Newton "
                    f"{first['newton_iterations']}, solve {record['timings']['total']:.3f} s")
    worst = max(max(r["deviations"].values()) for r in runs)
    return {"repeats": repeats, "tolerance": PATCH_TOLERANCE, "runs": runs,
            "max_deviation": worst, "all_exact": worst < PATCH_TOLERANCE}


# -- Hertz sphere: work-precision -----------------------------------------------------------


def run_hertz_sphere(argv: list[str], comm: MPI.Intracomm = MPI.COMM_WORLD) -> dict:
    """demos/hertz_sphere.py through run_demo, with the inner GMRES iterations of every
    application of the condensed preconditioner (iterative solver; [] for LU)."""
    problems = []
    summary = run_demo("hertz_sphere", argv, comm=comm, on_problem=problems.append)
    condenser = getattr(problems[0], "_condenser", None) if problems else None
    summary["inner_krylov_iterations"] = (list(condenser.inner_iterations)
                                          if condenser is not None else [])
    return summary


def hertz3d_record(summary: dict) -> dict:
    """What the tables need of one hertz_sphere summary."""
    newton = list(summary["newton_iterations"])
    krylov = list(summary["krylov_iterations"])
    return {
        "num_dofs": summary["num_dofs"], "num_cells": summary["num_cells"],
        "num_ranks": summary["num_ranks"], "refinement": summary["refinement"],
        "elements_per_radius": summary["elements_per_radius"],
        "h_contact": summary["h_contact"], "h_slave_measured": summary["h_slave_measured"],
        "errors": {key: abs(float(summary[key])) for key in HERTZ3D_ERRORS},
        "p_max": summary["p_max"], "p0_exact": summary["p0_exact"],
        "newton_iterations": newton, "krylov_iterations": krylov,
        "krylov_per_linear_solve": sum(krylov) / max(sum(newton), 1),
        "inner_krylov_iterations": summary.get("inner_krylov_iterations", []),
        "linear_solver": summary["linear_solver"],
        "timings": summary["timings"], "wall_time_s": summary["wall_time_s"],
    }


def hertz3d(refinements: list[int], repeats: int, variants: list[dict] = HERTZ3D_VARIANTS,
            elements_per_radius: int = 2, direct_max_refinement: int | None = None) -> dict:
    """Every variant x refinement of demos/hertz_sphere.py (quarter model, linear, its load steps);
    the direct solver only up to ``direct_max_refinement`` (its fill-in grows fastest)."""
    base = ["--elements-per-radius", str(elements_per_radius)]
    run_demo("hertz_sphere", base + ["--refinement", "0"])  # warm-up: JIT, gmsh
    runs = []
    for refinement in refinements:
        for variant in variants:
            record = {"variant": variant["name"], "label": variant["label"],
                      "refinement": refinement}
            if (variant["name"].endswith("direct") and direct_max_refinement is not None
                    and refinement > direct_max_refinement):
                record.update(failed=True, error=f"not run (--direct-max-refinement "
                                                 f"{direct_max_refinement})")
                runs.append(record)
                continue
            argv = base + ["--refinement", str(refinement)] + variant["args"]
            samples = []
            try:
                for _ in range(repeats):
                    start = time.perf_counter()
                    samples.append(run_hertz_sphere(argv))
                    log(f"[hertz3d] {variant['name']} r{refinement}: "
                        f"{samples[-1]['num_dofs']} dofs, L2 error "
                        f"{samples[-1]['l2_pressure_error_rel']:.3e}, Newton "
                        f"{samples[-1]['newton_iterations']}, Krylov "
                        f"{samples[-1]['krylov_iterations']}, solve "
                        f"{samples[-1]['timings']['total']:.1f} s, wall "
                        f"{time.perf_counter() - start:.1f} s, load {os.getloadavg()[0]:.2f}")
            except Exception as error:  # noqa: BLE001 - recorded and reported
                record.update(failed=True, error=f"{type(error).__name__}: {error}")
                log(f"[hertz3d] {variant['name']} r{refinement}: FAILED {record['error']}")
                runs.append(record)
                continue
            record.update(hertz3d_record(samples[0]))
            record.update(
                failed=False, argv=argv, repeats=len(samples),
                timings=median_timings([s["timings"] for s in samples]),
                timings_samples=[s["timings"] for s in samples],
                wall_time_s=statistics.median(s["wall_time_s"] for s in samples),
                solve_cpu_s=statistics.median(s["probe"]["solve_cpu_s"] for s in samples),
                peak_rss_mib=max(s["peak_rss_mib"] for s in samples),
            )
            runs.append(record)
    return {"refinements": refinements, "repeats": repeats,
            "elements_per_radius": elements_per_radius, "variants": variants, "runs": runs,
            "rates": hertz3d_rates(runs, variants)}


def hertz3d_rates(runs: list[dict], variants: list[dict]) -> dict:
    """Fitted log-log slopes of the L2 pressure error against h (measured slave edge
    length) and against dofs, per variant, over all refinements and the finest three."""
    rates = {}
    for variant in variants:
        done = sorted((r for r in runs if r["variant"] == variant["name"] and not r["failed"]),
                      key=lambda r: r["refinement"])
        h = [r["h_slave_measured"] for r in done]
        dofs = [r["num_dofs"] for r in done]
        error = [r["errors"]["l2_pressure_error_rel"] for r in done]
        rates[variant["name"]] = {
            "refinements": [r["refinement"] for r in done],
            "l2_vs_h": loglog_slope(h, error),
            "l2_vs_h_finest_3": loglog_slope(h[-3:], error[-3:]) if len(done) > 3 else None,
            "l2_vs_dofs": loglog_slope(dofs, error),
        }
    return rates


# -- Hertz sphere: solver scaling, one process per run ----------------------------------------


def peak_rss_mib() -> float | None:
    """VmHWM of this process (/proc/self/status), MiB: the peak of this process image.
    ru_maxrss is not: Linux carries the parent's high-water mark over fork + exec."""
    try:
        for line in pathlib.Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    except OSError:  # pragma: no cover
        pass
    return None


def scaling_worker(demo_name: str, argv: list[str], path: pathlib.Path) -> None:
    """Under mpirun or alone: one demo run; rank 0 writes its record with every rank's
    peak resident memory (VmHWM, and ru_maxrss as the brief asked for)."""
    comm = MPI.COMM_WORLD
    start = time.perf_counter()
    load_start = os.getloadavg()[0]
    summary = (run_hertz_sphere(argv, comm) if demo_name == "hertz_sphere"
               else run_demo(demo_name, argv, comm=comm))
    hwm = comm.gather(peak_rss_mib(), root=0)
    maxrss = comm.gather(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, root=0)
    if comm.rank == 0:
        record = hertz3d_record(summary)
        record.update(peak_rss_mib_per_rank=hwm, ru_maxrss_mib_per_rank=maxrss,
                      process_run_s=time.perf_counter() - start,
                      argv=argv, solve_cpu_s_rank0=summary["probe"]["solve_cpu_s"],
                      load_1min_start=load_start, load_1min_end=os.getloadavg()[0],
                      petsc_options_env=os.environ.get("PETSC_OPTIONS", ""))
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(record, indent=1))


def _clean_env() -> dict:
    env = dict(os.environ)
    for key in list(env):  # this process's singleton MPI must not leak into mpirun
        if key.startswith(("PMIX_", "OMPI_COMM_", "OMPI_MCA_orte_", "OMPI_FILE_LOCATION")):
            del env[key]
    return env


def _seconds_until(stop_at: str | None) -> float | None:
    """Seconds from now to ``stop_at`` ("HH:MM", UTC, today); None if no limit."""
    if stop_at is None:
        return None
    now = datetime.datetime.now(datetime.timezone.utc)
    hours, minutes = (int(v) for v in stop_at.split(":"))
    stop = now.replace(hour=hours, minute=minutes, second=0, microsecond=0)
    return (stop - now).total_seconds()


def scaling_command(n0: int, refinement: int, solver: str, ranks: int,
                    path: pathlib.Path) -> list[str]:
    argv = ["--elements-per-radius", str(n0), "--refinement", str(refinement),
            "--linear-solver", solver]
    command = [sys.executable, str(RUN), "--worker-demo",
               "hertz_sphere", "--worker-json", str(path), "--worker-argv", shlex.join(argv)]
    return (["mpirun", "-n", str(ranks)] if ranks > 1 else []) + command


def complete_run(record: dict) -> dict:
    """Per-Newton-iteration times of a finished run's record (in place)."""
    iterations = max(sum(record["newton_iterations"]), 1)
    record["time_per_newton_s"] = record["timings"]["total"] / iterations
    record["linear_solve_per_newton_s"] = record["timings"]["linear solve"] / iterations
    return record


def stored_runs(path: pathlib.Path) -> list[dict]:
    """Runs made apart from this command (a run too long for it, e.g. >= 1e6 dofs), from
    a JSON file of one worker record or a list of them, each with its ``command``: shown
    in the table as stored, with the load average of its own run."""
    data = json.loads(pathlib.Path(path).read_text())
    runs = []
    for record in data if isinstance(data, list) else [data]:
        record = dict(record, stored=str(path), failed=bool(record.get("failed", False)))
        if not record["failed"]:
            record.setdefault("process_wall_s", record.get("process_run_s", math.nan))
            complete_run(record)
        runs.append(record)
    return runs


def scaling3d(meshes: list[tuple[int, int]], solvers=SCALING3D_SOLVERS, ranks=(1, 2),
              stop_at: str | None = None, stored: list[pathlib.Path] | None = None) -> dict:
    """Each mesh (in the order given, growing) x solver x rank count as its own process.
    With ``stop_at`` ("HH:MM" UTC) a run is not started if its estimate (the last run
    of its solver and rank count, scaled by dofs^SCALING3D_EXPONENT) would end later,
    and a started run is stopped at that time; both are recorded. ``stored``: JSON
    files of runs made separately (:func:`stored_runs`), added after the measured ones."""
    scratch = pathlib.Path(tempfile.mkdtemp(prefix="dolfinx_mortar_scaling3d_"))
    env = _clean_env()
    runs, last = [], {}
    for n0, refinement in meshes:
        for solver in solvers:
            for n in ranks:
                path = scratch / f"run_{n0}_{refinement}_{solver}_{n}.json"
                command = scaling_command(n0, refinement, solver, n, path)
                shown = shlex.join(["mpirun", "-n", str(n)] if n > 1 else [])
                shown = (shown + " " if shown else "") + shlex.join(
                    ["python3", "benchmarks/run.py"]
                    + command[command.index("--worker-demo"):command.index("--worker-json")]
                    + ["--worker-json", path.name] + command[command.index("--worker-argv"):])
                record = {"elements_per_radius": n0, "refinement": refinement,
                          "linear_solver": solver, "num_ranks": n, "command": shown}
                left = _seconds_until(stop_at)
                previous = last.get((solver, n))
                if left is not None and previous is not None:
                    estimate = previous["process_wall_s"] * (
                        SCALING3D_DOFS.get((n0, refinement), previous["num_dofs"])
                        / previous["num_dofs"]) ** SCALING3D_EXPONENT[solver]
                    record["estimated_s"] = estimate
                    if estimate > left:
                        record.update(failed=True, error=f"not started: estimated "
                                      f"{estimate / 60:.0f} min, {left / 60:.0f} min left "
                                      f"before --stop-at {stop_at}")
                        log(f"[scaling3d] {shown}: {record['error']}")
                        runs.append(record)
                        continue
                if left is not None and left <= 0:
                    record.update(failed=True, error=f"not started: past --stop-at {stop_at}")
                    runs.append(record)
                    continue
                log(f"[scaling3d] {shown} (load {os.getloadavg()[0]:.2f})")
                start = time.perf_counter()
                process = subprocess.Popen(command, env=env, cwd=REPOSITORY,
                                           stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                           text=True, start_new_session=True)
                try:
                    _, stderr = process.communicate(timeout=left)
                except subprocess.TimeoutExpired:
                    os.killpg(process.pid, signal.SIGKILL)
                    _, stderr = process.communicate()
                    record.update(failed=True, error=f"stopped at --stop-at {stop_at} after "
                                  f"{(time.perf_counter() - start) / 60:.1f} min")
                    log(f"[scaling3d] {shown}: {record['error']}")
                    runs.append(record)
                    continue
                wall = time.perf_counter() - start
                if process.returncode != 0 or not path.exists():
                    record.update(failed=True, error=f"exit {process.returncode}: "
                                  f"{stderr[-1500:]}")
                    log(f"[scaling3d] {shown}: FAILED {record['error']}")
                    runs.append(record)
                    continue
                record.update(json.loads(path.read_text()), failed=False, process_wall_s=wall)
                path.unlink()
                complete_run(record)
                last[(solver, n)] = record
                runs.append(record)
                log(f"[scaling3d] {record['num_dofs']} dofs {solver} n={n}: Newton "
                    f"{record['newton_iterations']}, Krylov {record['krylov_iterations']}, "
                    f"{record['time_per_newton_s']:.2f} s per Newton iteration, process "
                    f"{wall:.1f} s, peak RSS {record['peak_rss_mib_per_rank']} MiB")
    for path in scratch.glob("*"):
        path.unlink()
    scratch.rmdir()
    for path in stored or []:
        runs += stored_runs(path)
    return {"meshes": [list(m) for m in meshes], "solvers": list(solvers), "ranks": list(ranks),
            "stop_at": stop_at, "exponents": SCALING3D_EXPONENT, "runs": runs}


# dofs of the Hertz sphere meshes (block, L = R, default load), measured: for the estimates
SCALING3D_DOFS = {(2, 0): 1362, (2, 1): 5823, (2, 2): 33846, (2, 3): 225975, (2, 4): 1642887,
                  (4, 0): 2703, (4, 1): 13407, (4, 2): 84726}
