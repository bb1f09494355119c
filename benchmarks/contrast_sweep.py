"""Hertz contact over the stiffness contrast of the two bodies, with either body as slave.

For ``--dim 2`` it runs ``demos/hertz.py`` (a cylinder on a block, ``--slave cylinder``
or ``block``), for ``--dim 3`` ``demos/hertz_sphere.py`` (``--case block``: a sphere on a
block, ``--case sphere``: two spheres; ``--slave sphere`` or ``block``; ``--cell
tetrahedron`` or ``hexahedron``), for every modulus ratio E_upper / E_lower (the
cylinder's or upper sphere's over the lower body's), slave side, cell type and
refinement. Every run is a process of its own (``python3 demos/... --json``, under
``mpirun -n N`` with ``--ranks N``), so a run that fails or hangs is recorded and the
sweep goes on.

Moduli: nu = 0.3 for both bodies, and for a ratio r the lower body gets
E = E* (1 + 1/r) (1 - nu^2) and the upper one r times that, with E* the demo's default
effective modulus, 1/E* = (1 - nu^2)/E_upper + (1 - nu^2)/E_lower (both bodies E = 200:
ratio 100 gives E = 10100 on 101). E*, hence the Hertz half-width a, p0 and the
mesh (refined where the contact zone is, from a) are those of the default case for every
ratio: the load stays the demo's, a stays inside the refined zone, and only the contrast
changes. (The demos are scale free: the same ratio with other moduli and a load scaled
with E* gives the same p_max / p0.)

Reported per run (markdown table and JSON with every demo summary): dofs, p_max / p0 - 1
(p_max the largest pressure the demo reports: in 3D the recovered one, in 2D the
multipliers; ContactProblem's pressure_recovery default), the fitted p0 where the demo fits
one (3D), the contact radius error (a_h - a) / h (a_h from the slave nodes in contact,
h the slave element size in the contact zone), the relative L2 pressure error over the
slave surface (of the pressure p_max is taken from, and in 3D also of the nodal
multipliers: on hexahedra the recovery's fit lowers the concave Hertz pressure, so the
two tell the method's error from the recovery's), Newton iterations per load step,
cut-backs, the linear solver chosen and the demo's wall time; and how many runs have
p_max within ``--goal`` of p0.

Run serially (it starts mpirun itself for ``--ranks``); 2D, the full default sweep
(56 runs with both normals, a few minutes):

    tools/run python3 benchmarks/contrast_sweep.py --dim 2 --normals master \\
        --output benchmarks/results/contrast_sweep
    tools/run python3 benchmarks/contrast_sweep.py --dim 3 --ratios 0.01 1 100 \\
        --refinements 0 --cells tetrahedron --output /tmp/contrast3d
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import pathlib
import shlex
import subprocess
import sys
import tempfile
import time

REPOSITORY = pathlib.Path(__file__).resolve().parents[1]

POISSON = 0.3
DEFAULT_MODULUS = 200.0
"""Both bodies' E in the demos' default case; it sets E* for every ratio."""

RATIOS = (1e-3, 1e-2, 1e-1, 1.0, 1e1, 1e2, 1e3)

DIMENSIONS = {
    2: {
        "demo": "hertz.py",
        "slaves": ("cylinder", "block"),
        "cases": ("B",),
        "cells": ("triangle",),
        "cell_option": "--cell-type",
        "moduli_options": ("--E-cylinder", "--E-block"),
        "poisson_options": ("--nu-cylinder", "--nu-block"),
        "refinements": (2, 3),
    },
    3: {
        "demo": "hertz_sphere.py",
        "slaves": ("sphere", "block"),
        "cases": ("block", "sphere"),
        "cells": ("tetrahedron", "hexahedron"),
        "cell_option": "--cell",
        "moduli_options": ("--E1", "--E2"),
        "poisson_options": ("--nu1", "--nu2"),
        "refinements": (0, 1),
    },
}


def moduli(ratio: float) -> tuple[float, float]:
    """(E_upper, E_lower) with E_upper / E_lower = ratio and the default case's E*."""
    lower = 0.5 * DEFAULT_MODULUS * (1.0 + 1.0 / ratio)
    return ratio * lower, lower


def demo_command(dim: int, case: str, slave: str, cell: str, refinement: int, ratio: float,
                 options: argparse.Namespace, json_path: pathlib.Path) -> list[str]:
    """The demo's command line of one run (under mpirun for more than one rank)."""
    spec = DIMENSIONS[dim]
    upper, lower = moduli(ratio)
    command = [
        sys.executable, str(REPOSITORY / "demos" / spec["demo"]),
        "--case", case, "--slave", slave, spec["cell_option"], cell,
        "--refinement", str(refinement),
        spec["moduli_options"][0], repr(upper), spec["moduli_options"][1], repr(lower),
        spec["poisson_options"][0], repr(POISSON), spec["poisson_options"][1], repr(POISSON),
        *([] if options.normals == "demo" else ["--normals", options.normals]),
        "--multipliers", options.multipliers,
        *shlex.split(options.demo_args), "--json", str(json_path),
    ]
    if options.ranks > 1:
        command = ["mpirun", "-n", str(options.ranks), *command]
    return command


