"""The kernel contract: what every mortar kernel takes and returns, in both dimensions.

A kernel (:class:`MortarKernel`) is a computation over a batch of (slave facet, master
facet) pairs, numpy arrays in and out (no MPI, no PETSc, no dolfinx). It takes the pairs'
coordinates (:class:`PairGeometry`) and the options (:class:`KernelOptions`) and returns one
:class:`PairQuantities`: D, M, Dn, Mn, the weighted gaps and the nodal areas, with the
derivatives of Dn, Mn, gap and area over the pair's *kernel variables* (2D: the six
nodes p, a, b, q, c, d; 3D: the slave nodes, the master nodes and the slave nodal
normals). The stencils (:mod:`dolfinx_mortar.stencils`) are the only callers; above
them nothing knows the dimension.

There is one implementation of each kernel, compiled C through cffi (:mod:`.compiled`), as
dolfinx's own form kernels are: it needs a C compiler and cffi, as dolfinx's form compilation
does. The vectorized numpy version that came first is kept as the tests' oracle
(``tests/oracle``), not in the package: two implementations behind an option would both have
to be kept right, and only one of them would be run. The ``kernels`` option and
``$DOLFINX_MORTAR_KERNELS`` that chose between them are gone (:data:`KERNELS_VARIABLE`).
"""

from __future__ import annotations

import dataclasses
import typing

import numpy as np

from ..deprecation import removed_keyword, warn_removed_variable
from ..dual import RowSubsetDual

NormalOption = typing.Literal["averaged", "slave", "master"]
IntegrationOption = typing.Literal["segment", "element"]
BasisOption = typing.Literal["standard", "dual"]

NORMAL_OPTIONS: tuple[str, ...] = typing.get_args(NormalOption)
INTEGRATION_OPTIONS: tuple[str, ...] = typing.get_args(IntegrationOption)
BASIS_OPTIONS: tuple[str, ...] = typing.get_args(BasisOption)
KERNELS_VARIABLE = "DOLFINX_MORTAR_KERNELS"
"""The environment variable that once chose the kernels' implementation; set, it warns."""

_ONE_IMPLEMENTATION = ("the mortar kernels have one implementation, compiled C through cffi "
                       "(it needs a C compiler and cffi, as dolfinx's form compilation does); "
                       "the numpy kernels were removed from the package and live on as the "
                       "tests' oracle (tests/oracle)")


def _refuse_numpy(kernels) -> None:
    if kernels != "compiled":
        raise ValueError(f"KernelOptions(kernels={kernels!r}): {_ONE_IMPLEMENTATION}")


@dataclasses.dataclass(frozen=True)
class KernelOptions:
    """How a kernel integrates.

    Attributes:
        normals: the normal field (averaged nodal, the slave facet's, the master facet's).
        integration: ``segment`` (over the overlaps, exact) or ``element`` (the slave
            facet's Gauss points that land on the master).
        basis: the multiplier basis of the kernel itself (the interface's covered dual
            basis runs the kernels with the standard one, :mod:`dolfinx_mortar.covered`).
        num_gauss_points: per segment or integration cell; None: the kernel's default.
        scalar_gradients: also keep the gradients of D and M (``D_dual``, ``M_dual``;
            friction's 3D tangent frames and the covered dual basis need them). The 2D
            kernel's gradients (``segment_gradients``) always hold those of D; with it they
            also hold M's.

    The ``kernels`` argument is gone with the numpy kernels (module docstring):
    ``kernels="compiled"`` still works for one release, with a DeprecationWarning;
    ``kernels="numpy"`` raises a ValueError. ``$DOLFINX_MORTAR_KERNELS``, set, is not read:
    it warns once per process.
    """

    normals: NormalOption = "averaged"
    integration: IntegrationOption = "segment"
    basis: BasisOption = "standard"
    num_gauss_points: int | None = None
    scalar_gradients: bool = False

    def __post_init__(self):
        for value, allowed, what in ((self.normals, NORMAL_OPTIONS, "normal option"),
                                     (self.integration, INTEGRATION_OPTIONS, "integration"),
                                     (self.basis, BASIS_OPTIONS, "multiplier basis")):
            if value not in allowed:
                raise ValueError(f"unknown {what} {value!r}; expected one of {allowed}")
        warn_removed_variable(KERNELS_VARIABLE, "the compiled kernels run: "
                              + _ONE_IMPLEMENTATION)


KernelOptions.__init__ = removed_keyword(
    "kernels", "KernelOptions(kernels=...) is deprecated: " + _ONE_IMPLEMENTATION
    + "; drop the argument", refuse=_refuse_numpy)(KernelOptions.__init__)


