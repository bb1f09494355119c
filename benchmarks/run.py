"""The benchmark suite's command line: ``tools/run python3 benchmarks/run.py --help``.

Work-precision, cost of contact, skipped work (2D) and the 3D sections, all written
as JSON, PNG and markdown into ``--output``; the sections and their options are
described in ``benchmarks/suite/__init__.py`` and in ``docs/benchmarks.md``. Run it
from a source checkout: it runs the demos of ``demos/`` and is not installed with
the package.
"""

from suite.cli import main

if __name__ == "__main__":
    raise SystemExit(main())
