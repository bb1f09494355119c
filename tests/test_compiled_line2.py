"""The compiled 2D kernel (kernels/line2.c through kernels/compiled.py) against the numpy oracle
(tests/oracle/line2_numpy.py, pair_quantities): values and every gradient to 1e-13 of each
output's largest entry, for every normal, integration and basis option, on random and degenerate
configurations (disjoint, touching at a point, parallel facets, facets not facing, slaves
without neighbours, crosspoints); a Taylor test of its gradients; and the compile cache of the
2D module (compiled once per cache, loaded by a second process)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from dolfinx_mortar.kernels import compiled

from oracle import line2_numpy

TOLERANCE = 1e-13
VALUES = ("D", "M", "Dn", "Mn", "gap", "area")
GRADIENTS = ("Dn", "Mn", "gap", "area", "D")
NORMALS = ("averaged", "slave", "master")


def rigid_motion(x: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Each pair (n, 6, 2) turned by a random angle and shifted by a random vector."""
    angle = rng.uniform(0.0, 2.0 * np.pi, x.shape[0])
    rotation = np.stack([np.stack([np.cos(angle), -np.sin(angle)], -1),
                         np.stack([np.sin(angle), np.cos(angle)], -1)], 1)
    return np.einsum("nij,nkj->nki", rotation, x) + rng.normal(size=(x.shape[0], 1, 2))


def random_pairs(n: int, seed: int, bend: float = 0.3):
    """Slave facets a -> b near (0.5, 0) -> (-0.5, 0) (outward normal +y), neighbours p, q bent
    by up to ``bend``, masters c -> d below them facing up, tilted, of random length and
    position (full, partial and no overlap), each pair moved rigidly; a random third of the
    neighbours absent, crosspoints at random."""
    rng = np.random.default_rng(seed)
    a = np.array([0.5, 0.0]) + rng.uniform(-0.05, 0.05, (n, 2)) * (1.0, 0.2)
    b = np.array([-0.5, 0.0]) + rng.uniform(-0.05, 0.05, (n, 2)) * (1.0, 0.2)
    bend_p, bend_q = rng.uniform(-bend, bend, (2, n))
    length_p, length_q = rng.uniform(0.3, 1.5, (2, n))
    p = a + length_p[:, None] * np.stack([np.cos(bend_p), -np.sin(bend_p)], -1)
    q = b + length_q[:, None] * np.stack([-np.cos(bend_q), -np.sin(bend_q)], -1)
    c = np.stack([rng.uniform(-1.5, 0.8, n), rng.uniform(-0.1, 0.05, n)], -1)
    tilt = rng.uniform(-0.4, 0.4, n)
    d = c + rng.uniform(0.2, 2.0, (n, 1)) * np.stack([np.cos(tilt), np.sin(tilt)], -1)
    x = rigid_motion(np.stack([p, a, b, q, c, d], axis=1), rng)
    has_neighbour = rng.random((n, 2)) < 0.7
    crosspoint = rng.random((n, 2)) < 0.2
    return x, has_neighbour, crosspoint


def reference(x, has_neighbour, **options):
    q = line2_numpy.pair_quantities(x, has_neighbour, **options)
    values = {"D": q.D, "M": q.M, "Dn": q.Dn.value, "Mn": q.Mn.value, "gap": q.gap.value,
              "area": q.area.value, "valid": q.valid, "overlap": q.overlap, "rows": q.rows}
    r = q.rows.size
    grads = {"Dn": q.Dn.grad_rows, "Mn": q.Mn.grad_rows, "gap": q.gap.grad_rows,
             "area": q.area.grad_rows,
             "D": q.segment_gradients.outputs(20, 24).reshape(r, 2, 2, 12)}
    return values, grads


