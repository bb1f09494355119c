"""The checks of a contact problem's set-up and of its steps, with the warnings they give.

A :class:`~dolfinx_mortar.problem.ContactProblem` runs them when it is built (before any
load step) and :meth:`~dolfinx_mortar.problem.ContactProblem.check_penetration` after each
accepted step. Each check is collective and raises (:func:`check_slave_body`) or warns
through :class:`ProblemWarnings`: a :class:`~dolfinx_mortar.diagnostics.ContactWarning`
shown once by rank 0 the first time a cause is met, INFO log lines after that.
"""

from __future__ import annotations

import logging
import typing

import numpy as np
from mpi4py import MPI

from . import diagnostics
from .deprecation import stacklevel_outside

logger = logging.getLogger("dolfinx_mortar")

INITIAL_OVERLAP = 0.05
"""A surface node deeper than this many facet lengths behind the other surface at
the start is reported as an initial overlap."""

STIFF_SLAVE_RATIO = 30.0
"""In 3D, a slave side this many times stiffer (about E) than its master gets a set-up
warning advising the swap: the dual multipliers of a stiff curved slave on a much softer
curved master oscillate (docs/benchmarks.md, "Contrast sweep in 3D")."""


COARSE_MASTER_RATIO = 2.0
"""``slave_side="auto"`` keeps a stiff slave whose master's facets are this many times
longer than its own: a coarse slave lets the master's nodes through it."""


class ProblemWarnings:
    """The ContactWarnings of one problem: each cause warns once, then logs.

    Attributes:
        setup: the texts of the warnings issued while the problem was built (on every
            rank): a failed load step's message repeats them.
        building: whether the problem is being built (its warnings go to ``setup``).
    """

    def __init__(self, comm: MPI.Intracomm):
        self.comm = comm
        self.seen: set = set()
        self.setup: list[str] = []
        self.building = True

    def __contains__(self, cause: tuple) -> bool:
        return cause in self.seen

    def warn(self, cause: tuple, message: str) -> None:
        """Collective: a :class:`ContactWarning` the first time this problem meets ``cause``
        (:func:`~dolfinx_mortar.diagnostics.warn`: shown once, by rank 0); later ones go to
        the ``dolfinx_mortar`` logger at INFO level (rank 0), as the progress lines do."""
        if cause in self.seen:
            if self.comm.rank == 0:
                logger.info("again: %s", message)
            return
        self.seen.add(cause)
        if self.building:
            self.setup.append(message)
        diagnostics.warn(self.comm, message, stacklevel=stacklevel_outside())


def pair_name(pair) -> str:
    """How messages name a :class:`~dolfinx_mortar.problem.ContactPair`."""
    label = f"'{pair.name}' " if pair.name else ""
    return f"contact pair {label}(slave tag {pair.slave}, master tag {pair.master})"


def check_slave_body(comm, pairs, interfaces, labels: np.ndarray) -> None:
    """Raise unless the slave and master surfaces of each pair lie on different bodies:
    meshes that share no node (a conforming mesh joins its parts: they move as one)."""
    for pair, interface in zip(pairs, interfaces, strict=True):
        if interface.self_contact:
            continue
        slave, master = interface.slave, interface.master
        slave_bodies = np.unique(np.concatenate(comm.allgather(labels[slave.cells])))
        master_bodies = np.unique(np.concatenate(comm.allgather(labels[master.cells])))
        if not np.intersect1d(slave_bodies, master_bodies).size:
            continue
        slave_nodes = np.concatenate(comm.allgather(slave.node_global_blocks))
        shared = np.isin(master.node_global_blocks, slave_nodes)
        count = np.unique(np.concatenate(
            comm.allgather(master.node_global_blocks[shared]))).size
        points = [p for p in comm.allgather(
            tuple(master.reference_coordinates[np.flatnonzero(shared)[0]])
            if shared.any() else None) if p is not None]
        where = (f"; the two surfaces share {count} node(s), one at ("
                 + ", ".join(f"{c:.4g}" for c in points[0]) + ")") if count else ""
        raise ValueError(
            f"{pair_name(pair)}: the slave and the master surface lie on one connected "
            f"mesh (cells joined through shared nodes{where}), so they cannot separate or "
            "slide. Either both tags are on the same body (is the slave or the master tag "
            "on the wrong body? a surface touching itself is one tag as both: "
            "ContactPair(tags, surface, surface)), or two bodies share nodes, "
            "as a gmsh model built with fragment or coherence makes them: build each body "
            "as its own mesh and join them with dolfinx_mortar.bodies.merge_meshes."
        )


