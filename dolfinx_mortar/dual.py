"""Forward-mode dual numbers over numpy arrays: values and exact first derivatives.

The mortar kernels return every mortar quantity together with its derivative with
respect to the nodal coordinates it depends on (at most 12 in 2D: two slave nodes,
their two neighbours that enter averaged normals, and two master nodes), as
:class:`RowSubsetDual` arrays. The compiled kernels compute them in C; the numpy
oracle of the tests (``tests/oracle``) is written in terms of :class:`Dual` arrays and
the functions here. Derivatives are exact to rounding: every operation applies its own
chain rule, nothing is approximated by differences.

A Dual holds ``value`` of shape ``S`` and ``grad`` of shape ``S + (n,)``; the
derivative axis is always last, so the usual numpy broadcasting of the leading
axes carries over.
"""

from __future__ import annotations

import numpy as np


class Dual:
    """An array of values with their gradients with respect to ``n`` variables."""

    __slots__ = ("value", "grad")
    __array_priority__ = 1000

    def __init__(self, value, grad):
        self.value = np.asarray(value, dtype=np.float64)
        self.grad = np.asarray(grad, dtype=np.float64)

    @classmethod
    def variables(cls, values: np.ndarray) -> Dual:
        """Independent variables: ``values`` of shape (m, n), each row its own n variables."""
        values = np.asarray(values, dtype=np.float64)
        grad = np.broadcast_to(np.eye(values.shape[-1]), values.shape + (values.shape[-1],))
        return cls(values, grad.copy())

    @classmethod
    def constant(cls, value, nvars: int) -> Dual:
        value = np.asarray(value, dtype=np.float64)
        return cls(value, np.zeros(value.shape + (nvars,)))

    @property
    def shape(self) -> tuple[int, ...]:
        return self.value.shape

    def __getitem__(self, index) -> Dual:
        if not isinstance(index, tuple):
            index = (index,)
        if any(item is Ellipsis for item in index):
            return Dual(self.value[index], self.grad[index + (slice(None),)])
        return Dual(self.value[index], self.grad[index])

    def _broadcast_grad(self, other) -> np.ndarray:
        if np.ndim(other) == 0:
            return self.grad
        shape = np.broadcast_shapes(self.value.shape, np.shape(other))
        return np.broadcast_to(self.grad, shape + self.grad.shape[-1:])

    def __neg__(self) -> Dual:
        return Dual(-self.value, -self.grad)

    def __add__(self, other) -> Dual:
        if isinstance(other, Dual):
            return Dual(self.value + other.value, self.grad + other.grad)
        return Dual(self.value + other, self._broadcast_grad(other))

    __radd__ = __add__

    def __sub__(self, other) -> Dual:
        if isinstance(other, Dual):
            return Dual(self.value - other.value, self.grad - other.grad)
        return Dual(self.value - other, self._broadcast_grad(other))

    def __rsub__(self, other) -> Dual:
        return Dual(other - self.value, -self._broadcast_grad(other))

    def __mul__(self, other) -> Dual:
        if isinstance(other, Dual):
            return Dual(
                self.value * other.value,
                self.grad * other.value[..., None] + other.grad * self.value[..., None],
            )
        other = np.asarray(other)
        return Dual(self.value * other, self.grad * other[..., None])

    __rmul__ = __mul__

    def __truediv__(self, other) -> Dual:
        if isinstance(other, Dual):
            inverse = 1.0 / other.value
            value = self.value * inverse
            return Dual(
                value,
                (self.grad - other.grad * value[..., None]) * inverse[..., None],
            )
        inverse = 1.0 / np.asarray(other)
        return Dual(self.value * inverse, self.grad * inverse[..., None])

    def __rtruediv__(self, other) -> Dual:
        inverse = 1.0 / self.value
        value = other * inverse
        return Dual(value, -self.grad * (value * inverse)[..., None])


