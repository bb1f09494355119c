"""The command line: ``python3 benchmarks/run.py`` (options: ``--help``)."""

from __future__ import annotations

import argparse
import os
import pathlib
import shlex
import sys
import time

from mpi4py import MPI

from . import __doc__ as PACKAGE_DOC
from . import three_d
from .common import DEFAULT_OUTPUT, SECTIONS, SECTIONS_3D, write_json
from .cost import cost_of_contact, parallel_worker
from .machine import LoadMonitor, machine_info
from .report import render, render_only
from .runner import quiet_logging
from .skipping import skipping
from .work_precision import VARIANTS, work_precision


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=PACKAGE_DOC.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter,
                                     epilog=PACKAGE_DOC.split("\n\n", 1)[1])
    parser.add_argument("--quick", action="store_true",
                        help="refinements 0..2, refinement 3 for the cost, 1 repeat (< 10 min)")
    parser.add_argument("--output", type=pathlib.Path, default=None,
                        help=f"default {DEFAULT_OUTPUT} (3D sections only: its 3d/)")
    parser.add_argument("--dim", type=int, choices=(2, 3), default=2,
                        help="the sections run without --only: 2D (work-precision cost skip) "
                             "or 3D (patch3d hertz3d scaling3d)")
    parser.add_argument("--only", nargs="+", choices=SECTIONS + SECTIONS_3D + ("parallel",),
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
    three = parser.add_argument_group("3D sections")
    three.add_argument("--patch-cells", nargs="+", default=list(three_d.PATCH_CELLS),
                       choices=three_d.PATCH_CELLS)
    three.add_argument("--patch-ratios", nargs="+", default=list(three_d.PATCH_RATIOS))
    three.add_argument("--hertz-refinements", type=int, nargs="+", default=None,
                       help="hertz3d refinements (default 0..3, quick 0..1; each run "
                            "--finest-repeats times)")
    three.add_argument("--elements-per-radius", type=int, default=2,
                       help="hertz3d: the demo's --elements-per-radius")
    three.add_argument("--hertz-variants", nargs="+", default=None,
                       choices=[v["name"] for v in three_d.HERTZ3D_VARIANTS])
    three.add_argument("--direct-max-refinement", type=int, default=None,
                       help="hertz3d: no direct solves above this refinement")
    three.add_argument("--scaling-meshes", nargs="+", type=three_d.parse_mesh, default=None,
                       metavar="N0:REF",
                       help="scaling3d meshes, elements per radius:refinement, growing (default "
                            "4:1 2:2 4:2 2:3 2:4, i.e. 1.3e4 .. 1.6e6 dofs; quick 2:0 2:1)")
    three.add_argument("--scaling-solvers", nargs="+", default=list(three_d.SCALING3D_SOLVERS),
                       choices=three_d.SCALING3D_SOLVERS)
    three.add_argument("--scaling-stored", nargs="+", type=pathlib.Path, default=None,
                       metavar="JSON", help="scaling3d: add runs made separately (worker "
                       "records with their command, e.g. a >= 1e6-dof run), marked stored")
    three.add_argument("--stop-at", default=None, metavar="HH:MM",
                       help="scaling3d: UTC time by which every run must have ended")
    parser.add_argument("--worker-json", type=pathlib.Path, help=argparse.SUPPRESS)
    parser.add_argument("--parallel-refinement", type=int, default=3, help=argparse.SUPPRESS)
    parser.add_argument("--worker-demo", help=argparse.SUPPRESS)
    parser.add_argument("--worker-argv", default="", help=argparse.SUPPRESS)
    return parser


def sections_of(args: argparse.Namespace) -> list[str]:
    """The sections a parsed command line runs."""
    if args.only:
        return [s for s in args.only if s != "parallel"]
    return list(SECTIONS if args.dim == 2 else SECTIONS_3D)


def output_of(args: argparse.Namespace) -> pathlib.Path:
    """--output, else benchmarks/results (its 3d/ if only 3D sections run)."""
    if args.output is not None:
        return args.output
    sections = sections_of(args)
    if sections and all(s in SECTIONS_3D for s in sections):
        return DEFAULT_OUTPUT / "3d"
    return DEFAULT_OUTPUT


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    quiet_logging()
    repeats = args.repeats if args.repeats is not None else (1 if args.quick else 3)
    finest_repeats = (args.finest_repeats if args.finest_repeats is not None
                      else (repeats if args.quick else 1))

    if args.worker_demo:
        if args.worker_json is None:
            parser.error("--worker-demo needs --worker-json PATH")
        three_d.scaling_worker(args.worker_demo, shlex.split(args.worker_argv),
                               args.worker_json)
        return 0
    if args.only == ["parallel"] or args.worker_json:
        if args.worker_json is None:
            parser.error("--only parallel is the mpirun worker: give --worker-json PATH "
                         "(the cost section starts it for 1 and 2 ranks)")
        parallel_worker(args.parallel_refinement, repeats, args.worker_json)
        return 0
    if MPI.COMM_WORLD.size != 1:
        parser.error("run the driver serially; it starts mpirun itself for the parallel runs")
    output = output_of(args)
    if args.render_only:
        print(render_only(output), end="", flush=True)
        return 0

    sections = sections_of(args)
    output.mkdir(parents=True, exist_ok=True)
    refinements = args.refinements or ([0, 1, 2] if args.quick else [0, 1, 2, 3, 4])
    variants = [v for v in VARIANTS if args.variants is None or v["name"] in args.variants
                or v["name"] == "default"]
    command = ("python3 benchmarks/run.py "
               + shlex.join(argv if argv is not None else sys.argv[1:])).rstrip()
    three_d_run = any(s in SECTIONS_3D for s in sections)
    machine = machine_info(("hertz", "patch_test") + (("hertz_sphere",) if three_d_run else ()))
    begin = time.perf_counter()
    work = cost = skip = None
    three: dict[str, dict] = {}
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
        if "patch3d" in sections:
            start = time.perf_counter()
            three["patch3d"] = three_d.patch3d(repeats, args.patch_cells, args.patch_ratios)
            timings["patch3d"] = time.perf_counter() - start
        if "hertz3d" in sections:
            start = time.perf_counter()
            hertz_variants = [v for v in three_d.HERTZ3D_VARIANTS if args.hertz_variants is None
                              or v["name"] in args.hertz_variants]
            three["hertz3d"] = three_d.hertz3d(
                args.hertz_refinements or ([0, 1] if args.quick else [0, 1, 2, 3]),
                finest_repeats, hertz_variants, args.elements_per_radius,
                args.direct_max_refinement)
            timings["hertz3d"] = time.perf_counter() - start
        if "scaling3d" in sections:
            start = time.perf_counter()
            meshes = args.scaling_meshes or (
                [(2, 0), (2, 1)] if args.quick else list(three_d.SCALING3D_MESHES))
            three["scaling3d"] = three_d.scaling3d(meshes, args.scaling_solvers, args.ranks,
                                                   args.stop_at, args.scaling_stored)
            timings["scaling3d"] = time.perf_counter() - start
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
    for name, data in three.items():
        write_json(output / f"{name}.json", {"meta": meta, **data})
    text = render(output, meta, work, cost, skip, three)
    print(text, end="", flush=True)
    return 0
