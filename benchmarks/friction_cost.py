"""What friction costs: the same demo frictionless, with mu = 0 and with Coulomb friction.

Runs each case ``--repeats`` times in this process, the variants interleaved, and
reports the median wall time, the Newton iterations (total and largest per
step) and the answer, as a markdown table (and JSON with ``--json``):

    tools/run python3 benchmarks/friction_cost.py --repeats 3 --json scratch/friction_cost.json

Cases: 2D ironing (500 steps, Neo-Hookean, mu = 0.3, the frictional shallow
ironing benchmark) and Hertz case B at refinement 2 (mu = 0.3; similar
materials, so friction changes the pressure only slightly); in 3D (two
tangential multipliers per node) the Hertz sphere on a block (quarter model,
2 elements per contact radius, refinement 1) and the 3D ironing setup with one
hexahedron through the thickness to t = 1.5 (375 of the 500 steps).
"""

from __future__ import annotations

import argparse
import json
import pathlib
import statistics

import numpy as np
from mpi4py import MPI

from suite.runner import demo

CASES = {
    "ironing": ("ironing", ["--steps", "500"], "vertical_force_at_t1_5"),
    "hertz": ("hertz", ["--refinement", "2", "--steps", "2"], "p_max"),
    "hertz_sphere": ("hertz_sphere", ["--elements-per-radius", "2", "--refinement", "1"],
                     "p_max"),
    "ironing3d": ("ironing", ["--dim", "3", "--layers", "1", "--steps", "500",
                              "--end-time", "1.5"], "horizontal_force_at_t1_5"),
}
VARIANTS = {"frictionless": [], "mu = 0": ["--mu", "0"], "mu = 0.3": ["--mu", "0.3"]}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--cases", nargs="+", choices=tuple(CASES), default=list(CASES))
    parser.add_argument("--json", type=pathlib.Path, default=None)
    args = parser.parse_args(argv)
    import logging

    logging.getLogger("dolfinx_mortar").setLevel(logging.WARNING)
    rows = []
    for case in args.cases:
        name, base, key = CASES[case]
        module = demo(name)
        # repeats interleaved (A B C A B C ...), so that load from elsewhere hits all alike
        results = {variant: [] for variant in VARIANTS}
        for _ in range(args.repeats):
            for variant, extra in VARIANTS.items():
                results[variant].append(module.main(base + extra, comm=MPI.COMM_WORLD))
        for variant, runs in results.items():
            iterations = np.array(runs[0]["newton_iterations"])
            rows.append({
                "case": case, "variant": variant,
                "wall_time_s": statistics.median(r["wall_time_s"] for r in runs),
                "newton_total": int(iterations.sum()), "newton_max": int(iterations.max()),
                "steps": int(iterations.size), "answer_key": key, "answer": runs[0][key],
            })
    lines = ["| case | variant | wall time (median) | Newton total | max per step | answer |",
             "|---|---|---|---|---|---|"]
    for row in rows:
        lines.append(f"| {row['case']} | {row['variant']} | {row['wall_time_s']:.1f} s | "
                     f"{row['newton_total']} | {row['newton_max']} | "
                     f"{row['answer_key']} = {row['answer']:.6g} |")
    print("\n".join(lines))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