def check_facing(warnings: ProblemWarnings, pairs, interfaces, u) -> None:
    """Warn when a slave surface looks away from its master where the two are closest."""
    for k, (pair, interface) in enumerate(zip(pairs, interfaces, strict=True)):
        if interface.self_contact:
            continue  # its facets face every way; the search pairs those that face
        slave, master = interface.slave, interface.master
        facing = diagnostics.facing_report(
            warnings.comm, slave.current_coordinates(u), slave.facets,
            master.current_coordinates(u), master.facets)
        if facing.looks_away:
            warnings.warn(
                ("facing", k),
                f"{pair_name(pair)}: the slave surface looks away from its master. Where "
                f"the two surfaces are closest ({facing.distance:.3g} apart), "
                f"{facing.facets_looking_away} of {facing.facets_compared} slave facets have "
                "an outward normal pointing the same way as the nearest master facet's "
                f"(mean cosine {facing.mean_cosine:+.2f}; facing surfaces have -1), so no "
                "facet can ever touch its master and the bodies would pass through each "
                "other. Likely cause: the slave or the master tag is on the wrong face of "
                "its body (outward normals point out of each body).",
            )


def check_initial_overlap(warnings: ProblemWarnings, pairs, interfaces, u) -> None:
    """Warn when the bodies start overlapping by more than :data:`INITIAL_OVERLAP`."""
    for k, (pair, interface) in enumerate(zip(pairs, interfaces, strict=True)):
        if ("facing", k) in warnings or interface.self_contact:
            continue  # the wrong face puts every node "behind": one message says it
        slave, master = interface.slave, interface.master
        report = diagnostics.penetration_report(
            warnings.comm, INITIAL_OVERLAP, slave.node_global_blocks,
            slave.current_coordinates(u), slave.facets, master.node_global_blocks,
            master.current_coordinates(u), master.facets)
        if report.count:
            other = "master" if report.side == "slave" else "slave"
            where = ", ".join(f"{c:.4g}" for c in report.where)
            warnings.warn(
                ("overlap", k),
                f"{pair_name(pair)}: the bodies overlap at the start: {report.count} "
                f"surface node(s) lie behind the other surface by more than "
                f"{INITIAL_OVERLAP:g} facet lengths, the deepest a {report.side} node "
                f"{report.depth:.3g} facet lengths behind the {other} surface, at "
                f"({where}). The first load step pushes the bodies apart with whatever "
                "force that takes, on top of the load. Unless the overlap is meant (an "
                "interference fit), move a body so that the surfaces touch or are apart "
                "(its mesh coordinates, or the initial displacement u), and check the "
                "geometry's units and the facet tags.",
            )


def check_stiff_slave(warnings: ProblemWarnings, pairs, gdim: int, ratio: float) -> None:
    """Advise the swap when, in 3D, the slave sides are :data:`STIFF_SLAVE_RATIO` times
    stiffer than the master sides (``ratio``: the stiffness scale s times the facet
    length h, about E, of each, slave over master)."""
    if gdim != 3 or not ratio >= STIFF_SLAVE_RATIO:
        return
    names = ", ".join(pair_name(pair) for pair in pairs)
    warnings.warn(
        ("stiff slave",),
        f"{names}: the slave side is about {ratio:.3g} times stiffer than the master "
        "side. The contact pressure of a stiff curved slave on a much softer curved "
        "body can oscillate node to node (the mean pressure and the force stay "
        "right); the softer body as the slave does not. Swap the two tags in "
        "ContactPair(facet_tags, slave, master) unless the soft side is flat or much "
        "coarser (slave_side='auto', the default, swaps them unless the soft side's facets "
        f"are {COARSE_MASTER_RATIO:g} times longer).",
    )


def report_swap(warnings: ProblemWarnings, pair, ratio: float, normals: str,
                solved_normals: str) -> None:
    """Say once, at set-up, that ``pair`` is solved with its sides swapped
    (``slave_side="auto"``), why, and how to keep them."""
    normals_note = ("" if normals == solved_normals else
                    f" normals={normals!r} is read as {solved_normals!r}, the same body's.")
    warnings.warn(
        ("swapped", pair.slave, pair.master, pair.name),
        f"{pair_name(pair)}: the slave side is about {ratio:.3g} times stiffer than the "
        "master side, so the pair is solved with the two sides swapped (master tag "
        f"{pair.master} as the slave): the contact pressure of a stiff curved slave on a "
        "much softer body oscillates node to node, the softer side's does not. Contact "
        "pressures and friction states are then at the nodes of tag "
        f"{pair.master}; contact_forces() keeps the order of the ContactPair "
        f"(ContactProblem.swapped, solved_pair()).{normals_note} Pass slave_side='given' "
        "to keep the sides as given.",
    )


