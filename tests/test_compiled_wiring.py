"""The compiled 3D kernel wired behind the contract (kernels/surface3_compiled.py): the
switch (KernelOptions.kernels, $DOLFINX_MORTAR_KERNELS), the values at evaluation and the
gradients on demand equal to the numpy kernel's, through the stencils and the interface
(matrices of the standard, dual, covered dual basis and the reference configuration), in
chunks of any size, and an evaluation that keeps no gradients."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest
from mpi4py import MPI
from petsc4py import PETSc
from test_kernel_surface3_speedpath import random_pairs
from test_mortar3d import bent_displacement, interface, two_blocks

from dolfinx_mortar.kernels import KernelOptions, PairGeometry, Surface3Kernel, surface3_compiled
from dolfinx_mortar.kernels.contract import KERNELS_VARIABLE

TOLERANCE = 1e-13


def assert_close(got: np.ndarray, expected: np.ndarray, tolerance: float = TOLERANCE, what=""):
    scale = np.abs(expected).max(initial=0.0)
    error = np.abs(got - expected).max(initial=0.0)
    assert error <= tolerance * scale or error == 0.0, (what, error, scale)


def test_switch(monkeypatch):
    monkeypatch.delenv(KERNELS_VARIABLE, raising=False)
    assert KernelOptions().kernels == "numpy"
    monkeypatch.setenv(KERNELS_VARIABLE, "compiled")
    assert KernelOptions().kernels == "compiled"
    assert KernelOptions(kernels="numpy").kernels == "numpy"
    monkeypatch.setenv(KERNELS_VARIABLE, "fortran")
    with pytest.raises(ValueError, match="kernels"):
        KernelOptions()


@pytest.mark.parametrize("rule", [1, 3, 7])
@pytest.mark.parametrize("basis", ["standard", "dual"])
@pytest.mark.parametrize("scalar_gradients", [False, True])
def test_kernel_equals_numpy(rule, basis, scalar_gradients):
    """Values, valid pairs, overlaps and every output's gradient (expanded from the numpy
    kernel's factors; made on demand by the compiled one)."""
    slave, master, nodal, crosspoint = random_pairs(300, seed=3)
    geometry = PairGeometry(slave, master, nodal)
    kernel = Surface3Kernel()
    for cross in (None, crosspoint):
        options = dict(basis=basis, num_gauss_points=rule, scalar_gradients=scalar_gradients)
        expected = kernel.evaluate(geometry, KernelOptions(kernels="numpy", **options),
                                   crosspoint=cross)
        got = kernel.evaluate(geometry, KernelOptions(kernels="compiled", **options),
                              crosspoint=cross)
        assert got.gradients_on_demand is not None and expected.gradients_on_demand is None
        np.testing.assert_array_equal(got.valid, expected.valid)
        np.testing.assert_array_equal(got.rows, expected.rows)
        assert 50 < got.rows.size < 300
        assert_close(got.overlap, expected.overlap, what="overlap")
        assert_close(got.D, expected.D, what="D")
        assert_close(got.M, expected.M, what="M")
        assert len(got.outputs()) == len(expected.outputs())
        for index, (a, b) in enumerate(zip(got.outputs(), expected.outputs(), strict=True)):
            assert_close(a.value, b.value, what=("value", index))
            assert_close(a.grad, b.grad, what=("grad", index))
        # any rows, in any order, the pairs that do not contribute too (zero)
        rows = np.random.default_rng(0).permutation(300)[:90]
        on_demand = got.gradients_on_demand.gradients(rows)
        for index, (a, b) in enumerate(zip(on_demand, expected.outputs(), strict=True)):
            assert_close(a, b.grad[rows], what=("rows", index))


def test_screened_candidates_are_far():
    """The candidates the compiled evaluation does not give the kernel (projected bounding
    discs apart) are not valid for the numpy kernel either; the others still reach it."""
    slave, master, nodal, _ = random_pairs(2000, seed=6)
    shift = np.random.default_rng(7).uniform(-2.0, 2.0, (2000, 1, 3))
    master = master + shift
    near = surface3_compiled._near(slave, master, nodal)
    assert 100 < near.size < 1900
    geometry = PairGeometry(slave, master, nodal)
    expected = Surface3Kernel().evaluate(geometry, KernelOptions(kernels="numpy"))
    assert np.isin(expected.rows, near).all() and expected.rows.size > 50
    got = Surface3Kernel().evaluate(geometry, KernelOptions(kernels="compiled"))
    np.testing.assert_array_equal(got.rows, expected.rows)


