"""The compiled 2D kernel behind the contract: values and gradients at evaluation, kept.

The C kernel (``line2.c`` through :mod:`.compiled`) integrates every 2D option (normals
averaged, slave or master; segment- or element-based; standard or dual basis; any Gauss
rule; crosspoints). Unlike the 3D glue (:mod:`.surface3_compiled`) it keeps the gradients of
the contributing pairs from the evaluation rather than making them again on demand: a 2D
pair's are 288 numbers (Dn, Mn, the areas, the gaps and D over 12 variables; 336 with M),
fewer than a factorized form would keep (the numpy oracle's, ``tests/oracle/factors.py``),
and the one C pass that makes the values makes them for a few percent more time, where a second
pass per Jacobian would cost the whole kernel again.

They are kept row by row, ``(rows, outputs, 12)`` in the stencils' output numbering
(:class:`FullGradients`), as the kernel writes them; a linear combination of outputs, what
every consumer asks for (:meth:`FullGradients.combine`, as
:meth:`.contract.PairGradients.combine`), is one C pass over them (``line2_combine``) that
writes the stencils' layout ``(terms, 12, rows)``.
"""

from __future__ import annotations

import numpy as np

from ..dual import RowSubsetDual
from . import compiled
from .contract import KernelOptions, PairGeometry, PairQuantities

NUM_VARIABLES = compiled.LINE2_NUM_VARIABLES
_SHAPES = {"Dn": (2, 2, 2), "Mn": (2, 2, 2), "area": (2,), "gap": (2,), "D": (2, 2),
           "M": (2, 2)}
_FIRST = {"Dn": 0, "Mn": 8, "area": 16, "gap": 18, "D": 20, "M": 24}


class FullGradients:
    """Every kept output's gradient of the contributing pairs, as the compiled kernel made
    them (:class:`~.contract.PairGradients`): ``grad`` (rows, outputs, 12), outputs numbered
    as the contract numbers them (Dn 0-7, Mn 8-15, area 16-17, gap 18-19, D 20-23) and, when
    kept, M 24-27."""

    def __init__(self, grad: np.ndarray):
        self.grad = grad

    @property
    def num_pairs(self) -> int:
        return self.grad.shape[0]

    @property
    def num_outputs(self) -> int:
        return self.grad.shape[1]

    def combine(self, terms) -> np.ndarray:
        """(len(terms), 12, n): row p sums weight * d output / dx over (output, weight) in
        terms[p] (a weight is a number or an (n,) array); one C pass over the rows."""
        n = self.num_pairs
        result = np.empty((len(terms), NUM_VARIABLES, n))
        entries = [entry for row in terms for entry in row]
        term_start = np.cumsum([0] + [len(row) for row in terms], dtype=np.intc)
        output = np.array([o for o, _ in entries], dtype=np.intc)
        if np.any((output < 0) | (output >= self.num_outputs)):
            raise ValueError(f"outputs {output[(output < 0) | (output >= self.num_outputs)]} "
                             "were not kept by the compiled 2D kernel")
        weight_start, step, weights = compiled.packed_weights([w for _, w in entries], n)
        if n == 0 or not terms:
            return np.zeros_like(result)
        module = compiled.load("line2")
        ffi = module.ffi

        def pointer(array, ctype="double *"):
            return compiled._pointer(ffi, array, ctype)

        grad = np.ascontiguousarray(self.grad)
        module.lib.line2_combine(
            n, self.num_outputs, pointer(grad), len(terms), pointer(term_start, "int *"),
            pointer(output, "int *"), pointer(weight_start, "long *"), pointer(step, "int *"),
            pointer(weights), pointer(result))
        return result

    def outputs(self, start: int, stop: int) -> np.ndarray:
        """(n, stop - start, 12): the gradients of outputs start .. stop - 1."""
        return np.ascontiguousarray(self.grad[:, start:stop])

    def rows_of(self, name: str) -> np.ndarray:
        """The gradients of output family ``name`` as ``RowSubsetDual.grad_rows`` holds them,
        (n, shape..., 12) (a view)."""
        shape = _SHAPES[name]
        start = _FIRST[name]
        block = self.grad[:, start:start + int(np.prod(shape))]
        return block.reshape((self.num_pairs,) + shape + (NUM_VARIABLES,))


def evaluate(geometry: PairGeometry, options: KernelOptions, num_gauss_points: int,
             crosspoint: np.ndarray | None = None,
             slave_facet: np.ndarray | None = None) -> PairQuantities:
    """The pairs' quantities by the compiled kernel, with the gradients of the contributing
    pairs (``segment_gradients``, a :class:`FullGradients`; with ``scalar_gradients`` also
    ``D_dual`` and ``M_dual``)."""
    if geometry.neighbour_x is None or geometry.has_neighbour is None:
        raise ValueError("the 2D kernel takes the slave facets' neighbours "
                         "(PairGeometry.neighbour_x, has_neighbour)")
    screening = compiled.Line2Screening(
        geometry.slave_x, geometry.master_x, geometry.neighbour_x, geometry.has_neighbour,
        normals=options.normals,
        integration=options.integration, basis=options.basis,
        num_gauss_points=num_gauss_points, crosspoint=crosspoint, slave_facet=slave_facet)
    n, rows = screening.num_pairs, screening.rows
    values = {name: np.empty((rows.size,) + shape) for name, shape in _SHAPES.items()}
    kept = 28 if options.scalar_gradients else 24
    grad = np.empty((rows.size, kept, NUM_VARIABLES))
    contributes = np.ones(rows.size, dtype=np.uint8)
    if rows.size:
        ffi = screening.module.ffi
        pointers = [compiled._pointer(ffi, values[name], "double *")
                    for name in ("D", "M", "Dn", "Mn", "gap", "area")]
        status = screening.module.lib.line2_integrate_rows(
            *screening.arguments(), compiled._pointer(ffi, contributes, "unsigned char *"),
            *pointers, kept, compiled._pointer(ffi, grad, "double *"))
        if status != 0:
            raise RuntimeError(f"compiled 2D kernel failed (status {status})")
    valid, overlap = screening.finish(contributes)
    gradients = FullGradients(grad)
    duals = {name: RowSubsetDual(values[name], rows, gradients.rows_of(name), n)
             for name in ("Dn", "Mn", "area", "gap")}
    if options.scalar_gradients:
        duals.update({name: RowSubsetDual(values[name], rows, gradients.rows_of(name), n)
                      for name in ("D", "M")})
    return PairQuantities(
        D_rows=values["D"], M_rows=values["M"], Dn=duals["Dn"], Mn=duals["Mn"], gap=duals["gap"],
        area=duals["area"], valid=valid, overlap=overlap, num_variables=NUM_VARIABLES,
        D_dual=duals.get("D"), M_dual=duals.get("M"), segment_gradients=gradients)
