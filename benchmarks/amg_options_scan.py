"""The inner solve of dumped condensed systems under BoomerAMG / GAMG option sets.

For each K_<k> of a directory written by benchmarks/condensed_systems.py (with its
near-nullspace) and each option set: GMRES rtol 1e-3 (as the inner solver) on the
stored right-hand sides; prints the iterations per right-hand side, the set-up's
and one iteration's process CPU time (CPU, not wall: the machine is shared).

    tools/run python3 benchmarks/amg_options_scan.py DIR K1,K2 [SET,SET...]
"""

from __future__ import annotations

import json
import pathlib
import sys
import time

import numpy as np
from petsc4py import PETSc

BASE = {"ksp_type": "gmres", "ksp_rtol": 1e-3, "ksp_max_it": 300, "ksp_gmres_restart": 100}
BOOMERAMG = "pc_hypre_boomeramg_"
HMIS = {"pc_type": "hypre", "pc_hypre_type": "boomeramg", BOOMERAMG + "coarsen_type": "HMIS",
        BOOMERAMG + "interp_type": "ext+i", BOOMERAMG + "P_max": 4}
NODAL4 = {**HMIS, BOOMERAMG + "nodal_coarsen": 4}
GAMG_SOR = {"pc_type": "gamg", "pc_gamg_threshold": 0.01, "mg_levels_ksp_type": "richardson",
            "mg_levels_pc_type": "sor"}
SETS = {
    "hmis": HMIS,
    "hmis_st0.5": {**HMIS, BOOMERAMG + "strong_threshold": 0.5},
    "hmis_st0.7": {**HMIS, BOOMERAMG + "strong_threshold": 0.7},
    "hmis_nodal4": NODAL4,
    "hmis_nodal4_vi1": {**NODAL4, BOOMERAMG + "vec_interp_variant": 1},
    "hmis_nodal4_vi2": {**NODAL4, BOOMERAMG + "vec_interp_variant": 2},
    "hmis_nodal4_vi2_q4": {**NODAL4, BOOMERAMG + "vec_interp_variant": 2,
                           BOOMERAMG + "vec_interp_qmax": 4},
    "hmis_nodal4_vi2_p2": {**NODAL4, BOOMERAMG + "vec_interp_variant": 2, BOOMERAMG + "P_max": 2},
    "hmis_nodal4_vi2_agg1": {**NODAL4, BOOMERAMG + "vec_interp_variant": 2,
                             BOOMERAMG + "agg_nl": 1},
    "hmis_nodal6_vi2": {**HMIS, BOOMERAMG + "nodal_coarsen": 6,
                        BOOMERAMG + "vec_interp_variant": 2},
    "hmis_nodal1_vi3": {**HMIS, BOOMERAMG + "nodal_coarsen": 1,
                        BOOMERAMG + "vec_interp_variant": 3},
    "hmis_st0.5_l1gs": {**HMIS, BOOMERAMG + "strong_threshold": 0.5,
                        BOOMERAMG + "relax_type_all": "l1scaled-SOR/Jacobi"},
    "hmis_st0.5_agg1": {**HMIS, BOOMERAMG + "strong_threshold": 0.5, BOOMERAMG + "agg_nl": 1},
    "hmis_st0.7_agg1": {**HMIS, BOOMERAMG + "strong_threshold": 0.7, BOOMERAMG + "agg_nl": 1},
    "hmis_st0.5_nodal4": {**NODAL4, BOOMERAMG + "strong_threshold": 0.5},
    "gamg_sor": GAMG_SOR,
    "gamg_sor_t0.05": {**GAMG_SOR, "pc_gamg_threshold": 0.05},
}


def load(path: pathlib.Path) -> PETSc.Viewer:
    return PETSc.Viewer().createBinary(str(path), "r")


def run(directory: pathlib.Path, names: list[str], steps: list[int]) -> list[dict]:
    info_path = directory / "info.json"
    dofs = json.loads(info_path.read_text())["dofs"] if info_path.exists() else 0
    modes_path = directory / "nullspace.npy"
    modes = np.load(modes_path) if modes_path.exists() else None
    rows = []
    for k in steps:
        K = PETSc.Mat().load(load(directory / f"K_{k}.dat"))
        K.setBlockSize(3)
        if modes is not None:
            vectors = []
            for values in modes:
                vector = K.createVecRight()
                vector.getArray()[:] = values
                vectors.append(vector)
            K.setNearNullSpace(PETSc.NullSpace().create(vectors=vectors))
        right_hand_sides = [PETSc.Vec().load(load(p))
                            for p in sorted(directory.glob(f"b_{k}_*.dat"))]
        for name in names:
            options = PETSc.Options()
            prefix = f"scan_{name.replace('.', '_')}_"
            for key, value in {**BASE, **SETS[name]}.items():
                options[prefix + key] = value
            ksp = PETSc.KSP().create()
            ksp.setOptionsPrefix(prefix)
            ksp.setOperators(K)
            ksp.setFromOptions()
            start = time.process_time()
            ksp.setUp()
            set_up = time.process_time() - start
            iterations, solve = [], 0.0
            for b in right_hand_sides:
                x = K.createVecRight()
                start = time.process_time()
                ksp.solve(b, x)
                solve += time.process_time() - start
                iterations.append(ksp.getIterationNumber())
            per_iteration_ms = solve / max(sum(iterations), 1) * 1e3
            rows.append({"dofs": dofs, "k": k, "options": name, "iterations": iterations,
                         "set_up_s": set_up, "ms_per_iteration": per_iteration_ms})
            print(f"{dofs:>8} K{k:<2} {name:<24} its {iterations} set-up {set_up:.2f} s "
                  f"{per_iteration_ms:.1f} ms/it", flush=True)
            ksp.destroy()
    return rows


if __name__ == "__main__":
    run(pathlib.Path(sys.argv[1]), sys.argv[3].split(",") if len(sys.argv) > 3 else list(SETS),
        [int(s) for s in sys.argv[2].split(",")])
