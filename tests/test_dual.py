"""The forward-mode dual numbers of :mod:`dolfinx_mortar.dual` against finite differences.

Every input is an affine function of ``NUM_VARIABLES`` parameters t, u(t) = u0 + J t,
given as a Dual with value u0 and grad J. An operation applied to such inputs must
return the derivative of its value with respect to t; the test compares it with
central differences of the operation's value at t = +-h e_k.
"""

from __future__ import annotations

import numpy as np
import pytest

from dolfinx_mortar import dual
from dolfinx_mortar.dual import Dual

NUM_VARIABLES = 5
STEP = 1e-6


def affine_input(rng: np.random.Generator, shape: tuple[int, ...], low=-2.0, high=2.0) -> Dual:
    return Dual(rng.uniform(low, high, shape), rng.normal(size=shape + (NUM_VARIABLES,)))


def shifted(item: Dual, parameters: np.ndarray) -> Dual:
    """The input at parameters t: value u0 + J t (same grad)."""
    return Dual(item.value + item.grad @ parameters, item.grad)


def central_differences(operation, inputs: list[Dual]) -> np.ndarray:
    columns = []
    for k in range(NUM_VARIABLES):
        step = np.zeros(NUM_VARIABLES)
        step[k] = STEP
        plus = operation(*[shifted(item, step) for item in inputs]).value
        minus = operation(*[shifted(item, -step) for item in inputs]).value
        columns.append((plus - minus) / (2.0 * STEP))
    return np.stack(columns, axis=-1)


def assert_derivative(operation, inputs: list[Dual], expected_value: np.ndarray) -> Dual:
    result = operation(*inputs)
    assert isinstance(result, Dual)
    np.testing.assert_allclose(result.value, expected_value, rtol=1e-14, atol=1e-14)
    assert result.grad.shape == result.value.shape + (NUM_VARIABLES,)
    differences = central_differences(operation, inputs)
    scale = max(1.0, np.abs(result.grad).max())
    np.testing.assert_allclose(result.grad, differences, rtol=0, atol=1e-7 * scale)
    return result


# --------------------------------------------------------------------------------------------
# construction
# --------------------------------------------------------------------------------------------


def test_variables_and_constants():
    values = np.arange(12.0).reshape(4, 3)
    variables = Dual.variables(values)
    np.testing.assert_array_equal(variables.value, values)
    np.testing.assert_array_equal(variables.grad, np.broadcast_to(np.eye(3), (4, 3, 3)))
    variables.grad[0, 0, 0] = 7.0  # a writable copy, one per row
    assert variables.grad[1, 0, 0] == 1.0
    constant = Dual.constant(np.ones((2, 3)), NUM_VARIABLES)
    assert constant.shape == (2, 3)
    np.testing.assert_array_equal(constant.grad, np.zeros((2, 3, NUM_VARIABLES)))


# --------------------------------------------------------------------------------------------
# arithmetic between Duals, with broadcasting of the value axes
# --------------------------------------------------------------------------------------------

SHAPE_PAIRS = [((4, 3), (4, 3)), ((4, 1), (3,)), ((3,), (2, 1, 3)), ((), (4, 3)), ((4, 3), ())]


@pytest.mark.parametrize("shape_a,shape_b", SHAPE_PAIRS)
@pytest.mark.parametrize(
    "name,operation,reference",
    [
        ("add", lambda a, b: a + b, np.add),
        ("sub", lambda a, b: a - b, np.subtract),
        ("mul", lambda a, b: a * b, np.multiply),
        ("div", lambda a, b: a / b, np.divide),
    ],
)
def test_binary_operations_between_duals(name, operation, reference, shape_a, shape_b):
    rng = np.random.default_rng(1)
    a = affine_input(rng, shape_a)
    b = affine_input(rng, shape_b, low=0.5, high=2.0)  # away from zero for the division
    assert_derivative(operation, [a, b], reference(a.value, b.value))


def test_negation():
    a = affine_input(np.random.default_rng(2), (3, 2))
    assert_derivative(lambda u: -u, [a], -a.value)


# --------------------------------------------------------------------------------------------
# arithmetic with plain numbers and arrays on either side
# --------------------------------------------------------------------------------------------

