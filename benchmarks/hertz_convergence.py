"""Convergence of the Hertz contact pressure under mesh refinement, and what limits it.

Runs ``demos/hertz.py`` (case B: P = 10, both bodies E = 200, nu = 0.3, linear
elasticity, dual multipliers, segment-based integration; normals as the demo
chooses them unless ``--normals`` is given) at refinements 0..N for one or more
cylinder radii and fits, by least squares over all meshes, the rate of the
relative L2 error of the pressure against Hertz theory in the slave element
size h. With ``--reference-refinement`` it also fits the rate against a finer
solution of the same problem, which separates discretization error from a
difference between the model and Hertz theory.

What this found: with the arc's averaged normals on the undeformed configuration
(the demo's default until the linear case switched to master normals) the
pressure converges (rate 0.98 against the refinement-5 solution) to a limit
1.7 % (L2) from Hertz at R = 8, so the rate against Hertz is 0.42. The normals
tilt by x/R from the vertical, so the traction leans by up to a/R = 0.12 rad at
the edge of the zone and the zone ends about 0.015 short of a. The offset
shrinks with a/R (rates 0.74 at R = 32, 1.00 at R = 128). With the block's
(master) normals, the common normal of the linearized theory, the limit is
0.29 % from Hertz and the rate against Hertz 0.86.

    tools/run python3 benchmarks/hertz_convergence.py --radii 8 --refinements 0 1 2 3 4 \\
        --reference-refinement 5 --json benchmarks/results/hertz_convergence_R8.json \\
        --markdown benchmarks/results/hertz_convergence_R8.md
    (the same with --normals averaged -> hertz_convergence_R8_averaged.*)
    tools/run python3 benchmarks/hertz_convergence.py --radii 32 128 --refinements 0 1 2 3 \\
        --normals averaged --json benchmarks/results/hertz_convergence_large_R.json \\
        --markdown benchmarks/results/hertz_convergence_large_R.md
"""

from __future__ import annotations

import argparse
import json
import math
import pathlib
import sys

import numpy as np
from mpi4py import MPI

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "demos"))

import hertz  # noqa: E402


def fitted_rate(h: np.ndarray, error: np.ndarray) -> float:
    """Least-squares slope of log(error) against log(h)."""
    return float(np.polyfit(np.log(h), np.log(error), 1)[0])


def profile_difference(x, p, x_ref, p_ref) -> float:
    """Relative L2 distance of two piecewise-linear pressure profiles p(x), p_ref(x_ref).

    Both are linear between the union of their nodes, so the integral of the squared
    difference is exact: h (d0^2 + d0 d1 + d1^2) / 3 on each piece.
    """
    lo, hi = max(x[0], x_ref[0]), min(x[-1], x_ref[-1])
    nodes = np.union1d(x, x_ref)
    nodes = nodes[(nodes >= lo) & (nodes <= hi)]
    h = np.diff(nodes)

    def squared(values):
        v0, v1 = values[:-1], values[1:]
        return float(np.sum(h * (v0 * v0 + v0 * v1 + v1 * v1) / 3.0))

    reference = np.interp(nodes, x_ref, p_ref)
    return math.sqrt(squared(np.interp(nodes, x, p) - reference) / squared(reference))


def run(radii, refinements, comm, reference_refinement=None, extra=()) -> dict:
    results = {}
    for radius in radii:
        rows = []
        profiles = []
        for refinement in refinements:
            summary = hertz.main(
                ["--radius", str(radius), "--refinement", str(refinement), "--steps", "2", *extra],
                comm,
            )
            profiles.append(summary["pressure_profile"])
            rows.append(
                {
                    key: summary[key]
                    for key in (
                        "refinement",
                        "num_dofs",
                        "h_contact",
                        "a_exact",
                        "p_max_error_rel",
                        "a_error_in_elements",
                        "l2_pressure_error_rel",
                        "total_force_error_rel",
                        "newton_iterations",
                        "wall_time_s",
                    )
                }
            )
        h = np.array([r["h_contact"] for r in rows])
        l2 = np.array([r["l2_pressure_error_rel"] for r in rows])
        results[str(radius)] = {
            "normals": summary["normals"],
            "a_over_R": rows[0]["a_exact"] / radius,
            "rows": rows,
            "l2_rate": fitted_rate(h, l2) if len(rows) > 1 else None,
        }
        if reference_refinement is not None:
            reference = hertz.main(
                [
                    "--radius",
                    str(radius),
                    "--refinement",
                    str(reference_refinement),
                    "--steps",
                    "2",
                    *extra,
                ],
                comm,
            )
            x_ref = np.array(reference["pressure_profile"]["x"])
            p_ref = np.array(reference["pressure_profile"]["pressure"])
            for row, profile in zip(rows, profiles, strict=True):
                row["l2_difference_to_reference_rel"] = profile_difference(
                    np.array(profile["x"]), np.array(profile["pressure"]), x_ref, p_ref
                )
            difference = np.array([r["l2_difference_to_reference_rel"] for r in rows])
            results[str(radius)]["reference"] = {
                "refinement": reference_refinement,
                "num_dofs": reference["num_dofs"],
                "h_contact": reference["h_contact"],
                "normals": reference["normals"],
                "l2_pressure_error_rel": reference["l2_pressure_error_rel"],
                "p_max_error_rel": reference["p_max_error_rel"],
                "wall_time_s": reference["wall_time_s"],
            }
            results[str(radius)]["l2_rate_to_reference"] = fitted_rate(h, difference)
    return results


