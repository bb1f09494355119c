"""The compiled 3D kernel (kernels/compiled.py) against the numpy oracle (tests/oracle, the
package's former numpy kernels, imported from there): time per pair on random
overlapping triangle pairs, peak memory, first-use compile time and a second process's load
time, -O2 against -O3; then per facet combination (triangles, quadrilaterals) and normal field.
With ``--dim 2`` the same for the 2D kernel (random candidate pairs, some overlapping, and
optionally, ``--interface N``, the candidate pairs of ``benchmarks/mortar_scaling.py``'s two
strips at N slave facets, as its interface hands them to the kernel).

    tools/run python3 benchmarks/compiled_kernel.py [--sizes 1000 10000 100000] [--json out.json]
        [--facet-pairs 2000]
    tools/run python3 benchmarks/compiled_kernel.py --dim 2 [--interface 100000]

Times are the median of ``--repeats`` calls in one process (the compiled module loaded
before). numpy is timed twice: as the contact code called it while it was the package's
kernel (``factorized=True``, the gradients of Dn, Mn and the areas kept factorized, expanded
later by their consumers) and with the full gradients the compiled kernel returns
(``factorized=False``, expanded with ``.grad``). Peak memory is tracemalloc's peak over one
call (numpy's allocations are traced; the compiled kernel's work arrays are on the C stack, so
its peak is its output arrays).
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import statistics
import subprocess
import sys
import tempfile
import time
import tracemalloc

import numpy as np

from dolfinx_mortar.kernels import compiled

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "tests"))

from oracle import line2_numpy, surface3_numpy, use_oracle  # noqa: E402


def overlapping_pairs(n: int, seed: int = 0):
    """Slave triangles with a facing master triangle shifted by less than its size (clip
    polygons of 3 to 6 vertices), nodal normals tilted by ~0.1, all rotated at random."""
    rng = np.random.default_rng(seed)
    slave = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]]) + 0.1 * rng.standard_normal((n, 3, 3))
    shift = rng.uniform(-0.3, 0.3, (n, 1, 3))
    shift[..., 2] = 0.05 * rng.standard_normal((n, 1))
    master = (np.array([[0, 0, 0], [0, 1, 0], [1, 0, 0.0]]) * rng.uniform(0.7, 1.3, (n, 1, 1))
              + shift + 0.1 * rng.standard_normal((n, 3, 3)))
    normals = np.array([0, 0, 1.0]) + 0.1 * rng.standard_normal((n, 3, 3))
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    Q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    crosspoint = rng.random((n, 3)) < 0.05
    return slave @ Q.T, master @ Q.T, normals @ Q.T, crosspoint


def overlapping_facets(n: int, ns: int, nm: int, seed: int = 0):
    """Triangles (3) or squares (4), perturbed out of their plane, the master turned over and
    shifted by less than its size, nodal normals tilted by ~0.1, all rotated at random."""
    rng = np.random.default_rng(seed)
    slave_reference = {3: [[0, 0, 0], [1, 0, 0], [0, 1, 0.0]],
                       4: [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.0]]}
    master_reference = {3: [[0, 0, 0], [0, 1, 0], [1, 0, 0.0]],
                        4: [[0, 0, 0], [0, 1, 0], [1, 1, 0], [1, 0, 0.0]]}
    slave = np.array(slave_reference[ns]) + 0.1 * rng.standard_normal((n, ns, 3))
    shift = rng.uniform(-0.3, 0.3, (n, 1, 3))
    shift[..., 2] = 0.05 * rng.standard_normal((n, 1))
    master = (np.array(master_reference[nm]) * rng.uniform(0.7, 1.3, (n, 1, 1)) + shift
              + 0.1 * rng.standard_normal((n, nm, 3)))
    normals = np.array([0, 0, 1.0]) + 0.1 * rng.standard_normal((n, ns, 3))
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    Q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    crosspoint = rng.random((n, ns)) < 0.05
    return slave @ Q.T, master @ Q.T, normals @ Q.T, crosspoint


def numpy_run(slave, master, nodal, options):
    q = surface3_numpy.pair_quantities(slave, master, nodal, factorized=False, **options)
    for item in (q.Dn, q.Mn, q.gap, q.area, q.D_dual, q.M_dual):
        item.grad  # noqa: B018 (the full gradients, as the compiled kernel returns)


def compiled_run(slave, master, nodal, options, pointwise=False):
    compiled.pair_quantities_compiled(slave, master, nodal, pointwise=pointwise, **options)


def facet_comparison(n: int, repeats: int) -> list:
    """us per pair, numpy (full gradients, D and M gradients too) against C, per facet
    combination, normal field and basis (segment-based; element-based with averaged
    normals); C on triangles also on its pointwise path."""
    rows = []
    cases = [(normals, basis, "segment") for normals in ("averaged", "slave", "master")
             for basis in ("standard", "dual")]
    cases += [("averaged", basis, "element") for basis in ("standard", "dual")]
    for ns, nm in ((3, 3), (3, 4), (4, 3), (4, 4)):
        slave, master, nodal, crosspoint = overlapping_facets(n, ns, nm)
        for normals, basis, integration in cases:
            options = dict(normals=normals, basis=basis, crosspoint=crosspoint,
                           scalar_gradients=True, integration=integration)

            arguments = (slave, master, nodal, options)
            numpy_run(*arguments), compiled_run(*arguments)  # warm-up
            row = {"ns": ns, "nm": nm, "normals": normals, "basis": basis,
                   "integration": integration, "pairs": n,
                   "numpy_us": 1e6 * median_time(numpy_run, arguments, repeats) / n,
                   "C_us": 1e6 * median_time(compiled_run, arguments, repeats) / n}
            if (ns, nm, normals, integration) == (3, 3, "averaged", "segment"):
                row["C_pointwise_us"] = 1e6 * median_time(
                    compiled_run, (*arguments, True), repeats) / n
            rows.append(row)
            extra = (f"  (C pointwise {row['C_pointwise_us']:.1f})"
                     if "C_pointwise_us" in row else "")
            print(f"{ns}/{nm} {integration:>7} {normals:>8} {basis:>8}: "
                  f"numpy {row['numpy_us']:8.1f} us/pair, C {row['C_us']:7.1f} us/pair{extra}")
    return rows


def numpy_kernel(factorized: bool):
    def run(slave, master, nodal, crosspoint):
        q = surface3_numpy.pair_quantities(slave, master, nodal, crosspoint=crosspoint,
                                     factorized=factorized)
        if not factorized:
            for item in (q.Dn, q.Mn, q.gap, q.area):
                item.grad  # noqa: B018 (the full gradients, as the compiled kernel returns)
        return q

    return run


def compiled_kernel(slave, master, nodal, crosspoint):
    return compiled.pair_quantities_compiled(slave, master, nodal, crosspoint=crosspoint)


def median_time(function, args, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        function(*args)
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def peak_memory(function, args) -> float:
    tracemalloc.start()
    function(*args)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return peak


def compile_and_load_times(kernel: str = "surface3") -> dict:
    """A fresh cache: the first process compiles, a second loads (each its own interpreter)."""
    script = (f"import json; from dolfinx_mortar.kernels import compiled; "
              f"compiled.load({kernel!r}); print(json.dumps(compiled.build_info({kernel!r})))")
    result = {}
    with tempfile.TemporaryDirectory() as cache:
        environment = dict(os.environ, DOLFINX_MORTAR_CACHE_DIR=cache)
        for key in ("first_process", "second_process"):
            start = time.perf_counter()
            out = subprocess.run([sys.executable, "-c", script], env=environment, check=True,
                                 capture_output=True, text=True).stdout
            info = json.loads(out.strip().splitlines()[-1])
            result[key] = {"compiled": info["compiled"], "build_or_load_seconds": info["seconds"],
                           "process_seconds": time.perf_counter() - start}
    return result


def flag_comparison(args, repeats: int) -> dict:
    """The compiled kernel's time per pair built with other flags (compiled into a temporary
    cache; the default module is put back afterwards)."""
    result = {}
    default = compiled._get()
    with tempfile.TemporaryDirectory() as cache:
        for flags in (("-O2",) + compiled.PORTABLE_ARGS[1:],
                      compiled.PORTABLE_ARGS,
                      compiled.PORTABLE_ARGS + ("-mavx2",),
                      compiled.PORTABLE_ARGS + ("-march=native",)):
            module, info = compiled.build(flags, directory=cache)
            compiled._modules["surface3"] = module
            try:
                seconds = median_time(compiled_kernel, args, repeats)
            finally:
                compiled._modules["surface3"] = default
            result[" ".join(flags)] = {"seconds_per_pair": seconds / args[0].shape[0],
                                       "compile_seconds": info.get("compile_seconds")}
    return result


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[1000, 10000, 100000])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--json", help="write the results here")
    parser.add_argument("--facet-pairs", type=int, default=2000,
                        help="pairs per facet combination (0: skip that comparison)")
    parser.add_argument("--skip-numpy-full", action="store_true",
                        help="do not time numpy with full gradients (memory)")
    parser.add_argument("--dim", type=int, choices=(2, 3), default=3)
    parser.add_argument("--interface", type=int, nargs="*", default=[],
                        help="2D: also the candidate pairs of mortar_scaling's strips at these "
                             "numbers of slave facets")
    options = parser.parse_args(argv)
    if options.dim == 2:
        return main_2d(options)

    report = {"compile": compile_and_load_times(), "sizes": []}
    compiled._get()  # loaded before timing
    print(f"compile (fresh cache, own process): "
          f"{report['compile']['first_process']['build_or_load_seconds']:.2f} s; "
          f"load in a second process: "
          f"{report['compile']['second_process']['build_or_load_seconds'] * 1e3:.1f} ms")
    kernels = {"numpy (factorized)": numpy_kernel(True), "C": compiled_kernel}
    if not options.skip_numpy_full:
        kernels["numpy (full gradients)"] = numpy_kernel(False)
    header = f"{'pairs':>8} {'valid':>8} " + " ".join(
        f"{name + ' us/pair':>28} {'peak MB':>8}" for name in kernels)
    print(header)
    for n in options.sizes:
        args = overlapping_pairs(n)
        row = {"pairs": n, "valid": int(compiled_kernel(*args)["valid"].sum())}
        for name, function in kernels.items():
            function(*args)  # warm-up
            seconds = median_time(function, args, options.repeats)
            row[name] = {"us_per_pair": 1e6 * seconds / n,
                         "peak_MB": peak_memory(function, args) / 1e6}
        report["sizes"].append(row)
        print(f"{n:>8} {row['valid']:>8} " + " ".join(
            f"{row[name]['us_per_pair']:>28.2f} {row[name]['peak_MB']:>8.0f}" for name in kernels))
    args = overlapping_pairs(min(options.sizes[-1], 20000), seed=1)
    report["flags"] = flag_comparison(args, options.repeats)
    for flags, result in report["flags"].items():
        print(f"C built with {flags}: {1e6 * result['seconds_per_pair']:.2f} us/pair "
              f"(compile {result['compile_seconds']:.2f} s)")
    if options.facet_pairs:
        report["facets"] = facet_comparison(options.facet_pairs, options.repeats)
    if options.json:
        with open(options.json, "w") as out:
            json.dump(report, out, indent=2)
    return report


# -- 2D ----------------------------------------------------------------------------------------


def random_line_pairs(n: int, seed: int = 0):
    """Candidate pairs as a search finds them: slave facets a -> b near (0.5, 0) -> (-0.5, 0)
    with bent neighbours (a few absent), masters facing them at random positions along the
    slave line (about a third overlapping it), each pair moved rigidly."""
    rng = np.random.default_rng(seed)
    a = np.array([0.5, 0.0]) + rng.uniform(-0.05, 0.05, (n, 2)) * (1.0, 0.2)
    b = np.array([-0.5, 0.0]) + rng.uniform(-0.05, 0.05, (n, 2)) * (1.0, 0.2)
    bend_p, bend_q = rng.uniform(-0.2, 0.2, (2, n))
    p = a + np.stack([np.cos(bend_p), -np.sin(bend_p)], -1)
    q = b + np.stack([-np.cos(bend_q), -np.sin(bend_q)], -1)
    c = np.stack([rng.uniform(-3.0, 2.0, n), rng.uniform(-0.1, 0.05, n)], -1)
    tilt = rng.uniform(-0.1, 0.1, n)
    d = c + rng.uniform(0.6, 1.4, (n, 1)) * np.stack([np.cos(tilt), np.sin(tilt)], -1)
    angle = rng.uniform(0.0, 2.0 * np.pi, n)
    rotation = np.stack([np.stack([np.cos(angle), -np.sin(angle)], -1),
                         np.stack([np.sin(angle), np.cos(angle)], -1)], 1)
    x = np.einsum("nij,nkj->nki", rotation, np.stack([p, a, b, q, c, d], 1))
    return x + rng.normal(size=(n, 1, 2)), rng.random((n, 2)) < 0.98


def interface_pairs(num_slave: int, repeats: int):
    """The pairs (x (n, 6, 2), has_neighbour) that mortar_scaling's interface hands the 2D kernel
    after a search at ``num_slave`` slave facets, and the times (medians) of that evaluation as
    mortar_scaling measures it (update with a new search, then the assembly) and of the numpy
    kernel's calls within it (the interface runs the numpy oracle here, :func:`oracle.use_oracle`,
    as it ran the numpy kernels when they were the package's)."""
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    import dolfinx
    import mortar_scaling

    from dolfinx_mortar import MortarInterface

    calls, kernel_seconds = [], []
    original = line2_numpy.Line2Kernel.evaluate

    def recording(self, geometry, options, **keywords):
        calls.append(geometry)
        start = time.perf_counter()
        result = original(self, geometry, options, **keywords)
        kernel_seconds.append(time.perf_counter() - start)
        return result

    mesh, tags, upper, lower, width = mortar_scaling.two_strips(num_slave)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    u = mortar_scaling.displacement(V, upper, lower, width)
    times = {"evaluation": [], "numpy_kernel": []}
    line2_numpy.Line2Kernel.evaluate = recording
    try:
        with use_oracle():
            interface = MortarInterface(V, tags, mortar_scaling.SLAVE_TAG,
                                        mortar_scaling.MASTER_TAG)
            interface.update(u)
            z = interface.create_multiplier_vector()
            z.set(1.0)
            mortar_scaling._assemble(interface, z)
            for _ in range(repeats):
                kernel_seconds.clear()
                interface.reuse.invalidate()
                start = time.perf_counter()
                interface.update(u)
                mortar_scaling._assemble(interface, z)
                times["evaluation"].append(time.perf_counter() - start)
                times["numpy_kernel"].append(sum(kernel_seconds))
            z.destroy()
    finally:
        line2_numpy.Line2Kernel.evaluate = original
    geometry = calls[-1]
    x = np.stack([geometry.neighbour_x[:, 0], geometry.slave_x[:, 0], geometry.slave_x[:, 1],
                  geometry.neighbour_x[:, 1], geometry.master_x[:, 0], geometry.master_x[:, 1]], 1)
    interface.destroy()
    return (x, geometry.has_neighbour), {key: statistics.median(values)
                                         for key, values in times.items()}


