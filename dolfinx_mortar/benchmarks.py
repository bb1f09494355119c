"""Benchmarks of dolfinx_mortar: work-precision, cost of contact, skipped work, parallel runs.

One command runs everything and writes JSON, PNG and markdown into ``--output``
(default ``benchmarks/results``); what it prints on stdout is ``summary.md``
there, byte for byte::

    tools/run python3 -m dolfinx_mortar.benchmarks --quick       # < 10 min on 2 cores
    tools/run python3 -m dolfinx_mortar.benchmarks               # the full run (about 65 min)
    tools/run python3 -m dolfinx_mortar.benchmarks --only cost skip --output scratch/b

Sections (``--only`` picks some):

``work-precision``
    Hertz cases A and B and the patch test (ratio 3:7, finer side slave) over
    refinements 0..4 (quick: 0..2) for each variant of ``VARIANTS``: one option
    changed at a time from the default (Lagrange multipliers, semismooth active
    set, dual basis, segment-based integration, averaged normals). Errors,
    Newton iterations, dofs and the solve time split by phase (medians over
    ``--repeats``, 3 in the full run, 1 in the quick run; the finest refinement,
    whose solves take a minute or more, ``--finest-repeats``, 1 by default).
    -> work_precision.json / .png / .md (+ work_precision_cpu.png, work_precision_pmax.png)
``cost``
    Share of a Newton iteration spent on contact at >= 1e5 dofs (Hertz B, the
    first refinement with that many dofs; quick: refinement 3), for linear
    elasticity (mortar integrals once, on the reference configuration) and
    Neo-Hookean (current configuration, integrals in every iteration); mortar
    time against slave facets over the refinements; a scene whose bodies never
    come near each other against the same bulk problem in a plain SNES without
    any contact pair; and the Hertz B run on 1 and 2 MPI ranks (``mpirun``
    started from here). -> cost_of_contact.json / .md, mortar_scaling.png
``skip``
    Work skipped where a scene does not need it, each counter with an A/B
    timing: searches reused, no pairs for far-apart surfaces, uncovered slave
    nodes, evaluations skipped. -> skipping.json / .md

The demos ``demos/hertz.py`` and ``demos/patch_test.py`` are run in-process
through their ``main(argv, comm)``; everything timed is ``ContactProblem.solve``
(the ``timings`` of its ``SolveReport``), wall times (with mesh generation and
setup) are reported next to it.
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import importlib.util
import io
import json
import logging
import math
import os
import pathlib
import platform
import resource
import shlex
import statistics
import subprocess
import sys
import threading
import time
import typing

import numpy as np
from mpi4py import MPI

REPOSITORY = pathlib.Path(__file__).resolve().parents[1]
DEMOS = REPOSITORY / "demos"
DEFAULT_OUTPUT = REPOSITORY / "benchmarks" / "results"
SECTIONS = ("work-precision", "cost", "skip")
PHASES = ("bulk assembly", "contact search", "mortar integration", "linear solve", "total")

# -- variants -----------------------------------------------------------------------

# One option changed at a time from the default (the first row). ``penalty``
# is a factor on the automatic E/h that the default run reports as penalty_used.
VARIANTS: list[dict] = [
    {"name": "default", "args": [],
     "label": "segment, Lagrange semismooth, dual (default; normals: the demo's, master "
              "for linear Hertz, averaged for the patch test)"},
    {"name": "element-2gp", "args": ["--integration", "element", "--gauss-points", "2"],
     "label": "element-based, 2 Gauss points"},
    {"name": "element-4gp", "args": ["--integration", "element", "--gauss-points", "4"],
     "label": "element-based, 4 Gauss points"},
    {"name": "element-8gp", "args": ["--integration", "element", "--gauss-points", "8"],
     "label": "element-based, 8 Gauss points"},
    {"name": "fixed-point", "args": ["--active-set", "fixed-point"],
     "label": "Lagrange, fixed-point active set"},
    {"name": "standard", "args": ["--multipliers", "standard"],
     "label": "standard multiplier basis"},
    {"name": "penalty-0.1", "args": ["--method", "penalty"], "penalty": 0.1,
     "label": "penalty, eps = 0.1 E/h"},
    {"name": "penalty-1", "args": ["--method", "penalty"], "penalty": 1.0,
     "label": "penalty, eps = E/h"},
    {"name": "penalty-10", "args": ["--method", "penalty"], "penalty": 10.0,
     "label": "penalty, eps = 10 E/h"},
    {"name": "augmented", "args": ["--method", "augmented"],
     "label": "augmented Lagrange (eps = 10 E/h)"},
    {"name": "normals-averaged", "args": ["--normals", "averaged"],
     "label": "averaged nodal normals (the library default)"},
    {"name": "normals-slave", "args": ["--normals", "slave"], "label": "slave normals"},
    {"name": "normals-master", "args": ["--normals", "master"], "label": "master normals"},
    {"name": "dual-condensed", "args": ["--condensation"],
     "label": "dual multipliers condensed out of the system (condensation=True)"},
]
CASES = {
    "hertz-A": {"demo": "hertz", "args": ["--case", "A"], "title": "Hertz case A (rigid plate)",
                "error": "l2_pressure_error_rel"},
    "hertz-B": {"demo": "hertz", "args": ["--case", "B"], "title": "Hertz case B (elastic block)",
                "error": "l2_pressure_error_rel"},
    "patch-3:7": {"demo": "patch_test", "args": ["--ratio", "3:7", "--slave", "bottom"],
                  "title": "patch test 3:7 (finer side slave)",
                  "error": "max_pressure_deviation_rel"},
}
ERROR_KEYS = {
    "hertz": ("p_max_error_rel", "a_error_rel", "a_error_in_elements", "l2_pressure_error_rel",
              "total_force_error_rel"),
    "patch_test": ("max_pressure_deviation_rel", "max_stress_deviation_rel",
                   "pressure_nonuniformity_rel"),
}
GOALS = {
    "contact_share": 0.15,
    "far_apart_overhead": 0.05,
    "semismooth_iterations_per_step": 8,
    "mortar_slope": 1.1,
}


def log(message: str) -> None:
    if MPI.COMM_WORLD.rank == 0:
        print(message, file=sys.stderr, flush=True)


# -- machine and load ------------------------------------------------------------------


class LoadMonitor:
    """Samples the 1-minute load average every few seconds in a background thread."""

    def __init__(self, interval: float = 5.0):
        self.interval = interval
        self.samples: list[float] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self.start_time = time.time()

    def _run(self) -> None:
        while not self._stop.is_set():
            self.samples.append(os.getloadavg()[0])
            self._stop.wait(self.interval)

    def __enter__(self) -> LoadMonitor:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()

    def summary(self) -> dict:
        samples = self.samples or [os.getloadavg()[0]]
        return {"min": min(samples), "mean": float(np.mean(samples)), "max": max(samples),
                "samples": len(samples), "interval_s": self.interval,
                "duration_s": time.time() - self.start_time}


def machine_info() -> dict:
    import dolfinx
    import petsc4py
    import scipy
    from petsc4py import PETSc

    memory = {}
    with contextlib.suppress(OSError):
        for line in pathlib.Path("/proc/meminfo").read_text().splitlines():
            key, value = line.split(":", 1)
            if key in ("MemTotal", "MemAvailable"):
                memory[key] = round(int(value.split()[0]) / 1024**2, 1)
    cpu = platform.processor()
    with contextlib.suppress(OSError):
        for line in pathlib.Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    try:
        usable = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover
        usable = os.cpu_count()
    os_release = ""
    with contextlib.suppress(OSError):
        for line in pathlib.Path("/etc/os-release").read_text().splitlines():
            if line.startswith("PRETTY_NAME="):
                os_release = line.split("=", 1)[1].strip('"')
    import hashlib

    package = pathlib.Path(__file__).resolve().parent
    sources = sorted(p for p in package.glob("*.py") if p.name != "benchmarks.py")
    sources += [DEMOS / "hertz.py", DEMOS / "patch_test.py"]
    digest = hashlib.sha256()
    for path in sources:
        if path.exists():
            digest.update(path.name.encode() + path.read_bytes())
    return {
        "dolfinx_mortar_path": str(package),
        "dolfinx_mortar_sources_sha256": digest.hexdigest()[:16],
        "nproc": usable,
        "cpu": cpu,
        "memory_gib": memory.get("MemTotal"),
        "memory_available_gib_at_start": memory.get("MemAvailable"),
        "load_at_start": list(os.getloadavg()),
        "os": os_release,
        "python": platform.python_version(),
        "dolfinx": dolfinx.__version__,
        "petsc": ".".join(str(v) for v in PETSc.Sys.getVersion()),
        "petsc4py": petsc4py.__version__,
        # Open MPI ends its version string with a NUL byte
        "mpi": MPI.Get_library_version().replace("\x00", "").splitlines()[0].strip(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "omp_num_threads": os.environ.get("OMP_NUM_THREADS"),
    }


# -- running the demos ------------------------------------------------------------------

_MODULES: dict[str, typing.Any] = {}


def demo(name: str):
    """The module of ``demos/NAME.py`` (loaded once, as tests/test_demos.py does)."""
    if name not in _MODULES:
        path = DEMOS / f"{name}.py"
        if not path.exists():
            raise FileNotFoundError(f"{path} not found: the benchmarks run the demos of a "
                                    "source checkout of dolfinx_mortar")
        spec = importlib.util.spec_from_file_location(f"benchmark_demo_{name}", path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        _MODULES[name] = module
    return _MODULES[name]


def quiet_logging() -> None:
    """Keep the demos' per-step log lines off the terminal (configure_logging adds none)."""
    logger = logging.getLogger("dolfinx_mortar")
    if not logger.handlers:
        logger.addHandler(logging.NullHandler())


