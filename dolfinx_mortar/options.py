"""The options of a contact problem: frozen, each choice a :data:`typing.Literal`.

:class:`ContactOptions` holds every keyword option of
:class:`~dolfinx_mortar.problem.ContactProblem` but the PETSc ones, checked once when it is
made (a typo in a choice raises there, naming the choices). Friction laws are the small
frozen dataclasses :class:`Coulomb` and :class:`Tresca`. Pure Python: importing this
module needs neither dolfinx nor PETSc.
"""

from __future__ import annotations

import dataclasses
import typing

from .deprecation import warn_deprecated

Method = typing.Literal["lagrange", "penalty", "augmented"]
ActiveSet = typing.Literal["semismooth", "fixed-point"]
Integration = typing.Literal["segment", "element"]
Normals = typing.Literal["averaged", "slave", "master"]
Basis = typing.Literal["dual", "standard"]
Configuration = typing.Literal["current", "reference"]
LinearSolver = typing.Literal["auto", "direct", "iterative"]
SlaveSide = typing.Literal["auto", "given"]


@dataclasses.dataclass(frozen=True)
class Coulomb:
    """Coulomb friction: a node sticks while its tangential traction is below mu times its
    normal pressure (:mod:`dolfinx_mortar.friction`)."""

    mu: float
    kind: typing.ClassVar[str] = "coulomb"

    def __post_init__(self):
        _check_nonnegative("coulomb", self.mu)

    @property
    def value(self) -> float:
        """The law's parameter: mu."""
        return float(self.mu)


@dataclasses.dataclass(frozen=True)
class Tresca:
    """Tresca friction: a node sticks while its tangential traction is below ``bound``, a
    pressure independent of the normal one."""

    bound: float
    kind: typing.ClassVar[str] = "tresca"

    def __post_init__(self):
        _check_nonnegative("tresca", self.bound)

    @property
    def value(self) -> float:
        """The law's parameter: the bound."""
        return float(self.bound)


FrictionLaw = Coulomb | Tresca


def _check_nonnegative(kind: str, value) -> None:
    if not float(value) >= 0.0:
        raise ValueError(f"the {kind} friction parameter must be >= 0, got {value}")


def friction_law(friction) -> Coulomb | Tresca | None:
    """A law from ``friction``: None, a :class:`Coulomb` or :class:`Tresca`, or (deprecated)
    a ``("coulomb", mu)`` or ``("tresca", bound)`` tuple."""
    if friction is None or isinstance(friction, Coulomb | Tresca):
        return friction
    try:
        kind, value = friction
    except (TypeError, ValueError):
        raise ValueError(
            f"friction must be None, Coulomb(mu) or Tresca(bound); got {friction!r}") from None
    laws = {"coulomb": Coulomb, "tresca": Tresca}
    if kind not in laws:
        raise ValueError(f"unknown friction law {kind!r}; expected one of {tuple(laws)}")
    warn_deprecated(f"friction=({kind!r}, {value!r}) is deprecated; pass "
                    f"{laws[kind].__name__}({value!r}) (from dolfinx_mortar import "
                    f"{laws[kind].__name__})")
    return laws[kind](float(value))