def markdown(results: dict) -> str:
    lines = []
    for radius, data in results.items():
        reference = data.get("reference")
        header = (
            f"R = {radius} (a/R = {data['a_over_R']:.3f}), {data['normals']} normals: "
            f"fitted L2 rate against Hertz "
            f"{data['l2_rate']:.2f} over {len(data['rows'])} meshes"
        )
        extra_head = extra_rule = ""
        if reference is not None:
            header += (
                f"; against the refinement-{reference['refinement']} solution of the same "
                f"problem ({reference['num_dofs']} dofs, h/a "
                f"{reference['h_contact'] / data['rows'][0]['a_exact']:.4f}) "
                f"{data['l2_rate_to_reference']:.2f}. That solution itself is "
                f"{100 * reference['l2_pressure_error_rel']:.2f} % from Hertz in L2 "
                f"(p_max {100 * reference['p_max_error_rel']:+.2f} %)."
            )
            extra_head, extra_rule = f" L2 to ref {reference['refinement']} |", "---|"
        lines.append(header + "\n")
        lines.append(
            "| refinement | dofs | h / a | p_max error | a error (elements) | L2 error "
            f"|{extra_head} Newton per step | time (s) |"
        )
        lines.append(f"|---|---|---|---|---|---|{extra_rule}---|---|")
        for r in data["rows"]:
            extra = (
                f" {100 * r['l2_difference_to_reference_rel']:.2f} % |"
                if reference is not None
                else ""
            )
            lines.append(
                f"| {r['refinement']} | {r['num_dofs']} | {r['h_contact'] / r['a_exact']:.4f} "
                f"| {100 * r['p_max_error_rel']:+.2f} % | {r['a_error_in_elements']:.2f} "
                f"| {100 * r['l2_pressure_error_rel']:.2f} % |{extra}"
                f" {', '.join(map(str, r['newton_iterations']))} | {r['wall_time_s']:.1f} |"
            )
        lines.append("")
    return "\n".join(lines)


def main(argv=None, comm: MPI.Intracomm = MPI.COMM_WORLD) -> dict:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--radii", type=float, nargs="+", default=[8.0, 128.0])
    parser.add_argument("--refinements", type=int, nargs="+", default=[0, 1, 2, 3])
    parser.add_argument(
        "--reference-refinement",
        type=int,
        help="also fit the rate against this (finer) refinement of the same problem",
    )
    parser.add_argument(
        "--normals",
        choices=("averaged", "slave", "master"),
        help="normals option of the demo (default: the demo's, master for linear elasticity)",
    )
    parser.add_argument("--json", type=pathlib.Path)
    parser.add_argument("--markdown", type=pathlib.Path)
    args = parser.parse_args(argv)
    extra = ["--normals", args.normals] if args.normals else []
    results = run(args.radii, args.refinements, comm, args.reference_refinement, extra)
    if comm.rank == 0:
        text = markdown(results)
        print(text)
        if args.json:
            args.json.parent.mkdir(parents=True, exist_ok=True)
            args.json.write_text(json.dumps(results, indent=1))
        if args.markdown:
            args.markdown.parent.mkdir(parents=True, exist_ok=True)
            args.markdown.write_text(text)
    return results


if __name__ == "__main__":
    main()
