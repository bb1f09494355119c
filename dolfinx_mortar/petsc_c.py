"""PETSc's C functions that petsc4py does not wrap, through ctypes.

An AIJ matrix's local CSR arrays, read in place. petsc4py's ``Mat.getValuesCSR`` copies a
rank's rows whole (values, global column indices and row starts: 12 bytes an entry); for
the Newton matrix, at every set-up of the condensed solve, that copy sat on top of the
set-up's other arrays (docs/benchmarks.md). PETSc keeps an MPIAIJ matrix as two
sequential CSR blocks, the diagonal one (this rank's columns) and the off-diagonal one
(the others, numbered through a column map), and a SeqAIJ matrix as one;
``MatMPIAIJGetSeqAIJ``, ``MatGetRowIJ`` and ``MatSeqAIJGetArrayRead`` hand out their
arrays, which :func:`local_blocks` wraps as numpy views for as long as its block runs.

A hypre matrix's exact preallocation. petsc4py's ``setPreallocationNNZ`` does not reach a
``MATHYPRE`` matrix (PETSc's AIJ preallocation routines skip it), which then takes its
default row sizes and hypre's auxiliary row store: every value is held twice until the
assembly, a second K_c at the set-up's peak. :func:`preallocate_hypre` calls
``MatHYPRESetPreallocation``; with ``MAT_SORTED_FULL`` set before it, hypre writes the
values into its matrix directly.
"""

from __future__ import annotations

import contextlib
import ctypes
import dataclasses
import typing

import numpy as np
from petsc4py import PETSc


@dataclasses.dataclass(frozen=True)
class CsrBlock:
    """One CSR block of a matrix's local rows: ``indices`` number the block's columns,
    ``columns`` maps them to the matrix's global columns."""

    indptr: np.ndarray
    indices: np.ndarray
    values: np.ndarray
    columns: np.ndarray

    def rows(self, count: int) -> CsrBlock:
        """The first ``count`` rows (views)."""
        end = int(self.indptr[count])
        return CsrBlock(self.indptr[: count + 1], self.indices[:end], self.values[:end],
                        self.columns)

    def global_columns(self, positions: np.ndarray | slice = slice(None)) -> np.ndarray:
        """The global columns of the entries at ``positions``."""
        return self.columns[self.indices[positions]]


_INT = {4: ctypes.c_int32, 8: ctypes.c_int64}[np.dtype(PETSc.IntType).itemsize]
_LIBRARY = None


def _library() -> ctypes.CDLL:
    """PETSc's C functions, through petsc4py's extension module (it links libpetsc)."""
    global _LIBRARY
    if _LIBRARY is None:
        library = ctypes.CDLL(PETSc.__file__)
        handle, integer, boolean = ctypes.c_void_p, ctypes.POINTER(_INT), ctypes.c_int
        pointer = ctypes.POINTER
        prototypes = {
            "MatMPIAIJGetSeqAIJ": [handle, pointer(handle), pointer(handle),
                                   pointer(integer)],
            "MatGetRowIJ": [handle, _INT, boolean, boolean, integer, pointer(integer),
                            pointer(integer), pointer(boolean)],
            "MatRestoreRowIJ": [handle, _INT, boolean, boolean, integer, pointer(integer),
                                pointer(integer), pointer(boolean)],
            "MatSeqAIJGetArrayRead": [handle, pointer(pointer(ctypes.c_double))],
            "MatSeqAIJRestoreArrayRead": [handle, pointer(pointer(ctypes.c_double))],
            "MatGetSize": [handle, integer, integer],
            "MatHYPRESetPreallocation": [handle, _INT, integer, _INT, integer],
        }
        for name, arguments in prototypes.items():
            function = getattr(library, name)
            function.argtypes = arguments
            function.restype = ctypes.c_int
        _LIBRARY = library
    return _LIBRARY


def _check(code: int, name: str) -> None:
    if code:
        raise RuntimeError(f"PETSc's {name} failed (error code {code})")


