"""Markdown of every section, the goals table, and the whole report of one run
(summary.md, summary.json and each section's .md and .png), also from saved JSON."""

from __future__ import annotations

import json
import pathlib

from . import report3d
from .common import GOALS, fmt, ms, write_json
from .machine import machine_markdown
from .plots import plot_scaling, plot_work_precision
from .runner import ERROR_KEYS
from .work_precision import CASES


def work_precision_markdown(data: dict, finest_only: bool = False) -> str:
    lines = []
    refinements = data["refinements"]
    for case_name, case in CASES.items():
        demo_name = case["demo"]
        keys = ERROR_KEYS[demo_name]
        names = [k.replace("_rel", "").replace("_", " ") for k in keys]
        header = (["variant", "ref", "dofs"] + names
                  + ["Newton its", "solve [s]", "bulk", "search", "mortar", "lin. solve",
                     "solve CPU [s]", "wall [s]"])
        title = f"#### {case['title']}"
        if finest_only:
            title += f", refinement {refinements[-1]}"
        lines += [title, "", "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
        for run in data["runs"]:
            if run["case"] != case_name or (finest_only and run["refinement"] != refinements[-1]):
                continue
            if run["failed"]:
                lines.append(f"| {run['variant']} | {run['refinement']} | "
                             f"failed: {run['error'][:160]} |" + " |" * (len(header) - 3))
                continue
            t = run["timings"]
            its = run["newton_iterations"]
            its = "+".join(str(i) for i in its) if isinstance(its, list) else str(its)
            cells = ([run["variant"], str(run["refinement"]), str(run["num_dofs"])]
                     + [fmt(run["errors"][k]) for k in keys]
                     + [its, f"{t['total']:.3g}"]
                     + [f"{100 * t[p] / t['total']:.0f} %" if t["total"] > 0 else "-"
                        for p in ("bulk assembly", "contact search", "mortar integration",
                                  "linear solve")]
                     + [f"{run['solve_cpu_s']:.3g}", f"{run['wall_time_s']:.3g}"])
            lines.append("| " + " | ".join(cells) + " |")
        for item in data.get("not_implemented", []):  # runs before the variant existed
            lines.append(f"| {item['name']} | - | - | {item['status']} |"
                         + " |" * (len(header) - 4))
        lines.append("")
    return "\n".join(lines)



def cost_markdown(data: dict) -> str:
    lines = [f"#### Share of a Newton iteration spent on contact (Hertz B, refinement "
             f"{data['big_refinement']})", "",
             "| material (mortar configuration) | dofs | Newton its | per iteration [ms]: bulk | "
             "search | mortar | linear solve | total | contact share | of which mortar kernels | "
             "goal <= 15 % |", "|" + "---|" * 11]
    for name, r in data["share"].items():
        p = r["per_iteration"]
        lines.append(
            f"| {name} ({r['configuration']}) | {r['num_dofs']} | "
            f"{'+'.join(str(i) for i in r['newton_iterations'])} | {ms(p['bulk assembly'])} | "
            f"{ms(p['contact search'])} | {ms(p['mortar integration'])} | "
            f"{ms(p['linear solve'])} | {ms(p['total'])} | {100 * r['contact_share']:.1f} % | "
            f"{100 * r['kernel_share']:.1f} % | "
            f"{'met' if r['contact_share'] <= GOALS['contact_share'] else 'missed'} |")
    lines += ["", "contact share = (contact search + mortar integration) / total of "
              "ContactProblem.solve; 'mortar integration' includes the contact blocks and "
              "the multiplier rows of the monolithic [u, z] matrix (the bulk is assembled in "
              "place, under 'bulk'); 'mortar kernels' = "
              "MortarInterface.statistics time_search + time_integration only.", ""]
    lines += ["#### Mortar time against slave facets (Hertz B, Neo-Hookean, current configuration)",
              "", "| ref | dofs | slave facets | pairs | segments | evaluations | kernel per "
              "evaluation [ms] | search per search [ms] | mortar phase per iteration [ms] | "
              "bulk per iteration [ms] | linear solve per iteration [ms] | Newton its |",
              "|" + "---|" * 12]
    for r in data["scaling"]:
        s, p = r["contact_statistics"], r["per_iteration"]
        lines.append(
            f"| {r['refinement']} | {r['num_dofs']} | {r['slave_facets']} | {s.get('pairs')} | "
            f"{s.get('segments')} | {s.get('evaluations')} | "
            f"{1e3 * r['kernel_time_per_evaluation']:.2f} | "
            f"{1e3 * r['search_time_per_search']:.2f} | {ms(p['mortar integration'])} | "
            f"{ms(p['bulk assembly'])} | {ms(p['linear solve'])} | "
            f"{'+'.join(str(i) for i in r['newton_iterations'])} |")
    sl = data["slopes"]

    def slope(value):
        return "-" if value is None else f"{value:.2f}"

    lines += ["", f"log-log slopes: kernel time per evaluation vs slave facets "
              f"{slope(sl['kernel_per_evaluation'])} (finest three: "
              f"{slope(sl['kernel_per_evaluation_finest_3'])}; goal linear, <= "
              f"{GOALS['mortar_slope']}); pairs vs slave facets {slope(sl['pairs'])}; mortar "
              f"phase per iteration vs slave facets {slope(sl['mortar_phase_per_iteration'])}, vs "
              f"dofs {slope(sl['mortar_phase_per_iteration_vs_dofs'])}; its non-kernel part vs "
              f"dofs {slope(sl['mortar_phase_other_per_iteration_vs_dofs'])}.", ""]
    far = data["far_apart"]
    c, p = far["contact"], far["plain"]
    lines += [f"#### Bodies that never come near: ContactProblem vs plain SNES (refinement "
              f"{far['refinement']}, {far['num_dofs']} dofs, {far['repeats']} repeats, "
              "interleaved)", "",
              "| solver | Newton its | setup [s] | solve [s] | solve CPU [s] | bulk | search | "
              "mortar | linear solve |", "|" + "---|" * 9]
    for name, d in (("ContactProblem (1 pair, never near)", c), ("plain SNES, no pair", p)):
        t = d["timings"]
        lines.append(f"| {name} | {'+'.join(str(i) for i in d['iterations'])} | "
                     f"{d['setup_s']:.3g} | {t['total']:.3g} | {d['solve_cpu_s']:.3g} | "
                     f"{t['bulk assembly']:.3g} | "
                     f"{t['contact search']:.3g} | {t['mortar integration']:.3g} | "
                     f"{t['linear solve']:.3g} |")
    st = far["statistics"]
    lines += ["", f"overhead of the contact pair: solve {100 * far['overhead_solve']:+.1f} % "
              f"(pairwise samples: "
              f"{', '.join(f'{100 * o:+.1f} %' for o in far['overhead_solve_pairwise'])}), setup + "
              f"solve {100 * far['overhead_setup_and_solve']:+.1f} %, solve CPU time "
              f"{100 * far['overhead_solve_cpu']:+.1f} %; goal <= "
              f"{100 * GOALS['far_apart_overhead']:.0f} %: "
              f"{'met' if far['overhead_solve'] <= GOALS['far_apart_overhead'] else 'missed'}. "
              f"Pairs {st.get('pairs')}, searches {st.get('searches_done')} done / "
              f"{st.get('searches_skipped')} skipped (pair pattern versions "
              f"{far['pattern_versions']}: each search, even one finding no pairs, makes a new "
              "monolithic matrix and a new symbolic LU), mortar kernel time "
              f"{1e3 * st.get('time_integration', 0.0):.2f} ms, {far['multiplier_rows']} extra "
              f"(identity) multiplier rows; displacements agree to "
              f"{far['max_displacement_difference_rel']:.1e}.", ""]
    par = data["parallel"]
    lines += [f"#### Hertz B (linear) on 1 and 2 MPI ranks, refinement {par['refinement']}", "",
              "| ranks | dofs | Newton its | solve [s] | solve CPU [s] | bulk | search | mortar | "
              "linear solve | wall [s] | speed-up (solve) | p_max difference to 1 rank |",
              "|" + "---|" * 12]
    for r in par["runs"]:
        if r.get("failed"):
            lines.append(f"| {r['num_ranks']} | failed (exit {r['returncode']}): "
                         f"{r['error'][-200:]!r} |" + " |" * 10)
            continue
        t = r["timings"]
        lines.append(f"| {r['num_ranks']} | {r['num_dofs']} | "
                     f"{'+'.join(str(i) for i in r['newton_iterations'])} | {t['total']:.3g} | "
                     f"{r['solve_cpu_s']:.3g} | {t['bulk assembly']:.3g} | "
                     f"{t['contact search']:.3g} | {t['mortar integration']:.3g} | "
                     f"{t['linear solve']:.3g} | {r['wall_time_s']:.3g} | "
                     f"{fmt(r.get('speedup_solve'))} | "
                     f"{fmt(r.get('p_max_difference_rel'))} |")
    lines += ["", "commands: " + "; ".join(f"`{c}`" for c in par["commands"]), ""]
    return "\n".join(lines)



def skipping_markdown(data: dict) -> str:
    s = data["searches"]
    d, f = s["default"], s["forced"]
    lines = ["#### Searches reused (Hertz B, Neo-Hookean, refinement "
             f"{s['refinement']}, {s['repeats']} repeats)", "",
             "| run | searches done | searches skipped | search time [s] | 'mortar integration' "
             "[s] | solve [s] | solve CPU [s] | Newton its |", "|" + "---|" * 8]
    for name, r in (("default (reuse while nodes moved < margin/2)", d),
                    ("search in every update (A/B)", f)):
        st = r["contact_statistics"]
        lines.append(f"| {name} | {st.get('searches_done')} | {st.get('searches_skipped')} | "
                     f"{r['timings']['contact search']:.3g} | "
                     f"{r['timings']['mortar integration']:.3g} | {r['timings']['total']:.3g} | "
                     f"{r['solve_cpu_s']:.3g} | "
                     f"{'+'.join(str(i) for i in r['newton_iterations'])} |")
    lines += ["", f"saving: {s['saved_solve_s']:.3g} s of the solve "
              f"({100 * s['saved_solve_rel']:.1f} %; CPU time {100 * s['saved_cpu_rel']:.1f} %); "
              f"same answer: {s['same_answer']}. A new search changes the pair pattern, so the "
              "monolithic matrix is rebuilt: that, not the search itself, is most of the "
              "saving.", ""]
    far = data["far_apart"]
    st = far["statistics"]
    t = far["contact"]["timings"]
    lines += [f"#### No pairs for far-apart surfaces (refinement {far['refinement']}, "
              f"{far['num_dofs']} dofs)", "",
              "| pairs | segments | searches done / skipped | evaluations | mortar kernel time "
              "[ms] | 'mortar integration' phase [s] | solve [s] | plain SNES solve [s] |",
              "|" + "---|" * 8,
              f"| {st.get('pairs')} | {st.get('segments')} | {st.get('searches_done')} / "
              f"{st.get('searches_skipped')} | {st.get('evaluations')} | "
              f"{1e3 * st.get('time_integration', 0.0):.2f} | {t['mortar integration']:.3g} | "
              f"{t['total']:.3g} | {far['plain']['timings']['total']:.3g} |", "",
              "With no pairs the 'mortar integration' phase holds only the multiplier rows "
              "(identity rows of the inactive multipliers) and the residual bookkeeping; the "
              "bulk is assembled in place into the monolithic [u, z] matrix.", ""]
    lines += ["#### Uncovered slave nodes (Hertz B, no mortar work for them)", "",
              "| run | ref | slave nodes | uncovered | slave facets x master facets | pairs "
              "evaluated | segments | kernel per evaluation [ms] | estimated if all covered "
              "[ms] |", "|" + "---|" * 9]
    for name, u in data["uncovered"].items():
        lines.append(f"| {name} | {u['refinement']} | {u['slave_nodes']} | "
                     f"{u['slave_nodes_uncovered']} | {u['all_pairs']} | {u['pairs']} | "
                     f"{u['segments']} | {1e3 * u['kernel_time_per_evaluation']:.2f} | "
                     f"{1e3 * u['estimated_time_if_all_covered']:.2f} |")
    lines += ["", "estimate: kernel time scaled by slave facets / covered slave facets (cost "
              "linear in pairs).", ""]
    lines += ["#### Evaluations skipped (nothing moved since the last evaluation)", "",
              "| run | evaluations | skipped | kernel time [s] | solve [s] | solve CPU [s] | "
              "saving (wall; CPU) | same answer |", "|" + "---|" * 8]
    for name, e in data["evaluations"].items():
        for kind in ("default", "forced"):
            r = e[kind]
            st = r["contact_statistics"]
            label = f"{name}, " + ("default" if kind == "default" else "always evaluate (A/B)")
            saving = (f"{e['saved_solve_s']:.3g} s ({100 * e['saved_solve_rel']:.1f} %); "
                      f"{e['saved_cpu_s']:.3g} s ({100 * e['saved_cpu_rel']:.1f} %)"
                      if kind == "default" else "")
            lines.append(f"| {label} | {st.get('evaluations')} | "
                         f"{st.get('evaluations_skipped', 'n/a')} | {r['kernel_time']:.3g} | "
                         f"{r['timings']['total']:.3g} | {r['solve_cpu_s']:.3g} | {saving} | "
                         f"{e['same_answer'] if kind == 'default' else ''} |")
        if not e["forced"]["probe"].get("forced_evaluation_supported", True):
            lines.append("| (this build has no evaluation skipping: the A/B is void) |"
                         + " |" * 7)
    lines.append("")
    return "\n".join(lines)


def goals(work: dict | None, cost: dict | None, patch3d: dict | None = None) -> list[dict]:
    rows = []
    if cost:
        for name, r in cost["share"].items():
            rows.append({"goal": f"contact share of a Newton iteration <= 15 % at >= 1e5 dofs "
                                 f"({name})", "measured": f"{100 * r['contact_share']:.1f} % "
                                 f"({r['num_dofs']} dofs)",
                         "met": r["contact_share"] <= GOALS["contact_share"]
                         and r["num_dofs"] >= 1e5,
                         "note": "" if r["num_dofs"] >= 1e5 else "mesh below 1e5 dofs (quick run)"})
        far = cost["far_apart"]
        rows.append({"goal": "far-apart overhead <= 5 %",
                     "measured": f"{100 * far['overhead_solve']:+.1f} % (solve), "
                                 f"{100 * far['overhead_setup_and_solve']:+.1f} % (setup + solve), "
                                 f"{100 * far['overhead_solve_cpu']:+.1f} % (solve CPU time)",
                     "met": far["overhead_solve"] <= GOALS["far_apart_overhead"], "note": ""})
        slope = cost["slopes"]["kernel_per_evaluation"]
        finest = cost["slopes"]["kernel_per_evaluation_finest_3"]
        rows.append({"goal": "mortar cost linear in slave facets (log-log slope <= 1.1)",
                     "measured": f"slope {slope:.2f} (finest three {finest:.2f})"
                     if slope is not None and finest is not None else "-",
                     "met": slope is not None and slope <= GOALS["mortar_slope"], "note": ""})
    iterations = []
    if work:
        for r in work["runs"]:
            if (not r["failed"] and r["case"].startswith("hertz")
                    and r["variant"] not in ("fixed-point",)
                    and not r["variant"].startswith(("penalty", "augmented"))):
                iterations.append((r["max_iterations_per_step"], r["case"], r["variant"],
                                   r["refinement"]))
    if cost:
        for r in cost["scaling"] + [cost["share"]["linear"]]:
            iterations.append((max(r["newton_iterations"]), "hertz-B " + r["material"], "default",
                               r["refinement"]))
    if iterations:
        worst = max(iterations)
        over = [i for i in iterations if i[0] > GOALS["semismooth_iterations_per_step"]]
        rows.append({"goal": "semismooth Newton <= 8 iterations per load step (Hertz, Lagrange)",
                     "measured": f"max {worst[0]} ({worst[1]}, {worst[2]}, refinement {worst[3]});"
                                 f" {len(over)} of {len(iterations)} runs above 8",
                     "met": worst[0] <= GOALS["semismooth_iterations_per_step"], "note": ""})
    if patch3d:
        rows.append({"goal": f"3D patch test exact (deviations < {patch3d['tolerance']:.0e})",
                     "measured": f"largest deviation {fmt(patch3d['max_deviation'])} "
                                 f"({len(patch3d['runs'])} runs)",
                     "met": patch3d["all_exact"], "note": ""})
    return rows


def goals_markdown(rows: list[dict]) -> str:
    lines = ["| goal | measured | met |", "|---|---|---|"]
    for row in rows:
        note = f" ({row['note']})" if row["note"] else ""
        lines.append(f"| {row['goal']} | {row['measured']}{note} | "
                     f"{'yes' if row['met'] else 'no'} |")
    return "\n".join(lines) + "\n"



# the 3D sections: JSON / markdown / PNG file stem and title
SECTIONS_3D_FILES = {"patch3d": ("patch3d", "3D patch test"),
                     "hertz3d": ("hertz3d", "3D Hertz sphere: work-precision"),
                     "scaling3d": ("scaling3d", "3D Hertz sphere: direct against iterative "
                                                "linear solver")}


def render(output: pathlib.Path, meta: dict, work: dict | None, cost: dict | None,
           skip: dict | None, three_d: dict | None = None) -> str:
    """Markdown, PNG and summary.json of one run, from its data; returns summary.md's text.
    ``three_d`` maps the 3D sections that ran (patch3d, hertz3d, scaling3d) to their data."""
    three_d = {k: v for k, v in (three_d or {}).items() if v is not None}
    header = [f"## dolfinx_mortar benchmarks{' (quick)' if meta['quick'] else ''}", "",
              machine_markdown(meta["machine"], meta["load_average_1min"], meta["command"],
                               meta["elapsed_s"], meta.get("label", "")),
              f"Timings: {meta['note']}; section times "
              + ", ".join(f"{k} {v / 60:.1f} min" for k, v in meta["section_times_s"].items())
              + ".", ""]
    parts = ["\n".join(header)]
    goal_rows = goals(work, cost, three_d.get("patch3d"))
    if goal_rows:
        parts.append("### Goals\n\n" + goals_markdown(goal_rows))
    if work is not None:
        plot_work_precision(work, output / "work_precision.png")
        plot_work_precision(work, output / "work_precision_cpu.png", time_key="cpu")
        plot_work_precision(work, output / "work_precision_pmax.png", "p_max_error_rel")
        table = work_precision_markdown(work)
        (output / "work_precision.md").write_text(
            "\n".join(header) + "\n### Work-precision (all refinements)\n\n" + table)
        parts.append("### Work-precision, finest refinement (all refinements: "
                     "work_precision.md)\n\n" + work_precision_markdown(work, finest_only=True))
    if cost is not None:
        plot_scaling(cost, output / "mortar_scaling.png")
        table = cost_markdown(cost)
        (output / "cost_of_contact.md").write_text("\n".join(header) + "\n### Cost of contact\n\n"
                                                   + table)
        parts.append("### Cost of contact\n\n" + table)
    if skip is not None:
        table = skipping_markdown(skip)
        (output / "skipping.md").write_text("\n".join(header) + "\n### Skipped work\n\n" + table)
        parts.append("### Skipped work\n\n" + table)
    for name, data in three_d.items():
        stem, title = SECTIONS_3D_FILES[name]
        if name == "patch3d":
            table = report3d.patch3d_markdown(data)
        elif name == "hertz3d":
            report3d.plot_hertz3d(data, output / f"{stem}.png")
            table = report3d.hertz3d_markdown(data)
        else:
            report3d.plot_scaling3d(data, output / f"{stem}.png")
            table = report3d.scaling3d_markdown(data)
        (output / f"{stem}.md").write_text("\n".join(header) + f"\n### {title}\n\n" + table)
        parts.append(f"### {title}\n\n" + table)
    text = "\n".join(parts)
    write_json(output / "summary.json", {"meta": meta, "goals": goal_rows})
    (output / "summary.md").write_text(text)
    return text


def render_only(output: pathlib.Path) -> str:
    """Re-create markdown and PNG from the JSON files a run left in ``output``."""
    names = ["work_precision", "cost_of_contact", "skipping"] + list(SECTIONS_3D_FILES)
    data = {}
    for name in ["summary"] + names:
        path = output / f"{name}.json"
        data[name] = json.loads(path.read_text()) if path.exists() else None
    if data["summary"] is None:
        raise FileNotFoundError(f"{output / 'summary.json'} not found: nothing to render")
    meta = data["summary"]["meta"]
    sections = {}
    for name in names:
        section = data[name]
        if section is not None and section["meta"]["command"] != meta["command"]:
            section = None  # left over from another run
        if section is not None:
            section = {k: v for k, v in section.items() if k != "meta"}
        sections[name] = section
    return render(output, meta, sections["work_precision"], sections["cost_of_contact"],
                  sections["skipping"], {name: sections[name] for name in SECTIONS_3D_FILES})