def check_free_bodies(warnings: ProblemWarnings, pairs, interfaces, labels: np.ndarray,
                      free: list[diagnostics.FreeBody],
                      smallest_gap: typing.Callable[[int], float], slave_length: float) -> None:
    """Warn about bodies that only contact could hold (``free``, from
    :func:`diagnostics.free_translations`) where none touches the other body at the start
    (a nodal gap, ``smallest_gap(k)`` of pair k's covered slave nodes over all ranks,
    within 1e-6 slave facet lengths of zero): the first Newton matrix is singular."""
    if not free:
        return
    comm = warnings.comm
    holding = {}  # body label -> (pairs on it, smallest covered nodal gap)
    for k, (pair, interface) in enumerate(zip(pairs, interfaces, strict=True)):
        bodies = np.unique(np.concatenate(comm.allgather(np.concatenate([
            labels[interface.slave.cells], labels[interface.master.cells]]))))
        if not any(body.label in bodies for body in free):
            continue
        smallest = smallest_gap(k)
        for label in bodies:
            names, gaps = holding.get(int(label), ([], []))
            holding[int(label)] = (names + [pair_name(pair)], gaps + [smallest])
    for body in free:
        names, gaps = holding.get(body.label, ([], []))
        if any(g <= 1e-6 * slave_length for g in gaps):
            continue
        warnings.warn(("free body", body.label), _free_body_message(body, names, gaps))


def _free_body_message(body: diagnostics.FreeBody, names: list[str], gaps: list[float]) -> str:
    axes = ", ".join("xyz"[a] for a in body.axes)
    direction = "that direction" if len(body.axes) == 1 else "those directions"
    box = " .. ".join("(" + ", ".join(f"{c:.4g}" for c in corner) + ")"
                      for corner in (body.lower, body.upper))
    if not names:
        contact = "it is on no contact pair"
    elif np.isfinite(min(gaps)):
        contact = (f"no contact is active at the start: the smallest nodal gap of its "
                   f"pair(s) ({'; '.join(names)}) is {min(gaps):.3g}")
    else:
        contact = (f"no contact is active at the start: no slave node of its pair(s) "
                   f"({'; '.join(names)}) has a master facet within the search margin")
    return (
        f"the body with nodes in {box} is free to move as a rigid body along {axes}: "
        f"no Dirichlet condition holds it in {direction} and {contact}. The first "
        "Newton system is then singular, and the solve fails (often reported as "
        "inverted elements or a failed linear solve) or leaves the body where it is. "
        "Hold it with a Dirichlet condition (e.g. a prescribed displacement on one "
        "face), or start it touching the other body."
    )


def check_penetration(warnings: ProblemWarnings, pairs, interfaces, u, threshold: float,
                      penalty: float | None) -> list[diagnostics.Penetration]:
    """Nodes of either surface more than ``threshold`` facet lengths behind the other one,
    per pair; warns if any (``penalty``: the penalty parameter of a penalty method, named
    among the causes; None with Lagrange multipliers)."""
    reports = []
    for k, (pair, interface) in enumerate(zip(pairs, interfaces, strict=True)):
        if interface.self_contact:
            report = diagnostics.penetration_report(
                warnings.comm, threshold, *interface.pair_sides())
        else:
            slave, master = interface.slave, interface.master
            report = diagnostics.penetration_report(
                warnings.comm, threshold, slave.node_global_blocks,
                slave.current_coordinates(u), slave.facets, master.node_global_blocks,
                master.current_coordinates(u), master.facets)
        reports.append(report)
        if report.count:
            other = "master" if report.side == "slave" else "slave"
            where = ", ".join(f"{c:.4g}" for c in report.where)
            causes = ["the slave or master tag on the wrong face of its body (normals "
                      "reversed)", "a load step that moved the bodies through each other "
                      f"by more than the search margin ({interface.reuse.margin:.3g})"]
            if penalty is not None:
                causes.append(f"a penalty parameter too soft (penalty={penalty:.3g})")
            warnings.warn(
                ("penetration", k),
                f"{pair_name(pair)}: {report.count} {report.side} node(s) ended the step "
                f"behind the {other} surface by more than {threshold:g} facet lengths "
                f"(deepest {report.depth:.3g} facet lengths, at ({where})), beyond what "
                "the weighted (mortar) gap condition allows. Likely causes: "
                + "; ".join(causes) + ".",
            )
    return reports
