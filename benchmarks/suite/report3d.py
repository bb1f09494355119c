"""Markdown tables and plots of the 3D sections (patch3d, hertz3d, scaling3d)."""

from __future__ import annotations

import pathlib

from .common import fmt
from .three_d import HERTZ3D_ERRORS


def _its(values) -> str:
    return "+".join(str(v) for v in values) if isinstance(values, list) else str(values)


def _inner(run: dict) -> str:
    """Inner GMRES iterations per application of the condensed preconditioner, mean / max."""
    inner = run.get("inner_krylov_iterations") or []
    return f"{sum(inner) / len(inner):.1f} / {max(inner)}" if inner else "-"


def _share(timings: dict, phase: str) -> str:
    total = timings["total"]
    return f"{100 * timings[phase] / total:.0f} %" if total > 0 else "-"


def patch3d_markdown(data: dict) -> str:
    header = ["cell", "ratio", "slave", "dofs", "Newton its", "pressure deviation",
              "interior", "stress deviation", "non-uniformity", "solve [s]", "wall [s]",
              f"exact (< {data['tolerance']:.0e})"]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for r in data["runs"]:
        d = r["deviations"]
        lines.append("| " + " | ".join([
            r["cell"], r["ratio"], r["slave"], str(r["num_dofs"]), str(r["newton_iterations"]),
            fmt(d["max_pressure_deviation_rel"]), fmt(d["max_pressure_deviation_interior_rel"]),
            fmt(d["max_stress_deviation_rel"]), fmt(d["pressure_nonuniformity_rel"]),
            f"{r['timings']['total']:.3g}", f"{r['wall_time_s']:.3g}",
            "yes" if r["exact"] else "no"]) + " |")
    lines += ["", f"largest deviation {fmt(data['max_deviation'])}; deviations relative to "
              "the exact pressure 10 (max over the slave nodes; 'interior': away from the "
              "interface's edges; stress: sigma_zz over the cells); timings: medians over "
              f"{data['repeats']} repeat(s).", ""]
    return "\n".join(lines)


def hertz3d_markdown(data: dict) -> str:
    names = {"l2_pressure_error_rel": "L2 pressure error", "p_max_error_rel": "p_max error",
             "p0_fit_error_rel": "fitted p0 error", "a_error_in_elements": "a error [h]",
             "total_force_error_rel": "force error"}
    header = (["variant", "ref", "dofs", "h"] + [names[k] for k in HERTZ3D_ERRORS]
              + ["Newton its", "Krylov its", "inner GMRES", "solve [s]", "bulk", "search", "mortar",
                 "lin. solve", "wall [s]", "peak RSS [MiB]"])
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for r in data["runs"]:
        if r["failed"]:
            lines.append(f"| {r['variant']} | {r['refinement']} | {r['error'][:160]} |"
                         + " |" * (len(header) - 3))
            continue
        t = r["timings"]
        lines.append("| " + " | ".join(
            [r["variant"], str(r["refinement"]), str(r["num_dofs"]), f"{r['h_slave_measured']:.4f}"]
            + [fmt(r["errors"][k]) for k in HERTZ3D_ERRORS]
            + [_its(r["newton_iterations"]), _its(r["krylov_iterations"]), _inner(r),
               f"{t['total']:.3g}"]
            + [_share(t, p) for p in ("bulk assembly", "contact search", "mortar integration",
                                      "linear solve")]
            + [f"{r['wall_time_s']:.3g}", f"{r['peak_rss_mib']:.0f}"]) + " |")
    lines += ["", "Fitted rates of the L2 pressure error (log-log least squares):", ""]
    for name, rate in data["rates"].items():
        if not rate["refinements"]:
            lines.append(f"- {name}: no run done")
            continue
        finest = rate["l2_vs_h_finest_3"]
        lines.append(f"- {name} (refinements {', '.join(str(v) for v in rate['refinements'])}):"
                     f" {fmt(rate['l2_vs_h'])} against h"
                     + (f" ({fmt(finest)} over the finest three)" if finest is not None else "")
                     + f", {fmt(rate['l2_vs_dofs'])} against dofs")
    lines += ["", f"Quarter model, --elements-per-radius {data['elements_per_radius']}, linear "
              "material, the load steps of each run (its Newton iterations per step); h is "
              "the measured mean slave edge length within a; "
              "Newton and Krylov iterations per load step (Krylov: the iterations of the "
              "linear solves, one per Newton iteration for LU, outer FGMRES iterations on "
              "[u, z] for the iterative solver); inner GMRES: iterations per application of "
              "the condensed preconditioner (rtol 1e-3, BoomerAMG), mean / max; peak RSS: of "
              "the benchmark "
              f"process so far; timings medians over {data['repeats']} repeat(s).", ""]
    return "\n".join(lines)