@dataclasses.dataclass(frozen=True)
class PairGeometry:
    """The coordinates of a batch of n pairs, as a kernel takes them.

    Attributes:
        slave_x: (n, ns, gdim) slave facet nodes (oriented outward, module docstrings of
            the kernels).
        master_x: (n, nm, gdim) master facet nodes.
        slave_normals: (n, ns, gdim) unit nodal normals at the slave nodes, given as
            kernel variables (3D: their own derivatives over the nodes' stars are chained
            by the stencil); None for a kernel that builds them from ``neighbour_x``.
        neighbour_x: (n, ns, gdim) per slave node, the other end of the slave facet
            adjacent there (2D: p and q, variables of the averaged normals); None in 3D.
        has_neighbour: (n, ns) whether that neighbour exists (absent: any coordinates).
    """

    slave_x: np.ndarray
    master_x: np.ndarray
    slave_normals: np.ndarray | None = None
    neighbour_x: np.ndarray | None = None
    has_neighbour: np.ndarray | None = None

    @property
    def num_pairs(self) -> int:
        return self.slave_x.shape[0]

    def part(self, index) -> PairGeometry:
        """The geometry of the pairs ``index`` (a slice or indices)."""
        def of(array):
            return None if array is None else array[index]

        return PairGeometry(of(self.slave_x), of(self.master_x), of(self.slave_normals),
                            of(self.neighbour_x), of(self.has_neighbour))


@dataclasses.dataclass(frozen=True)
class IndexedPairGeometry:
    """The coordinates of a batch of pairs as rows of node tables (3D): a kernel gathers
    them a part at a time (:meth:`part`), so that a search's candidates, most of which do
    not overlap, never have their coordinates copied all at once.

    Attributes:
        node_x: (num_nodes, gdim) node coordinates.
        slave_nodes, master_nodes: (n, ns) and (n, nm) rows of ``node_x``.
        normals: (num_normals, gdim) unit nodal normals; normal_rows: (n, ns) the row of
            each slave node's in it. None: no normals (:attr:`PairGeometry.slave_normals`).
    """

    node_x: np.ndarray
    slave_nodes: np.ndarray
    master_nodes: np.ndarray
    normals: np.ndarray | None = None
    normal_rows: np.ndarray | None = None
    neighbour_x = None
    has_neighbour = None

    @property
    def num_pairs(self) -> int:
        return self.slave_nodes.shape[0]

    def part(self, index) -> PairGeometry:
        """The :class:`PairGeometry` of the pairs ``index`` (a slice or indices)."""
        normals = None if self.normals is None else self.normals[self.normal_rows[index]]
        return PairGeometry(self.node_x[self.slave_nodes[index]],
                            self.node_x[self.master_nodes[index]], normals)

    @property
    def slave_x(self) -> np.ndarray:
        return self.node_x[self.slave_nodes]

    @property
    def master_x(self) -> np.ndarray:
        return self.node_x[self.master_nodes]

    @property
    def slave_normals(self) -> np.ndarray | None:
        return None if self.normals is None else self.normals[self.normal_rows]


class PairGradients(typing.Protocol):
    """The 2D kernel's gradients of its outputs over the contributing pairs, in the form the
    kernel keeps them, and what the stencils ask of them: linear combinations of outputs
    (:meth:`combine`; in 2D they hold every pair at once) and the gradients of a range of
    outputs. Outputs are numbered ``Dn`` (0-7, 4 j + 2 k + c), ``Mn`` (8-15, 8 + 4 j + 2 l
    + c), ``area`` (16, 17), ``gap`` (18, 19), ``D`` (20-23, 20 + 2 j + k: the covered dual
    basis of :mod:`dolfinx_mortar.covered` needs it) and, where kept, ``M`` (24-27)."""

    @property
    def num_pairs(self) -> int:
        """The contributing pairs (the result's ``rows``)."""
        ...

    def combine(self, terms) -> np.ndarray:
        """(len(terms), 12, num_pairs): row p sums weight * d output / dx over (output,
        weight) in terms[p]; a weight is a number or a (num_pairs,) array."""
        ...

    def outputs(self, start: int, stop: int) -> np.ndarray:
        """(num_pairs, stop - start, 12): the gradients of outputs start .. stop - 1."""
        ...


class GradientsOnDemand(typing.Protocol):
    """The gradients of a kernel's outputs, made again for the pairs a consumer asks for
    rather than kept for every pair (a 3D pair's are ~1,700 numbers)."""

    chunk: int
    """Pairs asked for at once by the stencils (their gradients then live together)."""

    def gradients(self, rows: np.ndarray,
                  outputs: typing.Sequence[int] | None = None) -> list[np.ndarray | None]:
        """The gradients of the pairs ``rows`` (any pairs of the evaluation; zero outside
        the contributing ones) over the kernel variables, one array per output in the
        order of :meth:`PairQuantities.outputs`, each (len(rows), output shape...,
        num_variables). ``outputs``: the indices of the outputs whose gradients the
        consumer needs (None: all); the others may be None, not made."""
        ...


