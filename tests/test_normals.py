"""Facet and averaged nodal normals: known values, the 2D kernel's normals, Taylor tests,
rotation and scale invariance."""

from __future__ import annotations

import numpy as np
import pytest

from dolfinx_mortar import normals

from oracle import line2_numpy


def grid_surface(kind: str, n: int = 4, seed: int = 0, amplitude: float = 0.05):
    """A bumpy n x n patch of the plane z = 0 seen from +z: triangles or quadrilaterals."""
    rng = np.random.default_rng(seed)
    s = np.linspace(0.0, 1.0, n + 1)
    X, Y = np.meshgrid(s, s, indexing="ij")
    x = np.column_stack([X.ravel(), Y.ravel(), np.zeros(X.size)])
    x += amplitude * rng.uniform(-1.0, 1.0, x.shape) / n
    node = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = node[:-1, :-1], node[1:, :-1], node[1:, 1:], node[:-1, 1:]
    if kind == "quadrilateral":
        facets = np.column_stack([a.ravel(), b.ravel(), c.ravel(), d.ravel()])
    else:
        facets = np.vstack([np.column_stack([a.ravel(), b.ravel(), c.ravel()]),
                            np.column_stack([a.ravel(), c.ravel(), d.ravel()])])
    return x, facets


def test_flat_patch_normals_are_the_plane_normal():
    for kind in ("triangle", "quadrilateral"):
        x, facets = grid_surface(kind, amplitude=0.0)
        result = normals.averaged_nodal_normals(x, facets)
        np.testing.assert_allclose(result.normals, np.tile([0.0, 0.0, 1.0], (x.shape[0], 1)),
                                   atol=1e-15)
        np.testing.assert_allclose(normals.facet_normals(x, facets)[:, 2], 1.0, atol=1e-15)
        # an interior node of the quad grid has 9 star nodes, of the triangle grid 7
        assert result.star.shape[1] == (9 if kind == "quadrilateral" else 7)
        corner = 0  # on one facet (quads) or two (triangles)
        assert np.count_nonzero(result.star[corner] >= 0) == (4 if kind == "quadrilateral" else 4)