@dataclasses.dataclass(frozen=True)
class ContactOptions:
    """How a :class:`~dolfinx_mortar.problem.ContactProblem` enforces and solves contact.

    Attributes:
        method: ``lagrange`` multipliers, ``penalty`` or ``augmented`` Lagrange.
        integration: ``segment`` (exact on the facet intersections) or ``element``
            (``num_gauss_points`` per slave facet).
        num_gauss_points: of ``element`` integration (None: the kernel's default).
        normals: ``averaged`` (nodal normals of the slave), ``slave`` or ``master``.
        active_set: ``semismooth`` or ``fixed-point`` (lagrange only).
        basis: of the multipliers, ``dual`` or ``standard`` (``multipliers=``, the old
            name of this option, still works for one release). Dual is the default: the
            conditions decouple node by node, and on Hertz it puts the contact edge
            within one element where standard does not (docs/benchmarks.md).
        c_n: complementarity parameter (unit pressure / length); default about E/h of
            the two sides in series, 1 / (1/s_slave + 1/s_master), each s estimated from
            the bulk stiffness at that side's nodes and its facet length. It changes the
            Newton path, never the solution.
        penalty: eps of penalty and augmented Lagrange; default the slave's E/h (10 E/h
            for augmented Lagrange, whose Uzawa updates converge faster with a stiffer eps).
        augmented_tolerance: Uzawa stops when max|lam_new - lam| <= this times
            max(max|lam|, 1e-4 E) (E the bulk stiffness scale).
        max_outer_iterations: of the fixed-point and Uzawa loops.
        search_margin: of the contact search (default 2 slave facet lengths).
        configuration: ``current`` (finite deformation) or ``reference`` (small strain:
            mortar integrals on the undeformed surfaces, to pair with linear elasticity).
        condensation: solve the Newton systems by static condensation of the multipliers
            (dual only): a displacement-sized matrix is factorized (options prefix
            ``<prefix>condensed_``, default MUMPS LU) and preconditions fgmres on the
            monolithic system (``<prefix>ksp_``, default rtol 1e-12), so the solution is
            the uncondensed one (:mod:`dolfinx_mortar.condensation`).
        linear_solver: ``auto`` (``iterative`` for 3D problems of at least
            :data:`~dolfinx_mortar.solvers.AUTO_ITERATIVE_MIN_DOFS` displacement dofs with
            dual multipliers (friction or not), else ``direct``; why:
            :func:`~dolfinx_mortar.solvers.automatic_linear_solver`), ``direct`` (MUMPS
            LU, of the monolithic system, or of the condensed one with ``condensation``)
            or ``iterative``: condensation (dual multipliers only) with GMRES and hypre's
            BoomerAMG on the condensed matrix, the rigid-body modes of each body as
            near-nullspace (options under ``<prefix>condensed_``, e.g. ``pc_type: gamg``).
            When the iterative solver that ``auto`` chose fails a linear solve, the direct
            one solves that load step again and the rest of the run, with a
            ContactWarning; an explicit ``iterative`` is kept (the step is cut back).
        friction: None (frictionless), a :class:`Coulomb` or :class:`Tresca` law, or a
            list of these (or None), one per pair, kept as a tuple (with ``lagrange``
            semismooth or ``penalty``; any linear solver).
        c_t: the tangential complementarity parameter (default c_n), or with ``penalty``
            the tangential penalty (default the normal one).
        pressure_recovery: whether ``contact_pressure`` gives the recovered pressure
            (:mod:`dolfinx_mortar.recovery`) or the multipliers, and
            ``tangential_traction`` likewise; None: recovered in 3D,
            where the multipliers of tetrahedral meshes scatter, the multipliers in 2D,
            where the fit would only add its curvature error (docs/benchmarks.md).
        slave_side: ``auto``: in 3D, a pair whose slave side is
            :data:`~dolfinx_mortar.checks.STIFF_SLAVE_RATIO` times stiffer than its master,
            and whose master is not much coarser, is solved with the two sides swapped
            (the multipliers on the softer side; a ContactWarning says so at set-up), since
            the multipliers of a stiff curved slave on a much softer body oscillate
            (docs/benchmarks.md, "Contrast sweep in 3D"); ``given``: the sides as the
            :class:`~dolfinx_mortar.problem.ContactPair` says (a stiff slave then gets the
            set-up advice to swap).
    """

    method: Method = "lagrange"
    integration: Integration = "segment"
    num_gauss_points: int | None = None
    normals: Normals = "averaged"
    active_set: ActiveSet = "semismooth"
    basis: Basis = "dual"
    c_n: float | None = None
    penalty: float | None = None
    augmented_tolerance: float = 1e-8
    max_outer_iterations: int = 100
    search_margin: float | None = None
    configuration: Configuration = "current"
    condensation: bool = False
    linear_solver: LinearSolver = "auto"
    friction: Coulomb | Tresca | tuple | None = None
    c_t: float | None = None
    pressure_recovery: bool | None = None
    slave_side: SlaveSide = "auto"

    def __post_init__(self):
        hints = typing.get_type_hints(ContactOptions)
        for field in dataclasses.fields(self):
            allowed = typing.get_args(hints[field.name])
            value = getattr(self, field.name)
            if typing.get_origin(hints[field.name]) is typing.Literal and value not in allowed:
                raise ValueError(f"unknown {field.name} {value!r}; expected one of {allowed}")
        for name in ("c_n", "penalty", "c_t"):
            value = getattr(self, name)
            if value is not None and not value > 0:
                raise ValueError(f"{name} must be positive, got {value}")
        if self.active_set == "fixed-point" and self.method != "lagrange":
            raise ValueError("active_set='fixed-point' applies to method='lagrange' only")
        if self.linear_solver == "iterative" and self.basis != "dual":
            raise ValueError(
                "linear_solver='iterative' solves the condensed displacement system, which "
                "needs dual multipliers, basis='dual' (formerly multipliers='dual'); got "
                f"basis={self.basis!r}")
        if self.condensation and self.basis != "dual":
            raise ValueError(
                "condensation=True needs dual multipliers, basis='dual' (formerly "
                "multipliers='dual'): with the standard basis the multipliers do not decouple "
                f"node by node; got basis={self.basis!r}")
        friction = (tuple(friction_law(f) for f in self.friction) if _per_pair(self.friction)
                    else friction_law(self.friction))
        object.__setattr__(self, "friction", friction)

    def friction_laws(self, num_pairs: int) -> list[Coulomb | Tresca | None]:
        """One law (or None) per pair: the one law for all, or one of the list's each."""
        if not isinstance(self.friction, tuple):
            return [self.friction] * num_pairs
        if len(self.friction) != num_pairs:
            raise ValueError(
                f"friction: got {len(self.friction)} laws for {num_pairs} contact pairs")
        return list(self.friction)

    @property
    def has_friction(self) -> bool:
        """Whether any pair has a friction law."""
        laws = self.friction if isinstance(self.friction, tuple) else (self.friction,)
        return any(law is not None for law in laws)


DEPRECATED_NAMES = {"multipliers": "basis"}
"""Old keyword names of the options, each with its new name (for one release)."""


def contact_options(options: ContactOptions | None, keywords: dict) -> ContactOptions:
    """``options`` (default :class:`ContactOptions`) with the fields in ``keywords``
    replaced; an old name of :data:`DEPRECATED_NAMES` warns and stands for the new one."""
    keywords = dict(keywords)
    for old, new in DEPRECATED_NAMES.items():
        if old in keywords:
            if new in keywords:
                raise TypeError(f"pass {new}= only ({old}= is its deprecated name)")
            warn_deprecated(f"the option {old}= is deprecated; it is called {new}= now")
            keywords[new] = keywords.pop(old)
    return dataclasses.replace(options or ContactOptions(), **keywords)


def _per_pair(friction) -> bool:
    """Is ``friction`` one law per pair (a list, or a tuple of laws), not one law?"""
    return isinstance(friction, list) or (
        isinstance(friction, tuple) and not (friction and isinstance(friction[0], str)))
