"""Section ``skip``: work skipped where a scene does not need it, each with an A/B timing."""

from __future__ import annotations

from .far_apart import far_apart
from .runner import contact_share_record, force_evaluation, force_search, hertz_runs, sizes_probe


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


