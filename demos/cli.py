"""Command-line helpers shared by the demos.

Every demo builds its parser with :func:`parser`, which gives ``--help`` its
defaults and the two output options all demos take: ``--output DIR`` (PNG,
ParaView and CSV files) and ``--json FILE`` (the summary that ``main`` returns).
The contact demos add the solver options with :func:`add_common_arguments` and
pass them on with :func:`problem_options`.

It lives beside the demos, not in the library: ``python3 demos/NAME.py`` finds it
first on ``sys.path``, and a demo loaded from its path (the tests, the benchmarks)
puts its own folder there before importing it. The package never imports
``demos/``.
"""

from __future__ import annotations

import argparse
import json
import pathlib
from collections.abc import Mapping
from typing import Any

from dolfinx_mortar import Coulomb, Tresca


class HelpFormatter(argparse.RawDescriptionHelpFormatter, argparse.ArgumentDefaultsHelpFormatter):
    """Keeps the module docstring's line breaks and appends "(default: ...)" to options."""


def parser(description: str | None) -> argparse.ArgumentParser:
    """An argument parser with ``--output DIR`` and ``--json FILE`` and defaults in ``--help``.

    Args:
        description: Shown by ``--help`` as written (usually the demo's docstring).
    """
    result = argparse.ArgumentParser(description=description, formatter_class=HelpFormatter)
    add_output_arguments(result)
    return result


def add_output_arguments(parser: argparse.ArgumentParser) -> None:
    """``--output DIR`` and ``--json FILE``, the output options every demo takes."""
    parser.add_argument(
        "--output",
        type=pathlib.Path,
        default=None,
        metavar="DIR",
        help="write PNG, ParaView (.bp) and CSV files in this directory",
    )
    parser.add_argument(
        "--json",
        type=pathlib.Path,
        default=None,
        metavar="FILE",
        help="write the JSON summary here",
    )


def add_material_argument(
    parser: argparse.ArgumentParser,
    help: str = "bulk material of both bodies",  # noqa: A002 (argparse's name)
) -> None:
    """``--material``: one of the library's models (:data:`dolfinx_mortar.materials.MODELS`),
    default ``linear``."""
    from dolfinx_mortar.materials import MODELS

    parser.add_argument("--material", choices=MODELS, default="linear", help=help)


def add_common_arguments(
    parser: argparse.ArgumentParser,
    normals: str | None = "averaged",
    normals_help: str = "normals of the contact constraints",
    mu: float | None = None,
) -> None:
    """The solver options every contact demo shares (method, integration, normals, ...).

    Args:
        parser: Gets the options.
        normals: Default of ``--normals`` (None lets the demo decide; say how in
            ``normals_help``).
        normals_help: Help text of ``--normals``.
        mu: Default of ``--mu`` (None: frictionless).
    """
    parser.add_argument(
        "--method",
        choices=("lagrange", "penalty", "augmented"),
        default="lagrange",
        help="how the contact constraints are enforced",
    )
    parser.add_argument(
        "--integration",
        choices=("segment", "element"),
        default="segment",
        help="mortar integration: on slave-master segments or per slave facet",
    )
    parser.add_argument(
        "--gauss-points",
        type=int,
        default=None,
        help="per segment / slave facet (None: the library's choice)",
    )
    parser.add_argument(
        "--normals", choices=("averaged", "slave", "master"), default=normals, help=normals_help
    )
    parser.add_argument(
        "--multipliers",
        choices=("standard", "dual"),
        default="dual",
        help="basis of the Lagrange multipliers",
    )
    parser.add_argument(
        "--active-set",
        choices=("semismooth", "fixed-point"),
        default="semismooth",
        help="active-set strategy",
    )
    parser.add_argument(
        "--c-n",
        type=float,
        default=None,
        help="complementarity parameter (None: scaled from E/h by the library)",
    )
    parser.add_argument(
        "--penalty",
        type=float,
        default=None,
        help="penalty parameter eps (None: scaled from E/h by the library)",
    )
    parser.add_argument(
        "--condensation",
        action="store_true",
        help="condense the (dual) multipliers: factorize a displacement-sized matrix",
    )
    parser.add_argument(
        "--linear-solver",
        choices=("auto", "direct", "iterative"),
        default="auto",
        help="direct: MUMPS LU; iterative: condensed system, GMRES + BoomerAMG (GAMG "
        "selectable) with rigid-body modes (dual multipliers); auto (default): iterative "
        "for large 3D problems with dual multipliers, else direct",
    )
    parser.add_argument(
        "--slave-side",
        choices=("auto", "given"),
        default="auto",
        help="auto (default): in 3D, a slave much stiffer than its master is solved as the "
        "master (the multipliers on the softer side); given: as the demo assigns them",
    )
    parser.add_argument(
        "--search-margin",
        type=float,
        default=None,
        help="contact search margin, a length (None: scaled from the facet size)",
    )
    friction = parser.add_mutually_exclusive_group()
    friction.add_argument(
        "--mu", type=float, default=mu,
        help="Coulomb friction coefficient (default: "
        + ("frictionless" if mu is None else f"{mu:g}") + ")")
    friction.add_argument(
        "--tresca", type=float, default=None, help="Tresca friction: the slip bound, a pressure"
    )
    parser.add_argument(
        "--c-t",
        type=float,
        default=None,
        help="tangential complementarity parameter (None: c_n; with --method penalty the "
        "tangential penalty)",
    )


