"""The compiled 3D kernel (kernels/surface3.c through kernels/compiled.py) against the numpy oracle
(tests/oracle/surface3_numpy.py, pair_quantities, factorized=False): values and every gradient
to 1e-13 of each output's largest entry, on random and mesh configurations, triangle and
quadrilateral facets, every normal field; Taylor tests of its gradients; and the compile cache
(one compile per cache, none in a second process, three processes on an empty cache)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from test_kernel_surface3_speedpath import random_pairs

from dolfinx_mortar.kernels import compiled

from oracle import surface3_numpy, use_oracle

TOLERANCE = 1e-13
VALUES = ("D", "M", "Dn", "Mn", "gap", "area")
GRADIENTS = ("Dn", "Mn", "gap", "area", "D", "M")


def reference(slave, master, nodal, **options):
    q = surface3_numpy.pair_quantities(slave, master, nodal, factorized=False,
                                       scalar_gradients=True, **options)
    values = {"D": q.D, "M": q.M, "Dn": q.Dn.value, "Mn": q.Mn.value, "gap": q.gap.value,
              "area": q.area.value, "valid": q.valid, "overlap": q.overlap}
    grads = {"Dn": q.Dn.grad, "Mn": q.Mn.grad, "gap": q.gap.grad, "area": q.area.grad,
             "D": q.D_dual.grad, "M": q.M_dual.grad}
    return values, grads


def assert_agree(slave, master, nodal, pointwise=False, **options):
    """The compiled kernel equals the numpy kernel; returns the number of valid pairs."""
    values, grads = reference(slave, master, nodal, **options)
    got = compiled.pair_quantities_compiled(slave, master, nodal, scalar_gradients=True,
                                            pointwise=pointwise, **options)
    np.testing.assert_array_equal(got["valid"], values["valid"])
    np.testing.assert_allclose(got["overlap"], values["overlap"], rtol=0, atol=TOLERANCE)
    # the gap is sum Mn xm - sum Dn xs: measured against its terms (1e3 times the gap on a
    # flat interface with a gap of 1e-3: either kernel's rounding of Mn and Dn shows there)
    terms = (np.abs(values["Mn"] * master[:, None]).sum(axis=(-1, -2))
             + np.abs(values["Dn"] * slave[:, None]).sum(axis=(-1, -2)))
    for name in VALUES:
        scale = np.abs(values[name]).max(initial=0.0)
        if name == "gap":
            scale = max(scale, terms.max(initial=0.0))
        error = np.abs(got[name] - values[name]).max(initial=0.0)
        assert error <= TOLERANCE * scale or error == 0.0, (name, error, scale)
    for name in GRADIENTS:
        scale = np.abs(grads[name]).max(initial=0.0)
        error = np.abs(got[name + "_grad"] - grads[name]).max(initial=0.0)
        assert error <= TOLERANCE * scale or error == 0.0, (name + "_grad", error, scale)
    return int(values["valid"].sum())


@pytest.mark.parametrize("basis", ["standard", "dual"])
@pytest.mark.parametrize("crosspoints", [False, True])
@pytest.mark.parametrize("rule", [1, 3, 7])
def test_random_pairs(basis, crosspoints, rule):
    """Overlapping, partly overlapping and disjoint pairs, rotated (clip polygons of 3 to 6
    vertices)."""
    slave, master, nodal, crosspoint = random_pairs(600, seed=21)
    valid = assert_agree(slave, master, nodal, basis=basis, num_gauss_points=rule,
                         crosspoint=crosspoint if crosspoints else None)
    assert 200 < valid < 600


def test_not_facing():
    """The master turned over (its nodes reversed) faces the same way as the slave."""
    slave, master, nodal, _ = random_pairs(200, seed=22)
    got = compiled.pair_quantities_compiled(slave, master[:, ::-1], nodal)
    assert not got["valid"].any()
    assert not np.abs(got["Dn_grad"]).any() and not np.abs(got["gap"]).any()
    assert assert_agree(slave, master[:, ::-1], nodal) == 0
    assert assert_agree(slave, master, nodal) > 50


def flat_pair(master_xy, z=0.1):
    """The unit slave triangle in z = 0 (outward normal +z) and a master triangle at height z
    facing down (clockwise seen from +z)."""
    slave = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    master = np.column_stack([master_xy, np.full(3, z)])
    return slave, master


def test_tiny_overlaps_near_the_area_tolerance():
    """A master corner reaching into the slave triangle by areas from 1e-17 to 1e-11 of it:
    both kernels keep or drop the same pairs (the tolerance is 1e-14)."""
    slaves, masters = [], []
    for depth in np.geomspace(1e-9, 1e-5, 120):
        # a master triangle (clockwise from +z) whose corner pokes depth into the slave's
        # corner region near (0.5, 0): overlap area ~ depth^2
        xy = np.array([[0.5, depth], [0.5 + 1.0, -1.0], [0.5 - 1.0, -1.0]])
        slave, master = flat_pair(xy)
        slaves.append(slave)
        masters.append(master)
    slave, master = np.array(slaves), np.array(masters)
    nodal = np.broadcast_to([0.0, 0.0, 1.0], slave.shape).copy()
    values, _ = reference(slave, master, nodal)
    ratio = values["overlap"]
    assert values["valid"].any() and not values["valid"].all()
    assert ratio[values["valid"]].min() < 1e-12
    for basis in ("standard", "dual"):
        for normals in ("averaged", "slave", "master"):
            assert_agree(slave, master, nodal, basis=basis, normals=normals)


def test_master_vertices_on_slave_edges():
    """Master vertices exactly on slave edges and slave vertices, master edges along slave
    edges: degenerate clip polygons, decided on the same bits as numpy."""
    rng = np.random.default_rng(23)
    configurations = [
        [[0.5, 0.0], [0.5, 1.0], [1.5, 0.0]],  # a vertex on an edge, an edge through a vertex
        [[0.0, 0.0], [0.0, 1.0], [1.0, 0.0]],  # the slave itself, reversed
        [[0.25, 0.0], [0.0, 0.5], [1.0, 0.5]],  # two vertices on two edges
        [[0.5, 0.5], [0.5, -0.5], [-0.5, 0.5]],  # a vertex on the hypotenuse
        [[0.0, 0.0], [0.5, 0.5], [1.0, 0.0]],  # a shared vertex and edge
    ]
    slaves, masters, normals = [], [], []
    for xy in configurations:
        xy = np.array(xy, float)
        a, b = xy[1] - xy[0], xy[2] - xy[0]
        if a[0] * b[1] - a[1] * b[0] > 0:
            xy = xy[::-1]  # clockwise seen from +z: the master faces down
        for z in (0.1, -0.05):
            slave, master = flat_pair(xy, z)
            for tilt in (0.0, 0.1):
                nodal = np.array([0.0, 0, 1]) + tilt * rng.uniform(-1, 1, (3, 3))
                slaves.append(slave)
                masters.append(master)
                normals.append(nodal / np.linalg.norm(nodal, axis=1, keepdims=True))
    slave, master, nodal = np.array(slaves), np.array(masters), np.array(normals)
    crosspoint = rng.random((slave.shape[0], 3)) < 0.3
    for basis in ("standard", "dual"):
        for normals in ("averaged", "slave", "master"):
            assert assert_agree(slave, master, nodal, basis=basis, normals=normals) > 10
            assert_agree(slave, master, nodal, basis=basis, normals=normals,
                         crosspoint=crosspoint)


def rotation(rng) -> np.ndarray:
    q, r = np.linalg.qr(rng.standard_normal((3, 3)))
    q = q * np.sign(np.diag(r))
    return q * np.linalg.det(q)


@pytest.mark.parametrize("ns", [3, 4])
def test_edges_that_coincide_under_rotation(ns):
    """A master facet shifted by half a facet along one edge of the slave facet: two pairs
    of edges coincide, as where two bodies end on one plane (the slit's lips at their
    roller planes). Turned and moved by 50 random rigid motions they coincide up to
    rounding only. The gradients stay those of the axis-aligned pair: no clip vertex at
    the intersection of two parallel lines, which rounding places anywhere along them,
    with a derivative up to 1 / rounding (before: up to 21 times the aligned pair's here,
    and Jacobian entries of 2e17 in the 3D self-contact patch test, which then took 4 to
    12 Newton iterations instead of 3). Both kernels agree on every pair."""
    rng = np.random.default_rng(7)
    if ns == 4:
        slave0 = np.array([[0, 0, 0], [0, 1, 0], [1, 1, 0], [1, 0, 0]], float)
        master0 = np.array([[0, 0.5, -0.1], [1, 0.5, -0.1], [1, 1.5, -0.1], [0, 1.5, -0.1]])
    else:
        slave0 = np.array([[0, 0, 0], [0, 1, 0], [1, 0, 0]], float)
        master0 = np.array([[0, 0.5, -0.1], [1, -0.5, -0.1], [0, 1.5, -0.1]])
    down = np.tile([0.0, 0.0, -1.0], (ns, 1))
    slaves, masters, normals = [slave0], [master0], [down]
    for _ in range(50):
        Q, shift = rotation(rng), rng.uniform(-5.0, 5.0, 3)
        slaves.append(slave0 @ Q.T + shift)
        masters.append(master0 @ Q.T + shift)
        normals.append(down @ Q.T)
    slave, master, nodal = np.array(slaves), np.array(masters), np.array(normals)
    for normals_option in ("averaged", "slave", "master"):
        for basis in ("standard", "dual"):
            values, grads = reference(slave, master, nodal, basis=basis, normals=normals_option)
            assert values["valid"].all()
            np.testing.assert_allclose(values["overlap"], values["overlap"][0], atol=1e-14)
            for name in GRADIENTS:
                aligned = np.abs(grads[name][0]).max()
                turned = np.abs(grads[name][1:]).max(axis=tuple(range(1, grads[name].ndim)))
                # a rotation changes the largest entry by at most sqrt(3)
                assert turned.max() <= 2.0 * aligned, (normals_option, basis, name,
                                                       turned.max(), aligned)
            assert_agree(slave, master, nodal, basis=basis, normals=normals_option)


@pytest.mark.parametrize("cell,sizes", [("tetrahedron", (3, 4)), ("tetrahedron", (4, 4)),
                                        ("hexahedron", (3, 4)), ("hexahedron", (4, 4))])
def test_mesh_interface_pairs(cell, sizes, monkeypatch):
    """The candidate pairs the interface hands the numpy kernel on two tetrahedral or
    hexahedral blocks (flat: nodes on each other's edges; bent), with every normal field."""
    from test_mortar3d import bent_displacement, interface, two_blocks

    calls = []
    original = surface3_numpy.pair_quantities

    def recording(slave_x, master_x, slave_normals, **options):
        calls.append((slave_x, master_x, slave_normals, options))
        return original(slave_x, master_x, slave_normals, **options)

    monkeypatch.setattr(surface3_numpy, "pair_quantities", recording)
    tagged = two_blocks(cell, *sizes)
    with use_oracle():  # (the pairs the numpy kernel is handed)
        for u in (None, bent_displacement(tagged)):
            mortar = interface(tagged, u, basis="dual")
            mortar.destroy()
    monkeypatch.undo()  # the comparison calls the numpy kernel itself
    assert calls, "the interface did not call surface3_numpy.pair_quantities"
    checked = False
    for slave, master, nodal, options in calls:
        if options.get("integration", "segment") != "segment":
            continue
        checked = True
        for basis in ("standard", "dual"):
            for normals in ("averaged", "slave", "master"):
                assert assert_agree(slave, master, nodal, basis=basis, normals=normals,
                                    num_gauss_points=options.get("num_gauss_points"),
                                    crosspoint=options.get("crosspoint")) > 10
    assert checked


@pytest.mark.parametrize("basis", ["standard", "dual"])
@pytest.mark.parametrize("normals", ["averaged", "slave", "master"])
def test_taylor(basis, normals):
    """f(x + h d) - f(x) - h f'(x) d = O(h^2) for the compiled gradients, several pairs."""
    slave, master, nodal, crosspoint = random_pairs(40, seed=24)
    keep = compiled.pair_quantities_compiled(slave, master, nodal)["overlap"] > 0.2
    slave, master, nodal, crosspoint = slave[keep], master[keep], nodal[keep], crosspoint[keep]
    n = slave.shape[0]
    assert n >= 5
    x = np.concatenate([slave.reshape(n, 9), master.reshape(n, 9), nodal.reshape(n, 9)], axis=1)
    direction = np.random.default_rng(25).uniform(-1, 1, x.shape)
    names = ("D", "M", "Dn", "Mn", "gap", "area")

    def evaluate(values):
        return compiled.pair_quantities_compiled(
            values[:, :9].reshape(n, 3, 3), values[:, 9:18].reshape(n, 3, 3),
            values[:, 18:].reshape(n, 3, 3), basis=basis, normals=normals,
            crosspoint=crosspoint, scalar_gradients=True)

    base = evaluate(x)
    flat = np.concatenate([base[name].reshape(n, -1) for name in names], axis=1)
    gradient = np.concatenate([base[name + "_grad"].reshape(n, -1, 27) for name in names],
                              axis=1)
    predicted = np.einsum("nov,nv->no", gradient, direction)
    assert np.abs(predicted).max() > 1e-3
    steps = np.array([1e-3, 5e-4, 2.5e-4, 1.25e-4])
    remainders = []
    for h in steps:
        moved = evaluate(x + h * direction)
        assert moved["valid"].all()
        shifted = np.concatenate([moved[name].reshape(n, -1) for name in names], axis=1)
        remainders.append(np.abs(shifted - flat - h * predicted).max())
    slopes = np.diff(np.log(remainders)) / np.diff(np.log(steps))
    assert np.all(np.abs(slopes - 2.0) < 0.1), slopes


# -- quadrilaterals, normal fields, the pointwise path ------------------------------------------


def random_facets(n: int, ns: int, nm: int, seed: int, noise: float = 0.12):
    """Perturbed unit triangles or squares (quadrilaterals warped out of their plane), the
    master turned over and shifted, rotated: overlapping, partly overlapping and disjoint."""
    rng = np.random.default_rng(seed)
    slave_reference = {3: [[0, 0, 0], [1, 0, 0], [0, 1, 0.0]],
                       4: [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.0]]}
    master_reference = {3: [[0, 0, 0], [0, 1, 0], [1, 0, 0.0]],
                        4: [[0, 0, 0], [0, 1, 0], [1, 1, 0], [1, 0, 0.0]]}
    slave = np.array(slave_reference[ns]) + noise * rng.standard_normal((n, ns, 3))
    shift = rng.uniform(-0.7, 0.7, (n, 1, 3))
    shift[..., 2] = 0.05 * rng.standard_normal((n, 1))
    master = (np.array(master_reference[nm]) * rng.uniform(0.6, 1.4, (n, 1, 1)) + shift
              + noise * rng.standard_normal((n, nm, 3)))
    normals = np.array([0, 0, 1.0]) + 0.2 * rng.standard_normal((n, ns, 3))
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    Q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    return slave @ Q.T, master @ Q.T, normals @ Q.T, rng.random((n, ns)) < 0.2


