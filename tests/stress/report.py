"""The stress suite's result table as markdown, from the rows conftest.py collects.

``DOLFINX_MORTAR_STRESS_REPORT=DIR`` (``make stress`` sets ``results/stress``) makes the
test session write ``DIR/stress.json`` (one row per test: outcome, duration, xfail
reason, and what the test recorded: converged, Newton iterations, cut-backs, error,
NaN, ...) and ``DIR/stress.md`` (a summary per case, the strict xfails with their
reasons, any failures, and every test). The markdown can be made again from the JSON::

    tools/run python3 -m tests.stress.report results/stress/stress.json

docs/stress.md quotes the summary of such a run.
"""

from __future__ import annotations

import argparse
import json
import math
import pathlib

# the cases of issue 5, in its order (the numbers the tests record)
CASES = {
    1: "penalty sweep (eps over six decades)",
    2: "c_n sweep (four decades and more)",
    3: "patch test, mesh ratios 1:1 to 1:10, either slave side",
    4: "unit-system invariance",
    5: "random surfaces (hypothesis), mortar identities",
    6: "aligned nodes, tiny overlaps",
    7: "grazing contact",
    8: "initial penetration",
    9: "separation after contact",
    10: "large sliding (ironing)",
    11: "two rings squeezed to large strain",
    12: "load steps too large (cut-back)",
}


def _number(value) -> str:
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "NaN"
        return "0" if value == 0.0 else f"{value:.2g}"
    return str(value)


def _iterations(row: dict) -> list[int]:
    values = row.get("iterations")
    if values is None:
        return []
    if isinstance(values, int | float):
        return [int(values)]
    return [int(v) for v in values if isinstance(v, int | float)]


def _iterations_text(values: list[int]) -> str:
    if not values:
        return "-"
    if len(values) > 6:
        return f"{len(values)} solves, {min(values)}-{max(values)}"
    return "+".join(str(v) for v in values)


def _span(values: list[int]) -> str:
    if not values:
        return "-"
    low, high = min(values), max(values)
    return str(low) if low == high else f"{low}-{high}"


def _cell(text: str) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def _name(row: dict) -> str:
    return row["test"].split("::", 1)[-1]


def summary_table(rows: list[dict]) -> list[str]:
    lines = [
        "| case | tests | passed | xfailed (strict) | xpassed (strict: a failure) | failed | "
        "converged | Newton its per solve | largest error (passed) | largest error (xfailed) "
        "| NaN | runtime [s] |",
        "|" + "---|" * 12,
    ]
    for case, title in CASES.items():
        group = [r for r in rows if r.get("case") == case]
        if not group:
            lines.append(f"| {case} {title} | 0 |" + " |" * 10)
            continue
        outcomes = [r.get("outcome", "?") for r in group]
        failed = sum(o in ("failed", "error") for o in outcomes)
        converged = [r["converged"] for r in group if isinstance(r.get("converged"), bool)]
        iterations = [i for r in group for i in _iterations(r)]
        errors = {"passed": [], "xfailed": []}
        for r in group:
            error = r.get("error")
            if isinstance(error, int | float) and r.get("outcome") in errors:
                errors[r["outcome"]].append(float(error))
        nan = any(r.get("nan") is True for r in group)
        runtime = sum(float(r.get("duration", 0.0)) for r in group)
        lines.append(
            f"| {case} {title} | {len(group)} | {outcomes.count('passed')} | "
            f"{outcomes.count('xfailed')} | {outcomes.count('xpassed')} | {failed} | "
            f"{sum(converged)} of {len(converged)} | {_span(iterations)} | "
            f"{_number(max(errors['passed'], default=None))} | "
            f"{_number(max(errors['xfailed'], default=None))} | {'yes' if nan else 'no'} | "
            f"{runtime:.1f} |"
        )
    return lines


