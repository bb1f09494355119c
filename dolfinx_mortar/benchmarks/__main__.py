"""``python3 -m dolfinx_mortar.benchmarks``: see the package's docstring or ``--help``."""

from .cli import main

if __name__ == "__main__":
    raise SystemExit(main())
