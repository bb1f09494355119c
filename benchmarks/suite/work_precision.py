"""Section ``work-precision``: Hertz A/B and the patch test over refinements, per variant."""

from __future__ import annotations

import os
import statistics
import time

from .common import log
from .runner import (
    errors_of,
    iterations_per_step,
    median_timings,
    pair_statistics,
    run_demo,
    sizes_probe,
)

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