def markdown(rows: list[dict], meta: dict | None = None) -> str:
    """The whole report: header, summary per case, xfails, failures, every test."""
    meta = meta or {}
    rows = sorted(rows, key=lambda r: (r.get("case", 0), r["test"]))
    counts: dict[str, int] = {}
    for row in rows:
        counts[row.get("outcome", "?")] = counts.get(row.get("outcome", "?"), 0) + 1
    lines = ["# Stress suite: measured results", ""]
    if meta:
        load = meta.get("load_average_1min", {})
        lines += [
            f"command: `{meta.get('command', '?')}`  ",
            f"library: {meta.get('library', '?')}  ",
            f"session wall time: {meta.get('wall_time_s', 0.0) / 60:.1f} min "
            f"({meta.get('wall_time_s', 0.0):.0f} s); {meta.get('nproc', '?')} cores "
            f"({meta.get('cpu', '?')}); 1-minute load average during the run: min "
            f"{load.get('min', float('nan')):.2f} / mean {load.get('mean', float('nan')):.2f} "
            f"/ max {load.get('max', float('nan')):.2f} ({load.get('samples', 0)} samples)  ",
            f"started {meta.get('started', '?')}; dolfinx {meta.get('dolfinx', '?')}, "
            f"PETSc {meta.get('petsc', '?')}, Python {meta.get('python', '?')}",
            "",
        ]
    lines += [
        "outcomes: " + ", ".join(f"{n} {k}" for k, n in sorted(counts.items())),
        "",
        "## Per case",
        "",
        "converged: solves whose every Newton solve / load step converged, of the tests "
        "that record it; error: the test's measured deviation from its known answer "
        "(what it is: see the test's docstring and docs/stress.md); NaN: any NaN or inf "
        "in u, the multipliers or a summary.",
        "",
        *summary_table(rows),
        "",
    ]
    xfails = [r for r in rows if r.get("outcome") == "xfailed"]
    lines += ["## Strict xfails (known defects)", ""]
    if xfails:
        lines += ["| case | test | what failed | reason (the defect) |", "|---|---|---|---|"]
        for r in xfails:
            lines.append(
                f"| {r.get('case', '?')} | `{_cell(_name(r))}` | "
                f"{_cell(r.get('failure', '-'))} | {_cell(r.get('xfail_reason', '-'))} |"
            )
    else:
        lines.append("none")
    lines.append("")
    broken = [r for r in rows if r.get("outcome") in ("failed", "xpassed", "error")]
    if broken:
        lines += ["## Failures", "", "| case | test | outcome | message |", "|---|---|---|---|"]
        for r in broken:
            lines.append(
                f"| {r.get('case', '?')} | `{_cell(_name(r))}` | {r.get('outcome')} | "
                f"{_cell(r.get('failure', r.get('xfail_reason', '-')))} |"
            )
        lines.append("")
    lines += [
        "## Every test",
        "",
        "| case | test | outcome | converged | Newton its | cut-backs | error | NaN | time [s] |",
        "|" + "---|" * 9,
    ]
    for r in rows:
        lines.append(
            f"| {r.get('case', '?')} | `{_cell(_name(r))}` | {r.get('outcome', '?')} | "
            f"{_number(r.get('converged'))} | {_iterations_text(_iterations(r))} | "
            f"{_number(r.get('cutbacks'))} | {_number(r.get('error'))} | "
            f"{_number(r.get('nan'))} | {float(r.get('duration', 0.0)):.2f} |"
        )
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("json", type=pathlib.Path, help="stress.json of a run")
    parser.add_argument("--output", type=pathlib.Path, help="markdown file (default: stdout)")
    args = parser.parse_args(argv)
    data = json.loads(args.json.read_text())
    rows, meta = (data, {}) if isinstance(data, list) else (data["rows"], data.get("meta", {}))
    text = markdown(rows, meta)
    if args.output:
        args.output.write_text(text)
    else:
        print(text, end="")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
