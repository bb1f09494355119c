"""The stress suite's switch for the full sweep and its table of measured results.

* ``--run-slow`` (``make stress``) runs the cases marked ``slow``; without it they are
  skipped, so ``pytest tests`` runs only the fast part. ``DOLFINX_MORTAR_RUN_SLOW=1``
  does the same, for runs that start pytest from the repository root with other
  test paths (pytest only knows this file's option when ``tests/stress`` is named).
* Each case calls :func:`common.record` with what it measured (converged, Newton
  iterations, error, NaN); the terminal summary prints them as a table when the
  full sweep runs or with ``-v``, and ``DOLFINX_MORTAR_STRESS_JSON=path`` writes
  them as JSON (docs/stress.md is made from that).
"""

from __future__ import annotations

import json
import os
import pathlib

import pytest

from .common import RESULTS


def pytest_addoption(parser):
    parser.addoption(
        "--run-slow",
        action="store_true",
        default=False,
        help="run the full stress sweep (tests marked slow in tests/stress)",
    )


def run_slow(config) -> bool:
    try:
        option = config.getoption("--run-slow")
    except ValueError:  # this conftest was not loaded when the options were parsed
        option = False
    return bool(option) or os.environ.get("DOLFINX_MORTAR_RUN_SLOW", "") not in ("", "0")


HERE = pathlib.Path(__file__).parent


def pytest_collection_modifyitems(config, items):
    """Mark the full sweep skipped unless --run-slow: skip markers act before any fixture
    is set up (a skip from a fixture would still pay for the suite's autouse fixtures)."""
    if run_slow(config):
        return
    skip = pytest.mark.skip(reason="full stress sweep: pass --run-slow (make stress)")
    for item in items:
        if item.get_closest_marker("slow") is not None and HERE in item.path.parents:
            item.add_marker(skip)


_DURATIONS: dict[str, dict] = {}
# the case of each test function, for tests that fail before they record anything
_CASES = {
    "test_penalty": 1,
    "test_cn": 2,
    "test_patch_test": 3,
    "test_kernel_quantities": 4,
    "test_contact_problem": 4,
    "test_random": 5,
    "test_aligned": 6,
    "test_grazing": 7,
    "test_single_corner": 7,
    "test_initial_penetration": 8,
    "test_separation": 9,
    "test_ironing_large": 10,
    "test_rings": 11,
    "test_too_large": 12,
    "test_no_cutback": 12,
    "test_ironing_in_one": 12,
    "test_ironing_sliding": 12,
}


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    report = outcome.get_result()
    if call.when == "call" and call.excinfo is not None and HERE in item.path.parents:
        entry = RESULTS.setdefault(item.nodeid, {})
        if "case" not in entry:
            name = item.name.split("[")[0]
            entry["case"] = next((c for p, c in _CASES.items() if name.startswith(p)), 0)
        message = str(call.excinfo.value).strip().splitlines()
        entry["failure"] = f"{call.excinfo.typename}: {message[0] if message else ''}"[:300]
    return report


def pytest_runtest_logreport(report):
    entry = _DURATIONS.setdefault(report.nodeid, {"duration": 0.0, "outcome": "passed"})
    entry["duration"] += report.duration
    if report.when == "call" or report.outcome != "passed":
        if hasattr(report, "wasxfail"):
            entry["outcome"] = "xpassed" if report.passed else "xfailed"
        else:
            entry["outcome"] = report.outcome


def _rows() -> list[dict]:
    rows = []
    for nodeid, values in RESULTS.items():
        row = {"test": nodeid, **_DURATIONS.get(nodeid, {}), **values}
        rows.append(row)
    return rows


def _short(value) -> str:
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:.2e}"
    if isinstance(value, list | tuple):
        if len(value) > 8:
            return f"{len(value)} steps, max {max(value)}"
        return "/".join(_short(v) for v in value)
    return str(value)


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    rows = [row for row in _rows() if row.get("outcome") != "skipped"]
    path = os.environ.get("DOLFINX_MORTAR_STRESS_JSON")
    if path and rows:
        with open(path, "w") as stream:
            json.dump(rows, stream, indent=1, default=str)
    if not rows or not (run_slow(config) or config.getoption("verbose") > 0):
        return
    terminalreporter.section("stress cases: measured")
    for row in sorted(rows, key=lambda r: (r.get("case", 0), r["test"])):
        name = row["test"].split("::", 1)[-1]
        fields = [
            f"case {row.get('case', '?'):>2}",
            f"{row.get('outcome', '?'):8}",
            f"{row.get('duration', 0.0):6.2f} s",
            name,
        ]
        for key in ("converged", "iterations", "cutbacks", "error", "nan", "examples", "failure"):
            if key in row:
                fields.append(f"{key} {_short(row[key])}")
        terminalreporter.write_line("  ".join(fields))