def assert_agree(x, has_neighbour, **options) -> int:
    """The compiled kernel equals the numpy kernel; returns the number of valid pairs."""
    options.setdefault("num_gauss_points", line2_numpy.DEFAULT_GAUSS_POINTS[
        options.get("integration", "segment")])
    values, grads = reference(x, has_neighbour, **options)
    got = compiled.line2_pair_quantities_compiled(x, has_neighbour, **options)
    np.testing.assert_array_equal(got["valid"], values["valid"])
    np.testing.assert_array_equal(got["rows"], values["rows"])
    np.testing.assert_allclose(got["overlap"], values["overlap"], rtol=0, atol=TOLERANCE * 2.0)
    for name in VALUES:
        scale = np.abs(values[name]).max(initial=0.0)
        error = np.abs(got[name] - values[name]).max(initial=0.0)
        assert error <= TOLERANCE * scale or error == 0.0, (name, error, scale)
    for name in GRADIENTS:
        scale = np.abs(grads[name]).max(initial=0.0)
        error = np.abs(got[name + "_grad"] - grads[name]).max(initial=0.0)
        assert error <= TOLERANCE * scale or error == 0.0, (name + "_grad", error, scale)
    return int(values["valid"].sum())


@pytest.mark.parametrize("normals", NORMALS)
@pytest.mark.parametrize("integration", ["segment", "element"])
@pytest.mark.parametrize("basis", ["standard", "dual"])
@pytest.mark.parametrize("crosspoints", [False, True])
def test_random_pairs(normals, integration, basis, crosspoints):
    """Full, partial and no overlaps, bent neighbours, some absent."""
    x, has_neighbour, crosspoint = random_pairs(800, seed=31)
    valid = assert_agree(x, has_neighbour, normals=normals, integration=integration,
                         basis=basis, crosspoint=crosspoint if crosspoints else None)
    assert 200 < valid < 800


@pytest.mark.parametrize("normals", NORMALS)
@pytest.mark.parametrize("integration", ["segment", "element"])
def test_runs_of_pairs_of_one_slave_facet(normals, integration):
    """Pairs in runs that share a slave facet, as a search returns them (sorted by slave
    facet): the kernel keeps a run's slave normals from one pair to the next, and takes them
    anew where the facet, a neighbour or a neighbour's presence changes within a run."""
    x, has_neighbour, crosspoint = random_pairs(20, seed=34)
    run = 6
    slave = np.repeat(x[:, :4], run, axis=0)
    tangent = (x[:, 2] - x[:, 1])[:, None, :]
    shift = np.tile(np.arange(run) - 2.5, x.shape[0])[:, None, None] * 0.3
    master = np.repeat(x[:, 4:], run, axis=0) + shift * np.repeat(tangent, run, axis=0)
    pairs = np.concatenate([slave, master], axis=1)
    has = np.repeat(has_neighbour, run, axis=0)
    has[3::run, 0] = ~has[3::run, 0]
    pairs[4::run, 3] += 1e-3
    valid = assert_agree(pairs, has, normals=normals, integration=integration,
                         crosspoint=np.repeat(crosspoint, run, axis=0))
    assert valid > 2 * x.shape[0]


@pytest.mark.parametrize("num_gauss_points", [1, 2, 5])
@pytest.mark.parametrize("integration", ["segment", "element"])
def test_other_gauss_rules(integration, num_gauss_points):
    x, has_neighbour, crosspoint = random_pairs(300, seed=32)
    assert assert_agree(x, has_neighbour, integration=integration, basis="dual",
                        num_gauss_points=num_gauss_points, crosspoint=crosspoint) > 50


def test_element_based_points_shared_by_master_facets():
    """Slave facets with several candidate master facets (a master line cut into pieces): each
    Gauss point goes to one master facet, as the numpy kernel decides it."""
    rng = np.random.default_rng(33)
    pairs, facets = [], []
    for facet in range(40):
        a, b = np.array([0.5, 0.0]), np.array([-0.5, 0.0])
        p, q = a + [1.0, -0.1], b + [-1.0, -0.05]
        cuts = np.sort(rng.uniform(-1.2, 1.2, 5))
        cuts[2] = 0.0  # a master node under the slave's middle Gauss point
        for c, d in zip(cuts[:-1], cuts[1:], strict=True):
            pairs.append([p, a, b, q, [c, -0.01], [d, -0.01]])
            facets.append(facet)
    x = rigid_motion(np.array(pairs, float), rng)
    has_neighbour = np.ones((x.shape[0], 2), dtype=bool)
    for points in (3, 4):
        assert assert_agree(x, has_neighbour, integration="element", num_gauss_points=points,
                            slave_facet=np.array(facets)) > 40


