"""The 3D kernel's triangle-on-triangle path (integrands from the fan cells' corners,
tests/oracle/surface3_numpy._affine_integrals) against the Gauss point path it replaces: the same
quadrature sums and derivatives to rounding, for every rule, basis and normal field."""

from __future__ import annotations

import numpy as np
import pytest

from oracle import surface3_numpy


def random_pairs(n: int, seed: int):
    """Perturbed unit triangles, the master turned over, rotated: clip polygons of 3 to 6
    vertices, some pairs disjoint."""
    rng = np.random.default_rng(seed)
    slave = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]]) + 0.15 * rng.standard_normal((n, 3, 3))
    shift = rng.uniform(-0.7, 0.7, (n, 1, 3))
    shift[..., 2] = 0.05 * rng.standard_normal((n, 1))
    master = (np.array([[0, 0, 0], [0, 1, 0], [1, 0, 0.0]]) * rng.uniform(0.6, 1.4, (n, 1, 1))
              + shift + 0.15 * rng.standard_normal((n, 3, 3)))
    normals = np.array([0, 0, 1.0]) + 0.2 * rng.standard_normal((n, 3, 3))
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    Q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    return slave @ Q.T, master @ Q.T, normals @ Q.T, rng.random((n, 3)) < 0.2


@pytest.mark.parametrize("rule", [1, 3, 7])
@pytest.mark.parametrize("basis", ["standard", "dual"])
@pytest.mark.parametrize("normals", ["averaged", "slave", "master"])
def test_corner_path_matches_gauss_points(rule, basis, normals):
    slave, master, nodal, crosspoint = random_pairs(120, seed=0)
    rows, _, batches = surface3_numpy._screen_segments(slave, master, nodal, normals)
    assert {b[1].shape[1] for b in batches} >= {3, 4, 5, 6}  # clip polygons of every size
    for cross in (np.zeros_like(crosspoint), crosspoint):
        for batch, *topology in batches:
            args = (slave[batch], master[batch], nodal[batch], cross[batch], normals, basis,
                    rule, *topology)
            fast = surface3_numpy._polygon_integrals(*args)
            slow = surface3_numpy._polygon_integrals(*args, pointwise=True)
            for name in ("D", "M", "Dn", "Mn", "gap", "area"):
                for part in ("value", "grad"):
                    a, b = getattr(fast[name], part), getattr(slow[name], part)
                    scale = np.abs(b).max()
                    assert scale > 0.0
                    assert np.abs(a - b).max() <= 1e-12 * scale, (name, part)
