"""The benchmark suite (``benchmarks/suite``, run by ``benchmarks/run.py``): its pure parts
(fits, tables, command line) on hand-made data, one real 3D patch-test run through the
benchmark code path, and the library apart from it (nothing of the benchmarks or the demos'
command line is installed with ``dolfinx_mortar``)."""

from __future__ import annotations

import json
import math
import pathlib
import subprocess
import sys

import numpy as np
import pytest

REPOSITORY = pathlib.Path(__file__).resolve().parents[1]
BENCHMARKS = REPOSITORY / "benchmarks"
if str(BENCHMARKS) not in sys.path:  # as ``python3 benchmarks/run.py`` finds it
    sys.path.insert(0, str(BENCHMARKS))

from suite import cli, common, report, report3d, three_d  # noqa: E402


def test_loglog_slope_recovers_powers():
    """y = x^2 has slope 2, y = 3 x^-1/2 slope -1/2; fewer than two positive pairs: None."""
    x = np.array([1.0, 2.0, 4.0, 8.0, 16.0])
    assert math.isclose(common.loglog_slope(x, x**2), 2.0, rel_tol=1e-12)
    assert math.isclose(common.loglog_slope(x, 3.0 / np.sqrt(x)), -0.5, rel_tol=1e-12)
    assert common.loglog_slope([1.0, 2.0], [0.0, 4.0]) is None


def patch_run(cell, ratio, deviation, dofs):
    return {"cell": cell, "ratio": ratio, "slave": "top", "num_dofs": dofs,
            "newton_iterations": 1, "exact": deviation < three_d.PATCH_TOLERANCE,
            "deviations": {"max_pressure_deviation_rel": deviation,
                           "max_pressure_deviation_interior_rel": 0.0,
                           "max_stress_deviation_rel": 2e-15,
                           "pressure_nonuniformity_rel": 3e-15},
            "timings": {"total": 0.25}, "wall_time_s": 0.5}


PATCH = {"repeats": 1, "tolerance": 1e-10, "max_deviation": 1e-3, "all_exact": False,
         "runs": [patch_run("tetrahedron", "1:1", 5e-15, 48),
                  patch_run("hexahedron", "3:7", 1e-3, 864)]}


def test_patch3d_markdown_rows():
    """One table row per run, in order, with the deviations and the exact/not verdict."""
    lines = report3d.patch3d_markdown(PATCH).splitlines()
    assert lines[0].startswith("| cell | ratio | slave | dofs | Newton its | pressure deviation")
    assert lines[2] == ("| tetrahedron | 1:1 | top | 48 | 1 | 5.00e-15 | 0 | 2.00e-15 | "
                        "3.00e-15 | 0.25 | 0.5 | yes |")
    assert lines[3] == ("| hexahedron | 3:7 | top | 864 | 1 | 0.001 | 0 | 2.00e-15 | 3.00e-15 "
                        "| 0.25 | 0.5 | no |")
    assert lines[4] == ""


def hertz_run(variant, refinement, h, error, dofs):
    return {"variant": variant, "refinement": refinement, "failed": False, "num_dofs": dofs,
            "h_slave_measured": h,
            "errors": {key: error for key in three_d.HERTZ3D_ERRORS},
            "newton_iterations": [3, 2], "krylov_iterations": [12, 9],
            "inner_krylov_iterations": [4, 9, 6, 7],
            "timings": {"total": 2.0, "bulk assembly": 0.5, "contact search": 0.0,
                        "mortar integration": 0.5, "linear solve": 1.0},
            "wall_time_s": 3.0, "peak_rss_mib": 100.0}