def single(p, a, b, q, c, d):
    return np.array([[p, a, b, q, c, d]], float)


def degenerate_pairs():
    """(name, x (n, 6, 2)): disjoint, touching at a point, parallel facets coincident or apart,
    the master perpendicular to the slave, the master inside the slave, the slave inside the
    master, each also turned and shifted (rounding at the decisions)."""
    p, a, b, q = [1.5, 0.0], [0.5, 0.0], [-0.5, 0.0], [-1.5, 0.0]
    cases = {
        "disjoint": single(p, a, b, q, [0.7, -0.1], [1.6, -0.1]),
        "touching at a": single(p, a, b, q, [0.5, -0.1], [1.6, -0.1]),
        "touching at b": single(p, a, b, q, [-1.6, -0.1], [-0.5, -0.1]),
        "parallel, coincident": single(p, a, b, q, [-0.5, 0.0], [0.5, 0.0]),
        "parallel, apart": single(p, a, b, q, [-0.3, -0.2], [0.9, -0.2]),
        "parallel, in contact from above": single(p, a, b, q, [-0.3, 0.1], [0.9, 0.1]),
        "perpendicular": single(p, a, b, q, [0.0, -0.1], [0.0, -1.1]),
        "master inside": single(p, a, b, q, [-0.2, -0.1], [0.3, -0.05]),
        "slave inside": single(p, a, b, q, [-3.0, -0.1], [3.0, -0.1]),
        "tiny overlap": single(p, a, b, q, [0.5 - 1e-12, -0.1], [1.6, -0.1]),
    }
    rng = np.random.default_rng(34)
    result = []
    for name, x in cases.items():
        result.append((name, x))
        result.append((name + ", moved", rigid_motion(np.repeat(x, 20, axis=0), rng)))
    return result


@pytest.mark.parametrize("normals", NORMALS)
@pytest.mark.parametrize("integration", ["segment", "element"])
@pytest.mark.parametrize("neighbours", ["both", "none", "one"])
def test_degenerate_configurations(normals, integration, neighbours):
    for name, x in degenerate_pairs():
        n = x.shape[0]
        has_neighbour = np.zeros((n, 2), dtype=bool)
        if neighbours == "both":
            has_neighbour[:] = True
        elif neighbours == "one":
            has_neighbour[:, 0] = True
        for basis in ("standard", "dual"):
            try:
                assert_agree(x, has_neighbour, normals=normals, integration=integration,
                             basis=basis)
            except AssertionError as error:
                raise AssertionError(f"{name}: {error}") from error


def test_degenerate_decisions():
    """What the degenerate cases decide (the same in both kernels, checked above)."""
    decided = {}
    for name, x in degenerate_pairs():
        got = compiled.line2_pair_quantities_compiled(x, np.ones((x.shape[0], 2), bool))
        decided[name] = bool(got["valid"][0])
    assert not decided["disjoint"] and not decided["perpendicular"]
    assert not decided["touching at a"] and not decided["touching at b"]
    assert decided["parallel, coincident"] and decided["master inside"]
    assert decided["slave inside"] and decided["tiny overlap"]


def test_not_facing():
    """The master turned over (c and d swapped) faces the same way as the slave."""
    x, has_neighbour, _ = random_pairs(300, seed=35)
    turned = x[:, [0, 1, 2, 3, 5, 4]]
    for integration in ("segment", "element"):
        got = compiled.line2_pair_quantities_compiled(turned, has_neighbour,
                                                      integration=integration)
        assert not got["valid"].any() and got["rows"].size == 0
        assert not np.abs(got["gap"]).any() and not np.abs(got["D"]).any()
        assert assert_agree(turned, has_neighbour, integration=integration) == 0