def shown(command: list[str]) -> str:
    """The command as one would type it from the repository (python3, relative paths)."""
    words = ["python3" if word == sys.executable else word for word in command]
    words = [os.path.relpath(word, REPOSITORY) if word.startswith(str(REPOSITORY)) else word
             for word in words]
    return shlex.join(words)


def run_one(command: list[str], json_path: pathlib.Path, timeout: float | None) -> dict:
    """Run one demo process; its summary, or the failure (return code, end of stderr)."""
    start = time.perf_counter()
    try:
        completed = subprocess.run(command, cwd=REPOSITORY, capture_output=True, text=True,
                                   timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"failed": True, "error": f"stopped after --timeout {timeout:g} s",
                "process_wall_s": time.perf_counter() - start}
    process_wall = time.perf_counter() - start
    if completed.returncode != 0 or not json_path.exists():
        return {"failed": True, "returncode": completed.returncode,
                "error": completed.stderr[-3000:], "process_wall_s": process_wall}
    summary = json.loads(json_path.read_text())
    return {"failed": False, "summary": summary, "process_wall_s": process_wall}


def row(run: dict) -> dict:
    """What the table shows of one run (None where the demo does not report it)."""
    s = run["summary"]
    h = s.get("h_slave_measured", s["h_contact"])
    return {
        "dofs": s["num_dofs"],
        "p_max_error_rel": s["p_max_error_rel"],
        "p0_fit_error_rel": s.get("p0_fit_error_rel"),
        "a_error_in_elements": (s["a_contact"] - s["a_exact"]) / h,
        "l2_pressure_error_rel": s["l2_pressure_error_rel"],
        "l2_multiplier_error_rel": s.get("l2_multiplier_error_rel"),
        "total_force_error_rel": s["total_force_error_rel"],
        "newton_iterations": s["newton_iterations"],
        "cutbacks": s["cutbacks"],
        "linear_solver": s["linear_solver"],
        "wall_time_s": s["wall_time_s"],
        "swapped": s.get("swapped", False),
    }


def percent(value: float | None, digits: int = 2) -> str:
    return "-" if value is None else f"{100.0 * value:+.{digits}f} %"


