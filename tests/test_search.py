"""Broad-phase search: swept boxes, candidate pairs against brute force, reuse decisions."""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_mortar import kernels, search
from dolfinx_mortar.kernels import compiled


def brute_force_pairs(slave_x, slave_facets, master_x, master_facets, margin,
                      slave_previous=None, master_previous=None):
    slave_lower, slave_upper = search.facet_boxes(slave_x, slave_facets, slave_previous)
    master_lower, master_upper = search.facet_boxes(master_x, master_facets, master_previous)
    overlap = search.boxes_overlap(slave_lower[:, None], slave_upper[:, None],
                                   master_lower[None], master_upper[None], margin)
    pairs = np.argwhere(overlap)
    if slave_previous is None and master_previous is None:
        return pairs
    # swept pairs stay only if found at the current positions too, or if a slave node
    # is now behind the master facet's line (outward normal (t_y, -t_x))
    kept = []
    for s, m in pairs:
        now = brute_force_pairs(slave_x, slave_facets[[s]], master_x, master_facets[[m]], margin)
        a, b = master_x[master_facets[m]]
        normal = np.array([b[1] - a[1], a[0] - b[0]])
        behind = any(float(np.dot(slave_x[k] - a, normal)) < 0.0 for k in slave_facets[s])
        if now.size or behind:
            kept.append((s, m))
    return np.array(kept, dtype=np.int64).reshape(-1, 2)


def test_swept_boxes_are_the_union_of_both_states():
    previous = np.array([[0.0, 0.0], [1.0, 0.5]])
    current = np.array([[2.0, -1.0], [2.5, -3.0]])
    facets = np.array([[0, 1]])
    lower, upper = search.facet_boxes(current, facets)
    assert np.array_equal(lower, [[2.0, -3.0]]) and np.array_equal(upper, [[2.5, -1.0]])
    lower, upper = search.facet_boxes(current, facets, previous)
    assert np.array_equal(lower, [[0.0, -3.0]]) and np.array_equal(upper, [[2.5, 0.5]])
    # a diverged (NaN) state does not erase the other one
    lower, upper = search.facet_boxes(np.full_like(current, np.nan), facets, previous)
    assert np.array_equal(lower, [[0.0, 0.0]]) and np.array_equal(upper, [[1.0, 0.5]])


def test_facet_pushed_through_by_more_than_the_margin_is_found_and_penetrates():
    """A slave facet above a master facet, moved down through it by 10 margins in one
    update: the box search at the new positions finds nothing, the swept one finds the
    pair, and the kernel sees a penetration of exactly that depth (gap = -depth * area)."""
    margin = 0.01
    master_x = np.array([[1.0, 0.0], [-1.0, 0.0]])  # normal (t_y, -t_x) = (0, 1): up
    slave_before = np.array([[-0.5, 0.005], [0.5, 0.005]])  # normal down
    depth = 10 * margin
    slave_after = slave_before - [0.0, 0.005 + depth]
    facets = np.array([[0, 1]])
    assert search.candidate_pairs(slave_after, facets, master_x, facets, margin).shape == (0, 2)
    pairs = search.candidate_pairs(slave_after, facets, master_x, facets, margin,
                                   slave_previous=slave_before, master_previous=master_x)
    assert pairs.tolist() == [[0, 0]]
    # p, a, b, q, c, d: no neighbours
    x = np.concatenate([slave_after[0], slave_after[0], slave_after[1], slave_after[1],
                        master_x[0], master_x[1]])[None]
    q = kernels.pair_quantities(x, np.zeros((1, 2), dtype=bool))
    assert q.valid[0]
    np.testing.assert_allclose(q.gap.value[0], -depth * q.area.value[0], rtol=1e-14)
    np.testing.assert_allclose(q.area.value[0], [0.5, 0.5], rtol=1e-14)


def test_facet_turned_over_is_not_a_contact_pair():
    """The kernels' facing test: a slave facet whose outward normal points the same way
    as the master's (turned by more than 90 degrees relative to it) gives no contribution,
    whether or not it crossed the master facet; the swept search still reports the pair."""
    master_x = np.array([[1.0, 0.0], [-1.0, 0.0]])
    slave_turned = np.array([[0.5, -0.1], [-0.5, -0.1]])  # normal up, like the master's
    x = np.concatenate([slave_turned[0], slave_turned[0], slave_turned[1], slave_turned[1],
                        master_x[0], master_x[1]])[None]
    q = kernels.pair_quantities(x, np.zeros((1, 2), dtype=bool))
    assert not q.valid[0]
    assert np.all(q.gap.value == 0.0) and np.all(q.area.value == 0.0)