def add_predictor_argument(parser: argparse.ArgumentParser, default: str = "none") -> None:
    """``--predictor``: the initial guess of each load step
    (:func:`dolfinx_mortar.loading.solve_load_steps`)."""
    parser.add_argument(
        "--predictor",
        choices=("none", "extrapolate"),
        default=default,
        help="initial guess of a load step: the last converged state (none) or the last two "
        "extrapolated linearly in the load parameter",
    )


def problem_options(args: argparse.Namespace) -> dict[str, Any]:
    """The keyword arguments of ContactProblem that :func:`add_common_arguments` set."""
    return {
        "method": args.method,
        "integration": args.integration,
        "num_gauss_points": args.gauss_points,
        "normals": args.normals,
        "basis": args.multipliers,
        "active_set": args.active_set,
        "c_n": args.c_n,
        "penalty": args.penalty,
        "condensation": args.condensation,
        "linear_solver": args.linear_solver,
        "search_margin": args.search_margin,
        "friction": friction_option(args),
        "c_t": args.c_t,
        "slave_side": args.slave_side,
    }


def option_record(args: argparse.Namespace) -> dict[str, Any]:
    """:func:`problem_options` as the demos' JSON summaries record them: plain values, the
    basis under its command-line name, a friction law as [kind, value]."""
    record = {("multipliers" if key == "basis" else key): value
              for key, value in problem_options(args).items()}
    law = record["friction"]
    record["friction"] = None if law is None else [law.kind, law.value]
    return record


def friction_option(args: argparse.Namespace) -> Coulomb | Tresca | None:
    """ContactProblem's ``friction`` from ``--mu`` / ``--tresca`` (None: frictionless)."""
    if args.mu is not None:
        return Coulomb(args.mu)
    if args.tresca is not None:
        return Tresca(args.tresca)
    return None


def save_figure(fig, path: pathlib.Path) -> None:
    """Write a demo's matplotlib figure to ``path`` (its folder made if needed) and close it."""
    import matplotlib.pyplot as plt

    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120, bbox_inches="tight")
    plt.close(fig)


def write_summary(path: pathlib.Path | None, summary: Mapping[str, Any]) -> None:
    """The ``--json`` option: write ``summary`` to ``path`` if given (call on one rank)."""
    if path:
        path = pathlib.Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(summary, indent=2))

