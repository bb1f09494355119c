"""The 3D numpy oracle's separation test (tests/oracle/surface3_numpy.py, _separated) drops
candidates before the clip: it must drop only pairs the clip finds no overlap for, so that the
kernel's output is the same with and without it, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest
from test_kernel_surface3_speedpath import random_pairs

from oracle import surface3_numpy


def clip_overlaps(slave, master, nodal, normals):
    """(separated, overlapping) of every pair, on the projected polygons."""
    xs, xm, n = surface3_numpy._pair_variables(slave, master, nodal, False)
    *_, S, Mp = surface3_numpy._auxiliary_plane(xs, xm, n, normals)
    separated = surface3_numpy._separated(S.value, Mp.value)
    _, count, positions = surface3_numpy._clip(S.value, Mp.value[:, ::-1])
    area = surface3_numpy._padded_area(positions, count)
    slave_area = np.abs(surface3_numpy._polygon_area(S.value))
    return separated, (count >= 3) & (area > surface3_numpy._AREA_TOLERANCE * slave_area)


@pytest.mark.parametrize("normals", ["averaged", "slave", "master"])
@pytest.mark.parametrize("scale", [0.3, 1.0, 3.0])
def test_separated_pairs_do_not_overlap(normals, scale):
    slave, master, nodal, _ = random_pairs(4000, seed=11)
    separated, overlapping = clip_overlaps(slave, master * scale, nodal, normals)
    assert not (separated & overlapping).any()
    assert 0.1 < separated.mean() < 0.9  # the test sees both kinds


def test_touching_triangles_are_not_separated():
    """Sharing an edge or only a corner: no gap, so left to the clip."""
    slave = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0.0]]] * 2)
    master = np.array([[[1, 0, 0], [0, 1, 0], [1, 1, 0.0]],  # the edge (1,0)-(0,1), reversed
                       [[1, 0, 0], [2, 1, 0], [2, 0, 0.0]]])  # only the corner (1, 0)
    nodal = np.broadcast_to([0, 0, 1.0], (2, 3, 3))
    separated, _ = clip_overlaps(slave, master, nodal, "averaged")
    assert not separated.any()
    shifted, _ = clip_overlaps(slave, master + [1e-3, 1e-3, 0.0], nodal, "averaged")
    assert shifted.all()


@pytest.mark.parametrize("normals", ["averaged", "master"])
def test_kernel_output_unchanged_by_the_separation_test(normals, monkeypatch):
    slave, master, nodal, crosspoint = random_pairs(1500, seed=5)
    args = dict(normals=normals, basis="dual", crosspoint=crosspoint, scalar_gradients=True)
    screened = surface3_numpy.pair_quantities(slave, master, nodal, **args)
    monkeypatch.setattr(surface3_numpy, "_separated",
                        lambda S, M: np.zeros(S.shape[0], dtype=bool))
    clipped = surface3_numpy.pair_quantities(slave, master, nodal, **args)
    assert screened.valid.sum() > 100
    np.testing.assert_array_equal(screened.valid, clipped.valid)
    np.testing.assert_array_equal(screened.overlap, clipped.overlap)
    for name in ("Dn", "Mn", "gap", "area", "D_dual", "M_dual"):
        a, b = getattr(screened, name), getattr(clipped, name)
        np.testing.assert_array_equal(a.value, b.value)
        np.testing.assert_array_equal(a.grad, b.grad)