PLAIN_OPERANDS = {
    "python float": 1.7,
    "numpy float": np.float64(-0.6),
    "0-d array": np.array(2.3),
    "same shape": np.linspace(0.5, 1.5, 12).reshape(4, 3),
    "row": np.array([0.7, 1.3, 2.1]),
    "column": np.array([[0.9], [1.1], [1.4], [0.6]]),
    "extra leading axis": np.linspace(0.5, 2.0, 24).reshape(2, 4, 3),
}


@pytest.mark.parametrize("plain_name", list(PLAIN_OPERANDS))
@pytest.mark.parametrize(
    "name,operation,reference",
    [
        ("dual + plain", lambda a, c: a + c, lambda a, c: a + c),
        ("plain + dual", lambda a, c: c + a, lambda a, c: c + a),
        ("dual - plain", lambda a, c: a - c, lambda a, c: a - c),
        ("plain - dual", lambda a, c: c - a, lambda a, c: c - a),
        ("dual * plain", lambda a, c: a * c, lambda a, c: a * c),
        ("plain * dual", lambda a, c: c * a, lambda a, c: c * a),
        ("dual / plain", lambda a, c: a / c, lambda a, c: a / c),
        ("plain / dual", lambda a, c: c / a, lambda a, c: c / a),
    ],
)
def test_operations_with_plain_operands(name, operation, reference, plain_name):
    plain = PLAIN_OPERANDS[plain_name]
    a = affine_input(np.random.default_rng(3), (4, 3), low=0.5, high=2.0)
    result = assert_derivative(
        lambda u: operation(u, plain), [a], reference(a.value, np.asarray(plain))
    )
    assert result.value.shape == np.broadcast_shapes((4, 3), np.shape(plain))


# --------------------------------------------------------------------------------------------
# functions of the module
# --------------------------------------------------------------------------------------------


def test_sqrt():
    a = affine_input(np.random.default_rng(4), (4, 3), low=0.2, high=3.0)
    assert_derivative(dual.sqrt, [a], np.sqrt(a.value))


def test_sqrt_of_zero_has_a_finite_zero_derivative():
    a = Dual(np.array([0.0, 4.0]), np.ones((2, NUM_VARIABLES)))
    result = dual.sqrt(a)
    np.testing.assert_array_equal(result.value, [0.0, 2.0])
    np.testing.assert_array_equal(result.grad[0], 0.0)
    np.testing.assert_allclose(result.grad[1], 0.25)


def test_where_takes_value_and_derivative_of_the_selected_branch():
    rng = np.random.default_rng(5)
    a, b = affine_input(rng, (4, 3)), affine_input(rng, (4, 3))
    condition = rng.uniform(size=(4, 3)) > 0.5
    result = assert_derivative(
        lambda u, v: dual.where(condition, u, v), [a, b], np.where(condition, a.value, b.value)
    )
    np.testing.assert_array_equal(result.grad[condition], a.grad[condition])
    np.testing.assert_array_equal(result.grad[~condition], b.grad[~condition])


def test_where_broadcasts_the_condition():
    rng = np.random.default_rng(6)
    a, b = affine_input(rng, (4, 2)), affine_input(rng, (4, 2))
    rows = np.array([True, False, False, True])
    result = assert_derivative(
        lambda u, v: dual.where(rows[:, None], u, v),
        [a, b],
        np.where(rows[:, None], a.value, b.value),
    )
    np.testing.assert_array_equal(result.grad[rows], a.grad[rows])


@pytest.mark.parametrize(
    "function,reference", [(dual.maximum, np.maximum), (dual.minimum, np.minimum)]
)
def test_maximum_minimum(function, reference):
    rng = np.random.default_rng(7)
    a, b = affine_input(rng, (5, 4)), affine_input(rng, (5, 4))
    assert np.abs(a.value - b.value).min() > 1e-3  # no tie within the difference step
    assert_derivative(function, [a, b], reference(a.value, b.value))


def test_maximum_minimum_tie_picks_the_first():
    rng = np.random.default_rng(8)
    a, b = affine_input(rng, (3,)), affine_input(rng, (3,))
    b = Dual(a.value.copy(), b.grad)
    np.testing.assert_array_equal(dual.maximum(a, b).grad, a.grad)
    np.testing.assert_array_equal(dual.minimum(a, b).grad, a.grad)