def test_normals_of_a_closed_octahedron_point_outward_radially():
    x = np.array([[1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
    top, bottom = 4, 5
    facets = []
    for i in range(4):
        j = (i + 1) % 4
        facets += [[i, j, top], [j, i, bottom]]
    result = normals.averaged_nodal_normals(x, np.array(facets))
    np.testing.assert_allclose(result.normals, x, atol=1e-15)


@pytest.mark.parametrize("kind", ["triangle", "quadrilateral"])
def test_stars_kept_over_moves_give_the_normals_of_a_fresh_computation(kind):
    """A stencil builds the stars once per search and evaluates the normals (values only, or
    with their Jacobian) at every later position: the same bits as from scratch there. The
    sums are made in the facets' order, as one facet after another adds its corner normals
    (checked against that loop)."""
    x, facets = grid_surface(kind, n=5, seed=4)
    facets = facets[np.random.default_rng(5).permutation(facets.shape[0])]
    x = np.vstack([x, [[9.0, 9.0, 9.0]]])  # a node on no facet: zero normal, empty star
    stars = normals.NormalStars(facets, x.shape[0])
    rng = np.random.default_rng(6)
    for _ in range(3):
        moved = x + 0.02 * rng.standard_normal(x.shape)
        fresh = normals.averaged_nodal_normals(moved, facets)
        only, with_jacobian = stars.normals(moved), stars.normals_and_jacobian(moved)
        assert np.array_equal(stars.star, fresh.star)
        assert np.array_equal(only, fresh.normals)
        assert np.array_equal(with_jacobian[0], fresh.normals)
        assert np.array_equal(with_jacobian[1], fresh.jacobian)
        summed = np.zeros_like(moved)
        corner = normals.facet_corner_normals(moved, facets)
        for f in range(facets.shape[0]):
            for i, node in enumerate(facets[f]):
                summed[node] += corner[f, i]
        length = np.linalg.norm(summed, axis=1)
        expected = np.divide(summed, length[:, None], out=np.zeros_like(summed),
                             where=length[:, None] > 0)
        assert np.array_equal(only, expected)
        assert not only[-1].any() and (fresh.star[-1] < 0).all()


def test_two_dimensional_normals_equal_the_kernel_normals():
    """On random open polylines, the averaged normals equal line2's at every facet end."""
    rng = np.random.default_rng(2)
    t = np.sort(rng.uniform(0.0, 3.0, 9))
    x = np.column_stack([t, 0.3 * np.sin(2.0 * t) + 0.05 * rng.uniform(-1, 1, t.size)])
    facets = np.column_stack([np.arange(8), np.arange(1, 9)])[:, ::-1]  # facing +y... any way
    result = normals.averaged_nodal_normals(x, facets)
    for f in range(facets.shape[0]):
        a, b = facets[f]
        p = facets[f + 1, 0] if f + 1 < facets.shape[0] else a
        q = facets[f - 1, 1] if f > 0 else b
        has = np.array([[f + 1 < facets.shape[0], f > 0]])
        X = np.array([x[p], x[a], x[b], x[q], x[a], x[b]]).reshape(12, 1)
        n_a, n_b, _, _ = line2_numpy._normal_field(X, has, "averaged", False)
        np.testing.assert_allclose(result.normals[a], np.ravel(n_a), rtol=0, atol=1e-15)
        np.testing.assert_allclose(result.normals[b], np.ravel(n_b), rtol=0, atol=1e-15)


def _taylor_slopes(x, facets, seed):
    rng = np.random.default_rng(seed)
    base = normals.averaged_nodal_normals(x, facets)
    direction = rng.uniform(-1.0, 1.0, x.shape) * 0.1 / np.sqrt(facets.shape[0])
    # J dx per node over its star
    star = np.where(base.star >= 0, base.star, 0)
    dx = np.where((base.star >= 0)[..., None], direction[star], 0.0)
    predicted = np.einsum("iasb,isb->ia", base.jacobian, dx)
    assert np.abs(predicted).max() > 1e-4
    steps = np.array([0.1, 0.05, 0.025, 0.0125])
    remainders = []
    for h in steps:
        moved = normals.averaged_nodal_normals(x + h * direction, facets).normals
        remainders.append(np.abs(moved - base.normals - h * predicted).max())
    return np.diff(np.log(remainders)) / np.diff(np.log(steps))


@pytest.mark.parametrize("kind", ["triangle", "quadrilateral"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_three_dimensional_jacobian_taylor(kind, seed):
    x, facets = grid_surface(kind, n=3, seed=seed, amplitude=0.3)
    slopes = _taylor_slopes(x, facets, seed)
    assert np.all(np.abs(slopes - 2.0) < 0.1), slopes


def test_two_dimensional_jacobian_taylor():
    t = np.linspace(0.0, 2.0, 7)
    x = np.column_stack([t, 0.2 * np.sin(3.0 * t)])
    facets = np.column_stack([np.arange(6), np.arange(1, 7)])
    slopes = _taylor_slopes(x, facets, 4)
    assert np.all(np.abs(slopes - 2.0) < 0.1), slopes


@pytest.mark.parametrize("kind", ["triangle", "quadrilateral"])
def test_rotation_and_scale_invariance(kind):
    x, facets = grid_surface(kind, n=3, seed=5, amplitude=0.3)
    rng = np.random.default_rng(7)
    R, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    R *= np.sign(np.linalg.det(R))
    base = normals.averaged_nodal_normals(x, facets)
    turned = normals.averaged_nodal_normals(1e3 * x @ R.T + [3.0, -2.0, 5.0], facets)
    np.testing.assert_allclose(turned.normals, base.normals @ R.T, atol=1e-14)
    # d n / d x scales as 1/length and rotates on both sides
    expected = np.einsum("ab,ibsc,dc->iasd", R, base.jacobian, R) * 1e-3
    np.testing.assert_allclose(turned.jacobian, expected, atol=1e-14 * np.abs(expected).max())