@pytest.mark.parametrize("ns,nm", [(3, 3), (3, 4), (4, 3), (4, 4)])
@pytest.mark.parametrize("normals", ["averaged", "slave", "master"])
@pytest.mark.parametrize("basis", ["standard", "dual"])
def test_facet_combinations(ns, nm, normals, basis):
    """Every facet combination and normal field, with and without crosspoints (triangle on
    triangle: the corner-value path and the pointwise path)."""
    slave, master, nodal, crosspoint = random_facets(150, ns, nm, seed=31 + 2 * ns + nm)
    for cross in (None, crosspoint):
        for pointwise in ((False, True) if (ns, nm) == (3, 3) else (False,)):
            valid = assert_agree(slave, master, nodal, basis=basis, normals=normals,
                                 crosspoint=cross, pointwise=pointwise)
            assert 50 < valid < 150


@pytest.mark.parametrize("rule", [1, 3])
def test_quadrilateral_rules(rule):
    slave, master, nodal, crosspoint = random_facets(100, 4, 4, seed=41)
    assert assert_agree(slave, master, nodal, basis="dual", normals="slave", crosspoint=crosspoint,
                        num_gauss_points=rule) > 30


def test_quadrilaterals_degenerate():
    """Flat unit squares: the master the slave itself (reversed), shifted by half a side (edges
    along edges, vertices on edges), turned by 45 degrees about a shared corner, touching along
    an edge only, disjoint, not facing, and a corner poking in by areas around the tolerance."""
    slave_square = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])

    def master(xy, z=0.1):
        xy = np.asarray(xy, float)
        return np.column_stack([xy[::-1], np.full(4, z)])  # clockwise seen from +z

    c, s = np.cos(np.pi / 4), np.sin(np.pi / 4)
    square = np.array([[0.0, 0], [1, 0], [1, 1], [0, 1]])
    masters = [master(square), master(square + [0.5, 0]), master(square + [0.5, 0.5]),
               master(square @ np.array([[c, s], [-s, c]])), master(square + [1.0, 0]),
               master(square + [2.0, 0]), master(square * 0.5 + [0.25, 0.25]),
               master(square, -0.05)]
    for depth in np.geomspace(1e-9, 1e-5, 12):
        masters.append(master(square @ np.array([[c, s], [-s, c]]) + [0.5, 1 - depth]))
    masters = np.array(masters)
    n = masters.shape[0]
    slaves = np.broadcast_to(slave_square, (n, 4, 3)).copy()
    rng = np.random.default_rng(43)
    nodal = np.array([0.0, 0, 1]) + 0.1 * rng.uniform(-1, 1, (n, 4, 3))
    nodal /= np.linalg.norm(nodal, axis=-1, keepdims=True)
    crosspoint = rng.random((n, 4)) < 0.3
    for normals in ("averaged", "slave", "master"):
        for basis in ("standard", "dual"):
            assert assert_agree(slaves, masters, nodal, basis=basis, normals=normals) > 5
            assert_agree(slaves, masters, nodal, basis=basis, normals=normals,
                         crosspoint=crosspoint)
            # the master turned over faces the same way as the slave: nothing
            turned = compiled.pair_quantities_compiled(slaves, masters[:, ::-1], nodal,
                                                       basis=basis, normals=normals)
            assert not turned["valid"].any() and not turned["Dn_grad"].any()
    # triangles on squares and squares on triangles, flat: vertices on edges
    triangle = np.array([[0.0, 0, 0.1], [0, 1, 0.1], [1, 0, 0.1]])
    assert_agree(slaves[:1], triangle[None], nodal[:1], basis="dual")
    assert_agree(triangle[None, ::-1] * [1, 1, 0], masters[:1], nodal[:1, :3], basis="dual")