def master_along_the_normal(n: int, seed: int):
    """Slave facets with one neighbour bent by 0.5 to 1.5 rad, and masters along the averaged
    normal field's direction at a 3-point Gauss point (xi = 0 or +-sqrt(3/5), the points of a
    segment that covers the whole slave facet), computed as the kernels compute it."""
    rng = np.random.default_rng(seed)
    bend = rng.uniform(0.5, 1.5, n)
    a, b = np.array([0.5, 0.0]), np.array([-0.5, 0.0])
    p = a + np.stack([np.cos(bend), -np.sin(bend)], -1)
    q = b + np.stack([-np.ones(n), rng.uniform(-0.1, 0.1, n)], -1)
    x = np.zeros((n, 6, 2))
    x[:, 0], x[:, 1], x[:, 2], x[:, 3] = p, a, b, q
    X = np.ascontiguousarray(x.reshape(n, 12).T)
    normal_a, normal_b, _, _ = line2_numpy._normal_field(X, np.ones((n, 2), bool), "averaged",
                                                         False)
    xi = rng.choice(line2_numpy.gauss_legendre(3)[0], n)
    N0, N1 = (1.0 - xi) * 0.5, (xi + 1.0) * 0.5
    normal = np.stack([N0 * normal_a[0] + N1 * normal_b[0],
                       N0 * normal_a[1] + N1 * normal_b[1]], -1)
    x[:, 4] = np.stack([rng.uniform(-3, 3, n), rng.uniform(-3, 0.5, n)], -1)
    x[:, 5] = x[:, 4] + (rng.choice([-1.0, 1.0], n) * rng.uniform(0.5, 5.0, n))[:, None] * normal
    return x


def test_master_parallel_to_the_normal_at_a_gauss_point():
    """Segment-based, such a pair is integrated and then dropped (not valid, zero outputs), as
    in the numpy kernel; element-based it is screened out."""
    x = master_along_the_normal(400, seed=39)
    has_neighbour = np.ones((x.shape[0], 2), dtype=bool)
    values, _ = reference(x, has_neighbour, num_gauss_points=3)
    dropped = ~values["valid"][values["rows"]]
    assert dropped.sum() > 10
    got = compiled.line2_pair_quantities_compiled(x, has_neighbour)
    assert not np.abs(got["Dn_grad"][dropped]).any() and not np.abs(got["Mn"][values["rows"][
        dropped]]).any()
    for integration in ("segment", "element"):
        for basis in ("standard", "dual"):
            assert_agree(x, has_neighbour, integration=integration, basis=basis)


def test_strongly_bent_normals():
    """Neighbours bent by up to 1.2 rad: averaged normals far from the facet's, projections
    near their limits, points where the master is nearly parallel to the normal."""
    x, has_neighbour, crosspoint = random_pairs(2000, seed=36, bend=1.2)
    for integration in ("segment", "element"):
        for basis in ("standard", "dual"):
            assert assert_agree(x, has_neighbour, integration=integration, basis=basis,
                                crosspoint=crosspoint) > 300


def test_empty_batch():
    got = compiled.line2_pair_quantities_compiled(np.zeros((0, 6, 2)), np.zeros((0, 2), bool))
    assert got["D"].shape == (0, 2, 2) and got["Dn_grad"].shape == (0, 2, 2, 2, 12)