@pytest.mark.parametrize("seed", range(4))
def test_candidate_pairs_equal_brute_force(seed):
    """Random facets of mixed sizes, some swept very far (a diverging iterate): the
    size-grouped k-d tree search returns exactly the pairs of the O(n^2) box test."""
    rng = np.random.default_rng(seed)
    num_slave, num_master, margin = 300, 200, 0.02

    def surface(n):
        start = rng.uniform(0.0, 1.0, (n, 2))
        length = 10.0 ** rng.uniform(-3.0, -1.0, (n, 1))
        angle = rng.uniform(0.0, 2 * np.pi, n)
        end = start + length * np.column_stack([np.cos(angle), np.sin(angle)])
        x = np.concatenate([start, end])
        previous = x + rng.normal(0.0, 0.01, x.shape)
        far = rng.random(x.shape[0]) < 0.02
        previous[far] += rng.normal(0.0, 3.0, (far.sum(), 2))
        return x, previous, np.column_stack([np.arange(n), np.arange(n, 2 * n)])

    slave_x, slave_previous, slave_facets = surface(num_slave)
    master_x, master_previous, master_facets = surface(num_master)
    for previous in (False, True):
        options = {"slave_previous": slave_previous, "master_previous": master_previous}
        if not previous:
            options = {}
        arguments = (slave_x, slave_facets, master_x, master_facets, margin)
        found = search.candidate_pairs(*arguments, **options)
        expected = brute_force_pairs(*arguments, **options)
        assert found.tolist() == expected.tolist()
        assert expected.shape[0] > 100
    lower, upper = search.facet_boxes(slave_x, slave_facets, slave_previous)
    assert np.ptp(np.log2(np.max(upper - lower, axis=1) + margin)) > 4  # several size groups


def test_reuse_sweeps_from_the_last_search():
    reuse = search.SearchReuse(margin=0.1)
    initial = np.zeros((3, 2))
    first = initial + [0.0, 1.0]
    assert reuse.needs_search(first, MPI.COMM_SELF)
    assert reuse.sweep_start(first, initial) is initial
    reuse.searched(first)
    assert not reuse.needs_search(first + 0.049 / np.sqrt(2), MPI.COMM_SELF)
    assert reuse.needs_search(first + [0.0, 0.051], MPI.COMM_SELF)
    assert np.array_equal(reuse.sweep_start(first + 5.0, initial), first)
    reuse.invalidate()
    assert reuse.needs_search(first, MPI.COMM_SELF)
    assert np.array_equal(reuse.sweep_start(first, initial), first)  # still from the last search
    assert reuse.searches_done == 1


def test_swept_pairs_of_a_body_moving_away_are_dropped():
    """A slave facet lifted from touching to 10 margins above the master: its swept box
    covers the master, but it lies in front of it now, so no pair remains; pushed down
    by as much instead, it is behind the master and the pair stays."""
    margin = 0.01
    master_x = np.array([[1.0, 0.0], [0.0, 0.0]])  # outward normal (0, 1)
    facets = np.array([[0, 1]])
    touching = np.array([[0.0, 0.0], [1.0, 0.0]])
    for shift, expected in ((10 * margin, 0), (-10 * margin, 1)):
        moved = touching + [0.0, shift]
        pairs = search.candidate_pairs(moved, facets, master_x, facets, margin,
                                       slave_previous=touching, master_previous=master_x)
        assert pairs.shape[0] == expected, shift
        brute = brute_force_pairs(moved, facets, master_x, facets, margin,
                                  slave_previous=touching, master_previous=master_x)
        assert brute.shape[0] == expected