@pytest.mark.parametrize("ns,nm,normals,basis", [
    (4, 4, "averaged", "dual"), (4, 3, "slave", "dual"), (3, 4, "master", "standard"),
    (4, 4, "master", "standard")])
def test_taylor_quadrilaterals(ns, nm, normals, basis):
    """f(x + h d) - f(x) - h f'(x) d = O(h^2): every output (D and M included)."""
    slave, master, nodal, crosspoint = random_facets(60, ns, nm, seed=45)
    keep = compiled.pair_quantities_compiled(slave, master, nodal, normals=normals)["overlap"] > 0.2
    slave, master, nodal, crosspoint = slave[keep], master[keep], nodal[keep], crosspoint[keep]
    n = slave.shape[0]
    assert n >= 5
    nv = 3 * (2 * ns + nm)
    x = np.concatenate([slave.reshape(n, -1), master.reshape(n, -1), nodal.reshape(n, -1)], axis=1)
    direction = np.random.default_rng(46).uniform(-1, 1, x.shape)
    names = ("D", "M", "Dn", "Mn", "gap", "area")

    def evaluate(values):
        return compiled.pair_quantities_compiled(
            values[:, :3 * ns].reshape(n, ns, 3), values[:, 3 * ns:3 * (ns + nm)].reshape(n, nm, 3),
            values[:, 3 * (ns + nm):].reshape(n, ns, 3), basis=basis, normals=normals,
            crosspoint=crosspoint, scalar_gradients=True)

    base = evaluate(x)
    flat = np.concatenate([base[name].reshape(n, -1) for name in names], axis=1)
    gradient = np.concatenate([base[name + "_grad"].reshape(n, -1, nv) for name in names], axis=1)
    predicted = np.einsum("nov,nv->no", gradient, direction)
    assert np.abs(predicted).max() > 1e-3
    steps = np.array([1e-3, 5e-4, 2.5e-4, 1.25e-4])
    remainders = []
    for h in steps:
        moved = evaluate(x + h * direction)
        assert moved["valid"].all()
        shifted = np.concatenate([moved[name].reshape(n, -1) for name in names], axis=1)
        remainders.append(np.abs(shifted - flat - h * predicted).max())
    slopes = np.diff(np.log(remainders)) / np.diff(np.log(steps))
    assert np.all(np.abs(slopes - 2.0) < 0.1), slopes