class RowSubsetDual:
    """Values and gradients that are zero outside some rows of their leading axis.

    Only those rows are kept (``rows``, sorted): their values (``value_rows``) and their
    gradients (``grad_rows``, given as an array or as a function that computes it when
    first needed). Most candidate pairs of a mortar interface do not overlap: their rows
    are never stored. :attr:`value` and :attr:`grad` make the full arrays
    (``num_pairs`` rows) on each access, for checks; assembly reads the kept rows
    (:meth:`value_of`).
    """

    __slots__ = ("rows", "value_rows", "num_pairs", "_grad_rows", "constant")

    def __init__(self, value_rows, rows, grad_rows, num_pairs: int):
        self.value_rows = np.asarray(value_rows, dtype=np.float64)
        self.rows = np.asarray(rows)
        self.num_pairs = int(num_pairs)
        self._grad_rows = grad_rows
        self.constant = False
        """Whether the gradients are zero (:meth:`of_constant`): consumers skip them."""
        if self.value_rows.shape[0] != self.rows.size:
            raise ValueError(f"{self.value_rows.shape[0]} rows of values for "
                             f"{self.rows.size} rows")

    @classmethod
    def of_constant(cls, value_rows, rows, num_variables: int, num_pairs: int) -> RowSubsetDual:
        """Values that do not depend on the variables: zero gradients, none stored."""
        value_rows = np.asarray(value_rows, dtype=np.float64)
        result = cls(value_rows, rows, np.broadcast_to(0.0, value_rows.shape + (num_variables,)),
                     num_pairs)
        result.constant = True
        return result

    @classmethod
    def of_full(cls, value, rows, grad_rows) -> RowSubsetDual:
        """From the values of every row (zero outside ``rows``)."""
        value = np.asarray(value, dtype=np.float64)
        return cls(value[rows], rows, grad_rows, value.shape[0])

    @property
    def shape(self) -> tuple[int, ...]:
        return (self.num_pairs,) + self.value_rows.shape[1:]

    @property
    def grad_rows(self) -> np.ndarray:
        if callable(self._grad_rows):
            self._grad_rows = np.asarray(self._grad_rows(), dtype=np.float64)
        return self._grad_rows

    def value_of(self, rows: np.ndarray) -> np.ndarray:
        """The values of ``rows`` (any rows; zero outside the kept ones)."""
        return rows_of(self.value_rows, self.rows, rows)

    @property
    def value(self) -> np.ndarray:
        full = np.zeros(self.shape)
        full[self.rows] = self.value_rows
        return full

    @property
    def grad(self) -> np.ndarray:
        grad_rows = self.grad_rows
        full = np.zeros(self.shape + (grad_rows.shape[-1],))
        full[self.rows] = grad_rows
        return full


def rows_of(array: np.ndarray, kept: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """The entries of ``rows`` of an array whose entries are those of the rows ``kept``
    (zero for rows not kept): a slice where they are consecutive kept rows."""
    if rows is kept:
        return array
    sorter = None if kept.size < 2 or np.all(kept[1:] > kept[:-1]) else np.argsort(kept)
    position = np.minimum(np.searchsorted(kept, rows, sorter=sorter), max(kept.size - 1, 0))
    if sorter is not None and kept.size:
        position = sorter[position]
    found = kept[position] == rows if kept.size else np.zeros(np.shape(rows), dtype=bool)
    if found.all():
        if sorter is None and rows.size and np.all(position[1:] == position[:-1] + 1):
            return array[position[0]:position[-1] + 1]
        return array[position]
    result = np.zeros((rows.size,) + array.shape[1:])
    result[found] = array[position[found]]
    return result


def sqrt(a: Dual) -> Dual:
    root = np.sqrt(a.value)
    with np.errstate(divide="ignore", invalid="ignore"):
        factor = np.where(root > 0.0, 0.5 / np.where(root > 0.0, root, 1.0), 0.0)
    return Dual(root, a.grad * factor[..., None])


def where(condition, a: Dual, b: Dual) -> Dual:
    """Elementwise selection; the derivative is the one of the selected branch."""
    condition = np.asarray(condition)
    return Dual(
        np.where(condition, a.value, b.value),
        np.where(condition[..., None], a.grad, b.grad),
    )


def maximum(a: Dual, b: Dual) -> Dual:
    return where(a.value >= b.value, a, b)


def minimum(a: Dual, b: Dual) -> Dual:
    return where(a.value <= b.value, a, b)


def stack(items: list[Dual], axis: int = -1) -> Dual:
    """Stack Duals along a new value axis (``axis`` counts value axes only)."""
    ndim = items[0].value.ndim + 1
    axis = axis % ndim
    return Dual(
        np.stack([item.value for item in items], axis=axis),
        np.stack([item.grad for item in items], axis=axis),
    )


def cross(a: Dual, b: Dual) -> Dual:
    """2D cross product a_x b_y - a_y b_x over the last value axis (of length 2)."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def dot(a: Dual, b: Dual) -> Dual:
    """Dot product over the last value axis."""
    return sum_(a * b, axis=-1)


def sum_(a: Dual, axis: int) -> Dual:
    """Sum over a value axis."""
    ndim = a.value.ndim
    axis = axis % ndim
    return Dual(a.value.sum(axis=axis), a.grad.sum(axis=axis))