@contextlib.contextmanager
def _sequential_block(library, matrix: int, columns: np.ndarray) -> typing.Iterator[CsrBlock]:
    """A SeqAIJ matrix (handle ``matrix``) as a :class:`CsrBlock` of views."""
    rows, done = _INT(), ctypes.c_int()
    starts, indices = ctypes.POINTER(_INT)(), ctypes.POINTER(_INT)()
    values = ctypes.POINTER(ctypes.c_double)()
    _check(library.MatGetRowIJ(matrix, 0, 0, 0, ctypes.byref(rows), ctypes.byref(starts),
                               ctypes.byref(indices), ctypes.byref(done)), "MatGetRowIJ")
    if not done.value:
        raise RuntimeError("PETSc's MatGetRowIJ gave no arrays for an AIJ block")
    try:
        _check(library.MatSeqAIJGetArrayRead(matrix, ctypes.byref(values)),
               "MatSeqAIJGetArrayRead")
        try:
            indptr = np.ctypeslib.as_array(starts, shape=(rows.value + 1,))
            size = int(indptr[-1])
            yield CsrBlock(
                indptr,
                np.ctypeslib.as_array(indices, shape=(size,)) if size else
                np.empty(0, dtype=PETSc.IntType),
                np.ctypeslib.as_array(values, shape=(size,)) if size else np.empty(0),
                columns)
        finally:
            _check(library.MatSeqAIJRestoreArrayRead(matrix, ctypes.byref(values)),
                   "MatSeqAIJRestoreArrayRead")
    finally:
        _check(library.MatRestoreRowIJ(matrix, 0, 0, 0, ctypes.byref(rows),
                                       ctypes.byref(starts), ctypes.byref(indices),
                                       ctypes.byref(done)), "MatRestoreRowIJ")


@contextlib.contextmanager
def local_blocks(matrix: PETSc.Mat) -> typing.Iterator[list[CsrBlock]]:
    """This rank's rows of ``matrix`` as CSR blocks of views into PETSc's own arrays (no
    copy), valid inside the block only and while the matrix is not changed: for MPIAIJ
    its diagonal and off-diagonal blocks, for SeqAIJ the matrix. Another type (none that
    this package makes), or a PETSc whose scalars are not real doubles, is copied through
    ``getValuesCSR`` into one block."""
    kind = matrix.getType()
    first = matrix.getOwnershipRangeColumn()[0]
    if (kind not in (PETSc.Mat.Type.MPIAIJ, PETSc.Mat.Type.SEQAIJ)
            or np.dtype(PETSc.ScalarType) != np.float64):  # (the views read doubles)
        indptr, indices, values = matrix.getValuesCSR()
        yield [CsrBlock(indptr, indices, values,
                        np.arange(matrix.getSize()[1], dtype=PETSc.IntType))]
        return
    library = _library()
    local_columns = np.arange(first, matrix.getOwnershipRangeColumn()[1],
                              dtype=PETSc.IntType)
    if kind == PETSc.Mat.Type.SEQAIJ:
        with _sequential_block(library, matrix.handle, local_columns) as block:
            yield [block]
        return
    diagonal, off_diagonal = ctypes.c_void_p(), ctypes.c_void_p()
    colmap = ctypes.POINTER(_INT)()
    _check(library.MatMPIAIJGetSeqAIJ(matrix.handle, ctypes.byref(diagonal),
                                      ctypes.byref(off_diagonal), ctypes.byref(colmap)),
           "MatMPIAIJGetSeqAIJ")
    rows, count = _INT(), _INT()
    _check(library.MatGetSize(off_diagonal, ctypes.byref(rows), ctypes.byref(count)),
           "MatGetSize")
    off_columns = (np.ctypeslib.as_array(colmap, shape=(count.value,)) if count.value
                   else np.empty(0, dtype=PETSc.IntType))
    with (_sequential_block(library, diagonal, local_columns) as inside,
          _sequential_block(library, off_diagonal, off_columns) as outside):
        yield [inside, outside]


def preallocate_hypre(matrix: PETSc.Mat, diagonal: np.ndarray, off_diagonal: np.ndarray
                      ) -> None:
    """Preallocate the ``MATHYPRE`` ``matrix``'s local rows exactly: ``diagonal`` and
    ``off_diagonal`` entries per row (in this rank's columns and the others'). Set
    ``MAT_SORTED_FULL`` before it when every row will be set once, whole (then hypre keeps
    no auxiliary copy of the values)."""
    diagonal = np.ascontiguousarray(diagonal, dtype=PETSc.IntType)
    off_diagonal = np.ascontiguousarray(off_diagonal, dtype=PETSc.IntType)
    pointer = ctypes.POINTER(_INT)
    _check(_library().MatHYPRESetPreallocation(
        matrix.handle, 0, diagonal.ctypes.data_as(pointer), 0,
        off_diagonal.ctypes.data_as(pointer)), "MatHYPRESetPreallocation")