# -- element-based integration -------------------------------------------------------------------


@pytest.mark.parametrize("ns,nm", [(3, 3), (3, 4), (4, 3), (4, 4)])
@pytest.mark.parametrize("normals", ["averaged", "slave", "master"])
def test_element_based(ns, nm, normals):
    """Each slave Gauss point given to one pair (pairs sharing a slave facet two by two), every
    rule, both bases, crosspoints. Quadrilaterals warped mildly: the projection onto a strongly
    warped master quadrilateral need not converge in 30 Newton steps (the numpy kernel then
    keeps the last iterate, whose bits neither kernel can reproduce)."""
    slave, master, nodal, crosspoint = random_facets(120, ns, nm, seed=51 + 2 * ns + nm,
                                                     noise=0.04)
    shared = np.repeat(np.arange(60), 2)
    for rule in (1, 3, 7):
        for basis in ("standard", "dual"):
            for slave_facet in (None, shared):
                assert assert_agree(slave, master, nodal, basis=basis, normals=normals,
                                    crosspoint=crosspoint, integration="element",
                                    num_gauss_points=rule, slave_facet=slave_facet) > 15


ELEMENT_TIES_ON_FLAT_TETRAHEDRA = (
    "flat 3 x 3 on 4 x 4 tetrahedral interface: slave Gauss points exactly on shared master "
    "edges score 0 up to rounding on two pairs; which pair gets a point depends on the last bits "
    "of the projection (numpy: LAPACK solve and inverse; C: Gauss-Jordan), D and M differ by up "
    "to 0.2 of their largest entry")