def numpy_line2(full: bool):
    def run(x, has_neighbour):
        q = line2_numpy.pair_quantities(x, has_neighbour)
        if full:
            for item in (q.Dn, q.Mn, q.gap, q.area):
                item.grad_rows  # noqa: B018 (the full gradients, as the compiled kernel returns)
            q.segment_gradients.outputs(20, 24)
        return q

    return run


def compiled_line2(x, has_neighbour):
    return compiled.line2_pair_quantities_compiled(x, has_neighbour)


def main_2d(options) -> dict:
    report = {"compile": compile_and_load_times("line2"), "sizes": [], "interface": []}
    compiled.load("line2")
    print(f"line2 compile (fresh cache, own process): "
          f"{report['compile']['first_process']['build_or_load_seconds']:.2f} s; "
          f"load in a second process: "
          f"{report['compile']['second_process']['build_or_load_seconds'] * 1e3:.1f} ms")
    kernels = {"numpy (factorized)": numpy_line2(False), "C": compiled_line2}
    if not options.skip_numpy_full:
        kernels["numpy (full gradients)"] = numpy_line2(True)
    print(f"{'pairs':>8} {'integrated':>10} " + " ".join(
        f"{name + ' us/pair':>28} {'peak MB':>8}" for name in kernels))
    cases = [("random", n, random_line_pairs(n)) for n in options.sizes]
    evaluations = {}
    for n in options.interface:
        args, evaluations[n] = interface_pairs(n, options.repeats)
        cases.append(("interface", n, args))
    for kind, size, args in cases:
        n = args[0].shape[0]
        row = {"pairs": n, "integrated": int(compiled_line2(*args)["rows"].size)}
        if kind == "interface":
            row["slave_facets"] = size
        for name, function in kernels.items():
            function(*args)  # warm-up
            seconds = median_time(function, args, options.repeats)
            row[name] = {"seconds": seconds, "us_per_pair": 1e6 * seconds / n,
                         "peak_MB": peak_memory(function, args) / 1e6}
        report["sizes" if kind == "random" else "interface"].append(row)
        label = f"{n:>8}" if kind == "random" else f"{n:>8} (interface, {size} slave facets)"
        print(f"{label} {row['integrated']:>10} " + " ".join(
            f"{row[name]['us_per_pair']:>28.3f} {row[name]['peak_MB']:>8.0f}" for name in kernels))
        if kind == "interface":
            # the evaluation with the C kernel in place of the numpy one, the rest unchanged
            # (its consumers still as today's, which read the factorized gradients)
            measured = evaluations[size]
            row["evaluation"] = dict(measured, estimate_with_C=measured["evaluation"]
                                     - measured["numpy_kernel"] + row["C"]["seconds"])
            print(f"    evaluation (update with a new search + assembly): "
                  f"{measured['evaluation']:.3f} s, of which the numpy kernel "
                  f"{measured['numpy_kernel']:.3f} s; with the C kernel instead: "
                  f"{row['evaluation']['estimate_with_C']:.3f} s (estimate)")
    if options.json:
        with open(options.json, "w") as out:
            json.dump(report, out, indent=2)
    return report


if __name__ == "__main__":
    main()
