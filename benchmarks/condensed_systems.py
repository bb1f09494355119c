"""Dump the condensed systems of a 3D Hertz run, for benchmarks/amg_options_scan.py.

Runs ``demos/hertz_sphere.py --linear-solver iterative`` serially and writes, for
every set-up of the condensed preconditioner (one per Newton iteration), the inner
matrix K_c (zeros dropped) as ``K_<k>.dat`` (PETSc binary), the right-hand sides
of its first two applications as ``b_<k>_<i>.dat``, the rigid-body modes as
``nullspace.npy`` and the inner GMRES iterations of every application per Newton
iteration in ``info.json`` (printed too): the first application of a Newton step
gets the Newton residual, the later ones FGMRES's Krylov directions.

    tools/run python3 benchmarks/condensed_systems.py N0 REF OUTPUT_DIR [DEMO OPTIONS...]

Further arguments go to the demo as they are (e.g. ``--cell hexahedron --steps 1``).
"""

from __future__ import annotations

import json
import pathlib
import sys

import numpy as np
from petsc4py import PETSc

from dolfinx_mortar import condensation

from suite.runner import demo


def save(obj, path: pathlib.Path) -> None:
    viewer = PETSc.Viewer().createBinary(str(path), "w")
    obj.view(viewer)
    viewer.destroy()


def main(n0: int, refinement: int, output: pathlib.Path, demo_options=()) -> dict:
    output.mkdir(parents=True, exist_ok=True)
    condenser_class = condensation.CondensedPreconditioner
    set_up, apply = condenser_class.setUp, condenser_class.apply
    log: list[dict] = []

    def logged_set_up(self, pc):
        set_up(self, pc)
        k = len(log)
        log.append({"applications": []})
        save(self._matrices["K_inner"], output / f"K_{k}.dat")
        if k == 0 and self.near_nullspace:
            np.save(output / "nullspace.npy", np.array(self.near_nullspace))

    def logged_apply(self, pc, x, y):
        apply(self, pc, x, y)
        applications = log[-1]["applications"]
        if len(applications) < 2:
            save(self._vectors["rc"], output / f"b_{len(log) - 1}_{len(applications)}.dat")
        applications.append(self.inner_iterations[-1])

    condenser_class.setUp, condenser_class.apply = logged_set_up, logged_apply
    try:
        summary = demo("hertz_sphere").main(["--elements-per-radius", str(n0), "--refinement",
                                             str(refinement), "--linear-solver", "iterative",
                                             *demo_options])
    finally:
        condenser_class.setUp, condenser_class.apply = set_up, apply
    info = {"dofs": summary["num_dofs"], "newton": summary["newton_iterations"],
            "krylov": summary["krylov_iterations"], "log": log,
            "linear": summary["timings"]["linear solve"]}
    (output / "info.json").write_text(json.dumps(info))
    print(n0, refinement, info["dofs"], info["newton"], info["krylov"])
    for k, entry in enumerate(log):
        print(k, entry["applications"])
    return info


if __name__ == "__main__":
    main(int(sys.argv[1]), int(sys.argv[2]), pathlib.Path(sys.argv[3]), sys.argv[4:])
