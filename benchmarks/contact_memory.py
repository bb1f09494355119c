"""Where the memory of a 3D Hertz run goes: resident set around the contact phases.

Runs ``demos/hertz_sphere.py`` (its arguments after ``--``) with the heavy phases
wrapped: the mortar update (search, kernel, stencil), the monolithic matrix's
pattern and the contact blocks' assembly. Each phase prints, on rank 0, its time
and the process's resident set (VmRSS) and peak (VmHWM) before and after it; each
new search prints its candidate pairs and stencil width. ``--whole-facet-dual``
replaces the dual basis over the covered part (``covered.CoveredStencil``, which
widens every pair's stencil by its facet's other master nodes) by the whole-facet
one: on a fully covered slave surface (the Hertz sphere) both give the same answer,
so the difference is the widening's memory. ``--search-margin`` overrides the
default margin (half the mean slave edge length in 3D).

    tools/run python3 benchmarks/contact_memory.py --json out.json -- \\
        --elements-per-radius 5 --refinement 2 --block-size 1.5 --steps 1
"""

from __future__ import annotations

import argparse
import functools
import importlib.util
import json
import pathlib
import time

from mpi4py import MPI

from dolfinx_mortar import covered, layout, mortar, problem, system

DEMO = pathlib.Path(__file__).resolve().parent.parent / "demos" / "hertz_sphere.py"


def memory_mib() -> dict:
    """VmRSS and VmHWM of this process in MiB."""
    values = {}
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith(("VmRSS", "VmHWM")):
                key, value = line.split(":")
                values[key] = int(value.split()[0]) / 1024
    return values


def wrap(records: list, cls, name: str, label: str) -> None:
    original = getattr(cls, name)

    @functools.wraps(original)
    def measured(*args, **kwargs):
        before, start = memory_mib(), time.perf_counter()
        result = original(*args, **kwargs)
        after = memory_mib()
        record = {"phase": label, "seconds": time.perf_counter() - start,
                  "rss_before": before["VmRSS"], "rss_after": after["VmRSS"],
                  "peak_before": before["VmHWM"], "peak_after": after["VmHWM"]}
        if label == "mortar update" and args[0].stencil is not None:
            interface = args[0]
            record.update(candidate_pairs=int(interface.stencil.num_pairs),
                          stencil_width=int(interface.stencil.width),
                          margin=float(interface.reuse.margin))
        records.append(record)
        if MPI.COMM_WORLD.rank == 0:
            extra = (f", {record['candidate_pairs']} candidate pairs, stencil width "
                     f"{record['stencil_width']}" if "candidate_pairs" in record else "")
            print(f"[memory] {label}: {record['seconds']:.2f} s, RSS {before['VmRSS']:.0f}"
                  f" -> {after['VmRSS']:.0f} MiB, peak {after['VmHWM']:.0f} MiB{extra}",
                  flush=True)
        return result

    setattr(cls, name, measured)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--whole-facet-dual", action="store_true",
                        help="the whole-facet dual basis instead of the covered one")
    parser.add_argument("--search-margin", type=float, default=None)
    parser.add_argument("--json", type=pathlib.Path, default=None)
    parser.add_argument("demo_args", nargs=argparse.REMAINDER)
    args = parser.parse_args()
    demo_args = args.demo_args[1:] if args.demo_args[:1] == ["--"] else args.demo_args
    if args.whole_facet_dual:
        covered.CoveredStencil = lambda stencil, **options: stencil
    if args.search_margin is not None:
        original = problem.ContactProblem.__init__

        @functools.wraps(original)
        def with_margin(self, *a, **k):
            k["search_margin"] = args.search_margin
            original(self, *a, **k)

        problem.ContactProblem.__init__ = with_margin
    records: list[dict] = []
    wrap(records, mortar.MortarInterface, "update", "mortar update")
    wrap(records, system.ContactSystem, "_update_pattern", "system pattern")
    wrap(records, system.ContactSystem, "assemble", "system assembly")
    wrap(records, layout.MonolithicMatrix, "__init__", "monolithic matrix")
    spec = importlib.util.spec_from_file_location("hertz_sphere", DEMO)
    demo = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(demo)
    summary = demo.main(demo_args)
    comm = MPI.COMM_WORLD
    peaks = comm.gather(memory_mib()["VmHWM"], root=0)
    if comm.rank == 0:
        result = {"demo_args": demo_args, "whole_facet_dual": args.whole_facet_dual,
                  "search_margin": args.search_margin, "peak_mib_per_rank": peaks,
                  "phases": records, "summary": summary}
        print(f"[memory] peak per rank {[round(p) for p in peaks]} MiB", flush=True)
        if args.json is not None:
            args.json.write_text(json.dumps(result, indent=1, default=str))


if __name__ == "__main__":
    main()