@dataclasses.dataclass
class PairQuantities:
    """The mortar contributions of a batch of candidate pairs, kept for the pairs that
    contribute only (``rows``): most candidates of a search do not overlap.

    Attributes:
        D_rows, M_rows: (r, ns, ns) and (r, ns, nm) values of the r pairs ``rows``.
        Dn, Mn: (n, ns, ns, gdim) and (n, ns, nm, gdim), slave node j, node k or l,
            component.
        gap: (n, ns) weighted gaps; area: (n, ns) int Phi_j over the overlap.
            The four are dual numbers over ``num_variables`` kernel variables, zero
            outside the pairs that contribute, whose values and gradients alone are kept
            (:class:`~dolfinx_mortar.dual.RowSubsetDual`).
        valid: (n,) the pair faces and overlaps.
        overlap: (n,) the overlap's length in the slave parameter (2D, 0 to 2) or the
            clipped area over the slave facet's area (3D).
        num_variables: kernel variables per pair.
        D_dual, M_dual: D and M with their gradients, when the options asked for them
            (:attr:`KernelOptions.scalar_gradients`); else None.
        normals_vary: whether the nodal normal variables follow the coordinates (False
            for integrals frozen in the reference configuration).
        segment_gradients: the 2D kernel's gradients of Dn, Mn, area, gap and D (and M where
            kept) over the pairs ``rows`` (:class:`PairGradients`; the compiled kernel keeps
            them in full, :class:`~.line2_compiled.FullGradients`); None once an output was
            replaced (:meth:`replaced`).
        gradients_on_demand: the compiled kernel keeps no gradients: it recomputes those of
            the pairs a consumer asks for (:class:`GradientsOnDemand`), a chunk at a time.
    """

    D_rows: np.ndarray
    M_rows: np.ndarray
    Dn: RowSubsetDual
    Mn: RowSubsetDual
    gap: RowSubsetDual
    area: RowSubsetDual
    valid: np.ndarray
    overlap: np.ndarray
    num_variables: int
    D_dual: RowSubsetDual | None = None
    M_dual: RowSubsetDual | None = None
    normals_vary: bool = True
    segment_gradients: PairGradients | None = None
    gradients_on_demand: GradientsOnDemand | None = None

    @property
    def rows(self) -> np.ndarray:
        """The pairs outside which every output is zero (sorted)."""
        return self.gap.rows

    @property
    def D(self) -> np.ndarray:  # noqa: N802
        """(n, ns, ns) D of every candidate, made on each access (checks; assembly reads
        ``D_rows``)."""
        return self._full(self.D_rows)

    @property
    def M(self) -> np.ndarray:  # noqa: N802
        """(n, ns, nm) M of every candidate, made on each access."""
        return self._full(self.M_rows)

    def _full(self, by_rows: np.ndarray) -> np.ndarray:
        full = np.zeros((self.valid.shape[0],) + by_rows.shape[1:])
        full[self.rows] = by_rows
        return full

    def outputs(self) -> list[RowSubsetDual]:
        """The outputs with gradients, in the stencils' numbering: Dn, Mn, area, gap, then D
        and M where kept."""
        kept = [self.Dn, self.Mn, self.area, self.gap]
        if self.D_dual is not None:
            kept += [self.D_dual, self.M_dual]
        return kept

    def replaced(self, **changes) -> PairQuantities:
        """A plain copy with some fields replaced; the kernel's own forms of its gradients
        (``segment_gradients``, ``gradients_on_demand``), which describe its outputs as it
        made them, are dropped unless given."""
        fields = {field.name: getattr(self, field.name)
                  for field in dataclasses.fields(PairQuantities)}
        fields.update(segment_gradients=None, gradients_on_demand=None)
        fields.update(changes)
        return PairQuantities(**fields)


class MortarKernel(typing.Protocol):
    """A mortar kernel of one facet dimension (:class:`~.line2.Line2Kernel`,
    :class:`~.surface3.Surface3Kernel`)."""

    gdim: int
    default_gauss_points: dict[str, int]
    """Per integration option, the Gauss points an interface takes by default."""

    def evaluate(self, geometry: PairGeometry, options: KernelOptions, *,
                 crosspoint: np.ndarray | None = None,
                 slave_facet: np.ndarray | None = None) -> PairQuantities:
        """The mortar contributions of every pair of ``geometry``.

        Args:
            geometry: the pairs' coordinates.
            options: how to integrate.
            crosspoint: (n, ns) slave nodes without a multiplier: their basis function
                is shared by the facet's other nodes.
            slave_facet: (n,) the slave facet of each pair: element-based integration
                gives each of its Gauss points to one master facet (default: every pair
                a facet of its own).
        """
        ...
