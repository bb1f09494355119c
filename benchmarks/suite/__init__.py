"""Benchmarks of dolfinx_mortar: work-precision, cost of contact, skipped work, parallel runs.

A package of the repository's ``benchmarks/`` folder, not of the library: it runs
the demos of a source checkout, imports ``dolfinx_mortar`` like a user would and is
not installed with it. One command runs everything and writes JSON, PNG and
markdown into ``--output`` (default ``benchmarks/results``); what it prints on
stdout is ``summary.md`` there, byte for byte::

    tools/run python3 benchmarks/run.py --quick       # < 10 min on 2 cores
    tools/run python3 benchmarks/run.py               # the full run (about 65 min)
    tools/run python3 benchmarks/run.py --only cost skip --output scratch/b
    tools/run python3 benchmarks/run.py --dim 3 --quick   # the 3D sections

The top-level scripts of ``benchmarks/`` (run as ``python3 benchmarks/NAME.py``,
which puts ``benchmarks/`` first on ``sys.path``) import it as ``suite``.

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

3D sections (``--dim 3`` runs all three, into ``benchmarks/results/3d`` by default):

``patch3d``
    demos/patch_test.py --dim 3 for tetrahedra and hexahedra, ratios 1:1, 2:3,
    3:7, either slave side: pressure and stress deviations, Newton iterations,
    time. -> patch3d.json / .md
``hertz3d``
    demos/hertz_sphere.py (--elements-per-radius 2) over refinements 0..3
    (quick: 0..1), direct (MUMPS LU) and iterative (condensed, GMRES +
    BoomerAMG) linear solver: errors, Newton and Krylov iterations, time, and
    the fitted L2 rate. -> hertz3d.json / .md / .png
``scaling3d``
    Hertz sphere meshes from 1.3e4 dofs up (``--scaling-meshes``), direct
    against iterative, on 1 and 2 ranks, each run a process of its own: time
    per Newton iteration, Krylov iterations per linear solve, peak memory per
    rank; ``--stop-at HH:MM`` (UTC) starts no run that its estimate says
    would end later. -> scaling3d.json / .md / .png

The demos ``demos/hertz.py``, ``demos/patch_test.py`` and ``demos/hertz_sphere.py``
are run in-process through their ``main(argv, comm)`` (loaded on first use, not at
import); everything timed is ``ContactProblem.solve`` (the ``timings`` of its
``SolveReport``), wall times (with mesh generation and setup) are reported next to it.
Modules: common (paths, formats), machine (load, versions), runner (running the
demos), work_precision, far_apart, cost, skipping, three_d (the runs of each
section), report, report3d and plots (markdown, PNG), cli (this command, started by ``run.py``).
"""


from .cli import build_parser, main
from .common import loglog_slope
from .runner import demo, run_demo
from .work_precision import CASES, VARIANTS

__all__ = ["CASES", "VARIANTS", "build_parser", "demo", "loglog_slope", "main", "run_demo"]
