"""The stress suite's switch for the full sweep and its table of measured results.

* ``--run-slow`` (``make stress``) runs the cases marked ``slow``; without it they are
  skipped, so ``pytest tests`` runs only the fast part. ``DOLFINX_MORTAR_RUN_SLOW=1``
  does the same, for runs that start pytest from the repository root with other
  test paths (pytest only knows this file's option when ``tests/stress`` is named).
* Each case calls :func:`common.record` with what it measured (converged, Newton
  iterations, error, NaN); the terminal summary prints them as a table when the
  full sweep runs or with ``-v``. ``DOLFINX_MORTAR_STRESS_REPORT=DIR`` (``make
  stress``) writes them with the outcomes, xfail reasons, machine and load to
  ``DIR/stress.json`` and ``DIR/stress.md`` (report.py; docs/stress.md quotes it);
  ``DOLFINX_MORTAR_STRESS_JSON=path`` writes only the JSON.
  ``DOLFINX_MORTAR_STRESS_LABEL`` names the library version in both (e.g. a commit).
"""

from __future__ import annotations

import hashlib
import json
import os
import pathlib
import platform
import shlex
import threading
import time

import pytest

from . import report as stress_report
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
        entry.setdefault("case", _case(item.nodeid))
        message = str(call.excinfo.value).strip().splitlines()
        entry["failure"] = f"{call.excinfo.typename}: {message[0] if message else ''}"[:300]
    return report


_ROOT: list[pathlib.Path] = []


def pytest_configure(config):
    _ROOT[:] = [config.rootpath]


def pytest_runtest_logreport(report):
    root = _ROOT[0] if _ROOT else pathlib.Path.cwd()
    if (root / report.nodeid.split("::", 1)[0]).resolve().parent != HERE:
        return
    entry = _DURATIONS.setdefault(report.nodeid, {"duration": 0.0, "outcome": "passed"})
    entry["duration"] += report.duration
    if report.when == "call" or report.outcome != "passed":
        if hasattr(report, "wasxfail"):
            entry["outcome"] = "xpassed" if report.passed else "xfailed"
            entry["xfail_reason"] = report.wasxfail
        elif report.failed and "XPASS(strict)" in str(report.longrepr):
            entry["outcome"] = "xpassed"
            entry["xfail_reason"] = str(report.longrepr)
        elif report.failed and report.when != "call":
            entry["outcome"] = "error"
        else:
            entry["outcome"] = report.outcome


class LoadMonitor:
    """The 1-minute load average, sampled every few seconds during the session."""

    def __init__(self, interval: float = 5.0):
        self.samples: list[float] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, args=(interval,), daemon=True)
        self._thread.start()

    def _run(self, interval: float) -> None:
        while not self._stop.is_set():
            self.samples.append(os.getloadavg()[0])
            self._stop.wait(interval)

    def stop(self) -> dict:
        self._stop.set()
        samples = self.samples or [os.getloadavg()[0]]
        return {
            "min": min(samples),
            "mean": sum(samples) / len(samples),
            "max": max(samples),
            "samples": len(samples),
        }


_SESSION: dict = {}


def _reporting() -> bool:
    variables = ("DOLFINX_MORTAR_STRESS_REPORT", "DOLFINX_MORTAR_STRESS_JSON")
    return any(os.environ.get(name) for name in variables)


def pytest_sessionstart(session):
    if _reporting():
        _SESSION.update(
            start=time.perf_counter(),
            started=time.strftime("%Y-%m-%d %H:%M:%S %Z"),
            monitor=LoadMonitor(),
        )


def library_label() -> str:
    """DOLFINX_MORTAR_STRESS_LABEL and a hash of the library's and demos' sources."""
    repository = HERE.parents[1]
    digest = hashlib.sha256()
    for path in sorted([*repository.glob("dolfinx_mortar/*.py"), *repository.glob("demos/*.py")]):
        digest.update(path.name.encode() + path.read_bytes())
    label = os.environ.get("DOLFINX_MORTAR_STRESS_LABEL", "")
    return f"{label + ', ' if label else ''}sources sha256 {digest.hexdigest()[:16]}"


def session_meta(config) -> dict:
    import dolfinx
    from petsc4py import PETSc

    cpu = platform.processor()
    try:
        for line in pathlib.Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {
        "command": "python3 -m pytest " + shlex.join(config.invocation_params.args),
        "library": library_label(),
        "started": _SESSION.get("started"),
        "wall_time_s": time.perf_counter() - _SESSION.get("start", time.perf_counter()),
        "load_average_1min": _SESSION["monitor"].stop() if "monitor" in _SESSION else {},
        "nproc": len(os.sched_getaffinity(0)),
        "cpu": cpu,
        "dolfinx": dolfinx.__version__,
        "petsc": ".".join(str(v) for v in PETSc.Sys.getVersion()),
        "python": platform.python_version(),
    }


def _case(nodeid: str) -> int:
    name = nodeid.split("::", 1)[-1].split("[")[0]
    return next((c for p, c in _CASES.items() if name.startswith(p)), 0)


def _rows() -> list[dict]:
    """One row per stress test that ran: what it recorded, outcome, duration, xfail reason."""
    rows = []
    for nodeid in dict.fromkeys([*RESULTS, *_DURATIONS]):
        row = {"test": nodeid, "case": _case(nodeid)}
        row.update(_DURATIONS.get(nodeid, {}))
        row.update(RESULTS.get(nodeid, {}))
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
    if rows and _reporting():
        data = {"meta": session_meta(config), "rows": rows}
        directory = os.environ.get("DOLFINX_MORTAR_STRESS_REPORT")
        paths = [os.environ.get("DOLFINX_MORTAR_STRESS_JSON")]
        if directory:
            pathlib.Path(directory).mkdir(parents=True, exist_ok=True)
            paths.append(os.path.join(directory, "stress.json"))
            markdown = stress_report.markdown(rows, data["meta"])
            pathlib.Path(directory, "stress.md").write_text(markdown)
        for path in filter(None, paths):
            with open(path, "w") as stream:
                json.dump(data, stream, indent=1, default=str)
        terminalreporter.write_line(f"stress results written: {', '.join(filter(None, paths))}")
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
