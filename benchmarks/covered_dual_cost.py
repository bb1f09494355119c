"""Cost of the dual basis over the covered part against the whole-facet dual basis.

The bodies of ``mortar_scaling.py`` (2D strips, 3D slabs; slid, so the master
ends inside slave facets), ``basis="dual"``. Per repeat, interleaved: an
``update`` that reuses the search (nodes moved) and the assembly of D, M, the gap,
the gap Jacobian, B and the force Jacobian (patterns reused), once with the
covered dual basis (the default) and once with the whole-facet one of the kernels
(``covered.CoveredStencil`` replaced by the plain stencil). Medians in seconds.

    tools/run python3 benchmarks/covered_dual_cost.py --dim 2 --size 10000 --repeats 5
    tools/run python3 benchmarks/covered_dual_cost.py --dim 3 --size 40 --repeats 5
"""

from __future__ import annotations

import argparse
import gc
import statistics
import time

import dolfinx
import numpy as np
from mortar_scaling import (
    MASTER_TAG,
    SLAVE_TAG,
    _assemble,
    displacement,
    displacement3d,
    two_slabs,
    two_strips,
)

from dolfinx_mortar import MortarInterface, covered

_CASE = ["covered"]
_WRAPPER = covered.CoveredStencil
covered.CoveredStencil = (
    lambda stencil, **options: stencil if _CASE[0] == "whole facet"
    else _WRAPPER(stencil, **options))


def build(dim: int, size: int, whole_facet: bool):
    if dim == 3:
        mesh, tags, upper, lower, width = two_slabs(size)
        V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (3,)))
        u = displacement3d(V, upper, lower, width)
    else:
        mesh, tags, upper, lower, width = two_strips(size)
        V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
        u = displacement(V, upper, lower, width)
    _CASE[0] = "whole facet" if whole_facet else "covered"
    interface = MortarInterface(V, tags, SLAVE_TAG, MASTER_TAG, basis="dual")
    interface.update(u)
    z = interface.create_multiplier_vector()
    z.set(1.0)
    _assemble(interface, z)
    states = [u.x.array.copy(), u.x.array + 1e-2 * width * np.sin(np.arange(u.x.array.size))]
    return interface, u, z, states


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dim", type=int, default=2)
    parser.add_argument("--size", type=int, default=10000)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)
    cases = {name: build(args.dim, args.size, name == "whole facet")
             for name in ("whole facet", "covered")}
    samples = {name: {"update": [], "assembly": []} for name in cases}
    for repeat in range(args.repeats):
        for name, (interface, u, z, states) in cases.items():
            _CASE[0] = name
            gc.collect()
            u.x.array[:] = states[(repeat + 1) % 2]
            start = time.perf_counter()
            interface.update(u)
            samples[name]["update"].append(time.perf_counter() - start)
            start = time.perf_counter()
            _assemble(interface, z)
            samples[name]["assembly"].append(time.perf_counter() - start)
    for name, (interface, *_rest) in cases.items():
        stencil = interface.stencil
        print(f"{name:12s} dim {args.dim} slave facets {interface.slave.num_facets} "
              f"pairs {stencil.num_pairs} stencil width {stencil.width}: "
              + ", ".join(f"{phase} {statistics.median(v):.3f} s"
                          for phase, v in samples[name].items()))


if __name__ == "__main__":
    main()