def test_gradients_survive_later_requests():
    """``grad`` of an output stays what it was when other rows were asked for since."""
    slave, master, nodal, _ = random_pairs(100, seed=8)
    first, second = (Surface3Kernel().evaluate(PairGeometry(slave, master, nodal),
                                               KernelOptions(kernels="compiled"))
                     for _ in range(2))
    assert first.Dn.grad.any()  # every output's gradients made here
    first.gradients_on_demand.gradients(first.rows[::-1])
    np.testing.assert_array_equal(first.Mn.grad, second.Mn.grad)


def test_uncovered_cases_stay_numpy():
    slave, master, nodal, _ = random_pairs(20, seed=1)
    kernel = Surface3Kernel()
    for options in (dict(normals="slave"), dict(integration="element")):
        q = kernel.evaluate(PairGeometry(slave, master, nodal),
                            KernelOptions(kernels="compiled", **options))
        assert q.gradients_on_demand is None
    quads = PairGeometry(np.zeros((2, 4, 3)), np.zeros((2, 4, 3)), np.zeros((2, 4, 3)))
    assert not surface3_compiled.covers(quads, KernelOptions(kernels="compiled"))


def test_evaluation_keeps_no_gradients():
    """The evaluation's memory: the values and reused kernel buffers, not the ~13.6 kB of
    gradients a pair."""
    slave, master, nodal, _ = random_pairs(20000, seed=2)
    geometry = PairGeometry(slave, master, nodal)
    kernel = Surface3Kernel()
    kernel.evaluate(geometry, KernelOptions(kernels="compiled"))  # compiled and loaded
    tracemalloc.start()
    q = kernel.evaluate(geometry, KernelOptions(kernels="compiled"))
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert q.rows.size > 5000
    chunk = surface3_compiled.EVALUATION_CHUNK * (2 * 27 * 27 + 2 * 3 * 27) * 8
    assert peak < chunk + 20000 * 1500, peak


def _matrices(mortar, z) -> dict:
    D, M = mortar.mortar_matrices()
    arrays = {"D": D, "M": M, "G": mortar.gap_jacobian(), "B": mortar.constraint_matrix(),
              "K": mortar.force_jacobian(z)}
    result = {name: matrix.convert("dense").getDenseArray().copy()
              for name, matrix in arrays.items()}
    result["gap"] = mortar.weighted_gap().getArray().copy()
    return result


@pytest.mark.parametrize(("basis", "configuration"), [
    ("standard", "current"), ("dual", "current"), ("dual", "reference"),
    ("standard", "reference")])
def test_interface_equals_numpy(monkeypatch, basis, configuration):
    """The interface's matrices and gaps (the covered dual basis runs the compiled kernel with
    the standard basis and its D gradients), with gradients made again in chunks of 37."""
    monkeypatch.setattr(surface3_compiled.CompiledGradients, "chunk", 37)
    tagged = two_blocks("tetrahedron", 3, 4, comm=MPI.COMM_SELF)
    u = bent_displacement(tagged)
    results = {}
    for kernels in ("numpy", "compiled"):
        monkeypatch.setenv(KERNELS_VARIABLE, kernels)
        mortar = interface(tagged, u, basis=basis, configuration=configuration)
        z = mortar.create_multiplier_vector()
        z.getArray()[:] = np.random.default_rng(5).uniform(0.5, 1.5, z.getLocalSize())
        z.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        results[kernels] = _matrices(mortar, z)
        if configuration == "current":
            q = mortar.quantities
            standard = q.standard if basis == "dual" else q
            assert (standard.gradients_on_demand is not None) == (kernels == "compiled")
            assert standard.rows.size > 37
        z.destroy()
        mortar.destroy()
    for name, expected in results["numpy"].items():
        # (frozen reference integrals: the force does not change with u)
        assert np.abs(expected).max() > 0.0 or (name, configuration) == ("K", "reference")
        assert_close(results["compiled"][name], expected, 1e-12, what=name)


def test_frozen_quantities_drop_the_gradients():
    slave, master, nodal, _ = random_pairs(10, seed=4)
    q = Surface3Kernel().evaluate(PairGeometry(slave, master, nodal),
                                  KernelOptions(kernels="compiled"))
    assert q.replaced(normals_vary=False).gradients_on_demand is None