def run_demo(name: str, argv: list[str], comm: MPI.Intracomm = MPI.COMM_WORLD,
             on_problem: typing.Callable | None = None) -> dict:
    """``demos/NAME.py``'s main(argv) with its printing captured.

    ``on_problem(problem)`` is called right after the demo builds its
    ContactProblem (to read sizes or to switch a reuse off for an A/B timing);
    whatever it returns is stored under ``summary["probe"]``, with the
    process CPU time of all ``solve`` calls (``solve_cpu_s``).
    """
    module = demo(name)
    original = module.ContactProblem
    probe: dict = {"solve_cpu_s": 0.0}

    class Probed(original):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            if on_problem is not None:
                probe.update(on_problem(self) or {})

        def solve(self):
            # process CPU time of the solves: less disturbed by other jobs than wall time
            start = time.process_time()
            try:
                return super().solve()
            finally:
                probe["solve_cpu_s"] += time.process_time() - start

    module.ContactProblem = Probed
    gc.collect()
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            summary = module.main(list(argv), comm=comm)
    finally:
        module.ContactProblem = original
    summary = dict(summary)
    summary["probe"] = probe
    summary["peak_rss_mib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return summary


def sizes_probe(problem) -> dict:
    """Global facet counts and the search margin of each pair."""
    comm = problem.comm
    return {
        "slave_facets": [comm.allreduce(i.slave.num_facets, op=MPI.SUM)
                         for i in problem.interfaces],
        "master_facets": [comm.allreduce(i.master.num_facets, op=MPI.SUM)
                          for i in problem.interfaces],
        "search_margin": [i.reuse.margin for i in problem.interfaces],
    }


def force_search(problem) -> dict:
    """A/B: search in every update (the reuse test always says 'moved')."""
    for interface in problem.interfaces:
        interface.reuse.needs_search = lambda coordinates, comm: True
    return sizes_probe(problem)


def force_evaluation(problem) -> dict:
    """A/B: evaluate in every update (forget what the last evaluation was done at)."""
    supported = all(hasattr(i, "_evaluated_x") for i in problem.interfaces)
    for interface in problem.interfaces:
        original = interface.update

        def update(u=None, interface=interface, original=original):
            interface._evaluated_x = None
            return original(u)

        interface.update = update
    return {**sizes_probe(problem), "forced_evaluation_supported": supported}


def pair_statistics(summary: dict) -> dict:
    """The statistics of the (single) contact pair of a demo run."""
    stats = summary.get("contact_statistics") or {}
    return next(iter(stats.values())) if stats else {}


def median_timings(samples: list[dict]) -> dict:
    return {key: statistics.median(s.get(key, 0.0) for s in samples) for key in PHASES}


def errors_of(demo_name: str, summary: dict) -> dict:
    if demo_name == "hertz":
        errors = {
            "p_max_error_rel": abs(summary["p_max_error_rel"]),
            "a_error_rel": abs(summary["a_contact"] - summary["a_exact"]) / summary["a_exact"],
            "a_error_in_elements": summary["a_error_in_elements"],
            "l2_pressure_error_rel": summary["l2_pressure_error_rel"],
            "total_force_error_rel": summary["total_force_error_rel"],
        }
    else:
        errors = {key: summary[key] for key in ERROR_KEYS["patch_test"]}
    return {key: float(value) for key, value in errors.items()}


def iterations_per_step(summary: dict) -> list[int]:
    iterations = summary["newton_iterations"]
    return list(iterations) if isinstance(iterations, list) else [int(iterations)]


# -- section 1: work-precision ---------------------------------------------------------------


def work_precision(refinements: list[int], repeats: int, variants: list[dict],
                   finest_repeats: int | None = None) -> dict:
    """Every case x refinement x variant, ``repeats`` times (interleaved: repeat outermost);
    the finest refinement only ``finest_repeats`` times (default: ``repeats``)."""
    finest_repeats = repeats if finest_repeats is None else finest_repeats
    samples: dict[tuple, list[dict]] = {}
    failures: dict[tuple, str] = {}
    penalty_base: dict[tuple, float] = {}
    for case in CASES.values():  # warm-up: JIT compilation, gmsh, imports
        run_demo(case["demo"], case["args"] + ["--refinement", "0"])
    for repeat in range(repeats):
        for case_name, case in CASES.items():
            for refinement in refinements:
                if refinement == refinements[-1] and repeat >= finest_repeats:
                    continue
                for variant in variants:
                    key = (case_name, variant["name"], refinement)
                    if key in failures:
                        continue
                    argv = case["args"] + ["--refinement", str(refinement)] + variant["args"]
                    if "penalty" in variant:
                        base = penalty_base.get((case_name, refinement))
                        if base is None:
                            failures[key] = "no penalty_used from the default run to scale"
                            continue
                        argv += ["--penalty", repr(variant["penalty"] * base)]
                    start = time.perf_counter()
                    try:
                        summary = run_demo(case["demo"], argv, on_problem=sizes_probe)
                    except Exception as error:  # noqa: BLE001 - recorded and reported
                        failures[key] = f"{type(error).__name__}: {error}"
                        log(f"[work-precision {repeat + 1}/{repeats}] {case_name} r{refinement} "
                            f"{variant['name']}: FAILED {failures[key]}")
                        continue
                    if variant["name"] == "default":
                        penalty_base[(case_name, refinement)] = summary["penalty_used"]
                    summary["argv"] = argv
                    samples.setdefault(key, []).append(summary)
                    error = errors_of(case["demo"], summary)[case["error"]]
                    log(f"[work-precision {repeat + 1}/{repeats}] {case_name} r{refinement} "
                        f"{variant['name']}: {case['error']} {error:.3e}, solve "
                        f"{summary['timings']['total']:.2f} s, wall "
                        f"{time.perf_counter() - start:.1f} s, load {os.getloadavg()[0]:.2f}")
    runs = []
    for case_name, case in CASES.items():
        for refinement in refinements:
            for variant in variants:
                key = (case_name, variant["name"], refinement)
                record = {"case": case_name, "variant": variant["name"], "label": variant["label"],
                          "refinement": refinement}
                if key in failures:
                    record.update(failed=True, error=failures[key],
                                  repeats_done=len(samples.get(key, [])))
                    runs.append(record)
                    continue
                runs_of_key = samples[key]
                first = runs_of_key[0]
                errors = errors_of(case["demo"], first)
                spread = max((abs(errors_of(case["demo"], s)[case["error"]] - errors[case["error"]])
                              for s in runs_of_key), default=0.0)
                steps = iterations_per_step(first)
                stats = pair_statistics(first)
                record.update(
                    failed=False,
                    argv=first["argv"],
                    repeats=len(runs_of_key),
                    num_dofs=first["num_dofs"],
                    errors=errors,
                    error_spread_over_repeats=spread,
                    newton_iterations=first["newton_iterations"],
                    max_iterations_per_step=max(steps),
                    outer_note=("iterations summed over the outer loop (fixed-point / Uzawa)"
                                if variant["name"] in ("fixed-point", "augmented") else ""),
                    timings=median_timings([s["timings"] for s in runs_of_key]),
                    timings_samples=[s["timings"] for s in runs_of_key],
                    solve_cpu_s=statistics.median(s["probe"]["solve_cpu_s"] for s in runs_of_key),
                    wall_time_s=statistics.median(s["wall_time_s"] for s in runs_of_key),
                    wall_time_samples=[s["wall_time_s"] for s in runs_of_key],
                    c_n=first.get("c_n"),
                    penalty_used=first.get("penalty_used"),
                    contact_statistics=stats,
                    sizes=first["probe"],
                )
                runs.append(record)
    return {"refinements": refinements, "repeats": repeats, "finest_repeats": finest_repeats,
            "runs": runs,
            "variants": variants,
            "cases": {name: {k: v for k, v in case.items()} for name, case in CASES.items()}}


def _fmt(value, digits: int = 3) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    if isinstance(value, int | np.integer):
        return str(value)
    if value == 0:
        return "0"
    if abs(value) >= 1e4 or abs(value) < 1e-3:
        return f"{value:.{digits - 1}e}"
    return f"{value:.{digits}g}"


def _ms(seconds: float) -> str:
    return f"{1e3 * seconds:.0f}" if seconds >= 0.1 else f"{1e3 * seconds:.1f}"


def work_precision_markdown(data: dict, finest_only: bool = False) -> str:
    lines = []
    refinements = data["refinements"]
    for case_name, case in CASES.items():
        demo_name = case["demo"]
        keys = ERROR_KEYS[demo_name]
        names = [k.replace("_rel", "").replace("_", " ") for k in keys]
        header = (["variant", "ref", "dofs"] + names
                  + ["Newton its", "solve [s]", "bulk", "search", "mortar", "lin. solve",
                     "solve CPU [s]", "wall [s]"])
        title = f"#### {case['title']}"
        if finest_only:
            title += f", refinement {refinements[-1]}"
        lines += [title, "", "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
        for run in data["runs"]:
            if run["case"] != case_name or (finest_only and run["refinement"] != refinements[-1]):
                continue
            if run["failed"]:
                lines.append(f"| {run['variant']} | {run['refinement']} | "
                             f"failed: {run['error'][:160]} |" + " |" * (len(header) - 3))
                continue
            t = run["timings"]
            its = run["newton_iterations"]
            its = "+".join(str(i) for i in its) if isinstance(its, list) else str(its)
            cells = ([run["variant"], str(run["refinement"]), str(run["num_dofs"])]
                     + [_fmt(run["errors"][k]) for k in keys]
                     + [its, f"{t['total']:.3g}"]
                     + [f"{100 * t[p] / t['total']:.0f} %" if t["total"] > 0 else "-"
                        for p in ("bulk assembly", "contact search", "mortar integration",
                                  "linear solve")]
                     + [f"{run['solve_cpu_s']:.3g}", f"{run['wall_time_s']:.3g}"])
            lines.append("| " + " | ".join(cells) + " |")
        for item in data.get("not_implemented", []):  # runs before the variant existed
            lines.append(f"| {item['name']} | - | - | {item['status']} |"
                         + " |" * (len(header) - 4))
        lines.append("")
    return "\n".join(lines)


def plot_work_precision(data: dict, path: pathlib.Path, error_key: str | None = None,
                        time_key: str = "wall") -> None:
    """Error against the median solve time (wall, or process CPU with time_key="cpu")."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cases = [c for c in CASES if error_key is None or CASES[c]["demo"] == "hertz"]
    width = 5.2 * len(cases) + 1.7
    fig, axes = plt.subplots(1, len(cases), figsize=(width, 4.6), squeeze=False)
    colours = plt.get_cmap("tab20").colors
    markers = "os^vD<>pPX*h"
    handles = {}
    for ax, case_name in zip(axes[0], cases, strict=True):
        key = error_key or CASES[case_name]["error"]
        for index, variant in enumerate(data["variants"]):
            runs = sorted((r for r in data["runs"] if r["case"] == case_name
                           and r["variant"] == variant["name"] and not r["failed"]),
                          key=lambda r: r["refinement"])
            if not runs:
                continue
            x = [r["timings"]["total"] if time_key == "wall" else r["solve_cpu_s"] for r in runs]
            y = [max(r["errors"][key], 1e-16) for r in runs]
            style = "--" if variant["name"].startswith("penalty") else (
                ":" if variant["name"].startswith("element") else "-")
            (line,) = ax.loglog(x, y, style, marker=markers[index % len(markers)], ms=4,
                                color=colours[(2 * index) % 20 if index < 10 else 2 * index - 19],
                                linewidth=2.2 if variant["name"] == "default" else 1.2)
            handles.setdefault(variant["name"], line)
        ax.set_title(CASES[case_name]["title"], fontsize=10)
        ax.set_xlabel(("solve time" if time_key == "wall" else "solve CPU time")
                      + f" [s] (median; refinements {data['refinements'][0]}.."
                      f"{data['refinements'][-1]})")
        ax.set_ylabel(key.replace("_", " "))
        ax.grid(True, which="both", linewidth=0.3)
    fig.tight_layout(rect=(0, 0, 1 - 1.6 / width, 1))
    fig.legend(handles.values(), handles.keys(), loc="center right", fontsize=8)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


# -- section 2: cost of contact ----------------------------------------------------------


def per_iteration(summary_timings: dict, iterations: int) -> dict:
    return {key: value / max(iterations, 1) for key, value in summary_timings.items()}


def contact_share_record(runs: list[dict], label: str) -> dict:
    """Medians over repeats of one Hertz run configuration, with the contact share."""
    first = runs[0]
    timings = median_timings([r["timings"] for r in runs])
    iterations = sum(iterations_per_step(first))
    stats = pair_statistics(first)
    kernel = statistics.median(pair_statistics(r).get("time_integration", 0.0) for r in runs)
    search = statistics.median(pair_statistics(r).get("time_search", 0.0) for r in runs)
    total = timings["total"]
    return {
        "label": label,
        "refinement": first["refinement"],
        "material": first["material"],
        "configuration": first["configuration"],
        "num_dofs": first["num_dofs"],
        "slave_facets": first["probe"].get("slave_facets", [None])[0],
        "master_facets": first["probe"].get("master_facets", [None])[0],
        "search_margin": first["probe"].get("search_margin", [None])[0],
        "repeats": len(runs),
        "newton_iterations": first["newton_iterations"],
        "iterations_total": iterations,
        "timings": timings,
        "timings_samples": [r["timings"] for r in runs],
        "per_iteration": per_iteration(timings, iterations),
        "contact_share": (timings["contact search"] + timings["mortar integration"]) / total,
        "kernel_time": kernel,
        "kernel_share": (kernel + search) / total,
        "mortar_phase_other": timings["mortar integration"] - kernel,
        "wall_time_s": statistics.median(r["wall_time_s"] for r in runs),
        "solve_cpu_s": statistics.median(r["probe"]["solve_cpu_s"] for r in runs),
        "p_max_error_rel": first["p_max_error_rel"],
        "l2_pressure_error_rel": first["l2_pressure_error_rel"],
        "contact_statistics": stats,
        "kernel_time_per_evaluation": kernel / max(stats.get("evaluations", 0), 1),
        "search_time_per_search": search / max(stats.get("searches_done", 0), 1),
        "peak_rss_mib": max(r["peak_rss_mib"] for r in runs),
    }


def hertz_runs(refinement: int, repeats: int, material: str, extra: list[str] | None = None,
               on_problem=sizes_probe, comm=MPI.COMM_WORLD, tag: str = "") -> list[dict]:
    argv = ["--case", "B", "--refinement", str(refinement), "--material", material] + (extra or [])
    runs = []
    for repeat in range(repeats):
        start = time.perf_counter()
        summary = run_demo("hertz", argv, comm=comm, on_problem=on_problem)
        runs.append(summary)
        t = summary["timings"]
        log(f"[{tag or 'hertz'} {repeat + 1}/{repeats}] B r{refinement} {material} "
            f"{' '.join(extra or [])}: {summary['num_dofs']} dofs, its "
            f"{summary['newton_iterations']}, solve {t['total']:.2f} s (search "
            f"{t['contact search']:.2f}, mortar {t['mortar integration']:.2f}), wall "
            f"{time.perf_counter() - start:.1f} s, load {os.getloadavg()[0]:.2f}")
    return runs


def loglog_slope(x, y) -> float | None:
    x, y = np.asarray(x, float), np.asarray(y, float)
    keep = (x > 0) & (y > 0)
    if keep.sum() < 2:
        return None
    return float(np.polyfit(np.log(x[keep]), np.log(y[keep]), 1)[0])


class PlainNewton:
    """The bulk problem alone in PETSc SNES, with ContactProblem's default options.

    dolfinx_mortar.compat has no NonlinearProblem wrapper, so this is the
    baseline of the far-apart comparison: residual F(u) with lifting and
    Dirichlet rows b = u - g, Jacobian dF/du with identity rows; newtonls,
    basic line search, rtol = atol = 1e-10, MUMPS LU.
    """

    OPTIONS = {"snes_type": "newtonls", "snes_linesearch_type": "basic", "snes_rtol": 1e-10,
               "snes_atol": 1e-10, "snes_stol": 0.0, "snes_max_it": 30, "ksp_type": "preonly",
               "pc_type": "lu", "pc_factor_mat_solver_type": "mumps"}

    def __init__(self, F, u, bcs, prefix: str = "benchmark_plain_"):
        import dolfinx
        import dolfinx.fem.petsc
        import ufl
        from petsc4py import PETSc

        from . import compat

        self.u, self.bcs = u, bcs
        self.F = dolfinx.fem.form(F)
        self.J = dolfinx.fem.form(ufl.derivative(F, u, ufl.TrialFunction(u.function_space)))
        self.b = compat.create_vector(self.F)
        self.A = compat.create_matrix(self.J)
        self.x = u.x.petsc_vec.copy()
        self.timings = {"bulk assembly": 0.0}
        snes = PETSc.SNES().create(u.function_space.mesh.comm)
        snes.setOptionsPrefix(prefix)
        options = PETSc.Options()
        for key, value in self.OPTIONS.items():
            options[f"{prefix}{key}"] = value
        snes.setFunction(self._residual, self.b)
        snes.setJacobian(self._jacobian, self.A)
        snes.setFromOptions()
        snes.getKSP().setFromOptions()
        for key in self.OPTIONS:
            options.delValue(f"{prefix}{key}")
        self.snes = snes

    def _residual(self, snes, x, b) -> None:
        import dolfinx.fem.petsc
        from petsc4py import PETSc

        from . import compat

        start = time.perf_counter()
        x.copy(self.u.x.petsc_vec)
        self.u.x.scatter_forward()
        with b.localForm() as local:
            local.set(0.0)
        dolfinx.fem.petsc.assemble_vector(b, self.F)
        dolfinx.fem.petsc.apply_lifting(b, [self.J], bcs=[self.bcs], x0=[self.u.x.petsc_vec],
                                        alpha=-1.0)
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        compat.set_bc(b, self.bcs, self.u.x.petsc_vec, -1.0)
        self.timings["bulk assembly"] += time.perf_counter() - start

    def _jacobian(self, snes, x, A, P) -> None:
        import dolfinx.fem.petsc

        start = time.perf_counter()
        A.zeroEntries()
        dolfinx.fem.petsc.assemble_matrix(A, self.J, bcs=self.bcs)
        A.assemble()
        self.timings["bulk assembly"] += time.perf_counter() - start

    def solve(self) -> dict:
        start = time.perf_counter()
        bulk = self.timings["bulk assembly"]
        self.u.x.petsc_vec.copy(self.x)
        self.snes.solve(None, self.x)
        self.x.copy(self.u.x.petsc_vec)
        self.u.x.scatter_forward()
        total = time.perf_counter() - start
        assembly = self.timings["bulk assembly"] - bulk
        return {"converged": self.snes.getConvergedReason() > 0,
                "reason": self.snes.getConvergedReason(),
                "iterations": self.snes.getIterationNumber(),
                "timings": {"bulk assembly": assembly, "contact search": 0.0,
                            "mortar integration": 0.0, "linear solve": total - assembly,
                            "total": total}}

    def destroy(self) -> None:
        for obj in (self.snes, self.A, self.b, self.x):
            obj.destroy()


def far_apart_scene(refinement: int, comm: MPI.Intracomm, lift_radii: float = 2.0,
                    body_force: float = 0.2):
    """Hertz B mesh, the cylinder lifted by 2R (Dirichlet on its top, and its start state).

    Both bodies Neo-Hookean (E = 200, nu = 0.3) under a body force (0, -f):
    the block sags on its support, the cylinder hangs from its top, and the
    bodies stay 2R apart, so contact never matters. Returns the pieces for
    ContactProblem or PlainNewton and a ``load(t)`` setter.
    """
    import dolfinx
    import ufl

    from . import meshes
    from .materials import Material, internal_work
    from .problem import ContactPair

    tagged = meshes.hertz(case="B", refinement=refinement, comm=comm)
    mesh, markers = tagged.mesh, tagged.markers
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    u = dolfinx.fem.Function(V, name="displacement")
    v = ufl.TestFunction(V)
    material = Material(200.0, 0.3, "neo-hookean")
    gravity = dolfinx.fem.Constant(mesh, np.array([0.0, 0.0]))
    # the same subdomain data as internal_work's measure (dolfinx allows one per form)
    dx = ufl.Measure("dx", domain=mesh, subdomain_data=tagged.cell_tags)
    F = internal_work(u, v, {markers["cylinder"]: material, markers["block"]: material},
                      tagged.cell_tags) - ufl.inner(gravity, v) * dx
    fdim = mesh.topology.dim - 1
    lift = lift_radii * 8.0

    def dofs(name, sub=None):
        space = V if sub is None else V.sub(sub)
        facets = tagged.facet_tags.find(markers[name])
        return dolfinx.fem.locate_dofs_topological(space, fdim, facets)

    bcs = [dolfinx.fem.dirichletbc(np.zeros(2), dofs("support"), V),
           dolfinx.fem.dirichletbc(np.array([0.0, lift]), dofs("load"), V)]
    for name in ("symmetry_slave", "symmetry_master"):
        bcs.append(dolfinx.fem.dirichletbc(np.float64(0.0), dofs(name, 0), V.sub(0)))
    cylinder = tagged.cell_tags.find(markers["cylinder"])

    def reset() -> None:
        u.x.array[:] = 0.0
        u.interpolate(lambda x: np.vstack([0.0 * x[0], lift + 0.0 * x[0]]), cylinder)
        u.x.scatter_forward()

    def load(t: float) -> None:
        gravity.value[:] = (0.0, -t * body_force)

    pair = ContactPair(tagged.facet_tags, markers["contact_slave"], markers["contact_master"],
                       name="cylinder-block")
    return {"F": F, "u": u, "bcs": bcs, "pair": pair, "reset": reset, "load": load,
            "num_dofs": V.dofmap.index_map.size_global * 2}


def far_apart(refinement: int, repeats: int, steps: int = 2) -> dict:
    """ContactProblem with a pair that never comes near, against PlainNewton; interleaved."""
    from .problem import ContactProblem

    comm = MPI.COMM_WORLD
    scene = far_apart_scene(refinement, comm)
    samples = {"contact": [], "plain": []}
    details: dict = {}

    def run(kind: str) -> dict:
        gc.collect()
        scene["reset"]()
        scene["load"](0.0)
        start = time.perf_counter()
        if kind == "contact":
            solver = ContactProblem(scene["F"], scene["u"], scene["bcs"], [scene["pair"]])
        else:
            solver = PlainNewton(scene["F"], scene["u"], scene["bcs"])
        setup = time.perf_counter() - start
        reports = []
        cpu = time.process_time()
        for step in range(1, steps + 1):
            scene["load"](step / steps)
            if kind == "contact":
                report = solver.solve()
                reports.append({"converged": report.converged, "iterations": report.iterations,
                                "timings": report.timings, "reason": report.reason})
            else:
                reports.append(solver.solve())
        cpu = time.process_time() - cpu
        result = {"setup_s": setup, "solve_cpu_s": cpu,
                  "timings": {k: sum(r["timings"][k] for r in reports) for k in PHASES},
                  "iterations": [r["iterations"] for r in reports],
                  "converged": all(r["converged"] for r in reports),
                  "u": scene["u"].x.array.copy()}
        if kind == "contact":
            result["statistics"] = pair_statistics({"contact_statistics": solver.statistics()})
            result["multiplier_rows"] = solver.interfaces[0].num_global_multipliers
            # each new pair pattern makes ContactProblem build a new monolithic matrix
            result["pattern_versions"] = getattr(solver.interfaces[0], "_pattern_version", None)
        solver.destroy()
        return result

    run("contact")  # warm-up (JIT, first factorizations)
    run("plain")
    for repeat in range(repeats):
        for kind in ("contact", "plain") if repeat % 2 == 0 else ("plain", "contact"):
            result = run(kind)
            samples[kind].append(result)
            log(f"[far-apart {repeat + 1}/{repeats}] r{refinement} {kind}: its "
                f"{result['iterations']}, setup {result['setup_s']:.2f} s, solve "
                f"{result['timings']['total']:.2f} s, load {os.getloadavg()[0]:.2f}")
    for kind, runs in samples.items():
        details[kind] = {
            "setup_s": statistics.median(r["setup_s"] for r in runs),
            "solve_cpu_s": statistics.median(r["solve_cpu_s"] for r in runs),
            "cpu_samples": [r["solve_cpu_s"] for r in runs],
            "timings": median_timings([r["timings"] for r in runs]),
            "solve_samples": [r["timings"]["total"] for r in runs],
            "setup_samples": [r["setup_s"] for r in runs],
            "iterations": runs[0]["iterations"],
            "converged": all(r["converged"] for r in runs),
        }
    contact, plain = samples["contact"][0], samples["plain"][0]
    scale = max(float(np.max(np.abs(plain["u"]))), 1e-300)
    solve_c, solve_p = details["contact"]["timings"]["total"], details["plain"]["timings"]["total"]
    setup_c, setup_p = details["contact"]["setup_s"], details["plain"]["setup_s"]
    return {
        "refinement": refinement,
        "num_dofs": scene["num_dofs"],
        "repeats": repeats,
        "steps": steps,
        "scene": "Hertz B mesh, cylinder lifted by 2R (Dirichlet (0, 2R) on its top and as start "
                 "state), Neo-Hookean, body force (0, -0.2) in 2 steps, no contact load",
        "contact": details["contact"],
        "plain": details["plain"],
        "statistics": contact["statistics"],
        "multiplier_rows": contact["multiplier_rows"],
        "pattern_versions": contact["pattern_versions"],
        "max_displacement_difference_rel": float(np.max(np.abs(contact["u"] - plain["u"])) / scale),
        "overhead_solve": solve_c / solve_p - 1.0,
        "overhead_solve_cpu": details["contact"]["solve_cpu_s"] / details["plain"]["solve_cpu_s"]
        - 1.0,
        "overhead_setup_and_solve": (solve_c + setup_c) / (solve_p + setup_p) - 1.0,
        "overhead_solve_pairwise": [c["timings"]["total"] / p["timings"]["total"] - 1.0
                                    for c, p in zip(samples["contact"], samples["plain"],
                                                    strict=True)],
    }


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
    """Start ``mpirun -n N python3 -m dolfinx_mortar.benchmarks --only parallel ...`` per N."""
    import tempfile

    results, commands = [], []
    scratch = pathlib.Path(tempfile.mkdtemp(prefix="dolfinx_mortar_parallel_"))
    env = dict(os.environ)
    for key in list(env):  # this process's singleton MPI must not leak into mpirun
        if key.startswith(("PMIX_", "OMPI_COMM_", "OMPI_MCA_orte_", "OMPI_FILE_LOCATION")):
            del env[key]
    for n in ranks:
        path = scratch / f"parallel_{n}.json"
        command = ["mpirun", "-n", str(n), sys.executable, "-m", "dolfinx_mortar.benchmarks",
                   "--only", "parallel", "--worker-json", str(path),
                   "--parallel-refinement", str(refinement), "--repeats", str(repeats)]
        commands.append(shlex.join(["mpirun", "-n", str(n), "python3"] + command[4:8]
                                   + ["--worker-json", f"parallel_{n}.json"] + command[10:]))
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


def cost_markdown(data: dict) -> str:
    lines = [f"#### Share of a Newton iteration spent on contact (Hertz B, refinement "
             f"{data['big_refinement']})", "",
             "| material (mortar configuration) | dofs | Newton its | per iteration [ms]: bulk | "
             "search | mortar | linear solve | total | contact share | of which mortar kernels | "
             "goal <= 15 % |", "|" + "---|" * 11]
    for name, r in data["share"].items():
        p = r["per_iteration"]
        lines.append(
            f"| {name} ({r['configuration']}) | {r['num_dofs']} | "
            f"{'+'.join(str(i) for i in r['newton_iterations'])} | {_ms(p['bulk assembly'])} | "
            f"{_ms(p['contact search'])} | {_ms(p['mortar integration'])} | "
            f"{_ms(p['linear solve'])} | {_ms(p['total'])} | {100 * r['contact_share']:.1f} % | "
            f"{100 * r['kernel_share']:.1f} % | "
            f"{'met' if r['contact_share'] <= GOALS['contact_share'] else 'missed'} |")
    lines += ["", "contact share = (contact search + mortar integration) / total of "
              "ContactProblem.solve; 'mortar integration' includes the contact blocks and "
              "the multiplier rows of the monolithic [u, z] matrix (the bulk is assembled in "
              "place, under 'bulk'); 'mortar kernels' = "
              "MortarInterface.statistics time_search + time_integration only.", ""]
    lines += ["#### Mortar time against slave facets (Hertz B, Neo-Hookean, current configuration)",
              "", "| ref | dofs | slave facets | pairs | segments | evaluations | kernel per "
              "evaluation [ms] | search per search [ms] | mortar phase per iteration [ms] | "
              "bulk per iteration [ms] | linear solve per iteration [ms] | Newton its |",
              "|" + "---|" * 12]
    for r in data["scaling"]:
        s, p = r["contact_statistics"], r["per_iteration"]
        lines.append(
            f"| {r['refinement']} | {r['num_dofs']} | {r['slave_facets']} | {s.get('pairs')} | "
            f"{s.get('segments')} | {s.get('evaluations')} | "
            f"{1e3 * r['kernel_time_per_evaluation']:.2f} | "
            f"{1e3 * r['search_time_per_search']:.2f} | {_ms(p['mortar integration'])} | "
            f"{_ms(p['bulk assembly'])} | {_ms(p['linear solve'])} | "
            f"{'+'.join(str(i) for i in r['newton_iterations'])} |")
    sl = data["slopes"]

    def slope(value):
        return "-" if value is None else f"{value:.2f}"

    lines += ["", f"log-log slopes: kernel time per evaluation vs slave facets "
              f"{slope(sl['kernel_per_evaluation'])} (finest three: "
              f"{slope(sl['kernel_per_evaluation_finest_3'])}; goal linear, <= "
              f"{GOALS['mortar_slope']}); pairs vs slave facets {slope(sl['pairs'])}; mortar "
              f"phase per iteration vs slave facets {slope(sl['mortar_phase_per_iteration'])}, vs "
              f"dofs {slope(sl['mortar_phase_per_iteration_vs_dofs'])}; its non-kernel part vs "
              f"dofs {slope(sl['mortar_phase_other_per_iteration_vs_dofs'])}.", ""]
    far = data["far_apart"]
    c, p = far["contact"], far["plain"]
    lines += [f"#### Bodies that never come near: ContactProblem vs plain SNES (refinement "
              f"{far['refinement']}, {far['num_dofs']} dofs, {far['repeats']} repeats, "
              "interleaved)", "",
              "| solver | Newton its | setup [s] | solve [s] | solve CPU [s] | bulk | search | "
              "mortar | linear solve |", "|" + "---|" * 9]
    for name, d in (("ContactProblem (1 pair, never near)", c), ("plain SNES, no pair", p)):
        t = d["timings"]
        lines.append(f"| {name} | {'+'.join(str(i) for i in d['iterations'])} | "
                     f"{d['setup_s']:.3g} | {t['total']:.3g} | {d['solve_cpu_s']:.3g} | "
                     f"{t['bulk assembly']:.3g} | "
                     f"{t['contact search']:.3g} | {t['mortar integration']:.3g} | "
                     f"{t['linear solve']:.3g} |")
    st = far["statistics"]
    lines += ["", f"overhead of the contact pair: solve {100 * far['overhead_solve']:+.1f} % "
              f"(pairwise samples: "
              f"{', '.join(f'{100 * o:+.1f} %' for o in far['overhead_solve_pairwise'])}), setup + "
              f"solve {100 * far['overhead_setup_and_solve']:+.1f} %, solve CPU time "
              f"{100 * far['overhead_solve_cpu']:+.1f} %; goal <= "
              f"{100 * GOALS['far_apart_overhead']:.0f} %: "
              f"{'met' if far['overhead_solve'] <= GOALS['far_apart_overhead'] else 'missed'}. "
              f"Pairs {st.get('pairs')}, searches {st.get('searches_done')} done / "
              f"{st.get('searches_skipped')} skipped (pair pattern versions "
              f"{far['pattern_versions']}: each search, even one finding no pairs, makes a new "
              "monolithic matrix and a new symbolic LU), mortar kernel time "
              f"{1e3 * st.get('time_integration', 0.0):.2f} ms, {far['multiplier_rows']} extra "
              f"(identity) multiplier rows; displacements agree to "
              f"{far['max_displacement_difference_rel']:.1e}.", ""]
    par = data["parallel"]
    lines += [f"#### Hertz B (linear) on 1 and 2 MPI ranks, refinement {par['refinement']}", "",
              "| ranks | dofs | Newton its | solve [s] | solve CPU [s] | bulk | search | mortar | "
              "linear solve | wall [s] | speed-up (solve) | p_max difference to 1 rank |",
              "|" + "---|" * 12]
    for r in par["runs"]:
        if r.get("failed"):
            lines.append(f"| {r['num_ranks']} | failed (exit {r['returncode']}): "
                         f"{r['error'][-200:]!r} |" + " |" * 10)
            continue
        t = r["timings"]
        lines.append(f"| {r['num_ranks']} | {r['num_dofs']} | "
                     f"{'+'.join(str(i) for i in r['newton_iterations'])} | {t['total']:.3g} | "
                     f"{r['solve_cpu_s']:.3g} | {t['bulk assembly']:.3g} | "
                     f"{t['contact search']:.3g} | {t['mortar integration']:.3g} | "
                     f"{t['linear solve']:.3g} | {r['wall_time_s']:.3g} | "
                     f"{_fmt(r.get('speedup_solve'))} | "
                     f"{_fmt(r.get('p_max_difference_rel'))} |")
    lines += ["", "commands: " + "; ".join(f"`{c}`" for c in par["commands"]), ""]
    return "\n".join(lines)


def plot_scaling(data: dict, path: pathlib.Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scaling = data["scaling"]
    facets = np.array([r["slave_facets"] for r in scaling], dtype=float)
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    series = {
        "mortar kernels per evaluation": [r["kernel_time_per_evaluation"] for r in scaling],
        "'mortar integration' phase per Newton iteration":
            [r["per_iteration"]["mortar integration"] for r in scaling],
        "bulk assembly per Newton iteration":
            [r["per_iteration"]["bulk assembly"] for r in scaling],
        "linear solve per Newton iteration":
            [r["per_iteration"]["linear solve"] for r in scaling],
    }
    for label, values in series.items():
        ax.loglog(facets, values, "o-", label=label)
    first = series["mortar kernels per evaluation"]
    ax.loglog(facets, first[-1] * facets / facets[-1], "k:", label="slope 1")
    ax.set_xlabel("slave facets (Hertz B arc, refinements "
                  f"{scaling[0]['refinement']}..{scaling[-1]['refinement']})")
    ax.set_ylabel("time [s] (median)")
    ax.set_title("Neo-Hookean Hertz B: mortar time against slave facets", fontsize=10)
    ax.grid(True, which="both", linewidth=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# -- section 3: skipped work -------------------------------------------------------------


def ab_timing(refinement: int, repeats: int, material: str, extra: list[str], forced,
              name: str) -> dict:
    """Default runs against runs with one reuse switched off, interleaved."""
    default_runs, forced_runs = [], []
    for repeat in range(repeats):
        order = (("default", sizes_probe), ("forced", forced))
        for kind, hook in order if repeat % 2 == 0 else order[::-1]:
            runs = hertz_runs(refinement, 1, material, extra, on_problem=hook,
                              tag=f"skip {name} {kind}")
            (default_runs if kind == "default" else forced_runs).extend(runs)
    result = {}
    for kind, runs in (("default", default_runs), ("forced", forced_runs)):
        record = contact_share_record(runs, kind)
        result[kind] = {k: record[k] for k in ("timings", "contact_statistics", "iterations_total",
                                               "newton_iterations", "kernel_time", "num_dofs",
                                               "timings_samples", "solve_cpu_s")}
        result[kind]["p_max"] = runs[0]["p_max"]
        result[kind]["probe"] = runs[0]["probe"]
    saved = result["forced"]["timings"]["total"] - result["default"]["timings"]["total"]
    result.update(
        refinement=refinement, material=material, options=extra, repeats=repeats,
        saved_solve_s=saved,
        saved_solve_rel=saved / result["forced"]["timings"]["total"],
        saved_cpu_s=result["forced"]["solve_cpu_s"] - result["default"]["solve_cpu_s"],
        saved_cpu_rel=1.0 - result["default"]["solve_cpu_s"] / result["forced"]["solve_cpu_s"],
        same_answer=abs(result["default"]["p_max"] / result["forced"]["p_max"] - 1.0) < 1e-8,
    )
    return result


def skipping(quick: bool, repeats: int, cost: dict | None) -> dict:
    refinement = 2 if quick else 3
    searches = ab_timing(refinement, repeats, "neo-hookean", [], force_search, "search")
    evaluations = {
        "default": ab_timing(refinement, repeats, "neo-hookean", [], force_evaluation,
                             "evaluation"),
        "augmented": ab_timing(refinement, repeats, "neo-hookean", ["--method", "augmented"],
                               force_evaluation, "evaluation (augmented)"),
    }
    far = cost["far_apart"] if cost else far_apart(refinement, repeats)
    if cost:
        uncovered_source = cost["share"]
    else:
        uncovered_source = {
            "linear": contact_share_record(hertz_runs(refinement, 1, "linear"), "linear"),
            "neo-hookean": contact_share_record(hertz_runs(refinement, 1, "neo-hookean"),
                                                "neo-hookean"),
        }
    uncovered = {}
    for name, record in uncovered_source.items():
        s = record["contact_statistics"]
        covered_facets = max(s.get("slave_nodes", 0) - s.get("slave_nodes_uncovered", 0) - 1, 1)
        per_eval = record["kernel_time_per_evaluation"]
        uncovered[name] = {
            "refinement": record["refinement"],
            "slave_nodes": s.get("slave_nodes"),
            "slave_nodes_uncovered": s.get("slave_nodes_uncovered"),
            "slave_facets": record["slave_facets"],
            "master_facets": record["master_facets"],
            "pairs": s.get("pairs"),
            "segments": s.get("segments"),
            "all_pairs": (record["slave_facets"] or 0) * (record["master_facets"] or 0),
            "kernel_time_per_evaluation": per_eval,
            "estimated_time_if_all_covered": per_eval * (record["slave_facets"] or 0)
            / covered_facets,
        }
    return {"searches": searches, "evaluations": evaluations, "far_apart": far,
            "uncovered": uncovered}


def skipping_markdown(data: dict) -> str:
    s = data["searches"]
    d, f = s["default"], s["forced"]
    lines = ["#### Searches reused (Hertz B, Neo-Hookean, refinement "
             f"{s['refinement']}, {s['repeats']} repeats)", "",
             "| run | searches done | searches skipped | search time [s] | 'mortar integration' "
             "[s] | solve [s] | solve CPU [s] | Newton its |", "|" + "---|" * 8]
    for name, r in (("default (reuse while nodes moved < margin/2)", d),
                    ("search in every update (A/B)", f)):
        st = r["contact_statistics"]
        lines.append(f"| {name} | {st.get('searches_done')} | {st.get('searches_skipped')} | "
                     f"{r['timings']['contact search']:.3g} | "
                     f"{r['timings']['mortar integration']:.3g} | {r['timings']['total']:.3g} | "
                     f"{r['solve_cpu_s']:.3g} | "
                     f"{'+'.join(str(i) for i in r['newton_iterations'])} |")
    lines += ["", f"saving: {s['saved_solve_s']:.3g} s of the solve "
              f"({100 * s['saved_solve_rel']:.1f} %; CPU time {100 * s['saved_cpu_rel']:.1f} %); "
              f"same answer: {s['same_answer']}. A new search changes the pair pattern, so the "
              "monolithic matrix is rebuilt: that, not the search itself, is most of the "
              "saving.", ""]
    far = data["far_apart"]
    st = far["statistics"]
    t = far["contact"]["timings"]
    lines += [f"#### No pairs for far-apart surfaces (refinement {far['refinement']}, "
              f"{far['num_dofs']} dofs)", "",
              "| pairs | segments | searches done / skipped | evaluations | mortar kernel time "
              "[ms] | 'mortar integration' phase [s] | solve [s] | plain SNES solve [s] |",
              "|" + "---|" * 8,
              f"| {st.get('pairs')} | {st.get('segments')} | {st.get('searches_done')} / "
              f"{st.get('searches_skipped')} | {st.get('evaluations')} | "
              f"{1e3 * st.get('time_integration', 0.0):.2f} | {t['mortar integration']:.3g} | "
              f"{t['total']:.3g} | {far['plain']['timings']['total']:.3g} |", "",
              "With no pairs the 'mortar integration' phase holds only the multiplier rows "
              "(identity rows of the inactive multipliers) and the residual bookkeeping; the "
              "bulk is assembled in place into the monolithic [u, z] matrix.", ""]
    lines += ["#### Uncovered slave nodes (Hertz B, no mortar work for them)", "",
              "| run | ref | slave nodes | uncovered | slave facets x master facets | pairs "
              "evaluated | segments | kernel per evaluation [ms] | estimated if all covered "
              "[ms] |", "|" + "---|" * 9]
    for name, u in data["uncovered"].items():
        lines.append(f"| {name} | {u['refinement']} | {u['slave_nodes']} | "
                     f"{u['slave_nodes_uncovered']} | {u['all_pairs']} | {u['pairs']} | "
                     f"{u['segments']} | {1e3 * u['kernel_time_per_evaluation']:.2f} | "
                     f"{1e3 * u['estimated_time_if_all_covered']:.2f} |")
    lines += ["", "estimate: kernel time scaled by slave facets / covered slave facets (cost "
              "linear in pairs).", ""]
    lines += ["#### Evaluations skipped (nothing moved since the last evaluation)", "",
              "| run | evaluations | skipped | kernel time [s] | solve [s] | solve CPU [s] | "
              "saving (wall; CPU) | same answer |", "|" + "---|" * 8]
    for name, e in data["evaluations"].items():
        for kind in ("default", "forced"):
            r = e[kind]
            st = r["contact_statistics"]
            label = f"{name}, " + ("default" if kind == "default" else "always evaluate (A/B)")
            saving = (f"{e['saved_solve_s']:.3g} s ({100 * e['saved_solve_rel']:.1f} %); "
                      f"{e['saved_cpu_s']:.3g} s ({100 * e['saved_cpu_rel']:.1f} %)"
                      if kind == "default" else "")
            lines.append(f"| {label} | {st.get('evaluations')} | "
                         f"{st.get('evaluations_skipped', 'n/a')} | {r['kernel_time']:.3g} | "
                         f"{r['timings']['total']:.3g} | {r['solve_cpu_s']:.3g} | {saving} | "
                         f"{e['same_answer'] if kind == 'default' else ''} |")
        if not e["forced"]["probe"].get("forced_evaluation_supported", True):
            lines.append("| (this build has no evaluation skipping: the A/B is void) |"
                         + " |" * 7)
    lines.append("")
    return "\n".join(lines)


# -- goals and the whole run -------------------------------------------------------------------


def goals(work: dict | None, cost: dict | None) -> list[dict]:
    rows = []
    if cost:
        for name, r in cost["share"].items():
            rows.append({"goal": f"contact share of a Newton iteration <= 15 % at >= 1e5 dofs "
                                 f"({name})", "measured": f"{100 * r['contact_share']:.1f} % "
                                 f"({r['num_dofs']} dofs)",
                         "met": r["contact_share"] <= GOALS["contact_share"]
                         and r["num_dofs"] >= 1e5,
                         "note": "" if r["num_dofs"] >= 1e5 else "mesh below 1e5 dofs (quick run)"})
        far = cost["far_apart"]
        rows.append({"goal": "far-apart overhead <= 5 %",
                     "measured": f"{100 * far['overhead_solve']:+.1f} % (solve), "
                                 f"{100 * far['overhead_setup_and_solve']:+.1f} % (setup + solve), "
                                 f"{100 * far['overhead_solve_cpu']:+.1f} % (solve CPU time)",
                     "met": far["overhead_solve"] <= GOALS["far_apart_overhead"], "note": ""})
        slope = cost["slopes"]["kernel_per_evaluation"]
        finest = cost["slopes"]["kernel_per_evaluation_finest_3"]
        rows.append({"goal": "mortar cost linear in slave facets (log-log slope <= 1.1)",
                     "measured": f"slope {slope:.2f} (finest three {finest:.2f})"
                     if slope is not None and finest is not None else "-",
                     "met": slope is not None and slope <= GOALS["mortar_slope"], "note": ""})
    iterations = []
    if work:
        for r in work["runs"]:
            if (not r["failed"] and r["case"].startswith("hertz")
                    and r["variant"] not in ("fixed-point",)
                    and not r["variant"].startswith(("penalty", "augmented"))):
                iterations.append((r["max_iterations_per_step"], r["case"], r["variant"],
                                   r["refinement"]))
    if cost:
        for r in cost["scaling"] + [cost["share"]["linear"]]:
            iterations.append((max(r["newton_iterations"]), "hertz-B " + r["material"], "default",
                               r["refinement"]))
    if iterations:
        worst = max(iterations)
        over = [i for i in iterations if i[0] > GOALS["semismooth_iterations_per_step"]]
        rows.append({"goal": "semismooth Newton <= 8 iterations per load step (Hertz, Lagrange)",
                     "measured": f"max {worst[0]} ({worst[1]}, {worst[2]}, refinement {worst[3]});"
                                 f" {len(over)} of {len(iterations)} runs above 8",
                     "met": worst[0] <= GOALS["semismooth_iterations_per_step"], "note": ""})
    return rows


def goals_markdown(rows: list[dict]) -> str:
    lines = ["| goal | measured | met |", "|---|---|---|"]
    for row in rows:
        note = f" ({row['note']})" if row["note"] else ""
        lines.append(f"| {row['goal']} | {row['measured']}{note} | "
                     f"{'yes' if row['met'] else 'no'} |")
    return "\n".join(lines) + "\n"


def machine_markdown(machine: dict, load: dict, command: str, elapsed: float,
                     label: str = "") -> str:
    code = (f"library: {label + ', ' if label else ''}sources sha256 "
            f"{machine.get('dolfinx_mortar_sources_sha256', '?')}; ")
    return (f"command: `{command}`; {code}{elapsed / 60:.1f} min; {machine['nproc']} cores "
            f"({machine['cpu']}), {machine['memory_gib']} GiB; load average (1 min) during the "
            f"run min {load['min']:.2f} / mean {load['mean']:.2f} / max {load['max']:.2f} "
            f"({load['samples']} samples); {machine['os']}, dolfinx {machine['dolfinx']}, PETSc "
            f"{machine['petsc']}, {machine['mpi'].replace(chr(0), '').strip()}, Python "
            f"{machine['python']}, numpy "
            f"{machine['numpy']}.\n")


def write_json(path: pathlib.Path, data: dict) -> None:
    path.write_text(json.dumps(data, indent=1, default=lambda o: o.tolist()
                               if isinstance(o, np.ndarray) else str(o)) + "\n")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter,
                                     epilog=__doc__.split("\n\n", 1)[1])
    parser.add_argument("--quick", action="store_true",
                        help="refinements 0..2, refinement 3 for the cost, 1 repeat (< 10 min)")
    parser.add_argument("--output", type=pathlib.Path, default=DEFAULT_OUTPUT)
    parser.add_argument("--only", nargs="+", choices=SECTIONS + ("parallel",),
                        help="run only these sections (parallel: the mpirun worker)")
    parser.add_argument("--repeats", type=int, default=None,
                        help="timed repeats (median); default 3, quick 1")
    parser.add_argument("--finest-repeats", type=int, default=None,
                        help="repeats of the finest work-precision refinement and of the cost "
                             "section's Hertz runs (default 1 in the full run, where those "
                             "solves take a minute or more; quick: --repeats)")
    parser.add_argument("--refinements", type=int, nargs="+", default=None,
                        help="work-precision refinements (default 0..4, quick 0..2)")
    parser.add_argument("--variants", nargs="+", default=None,
                        choices=[v["name"] for v in VARIANTS])
    parser.add_argument("--big-refinement", type=int, default=None,
                        help="cost section: Hertz B refinement (default: first with >= 1e5 dofs)")
    parser.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--label", default="",
                        help="free text naming the library version (e.g. a git commit), "
                             "recorded in the outputs")
    parser.add_argument("--render-only", action="store_true",
                        help="only re-create markdown and PNG from the JSON files in --output")
    parser.add_argument("--worker-json", type=pathlib.Path, help=argparse.SUPPRESS)
    parser.add_argument("--parallel-refinement", type=int, default=3, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    quiet_logging()
    repeats = args.repeats if args.repeats is not None else (1 if args.quick else 3)
    finest_repeats = (args.finest_repeats if args.finest_repeats is not None
                      else (repeats if args.quick else 1))

    if args.only == ["parallel"] or args.worker_json:
        if args.worker_json is None:
            parser.error("--only parallel is the mpirun worker: give --worker-json PATH "
                         "(the cost section starts it for 1 and 2 ranks)")
        parallel_worker(args.parallel_refinement, repeats, args.worker_json)
        return 0
    if MPI.COMM_WORLD.size != 1:
        parser.error("run the driver serially; it starts mpirun itself for the parallel runs")
    if args.render_only:
        print(render_only(args.output), end="", flush=True)
        return 0

    sections = args.only or list(SECTIONS)
    output = args.output
    output.mkdir(parents=True, exist_ok=True)
    refinements = args.refinements or ([0, 1, 2] if args.quick else [0, 1, 2, 3, 4])
    variants = [v for v in VARIANTS if args.variants is None or v["name"] in args.variants
                or v["name"] == "default"]
    command = ("python3 -m dolfinx_mortar.benchmarks "
               + shlex.join(argv if argv is not None else sys.argv[1:])).rstrip()
    machine = machine_info()
    begin = time.perf_counter()
    work = cost = skip = None
    timings: dict[str, float] = {}
    with LoadMonitor() as monitor:
        if "work-precision" in sections:
            start = time.perf_counter()
            work = work_precision(refinements, repeats, variants, finest_repeats)
            timings["work-precision"] = time.perf_counter() - start
        if "cost" in sections:
            start = time.perf_counter()
            cost = cost_of_contact(args.quick, finest_repeats, args.ranks, args.big_refinement,
                                   far_apart_repeats=None if args.quick else max(repeats, 5))
            timings["cost"] = time.perf_counter() - start
        if "skip" in sections:
            start = time.perf_counter()
            skip = skipping(args.quick, repeats, cost)
            timings["skip"] = time.perf_counter() - start
    elapsed = time.perf_counter() - begin
    load = monitor.summary()
    meta = {"command": command, "label": args.label, "quick": args.quick, "repeats": repeats,
            "finest_repeats": finest_repeats, "machine": machine,
            "load_average_1min": load, "load_at_end": list(os.getloadavg()),
            "elapsed_s": elapsed, "section_times_s": timings,
            "note": ("quick run: 1 repeat, timings are single samples" if repeats == 1 else
                     f"medians over {repeats} repeats"
                     + (f"; the finest work-precision refinement and the cost section's Hertz "
                        f"runs {finest_repeats} (the far-apart A/B {max(repeats, 5)})"
                        if finest_repeats != repeats else ""))}
    if work is not None:
        write_json(output / "work_precision.json", {"meta": meta, **work})
    if cost is not None:
        write_json(output / "cost_of_contact.json", {"meta": meta, **cost})
    if skip is not None:
        write_json(output / "skipping.json", {"meta": meta, **skip})
    text = render(output, meta, work, cost, skip)
    print(text, end="", flush=True)
    return 0


def render(output: pathlib.Path, meta: dict, work: dict | None, cost: dict | None,
           skip: dict | None) -> str:
    """Markdown, PNG and summary.json of one run, from its data; returns summary.md's text."""
    header = [f"## dolfinx_mortar benchmarks{' (quick)' if meta['quick'] else ''}", "",
              machine_markdown(meta["machine"], meta["load_average_1min"], meta["command"],
                               meta["elapsed_s"], meta.get("label", "")),
              f"Timings: {meta['note']}; section times "
              + ", ".join(f"{k} {v / 60:.1f} min" for k, v in meta["section_times_s"].items())
              + ".", ""]
    parts = ["\n".join(header)]
    goal_rows = goals(work, cost)
    if goal_rows:
        parts.append("### Goals\n\n" + goals_markdown(goal_rows))
    if work is not None:
        plot_work_precision(work, output / "work_precision.png")
        plot_work_precision(work, output / "work_precision_cpu.png", time_key="cpu")
        plot_work_precision(work, output / "work_precision_pmax.png", "p_max_error_rel")
        table = work_precision_markdown(work)
        (output / "work_precision.md").write_text(
            "\n".join(header) + "\n### Work-precision (all refinements)\n\n" + table)
        parts.append("### Work-precision, finest refinement (all refinements: "
                     "work_precision.md)\n\n" + work_precision_markdown(work, finest_only=True))
    if cost is not None:
        plot_scaling(cost, output / "mortar_scaling.png")
        table = cost_markdown(cost)
        (output / "cost_of_contact.md").write_text("\n".join(header) + "\n### Cost of contact\n\n"
                                                   + table)
        parts.append("### Cost of contact\n\n" + table)
    if skip is not None:
        table = skipping_markdown(skip)
        (output / "skipping.md").write_text("\n".join(header) + "\n### Skipped work\n\n" + table)
        parts.append("### Skipped work\n\n" + table)
    text = "\n".join(parts)
    write_json(output / "summary.json", {"meta": meta, "goals": goal_rows})
    (output / "summary.md").write_text(text)
    return text


def render_only(output: pathlib.Path) -> str:
    """Re-create markdown and PNG from the JSON files a run left in ``output``."""
    data = {}
    for name in ("summary", "work_precision", "cost_of_contact", "skipping"):
        path = output / f"{name}.json"
        data[name] = json.loads(path.read_text()) if path.exists() else None
    if data["summary"] is None:
        raise FileNotFoundError(f"{output / 'summary.json'} not found: nothing to render")
    meta = data["summary"]["meta"]
    sections = []
    for name in ("work_precision", "cost_of_contact", "skipping"):
        section = data[name]
        if section is not None and section["meta"]["command"] != meta["command"]:
            section = None  # left over from another run
        if section is not None:
            section = {k: v for k, v in section.items() if k != "meta"}
        sections.append(section)
    return render(output, meta, *sections)


if __name__ == "__main__":
    raise SystemExit(main())
