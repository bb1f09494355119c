"""The 3D numpy oracle (tests/oracle/surface3_numpy.py) keeps the gradients of Dn, Mn and the areas
of triangle pairs factorized (tests/oracle/factors.py, AffineFactors: over the plane
coordinates, a chain, the normals' weights), expanded when first asked for. Expanded they must
be the unfactorized kernel's gradients bit for bit, and so the stencil's combined gradients
of an interface those of the unfactorized oracle."""

from __future__ import annotations

import numpy as np
import pytest
from test_kernel_surface3_speedpath import random_pairs
from test_mortar3d import bent_displacement, interface, two_blocks

from oracle import surface3_numpy, use_oracle
from oracle.factors import AffineFactors


@pytest.fixture
def expansions(monkeypatch):
    """The names AffineFactors.expanded was asked for, in order."""
    asked = []
    expanded = AffineFactors.expanded

    def spy(self, name):
        asked.append(name)
        return expanded(self, name)

    monkeypatch.setattr(AffineFactors, "expanded", spy)
    return asked


@pytest.mark.parametrize("crosspoints", [False, True])
def test_expanded_factors_are_the_kernel_gradients(crosspoints, expansions):
    slave, master, nodal, crosspoint = random_pairs(1500, seed=7)
    args = dict(crosspoint=crosspoint if crosspoints else None)
    factorized = surface3_numpy.pair_quantities(slave, master, nodal, factorized=True, **args)
    full = surface3_numpy.pair_quantities(slave, master, nodal, factorized=False, **args)
    assert factorized.valid.sum() > 100
    for name in ("Dn", "Mn", "area", "gap", "D", "M"):
        a, b = getattr(factorized, name), getattr(full, name)
        np.testing.assert_array_equal(getattr(a, "value", a), getattr(b, "value", b))
        if name not in ("D", "M"):
            np.testing.assert_array_equal(a.grad_rows, b.grad_rows)
    assert expansions == ["Dn", "Mn", "area"]  # the factorized result's, from its factors


def test_combined_gradients_of_the_factors(monkeypatch, expansions):
    """K's and the friction rows' terms (per-pair weights on Dn, Mn, area, gap) over a
    subset of pairs that includes pairs without overlap, on an interface of the oracle
    whose triangle pairs keep their factors, equal those of the unfactorized oracle."""
    tagged = two_blocks("tetrahedron", 3, 4)
    u = bent_displacement(tagged)
    with use_oracle():
        mortar = interface(tagged, u)
        monkeypatch.setattr(surface3_numpy.Surface3Kernel, "factorized", False)
        unfactorized = interface(tagged, u)
    q, stencil = mortar.quantities, mortar.stencil
    assert callable(q.Dn._grad_rows) and not callable(unfactorized.quantities.Dn._grad_rows)
    np.testing.assert_array_equal(q.rows, unfactorized.quantities.rows)
    rng = np.random.default_rng(2)
    rows = np.sort(rng.choice(stencil.num_pairs, 60, replace=False))
    rows = np.union1d(rows, q.gap.rows[::3])
    weight = rng.standard_normal(rows.size)
    terms = [[(stencil.dn(j, k, c), weight), (stencil.mn(j, (k + 1) % 3, c), 0.5)]
             for j in range(3) for k in range(3) for c in range(3)]
    terms += [[(stencil.AREA + j, weight), (stencil.GAP + j, -weight)] for j in range(3)]
    got = stencil.combined_gradients(q, rows, terms)
    assert sorted(expansions) == ["Dn", "Mn", "area"]
    expected = unfactorized.stencil.combined_gradients(unfactorized.quantities, rows, terms)
    assert np.abs(expected).max() > 0
    np.testing.assert_array_equal(got, expected)
    mortar.destroy()
    unfactorized.destroy()