def test_hertz3d_rates_and_rows():
    """Errors exactly c h^(3/4) on meshes with dofs ~ h^-3 fit the rate 3/4 against h and
    -1/4 against dofs; a run not done is a row with its reason."""
    h = 0.1 / 2.0 ** np.arange(4)
    runs = [hertz_run("iterative", k, h[k], 0.5 * h[k] ** 0.75, int(round(h[k] ** -3)))
            for k in range(4)]
    runs.append({"variant": "direct", "refinement": 3, "failed": True,
                 "error": "not run (--direct-max-refinement 2)"})
    rates = three_d.hertz3d_rates(runs, three_d.HERTZ3D_VARIANTS)
    assert math.isclose(rates["iterative"]["l2_vs_h"], 0.75, rel_tol=1e-12)
    assert math.isclose(rates["iterative"]["l2_vs_h_finest_3"], 0.75, rel_tol=1e-12)
    assert math.isclose(rates["iterative"]["l2_vs_dofs"], -0.25, rel_tol=1e-6)
    assert rates["direct"]["l2_vs_h"] is None
    data = {"runs": runs, "rates": rates, "elements_per_radius": 2, "repeats": 1}
    lines = report3d.hertz3d_markdown(data).splitlines()
    assert lines[2].startswith("| iterative | 0 | 1000 | 0.1000 | 0.0889 | 0.0889 |")
    assert lines[2].endswith("| 3+2 | 12+9 | 6.5 / 9 | 2 | 25 % | 0 % | 25 % | 50 % | 3 | 100 |")
    assert lines[6].startswith("| direct | 3 | not run (--direct-max-refinement 2) |")
    assert ("- iterative (refinements 0, 1, 2, 3): 0.75 against h (0.75 over the finest three), "
            "-0.25 against dofs") in lines
    assert "- direct: no run done" in lines


def test_cli_parses_3d_options():
    """--dim 3 selects the three 3D sections and benchmarks/results/3d; --only mixes
    sections; meshes are N0:REF pairs; without options the 2D sections run as before."""
    parser = cli.build_parser()
    args = parser.parse_args(["--dim", "3", "--scaling-meshes", "4:1", "2:3",
                              "--scaling-solvers", "iterative", "--stop-at", "19:20",
                              "--hertz-refinements", "0", "1", "--direct-max-refinement", "0"])
    assert cli.sections_of(args) == ["patch3d", "hertz3d", "scaling3d"]
    assert cli.output_of(args) == common.DEFAULT_OUTPUT / "3d"
    assert args.scaling_meshes == [(4, 1), (2, 3)]
    assert args.scaling_solvers == ["iterative"] and args.stop_at == "19:20"
    assert args.hertz_refinements == [0, 1] and args.direct_max_refinement == 0
    args = parser.parse_args([])
    assert cli.sections_of(args) == ["work-precision", "cost", "skip"]
    assert cli.output_of(args) == common.DEFAULT_OUTPUT
    args = parser.parse_args(["--only", "cost", "patch3d", "--output", "x"])
    assert cli.sections_of(args) == ["cost", "patch3d"] and cli.output_of(args) == pathlib.Path("x")
    with pytest.raises(SystemExit):
        parser.parse_args(["--only", "hertz4d"])