@pytest.mark.parametrize("cell,sizes", [
    pytest.param("tetrahedron", (3, 4), marks=pytest.mark.xfail(
        strict=True, reason=ELEMENT_TIES_ON_FLAT_TETRAHEDRA)),
    ("tetrahedron", (4, 4)), ("hexahedron", (3, 4)), ("hexahedron", (4, 4))])
def test_element_based_mesh_pairs(cell, sizes, monkeypatch):
    """Element-based integration of the candidate pairs of two blocks (flat, bent), the pairs
    of one slave facet competing for its Gauss points."""
    from test_mortar3d import bent_displacement, interface, two_blocks

    calls = []
    original = surface3_numpy.pair_quantities

    def recording(slave_x, master_x, slave_normals, **options):
        calls.append((slave_x, master_x, slave_normals, options))
        return original(slave_x, master_x, slave_normals, **options)

    monkeypatch.setattr(surface3_numpy, "pair_quantities", recording)
    tagged = two_blocks(cell, *sizes)
    with use_oracle():  # (the pairs the numpy kernel is handed)
        for u in (None, bent_displacement(tagged)):
            interface(tagged, u, basis="dual").destroy()
    monkeypatch.undo()
    assert calls
    for slave, master, nodal, options in calls:
        _, slave_facet = np.unique(slave.reshape(len(slave), -1), axis=0, return_inverse=True)
        for normals in ("averaged", "master"):
            assert assert_agree(slave, master, nodal, basis="dual", normals=normals,
                                crosspoint=options.get("crosspoint"), integration="element",
                                slave_facet=slave_facet) > 10


