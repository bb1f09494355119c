"""The machine a benchmark ran on: load average during the run, hardware and versions."""

from __future__ import annotations

import contextlib
import os
import pathlib
import platform
import threading
import time

import numpy as np
from mpi4py import MPI

from .common import DEMOS


class LoadMonitor:
    """Samples the 1-minute load average every few seconds in a background thread."""

    def __init__(self, interval: float = 5.0):
        self.interval = interval
        self.samples: list[float] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self.start_time = time.time()

    def _run(self) -> None:
        while not self._stop.is_set():
            self.samples.append(os.getloadavg()[0])
            self._stop.wait(self.interval)

    def __enter__(self) -> LoadMonitor:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()

    def summary(self) -> dict:
        samples = self.samples or [os.getloadavg()[0]]
        return {"min": min(samples), "mean": float(np.mean(samples)), "max": max(samples),
                "samples": len(samples), "interval_s": self.interval,
                "duration_s": time.time() - self.start_time}


def machine_info(demos: tuple[str, ...] = ("hertz", "patch_test")) -> dict:
    """Hardware, load and versions; a hash of the library's modules and of ``demos``."""
    import dolfinx
    import petsc4py
    import scipy
    from petsc4py import PETSc

    memory = {}
    with contextlib.suppress(OSError):
        for line in pathlib.Path("/proc/meminfo").read_text().splitlines():
            key, value = line.split(":", 1)
            if key in ("MemTotal", "MemAvailable"):
                memory[key] = round(int(value.split()[0]) / 1024**2, 1)
    cpu = platform.processor()
    with contextlib.suppress(OSError):
        for line in pathlib.Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    try:
        usable = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover
        usable = os.cpu_count()
    os_release = ""
    with contextlib.suppress(OSError):
        for line in pathlib.Path("/etc/os-release").read_text().splitlines():
            if line.startswith("PRETTY_NAME="):
                os_release = line.split("=", 1)[1].strip('"')
    import hashlib

    import dolfinx_mortar

    package = pathlib.Path(dolfinx_mortar.__file__).resolve().parent
    sources = sorted(package.glob("*.py"))
    sources += [DEMOS / f"{name}.py" for name in demos]
    digest = hashlib.sha256()
    for path in sources:
        if path.exists():
            digest.update(path.name.encode() + path.read_bytes())
    return {
        "dolfinx_mortar_path": str(package),
        "dolfinx_mortar_sources_sha256": digest.hexdigest()[:16],
        "nproc": usable,
        "cpu": cpu,
        "memory_gib": memory.get("MemTotal"),
        "memory_available_gib_at_start": memory.get("MemAvailable"),
        "load_at_start": list(os.getloadavg()),
        "os": os_release,
        "python": platform.python_version(),
        "dolfinx": dolfinx.__version__,
        "petsc": ".".join(str(v) for v in PETSc.Sys.getVersion()),
        "petsc4py": petsc4py.__version__,
        # Open MPI ends its version string with a NUL byte
        "mpi": MPI.Get_library_version().replace("\x00", "").splitlines()[0].strip(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "omp_num_threads": os.environ.get("OMP_NUM_THREADS"),
    }



def machine_markdown(machine: dict, load: dict, command: str, elapsed: float,
                     label: str = "") -> str:
    code = (f"library: {label + ', ' if label else ''}sources sha256 "
            f"{machine.get('dolfinx_mortar_sources_sha256', '?')}; ")
    return (f"command: `{command}`; {code}{elapsed / 60:.1f} min; {machine['nproc']} cores "
            f"({machine['cpu']}), {machine['memory_gib']} GiB; load average (1 min) during the "
            f"run min {load['min']:.2f} / mean {load['mean']:.2f} / max {load['max']:.2f} "
            f"({load['samples']} samples); {machine['os']}, dolfinx {machine['dolfinx']}, PETSc "
            f"{machine['petsc']}, {machine['mpi'].replace(chr(0), '').strip()}, Python "
            f"{machine['python']}, numpy "
            f"{machine['numpy']}.\n")