def test_import_loads_no_demo_and_help_runs():
    """Importing the suite loads no demo module; ``python3 benchmarks/run.py --help`` lists
    the 3D sections."""
    code = (f"import sys; sys.path.insert(0, {str(BENCHMARKS)!r}); import suite as b; "
            "print(sorted(m for m in sys.modules if m.startswith('benchmark_demo_')), "
            "len(b.runner._MODULES))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == "[] 0"
    help_text = subprocess.run([sys.executable, str(BENCHMARKS / "run.py"), "--help"],
                               capture_output=True, text=True, check=True).stdout
    for word in ("--dim {2,3}", "patch3d", "hertz3d", "scaling3d", "--render-only"):
        assert word in help_text


MACHINE = {"nproc": 2, "cpu": "test cpu", "memory_gib": 1.0, "os": "test os",
           "dolfinx": "0", "petsc": "0", "mpi": "test mpi", "python": "3", "numpy": "2",
           "dolfinx_mortar_sources_sha256": "0123"}


def test_render_and_render_only_3d(tmp_path):
    """A 3D patch section renders its table and the goal row; render-only from the saved
    JSON gives the same summary."""
    meta = {"command": "python3 benchmarks/run.py --only patch3d", "label": "",
            "quick": True, "machine": MACHINE, "elapsed_s": 60.0, "note": "test",
            "section_times_s": {"patch3d": 60.0},
            "load_average_1min": {"min": 0.0, "mean": 0.5, "max": 1.0, "samples": 3}}
    text = report.render(tmp_path, meta, None, None, None, {"patch3d": PATCH})
    assert ("| 3D patch test exact (deviations < 1e-10) | largest deviation 0.001 (2 runs) | no |"
            in text.splitlines())
    assert report3d.patch3d_markdown(PATCH) in (tmp_path / "patch3d.md").read_text()
    common.write_json(tmp_path / "patch3d.json", {"meta": meta, **PATCH})
    assert json.loads((tmp_path / "summary.json").read_text())["goals"][0]["met"] is False
    assert report.render_only(tmp_path) == text


def test_patch3d_smallest_case_is_exact():
    """The smallest 3D patch test (hexahedra 1:1, 48 dofs) through three_d.patch3d: one
    Newton iteration, uniform pressure and stress to 1e-10."""
    data = three_d.patch3d(1, cells=("hexahedron",), ratios=("1:1",), slaves=("top",),
                           warm_up=False)
    (run,) = data["runs"]
    assert run["converged"] and run["newton_iterations"] == 1 and run["num_dofs"] == 48
    assert max(run["deviations"].values()) < 1e-10
    assert run["exact"] and data["all_exact"] and data["max_deviation"] < 1e-10
    assert run["timings"]["total"] > 0.0


def test_scaling3d_stored_run_becomes_a_marked_row(tmp_path):
    """A worker record saved apart (a run too long for the benchmark command) is read by
    --scaling-stored, gets its per-Newton times (total / Newton iterations) and is shown
    as stored with the load of its own run."""
    record = {"num_dofs": 1000, "num_ranks": 2, "elements_per_radius": 2, "refinement": 4,
              "linear_solver": "iterative", "newton_iterations": [3, 2],
              "krylov_iterations": [12, 9], "krylov_per_linear_solve": 4.2,
              "inner_krylov_iterations": [4, 9, 6, 7],
              "timings": {"total": 10.0, "linear solve": 5.0}, "wall_time_s": 12.0,
              "process_run_s": 13.0, "peak_rss_mib_per_rank": [300.0, 200.0],
              "errors": {"l2_pressure_error_rel": 0.01}, "load_1min_start": 2.0,
              "load_1min_end": 3.5, "command": "mpirun -n 2 python3 x"}
    path = tmp_path / "stored.json"
    path.write_text(json.dumps(record))
    args = cli.build_parser().parse_args(["--only", "scaling3d", "--scaling-stored", str(path)])
    assert args.scaling_stored == [path]
    runs = three_d.stored_runs(path)
    assert len(runs) == 1 and runs[0]["time_per_newton_s"] == 2.0
    assert runs[0]["linear_solve_per_newton_s"] == 1.0 and runs[0]["process_wall_s"] == 13.0
    data = {"runs": runs, "solvers": ["iterative"], "ranks": [2]}
    lines = report3d.scaling3d_markdown(data).splitlines()
    assert lines[2] == ("| iterative (stored) | 2 | 2:4 | 1000 | 3+2 | 4.2 | 6.5 / 9 | 2 | 1 | "
                        "10 | 12 | 13 | 300, 200 | 0.01 | 2.0 / 3.5 |")
    assert "commands: `mpirun -n 2 python3 x`" in lines


def test_library_ships_neither_benchmarks_nor_demo_helpers():
    """``dolfinx_mortar`` has no ``benchmarks`` subpackage and no ``cli`` module, and no
    module of it imports the suite, the demos or their command line (``benchmarks/``,
    ``demos/`` and ``demos/cli.py`` live in the repository only)."""
    import importlib.util

    import dolfinx_mortar

    assert importlib.util.find_spec("dolfinx_mortar.benchmarks") is None
    assert importlib.util.find_spec("dolfinx_mortar.cli") is None
    package = pathlib.Path(dolfinx_mortar.__file__).parent
    for path in package.rglob("*.py"):
        for line in path.read_text().splitlines():
            words = line.split()
            if words[:1] in (["import"], ["from"]) and len(words) > 1:
                module = words[1].split(".")[0]
                assert module not in ("benchmarks", "suite", "demos", "cli"), (path, line)


def contact_vs_bonded():
    import importlib.util

    spec = importlib.util.spec_from_file_location("contact_vs_bonded",
                                                  BENCHMARKS / "contact_vs_bonded.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_contact_vs_bonded_measures_both_on_the_same_mesh(tmp_path):
    """Issue 26's baseline: the bonded solve converges (CG + GAMG, block size 3, the
    six rigid-body modes) on the contact problem's mesh (same dofs); the contact run's
    parts are recorded (the inner iterations per set-up, one application per outer
    iteration, times per Newton iteration) and the ratio is the contact time per Newton
    iteration over the median of the bonded solves after the first (which pays one-off
    costs)."""
    path = tmp_path / "cvb.json"
    result = contact_vs_bonded().main(["--refinement", "0", "--bonded-repeats", "3",
                                       "--json", str(path), "--", "--steps", "1",
                                       "--linear-solver", "iterative"])
    bonded, contact = result["bonded"], result["contact"]
    solve = bonded["solves"][0]
    assert solve["reason"] > 0 and 0 < solve["iterations"] < 100
    assert solve["block_size"] == 3 and bonded["near_nullspace_vectors"] == 6
    assert bonded["num_dofs"] == contact["num_dofs"] == 2703
    assert contact["linear_solver"] == "iterative" and contact["inner_solver"] == "hypre"
    newton = sum(contact["newton_iterations"])
    assert len(contact["inner_iterations"]) == newton
    assert contact["applications"] == sum(contact["outer_iterations"])
    per_newton = contact["per_newton_s"]
    assert per_newton["total"] == pytest.approx(contact["timings"]["total"] / newton)
    assert len(bonded["solves"]) == 3
    later = sorted(s["total_s"] for s in bonded["solves"][1:])
    assert bonded["median_s"] == pytest.approx(0.5 * (later[0] + later[1]))
    assert result["ratio"] == pytest.approx(per_newton["total"] / bonded["median_s"])
    assert json.loads(path.read_text())["bonded"]["num_dofs"] == 2703


def test_contact_vs_bonded_reports_that_friction_takes_the_direct_solver():
    """Below solvers.AUTO_ITERATIVE_MIN_DOFS a frictional problem takes the direct solver,
    as a frictionless one does: the record says which solver ran, and there is no inner
    solve to report."""
    result = contact_vs_bonded().main(["--refinement", "0", "--bonded-repeats", "1", "--",
                                       "--steps", "1", "--mu", "0.3"])
    contact = result["contact"]
    assert contact["linear_solver"] == "direct"
    assert contact["friction"] == ["coulomb", 0.3]
    assert contact["inner_solver"] is None and contact["applications"] == 0


def test_edge_ratios_of_a_unit_cube():
    """Longest over shortest edge per cell: 1 for the cubes of a uniform hexahedral box; on
    its tetrahedra (each cube cut into six along a body diagonal) the body diagonal over a
    cube edge, sqrt(3), for every cell."""
    import dolfinx
    from mpi4py import MPI

    ratios = contact_vs_bonded().edge_ratios
    cube = dolfinx.mesh.create_unit_cube(MPI.COMM_WORLD, 3, 3, 3,
                                         dolfinx.mesh.CellType.hexahedron)
    assert ratios(cube) == {"median": pytest.approx(1.0), "p90": pytest.approx(1.0),
                            "max": pytest.approx(1.0), "fraction_above_10": 0.0}
    cube = dolfinx.mesh.create_unit_cube(MPI.COMM_WORLD, 3, 3, 3,
                                         dolfinx.mesh.CellType.tetrahedron)
    result = ratios(cube)
    assert result["median"] == pytest.approx(math.sqrt(3.0))
    assert result["max"] == pytest.approx(math.sqrt(3.0))