@pytest.mark.parametrize("ns,nm,normals", [(4, 4, "averaged"), (3, 4, "slave"), (4, 3, "master")])
def test_taylor_element_based(ns, nm, normals):
    slave, master, nodal, crosspoint = random_facets(40, ns, nm, seed=53, noise=0.04)
    options = dict(basis="dual", normals=normals, crosspoint=None, integration="element",
                   scalar_gradients=True)
    overlap = compiled.pair_quantities_compiled(slave, master, nodal, **options)["overlap"]
    keep = overlap > 0.3
    slave, master, nodal, overlap = slave[keep], master[keep], nodal[keep], overlap[keep]
    n = slave.shape[0]
    assert n >= 5
    nv = 3 * (2 * ns + nm)
    x = np.concatenate([slave.reshape(n, -1), master.reshape(n, -1), nodal.reshape(n, -1)], axis=1)
    direction = np.random.default_rng(54).uniform(-1, 1, x.shape)
    names = ("D", "M", "Dn", "Mn", "gap", "area")

    def evaluate(values):
        return compiled.pair_quantities_compiled(
            values[:, :3 * ns].reshape(n, ns, 3), values[:, 3 * ns:3 * (ns + nm)].reshape(n, nm, 3),
            values[:, 3 * (ns + nm):].reshape(n, ns, 3), **options)

    base = evaluate(x)
    flat = np.concatenate([base[name].reshape(n, -1) for name in names], axis=1)
    gradient = np.concatenate([base[name + "_grad"].reshape(n, -1, nv) for name in names], axis=1)
    predicted = np.einsum("nov,nv->no", gradient, direction)
    steps = np.array([1e-4, 5e-5, 2.5e-5, 1.25e-5])
    remainders = []
    for h in steps:
        moved = evaluate(x + h * direction)
        # the same points on the master facets (one point's share is more than 0.02)
        assert np.abs(moved["overlap"] - overlap).max() < 0.01
        shifted = np.concatenate([moved[name].reshape(n, -1) for name in names], axis=1)
        remainders.append(np.abs(shifted - flat - h * predicted).max())
    slopes = np.diff(np.log(remainders)) / np.diff(np.log(steps))
    assert np.all(np.abs(slopes - 2.0) < 0.1), slopes


