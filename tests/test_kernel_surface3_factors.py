"""The 3D numpy oracle (tests/oracle/surface3_numpy.py) keeps the gradients of Dn, Mn and the areas
of triangle pairs factorized (kernels.AffineFactors, the result's ``affine_factors``: over the
plane coordinates, a chain, the normals' weights). Expanded they must be the unfactorized
kernel's gradients bit for bit, and the stencil's combined gradients (contracted before the
chain) those of the expanded gradients."""

from __future__ import annotations

import numpy as np
import pytest
from test_kernel_surface3_speedpath import random_pairs
from test_mortar3d import bent_displacement, interface, two_blocks

from dolfinx_mortar.dual import RowSubsetDual
from dolfinx_mortar.kernels import AffineFactors

from oracle import surface3_numpy, use_oracle


@pytest.mark.parametrize("crosspoints", [False, True])
def test_expanded_factors_are_the_kernel_gradients(crosspoints):
    slave, master, nodal, crosspoint = random_pairs(1500, seed=7)
    args = dict(crosspoint=crosspoint if crosspoints else None)
    factorized = surface3_numpy.pair_quantities(slave, master, nodal, factorized=True, **args)
    full = surface3_numpy.pair_quantities(slave, master, nodal, factorized=False, **args)
    assert factorized.valid.sum() > 100
    assert isinstance(factorized.affine_factors, AffineFactors)
    assert full.affine_factors is None
    for name in ("Dn", "Mn", "area", "gap", "D", "M"):
        a, b = getattr(factorized, name), getattr(full, name)
        np.testing.assert_array_equal(getattr(a, "value", a), getattr(b, "value", b))
        if name not in ("D", "M"):
            np.testing.assert_array_equal(a.grad_rows, b.grad_rows)


def _unfactorized(q):
    """q with Dn, Mn and the areas carrying their expanded gradients (no factors)."""

    def plain(item):
        return RowSubsetDual(item.value, item.rows, item.grad_rows)

    return q.replaced(Dn=plain(q.Dn), Mn=plain(q.Mn), area=plain(q.area))


def test_combined_gradients_of_the_factors():
    """K's and the friction rows' terms (per-pair weights on Dn, Mn, area, gap) over a
    subset of pairs that includes pairs without overlap (the numpy oracle's factors: the
    compiled kernel keeps none)."""
    tagged = two_blocks("tetrahedron", 3, 4)
    with use_oracle():
        mortar = interface(tagged, bent_displacement(tagged))
    q, stencil = mortar.quantities, mortar.stencil
    assert q.affine_factors is not None
    rng = np.random.default_rng(2)
    rows = np.sort(rng.choice(stencil.num_pairs, 60, replace=False))
    rows = np.union1d(rows, q.gap.rows[::3])
    weight = rng.standard_normal(rows.size)
    terms = [[(stencil.dn(j, k, c), weight), (stencil.mn(j, (k + 1) % 3, c), 0.5)]
             for j in range(3) for k in range(3) for c in range(3)]
    terms += [[(stencil.AREA + j, weight), (stencil.GAP + j, -weight)] for j in range(3)]
    got = stencil.combined_gradients(q, rows, terms)
    assert q.Dn._full is None and callable(q.Dn._grad_rows)  # never expanded
    expected = stencil.combined_gradients(_unfactorized(q), rows, terms)
    assert np.abs(expected).max() > 0
    assert np.abs(got - expected).max() <= 1e-14 * np.abs(expected).max()
    mortar.destroy()