@pytest.mark.parametrize("gdim", [2, 3])
def test_boxes_swept_across_the_surface_stay_a_narrow_search(gdim):
    """A flat slave surface of n facets swept across its normal by 10^3 facet lengths (the
    first update of benchmarks/mortar_scaling.py from the undeformed surface): the pairs
    are the brute-force ones, and the box tests done are few per facet (a ball
    around the centres as wide as the sweep took ~10^3 per facet)."""
    rng = np.random.default_rng(3)
    n, margin = 400, 2e-3
    h = 1.0 / n
    if gdim == 2:
        slave_x = np.column_stack([np.linspace(0.0, 1.0, n + 1), np.zeros(n + 1)])
        slave_facets = np.column_stack([np.arange(n), np.arange(1, n + 1)])
        master_x = np.column_stack([np.linspace(1.0, 0.0, 301), np.full(301, -0.1 * h)])
        master_facets = np.column_stack([np.arange(300), np.arange(1, 301)])
    else:
        grid = np.linspace(0.0, 1.0, 21)
        X, Y = np.meshgrid(grid, grid, indexing="ij")
        slave_x = np.column_stack([X.ravel(), Y.ravel(), np.zeros(X.size)])
        corner = (np.arange(20)[:, None] * 21 + np.arange(20)[None, :]).ravel()
        slave_facets = np.concatenate([
            np.column_stack([corner, corner + 21, corner + 22]),
            np.column_stack([corner, corner + 22, corner + 1])])
        master_x = slave_x * [1.0, 1.0, 0.0] + [0.013, 0.007, -0.1 * h]
        master_facets = slave_facets[:, ::-1].copy()
        h = 1.0 / 20
    slave_previous = slave_x.copy()
    slave_previous[:, -1] += 1e3 * h * rng.uniform(0.5, 1.0, slave_x.shape[0])
    arguments = (slave_x, slave_facets, master_x, master_facets, margin)
    options = {"slave_previous": slave_previous, "master_previous": master_x}
    found = search.candidate_pairs(*arguments, **options)
    slave_lower, slave_upper = search.facet_boxes(slave_x, slave_facets, slave_previous)
    master_lower, master_upper = search.facet_boxes(master_x, master_facets)
    overlap = search.boxes_overlap(slave_lower[:, None], slave_upper[:, None],
                                   master_lower[None], master_upper[None], margin)
    assert found.tolist() == np.argwhere(overlap).tolist()  # (all near now: none dropped)
    pairs, tested = compiled.search_boxes(slave_lower, slave_upper, master_lower, master_upper,
                                          margin)
    assert pairs.tolist() == found.tolist()
    assert found.shape[0] <= tested <= 3 * found.shape[0]


@pytest.mark.parametrize("dim", [1, 2, 3])
def test_search_boxes_equal_the_box_test_of_every_pair(dim):
    """The compiled search against the O(n^2) box test, in 1 to 3 coordinates, on boxes of
    sizes over five decades (several size groups and grids), a few of them not finite (the
    nodes of a diverged iterate): those pair with nothing, the others as the box test says."""
    rng = np.random.default_rng(dim)
    margin = 1e-3

    def boxes(n):
        lower = rng.uniform(0.0, 1.0, (n, dim))
        upper = lower + 10.0 ** rng.uniform(-4.0, 1.0, (n, 1)) * rng.uniform(0.2, 1.0, (n, dim))
        return lower, upper

    slave_lower, slave_upper = boxes(400)
    master_lower, master_upper = boxes(300)
    slave_lower[7, 0], slave_upper[9, -1], master_upper[5, 0] = np.nan, np.inf, np.nan
    master_lower[11, -1] = -np.inf
    pairs, tested = compiled.search_boxes(slave_lower, slave_upper, master_lower, master_upper,
                                          margin)
    overlap = search.boxes_overlap(slave_lower[:, None], slave_upper[:, None],
                                   master_lower[None], master_upper[None], margin)
    finite = [np.all(np.isfinite(lower) & np.isfinite(upper), axis=1)
              for lower, upper in ((slave_lower, slave_upper), (master_lower, master_upper))]
    assert overlap[9].any()  # an infinite box overlaps others by the box test alone
    overlap &= finite[0][:, None] & finite[1][None, :]
    assert pairs.tolist() == np.argwhere(overlap).tolist()
    assert pairs.shape[0] <= tested < overlap.size


def test_search_boxes_of_empty_sides():
    some = np.zeros((3, 2)), np.ones((3, 2))
    none = np.zeros((0, 2)), np.zeros((0, 2))
    for sides in ((*some, *none), (*none, *some), (*none, *none)):
        pairs, tested = compiled.search_boxes(*sides, 0.1)
        assert pairs.shape == (0, 2) and tested == 0
