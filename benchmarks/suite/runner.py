"""Running the demos in-process: ``demos/NAME.py``'s main(argv) with probes, and the
records (errors, timings, the contact share) made of their summaries."""

from __future__ import annotations

import contextlib
import gc
import importlib.util
import io
import logging
import os
import resource
import statistics
import time
import typing

from mpi4py import MPI

from .common import DEMOS, PHASES, log

ERROR_KEYS = {
    "hertz": ("p_max_error_rel", "a_error_rel", "a_error_in_elements", "l2_pressure_error_rel",
              "total_force_error_rel"),
    "patch_test": ("max_pressure_deviation_rel", "max_stress_deviation_rel",
                   "pressure_nonuniformity_rel"),
}


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