@pytest.mark.parametrize("axis", [0, 1, 2, -1, -2, -3])
def test_stack(axis):
    rng = np.random.default_rng(9)
    items = [affine_input(rng, (4, 3)) for _ in range(3)]
    assert_derivative(
        lambda *parts: dual.stack(list(parts), axis=axis),
        items,
        np.stack([item.value for item in items], axis=axis),
    )


@pytest.mark.parametrize("axis", [0, 1, 2, -1, -3])
def test_sum(axis):
    a = affine_input(np.random.default_rng(10), (4, 3, 2))
    assert_derivative(lambda u: dual.sum_(u, axis=axis), [a], a.value.sum(axis=axis))


@pytest.mark.parametrize("shape_a,shape_b", [((6, 2), (6, 2)), ((3, 4, 2), (4, 2)), ((2,), (5, 2))])
def test_cross_and_dot(shape_a, shape_b):
    rng = np.random.default_rng(11)
    a, b = affine_input(rng, shape_a), affine_input(rng, shape_b)
    expected_cross = a.value[..., 0] * b.value[..., 1] - a.value[..., 1] * b.value[..., 0]
    assert_derivative(dual.cross, [a, b], expected_cross)
    assert_derivative(dual.dot, [a, b], (a.value * b.value).sum(axis=-1))


# --------------------------------------------------------------------------------------------
# indexing
# --------------------------------------------------------------------------------------------

INDICES = {
    "integer": 2,
    "negative integer": -1,
    "slice": slice(1, 3),
    "stepped slice": slice(None, None, -2),
    "tuple of integers": (1, 2),
    "slice and integer": (slice(None), 0),
    "ellipsis and integer": (Ellipsis, 1),
    "ellipsis and slice": (Ellipsis, slice(0, 2)),
    "integer and ellipsis": (0, Ellipsis),
    "none first": (None,),
    "slices and none": (slice(None), slice(None), None),
    "slice, none, slice": (slice(1, None), None, slice(None, 2)),
    "ellipsis and none": (Ellipsis, None),
    "none, ellipsis, integer": (None, Ellipsis, 0),
    "integer array": np.array([3, 0, 0]),
    "integer arrays": (np.array([0, 2]), np.array([1, 1])),
    "boolean mask": np.array([True, False, True, True]),
}


@pytest.mark.parametrize("name", list(INDICES))
def test_indexing(name):
    index = INDICES[name]
    a = affine_input(np.random.default_rng(12), (4, 3, 2))
    result = assert_derivative(lambda u: u[index], [a], a.value[index])
    assert result.shape == a.value[index].shape


def test_indexing_gives_the_rows_of_the_gradient():
    a = affine_input(np.random.default_rng(13), (4, 3))
    np.testing.assert_array_equal(a[1, 2].grad, a.grad[1, 2])
    np.testing.assert_array_equal(a[..., 2].grad, a.grad[:, 2])
    np.testing.assert_array_equal(a[:, None, 1].grad, a.grad[:, None, 1])


# --------------------------------------------------------------------------------------------
# a composite: the kernels' unit normal (t_y, -t_x)/|t|, against its closed-form derivative
# --------------------------------------------------------------------------------------------


def test_composite_unit_normal():
    rng = np.random.default_rng(14)
    points = rng.normal(size=(6, 4))
    x = Dual.variables(points)
    tangent = x[:, 2:4] - x[:, 0:2]
    length = dual.sqrt(dual.dot(tangent, tangent))
    normal = dual.stack([tangent[..., 1], -tangent[..., 0]], axis=-1) / length[..., None]
    t = points[:, 2:4] - points[:, 0:2]
    norm = np.linalg.norm(t, axis=1)
    unit = t / norm[:, None]
    # d(t/|t|)/dt = (I - u u^T)/|t|; the normal is the rotation R = [[0, 1], [-1, 0]] of it
    rotation = np.array([[0.0, 1.0], [-1.0, 0.0]])
    projector = (np.eye(2) - np.einsum("ni,nj->nij", unit, unit)) / norm[:, None, None]
    d_normal_d_t = rotation @ projector
    np.testing.assert_allclose(normal.value, unit @ rotation.T, rtol=1e-14)
    np.testing.assert_allclose(normal.grad[:, :, 2:4], d_normal_d_t, rtol=1e-13, atol=1e-14)
    np.testing.assert_allclose(normal.grad[:, :, 0:2], -d_normal_d_t, rtol=1e-13, atol=1e-14)