def scaling3d_markdown(data: dict) -> str:
    header = ["solver", "ranks", "n0:ref", "dofs", "Newton its", "Krylov per linear solve",
              "inner GMRES", "per Newton iteration [s]", "of which linear solve [s]", "solve [s]",
              "demo wall [s]", "process [s]", "peak RSS per rank [MiB]", "L2 pressure error",
              "load (1 min) start / end"]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for r in data["runs"]:
        mesh = f"{r['elements_per_radius']}:{r['refinement']}"
        if r["failed"]:
            lines.append(f"| {r['linear_solver']} | {r['num_ranks']} | {mesh} | "
                         f"{r['error'][:200]} |" + " |" * (len(header) - 4))
            continue
        load = (f"{r['load_1min_start']:.1f} / {r['load_1min_end']:.1f}"
                if r.get("load_1min_start") is not None else "-")
        solver = r["linear_solver"] + (" (stored)" if r.get("stored") else "")
        lines.append("| " + " | ".join([
            solver, str(r["num_ranks"]), mesh, str(r["num_dofs"]),
            _its(r["newton_iterations"]), f"{r['krylov_per_linear_solve']:.1f}", _inner(r),
            f"{r['time_per_newton_s']:.3g}", f"{r['linear_solve_per_newton_s']:.3g}",
            f"{r['timings']['total']:.3g}", f"{r['wall_time_s']:.3g}",
            f"{r['process_wall_s']:.3g}",
            ", ".join(f"{m:.0f}" for m in r["peak_rss_mib_per_rank"]),
            fmt(r["errors"]["l2_pressure_error_rel"]), load]) + " |")
    lines += ["", "One process per run (a fresh high-water mark of its memory). Hertz sphere "
              "on a block, quarter model, linear, the load steps of each run (Newton: "
              "iterations per step); n0:ref = --elements-per-radius:"
              "--refinement. direct: MUMPS LU of the monolithic [u, z] system; iterative: "
              "FGMRES on [u, z] (the 'Krylov' count) preconditioned by the condensed "
              "displacement system, GMRES rtol 1e-3 + BoomerAMG ('inner GMRES' per "
              "application, mean / max). 'solve' is ContactProblem.solve"
              " (summed over the steps), 'demo wall' adds mesh generation and setup, 'process' "
              "adds start-up and JIT; peak RSS: VmHWM of each rank's process (ru_maxrss, "
              "also in the JSON, carries the starting process's high-water mark over fork + "
              "exec: for the serial runs it is the driver's). 'stored': a run made apart "
              "from this command (--scaling-stored), with its own command below.", "",
              "commands: "
              + "; ".join(f"`{r['command']}`" for r in data["runs"]), ""]
    return "\n".join(lines)


def plot_hertz3d(data: dict, path: pathlib.Path) -> None:
    """L2 pressure error against the solve time and against h, per variant."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10.5, 4.3))
    for variant in data["variants"]:
        runs = sorted((r for r in data["runs"] if r["variant"] == variant["name"]
                       and not r["failed"]), key=lambda r: r["refinement"])
        if not runs:
            continue
        error = [r["errors"]["l2_pressure_error_rel"] for r in runs]
        axes[0].loglog([r["timings"]["total"] for r in runs], error, "o-", label=variant["name"])
        axes[1].loglog([r["h_slave_measured"] for r in runs], error, "o-", label=variant["name"])
    axes[0].set_xlabel("solve time [s]")
    axes[1].set_xlabel("h (mean slave edge within a)")
    for ax in axes:
        ax.set_ylabel("L2 pressure error (relative)")
        ax.grid(True, which="both", linewidth=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(f"Hertz sphere, --elements-per-radius {data['elements_per_radius']}, "
                 f"refinements {data['refinements'][0]}..{data['refinements'][-1]}", fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_scaling3d(data: dict, path: pathlib.Path) -> None:
    """Time per Newton iteration and peak memory per rank against dofs."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10.5, 4.3))
    for solver in data["solvers"]:
        for n in data["ranks"]:
            runs = sorted((r for r in data["runs"] if not r["failed"]
                           and r["linear_solver"] == solver and r["num_ranks"] == n),
                          key=lambda r: r["num_dofs"])
            if not runs:
                continue
            dofs = [r["num_dofs"] for r in runs]
            label = f"{solver}, {n} rank{'s' if n > 1 else ''}"
            style = "o-" if solver == "direct" else "s--"
            axes[0].loglog(dofs, [r["time_per_newton_s"] for r in runs], style, label=label)
            axes[1].loglog(dofs, [max(r["peak_rss_mib_per_rank"]) for r in runs], style,
                           label=label)
    axes[0].set_ylabel("solve time per Newton iteration [s]")
    axes[1].set_ylabel("peak RSS, largest rank [MiB]")
    for ax in axes:
        ax.set_xlabel("dofs")
        ax.grid(True, which="both", linewidth=0.3)
        ax.legend(fontsize=8)
    fig.suptitle("Hertz sphere: MUMPS LU against GMRES + BoomerAMG (condensed)", fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