# -- the compile cache -------------------------------------------------------------------------

PROBE = textwrap.dedent("""
    import json, sys
    sys.path.insert(0, {tests!r})
    import numpy as np
    from test_kernel_surface3_speedpath import random_pairs
    from dolfinx_mortar.kernels import compiled
    slave, master, nodal, _ = random_pairs(50, seed=1)
    out = compiled.pair_quantities_compiled(slave, master, nodal)
    info = compiled.build_info()
    print(json.dumps({{"compiled": info["compiled"], "seconds": info["seconds"],
                      "valid": int(out["valid"].sum()), "area": float(out["area"].sum())}}))
""")


def probe(cache, count=1, errors=None):
    """Start ``count`` processes at once on the cache directory; their reports (their
    standard errors appended to ``errors``)."""
    import json

    environment = dict(os.environ, DOLFINX_MORTAR_CACHE_DIR=str(cache))
    script = PROBE.format(tests=os.path.dirname(os.path.abspath(__file__)))
    processes = [subprocess.Popen([sys.executable, "-c", script], env=environment,
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
                 for _ in range(count)]
    reports = []
    for process in processes:
        stdout, stderr = process.communicate(timeout=600)
        assert process.returncode == 0, stderr
        reports.append(json.loads(stdout.strip().splitlines()[-1]))
        if errors is not None:
            errors.append(stderr)
    return reports


def test_cache_compiles_once(tmp_path):
    """... and silently: the compiler's warnings would reach a new user's screen."""
    errors = []
    (first,) = probe(tmp_path, errors=errors)
    assert first["compiled"] and first["valid"] > 10
    assert "warning" not in errors[0], errors[0][:2000]
    modules = list(tmp_path.glob("_dolfinx_mortar_surface3_*.so"))
    assert len(modules) == 1
    assert not [p for p in tmp_path.iterdir() if p.is_dir()]  # no build directory left
    (second,) = probe(tmp_path)
    assert not second["compiled"]
    assert second["area"] == first["area"]
    assert modules[0].stat().st_mtime == list(tmp_path.glob("*.so"))[0].stat().st_mtime


def test_concurrent_processes_on_an_empty_cache(tmp_path):
    reports = probe(tmp_path / "cache", count=3)
    assert sum(report["compiled"] for report in reports) == 1
    assert len({report["area"] for report in reports}) == 1
    assert len(list((tmp_path / "cache").glob("*.so"))) == 1


def test_lock_timeout(tmp_path, monkeypatch):
    """A lock held elsewhere: the wait ends with an error naming the lock file."""
    import fcntl

    monkeypatch.setenv("DOLFINX_MORTAR_COMPILE_TIMEOUT", "0.3")
    name = compiled.module_name()
    tmp_path.mkdir(exist_ok=True)
    with open(tmp_path / (name + ".lock"), "a") as held:
        fcntl.flock(held, fcntl.LOCK_EX)
        script = (f"import sys; from dolfinx_mortar.kernels import compiled\n"
                  f"compiled.build(directory={str(tmp_path)!r})")
        result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                                env=dict(os.environ, DOLFINX_MORTAR_COMPILE_TIMEOUT="0.3"),
                                timeout=120)
    assert result.returncode != 0
    assert "lock" in result.stderr and name in result.stderr