def markdown(record: dict) -> str:
    """The table of every run, and how many meet the p_max goal."""
    goal = record["goal"]
    lines = [
        f"Hertz {record['dim']}D contrast sweep, {record['normals']} normals, "
        f"{record['multipliers']} multipliers, {record['ranks']} rank(s); E_upper / E_lower "
        f"= ratio at the default E* (same a, p0 and mesh for every ratio).",
        "",
        "| case | ratio | slave | cell | refinement | dofs | p_max/p0-1 | p0 fit | "
        "(a_h-a)/h | L2 error | L2 multipliers | force error | Newton | cut-backs | "
        "linear solver | wall [s] |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    met = done = 0
    for run in record["runs"]:
        slave = run["slave"]
        if not run["failed"] and run["row"]["swapped"]:  # slave_side="auto" swapped them
            slave += " (swapped)"
        head = (f"| {run['case']} | {run['ratio']:g} | {slave} | {run['cell']} | "
                f"{run['refinement']} |")
        if run["failed"]:
            error = run["error"].strip().splitlines()[-1] if run["error"].strip() else ""
            lines.append(f"{head} failed: {error.replace('|', '/')} |" + " |" * 10)
            continue
        r = run["row"]
        done += 1
        within = abs(r["p_max_error_rel"]) <= goal
        met += within
        lines.append(
            f"{head} {r['dofs']} | {percent(r['p_max_error_rel'])}{'' if within else ' (!)'} | "
            f"{percent(r['p0_fit_error_rel'])} | {r['a_error_in_elements']:+.2f} | "
            f"{100.0 * r['l2_pressure_error_rel']:.2f} % | "
            f"{percent(r.get('l2_multiplier_error_rel')).lstrip('+')} | "
            f"{r['total_force_error_rel']:.1e} | "
            f"{', '.join(map(str, r['newton_iterations']))} | {r['cutbacks']} | "
            f"{r['linear_solver']} | {r['wall_time_s']:.1f} |"
        )
    failed = len(record["runs"]) - done
    lines += [
        "",
        f"p_max within {100 * goal:g} % of p0 in {met} of {done} runs"
        + (f" ({failed} failed)" if failed else "") + "; (!) marks the others.",
    ]
    return "\n".join(lines) + "\n"


def parse(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--dim", type=int, choices=(2, 3), default=2)
    parser.add_argument("--ratios", type=float, nargs="+", default=list(RATIOS),
                        help="E_upper / E_lower (default: 1e-3 ... 1e3 by decades)")
    parser.add_argument("--slaves", nargs="+",
                        help="slave sides (default: both; 2D cylinder block, 3D sphere block)")
    parser.add_argument("--cases", nargs="+",
                        help="demo cases (default: 2D B, 3D block sphere)")
    parser.add_argument("--cells", nargs="+",
                        help="cell types (default: 2D triangle, 3D tetrahedron hexahedron)")
    parser.add_argument("--refinements", type=int, nargs="+",
                        help="refinement levels (default: 2D 2 3, the demo's default and "
                        "one finer; 3D 0 1)")
    parser.add_argument("--normals", choices=("demo", "averaged", "slave", "master"),
                        default="demo",
                        help="passed to the demo (demo: its default, for a linear material "
                        "the lower body's normals, whichever side is the slave)")
    parser.add_argument("--multipliers", choices=("dual", "standard"), default="dual",
                        help="passed to the demo")
    parser.add_argument("--ranks", type=int, default=1, help="mpirun -n RANKS per run")
    parser.add_argument("--demo-args", default="",
                        help="more options for every demo run, one string (e.g. '--steps 4')")
    parser.add_argument("--goal", type=float, default=0.02,
                        help="|p_max / p0 - 1| counted as met (default 0.02)")
    parser.add_argument("--timeout", type=float, default=None,
                        help="seconds after which a run is stopped and recorded as failed")
    parser.add_argument("--output", type=pathlib.Path, required=True,
                        help="directory of contrast_sweep_{2,3}d_NORMALS.json and .md")
    args = parser.parse_args(argv)
    spec = DIMENSIONS[args.dim]
    for name in ("slaves", "cases", "cells", "refinements"):
        if getattr(args, name) is None:
            setattr(args, name, list(spec[name]))
    for name in ("slaves", "cases", "cells"):
        wrong = sorted(set(getattr(args, name)) - set(spec[name]))
        if wrong:
            parser.error(f"--{name} {' '.join(wrong)}: not one of {' '.join(spec[name])} "
                         f"in {args.dim}D")
    if not all(r > 0.0 and math.isfinite(r) for r in args.ratios):
        parser.error("--ratios must be positive")
    if args.ranks < 1:
        parser.error("--ranks must be at least 1")
    return args


def main(argv: list[str] | None = None) -> dict:
    args = parse(argv)
    args.output.mkdir(parents=True, exist_ok=True)
    stem = f"contrast_sweep_{args.dim}d_{args.normals}"
    scratch = pathlib.Path(tempfile.mkdtemp(prefix="contrast_sweep_"))
    record = {
        "dim": args.dim, "normals": args.normals, "multipliers": args.multipliers,
        "ranks": args.ranks, "goal": args.goal, "demo_args": args.demo_args,
        "poisson": POISSON, "default_modulus": DEFAULT_MODULUS,
        "started": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "command": shlex.join(["python3", "benchmarks/contrast_sweep.py",
                               *(sys.argv[1:] if argv is None else argv)]),
        "runs": [],
    }
    for case in args.cases:
        for cell in args.cells:
            for refinement in args.refinements:
                for ratio in args.ratios:
                    for slave in args.slaves:
                        name = f"{case}_{cell}_r{refinement}_{ratio:g}_{slave}"
                        json_path = scratch / f"{name}.json"
                        command = demo_command(args.dim, case, slave, cell, refinement, ratio,
                                               args, json_path)
                        run = {"case": case, "cell": cell, "refinement": refinement,
                               "ratio": ratio, "slave": slave, "moduli": moduli(ratio),
                               "command": shown(command),
                               "load_1min_start": os.getloadavg()[0],
                               **run_one(command, json_path, args.timeout)}
                        if not run["failed"]:
                            run["row"] = row(run)
                            message = (f"p_max/p0-1 {percent(run['row']['p_max_error_rel'])}, "
                                       f"L2 {100 * run['row']['l2_pressure_error_rel']:.2f} %, "
                                       f"Newton {run['row']['newton_iterations']}")
                        else:
                            message = "FAILED " + run["error"].strip()[-300:]
                        print(f"[{len(record['runs']) + 1}] {name}: {message} "
                              f"({run['process_wall_s']:.1f} s)", file=sys.stderr, flush=True)
                        record["runs"].append(run)
                        json_path.unlink(missing_ok=True)
    scratch.rmdir()
    text = markdown(record)
    print(text)
    (args.output / f"{stem}.md").write_text(text)
    (args.output / f"{stem}.json").write_text(json.dumps(record, indent=1) + "\n")
    return record


if __name__ == "__main__":
    main()