@pytest.mark.parametrize("normals", NORMALS)
@pytest.mark.parametrize("integration", ["segment", "element"])
@pytest.mark.parametrize("basis", ["standard", "dual"])
def test_taylor(normals, integration, basis):
    """f(x + h v) - f(x) - h f'(x) v = O(h^2) for the compiled gradients (D, M, Dn, Mn, gap,
    area), pairs well inside their overlaps (element-based: pairs whose Gauss points stay on
    or off the master within the steps)."""
    x, has_neighbour, crosspoint = random_pairs(60, seed=37)
    direction = np.random.default_rng(38).uniform(-1, 1, x.shape)
    keep = compiled.line2_pair_quantities_compiled(x, has_neighbour, normals=normals)[
        "overlap"] > 0.3
    if integration == "element":
        overlaps = [compiled.line2_pair_quantities_compiled(
            x + h * direction, has_neighbour, normals=normals, integration="element")["overlap"]
            for h in (0.0, -2e-3, 2e-3)]
        keep &= (overlaps[0] > 0.0) & (overlaps[1] == overlaps[0]) & (overlaps[2] == overlaps[0])
    x, has_neighbour, crosspoint = x[keep], has_neighbour[keep], crosspoint[keep]
    direction = direction[keep]
    n = x.shape[0]
    assert n >= 5
    names = ("D", "M", "Dn", "Mn", "gap", "area")

    def evaluate(values):
        return compiled.line2_pair_quantities_compiled(
            values, has_neighbour, normals=normals, integration=integration, basis=basis,
            crosspoint=crosspoint, scalar_gradients=True)

    base = evaluate(x)
    assert base["rows"].size == n
    flat = np.concatenate([base[name].reshape(n, -1) for name in names], axis=1)
    gradient = np.concatenate([base[name + "_grad"].reshape(n, -1, 12) for name in names],
                              axis=1)
    predicted = np.einsum("nov,nv->no", gradient, direction.reshape(n, 12))
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


# -- the compile cache of the 2D module ---------------------------------------------------------

PROBE = textwrap.dedent("""
    import json, sys
    sys.path.insert(0, {tests!r})
    from test_compiled_line2 import random_pairs
    from dolfinx_mortar.kernels import compiled
    x, has_neighbour, _ = random_pairs(50, seed=1)
    out = compiled.line2_pair_quantities_compiled(x, has_neighbour)
    info = compiled.build_info("line2")
    print(json.dumps({{"compiled": info["compiled"], "seconds": info["seconds"],
                      "surface3_loaded": bool(compiled.build_info("surface3")),
                      "valid": int(out["valid"].sum()), "area": float(out["area"].sum())}}))
""")


def probe(cache, count=1):
    """Start ``count`` processes at once on the cache directory; their reports."""
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
    return reports


def test_cache_compiles_once(tmp_path):
    """A fresh cache: the first process compiles the 2D module alone (not the 3D one), a
    second loads it."""
    (first,) = probe(tmp_path)
    assert first["compiled"] and first["valid"] > 10 and not first["surface3_loaded"]
    modules = list(tmp_path.glob("_dolfinx_mortar_line2_*.so"))
    assert len(modules) == 1
    assert not list(tmp_path.glob("_dolfinx_mortar_surface3_*"))
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


def test_modules_have_their_own_names_and_locks():
    names = {kernel: compiled.module_name(kernel=kernel) for kernel in compiled.KERNELS}
    assert names["line2"].startswith("_dolfinx_mortar_line2_")
    assert names["surface3"].startswith("_dolfinx_mortar_surface3_")
    with pytest.raises(ValueError, match="unknown compiled kernel"):
        compiled.module_name(kernel="quad4")


def test_gather_reads_the_node_table_as_numpy_indexing_does():
    rng = np.random.default_rng(35)
    node_x = rng.normal(size=(50, 2))
    nodes = rng.integers(0, 50, (200, 6))
    slave, master, neighbour = compiled.line2_gather(nodes, node_x)
    assert np.array_equal(slave, node_x[nodes[:, 1:3]])
    assert np.array_equal(master, node_x[nodes[:, 4:6]])
    assert np.array_equal(neighbour, node_x[nodes[:, [0, 3]]])
    for bad in (-1, 50):
        nodes[17, 2] = bad
        with pytest.raises(IndexError):
            compiled.line2_gather(nodes, node_x)