def test_a_failed_compile_says_what_it_needs(tmp_path, monkeypatch):
    """Without a working compiler the error names the cache, the cause and what the kernels
    need (a C compiler and cffi, as dolfinx's form compilation); it no longer points at the
    numpy kernels, which are not in the package. No module and no build directory are left
    behind."""
    def broken(*args):
        raise OSError("cc: not found")

    monkeypatch.setattr(compiled, "_compile", broken)
    with pytest.raises(RuntimeError, match=re.escape(str(tmp_path)) + r".*cc: not found"
                       r".*dolfinx's form compilation.*cffi.*C compiler") as raised:
        compiled.build(directory=tmp_path, kernel="line2")
    assert "numpy" not in str(raised.value) and "DOLFINX_MORTAR_KERNELS" not in str(raised.value)
    assert not list(tmp_path.glob("*.so"))
    assert not [p for p in tmp_path.iterdir() if p.is_dir()]


def test_a_pointer_holds_its_array_alive():
    """A temporary array (a gathered chunk of coordinates) given to a kernel call lives as long
    as the pointer made of it: the call never reads freed memory (it did: the element scores
    read a chunk gathered in the argument list)."""
    import weakref

    ffi = compiled.load("surface3").ffi
    array = np.arange(5.0) * 2.0
    alive = weakref.ref(array)
    pointer = compiled._pointer(ffi, array, "double *")
    del array
    assert alive() is not None
    assert [pointer[i] for i in range(5)] == [0.0, 2.0, 4.0, 6.0, 8.0]
    del pointer
    assert alive() is None
    assert compiled._pointer(ffi, None, "double *") == ffi.NULL
    with pytest.raises(ValueError, match="a pointer type"):
        compiled._pointer(ffi, np.zeros(2), "double")
