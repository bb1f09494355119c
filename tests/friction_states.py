"""A frictional problem put into a chosen state for its Taylor tests (test_friction,
test_friction3d, test_self_contact): every active node slipping, or every one sticking."""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from dolfinx_mortar import Coulomb


def put_active_nodes_in(problem, state: str, method: str = "lagrange") -> None:
    """Set pair 0's Coulomb mu so that every active node is in ``state`` ("slipping" or
    "sticking") with a margin of 2 from the kink: |v_j| against the bound mu (z_j - c_n
    g^_j) (penalty: mu z_j), v_j = y_j + c_t s_j (penalty: c_t s_j) without the components
    held by a prescribed displacement, as the law leaves them out (module docstring of
    dolfinx_mortar.friction; e.g. a slit's bottom nodes in 3D, whose tau^1 lies along a
    held u_y); checks it. Collective."""
    comm = problem.comm
    problem.equations.residual(problem.snes, problem.x, problem.b)
    active = problem.active[0]
    z = problem.multipliers[0].getArray(readonly=True)[active]
    if method == "lagrange":
        z = z - problem.c_n * problem.gaps[0][active] / problem.areas[0][active]
    now = problem.friction_state()
    m = problem.friction.components  # (a rank may have no active node: no -1 in reshape)
    held = problem.friction.held[0]
    free = 1.0 if held is None else ~held[active]
    y = now["traction"][active].reshape(z.size, m) if method == "lagrange" else 0.0
    v = np.linalg.norm((y + problem.c_t * now["slip"][active].reshape(z.size, m)) * free,
                       axis=1)
    if state == "slipping":
        mu = 0.5 * comm.allreduce(float(np.min(v, initial=np.inf)), op=MPI.MIN) / \
            comm.allreduce(float(np.max(z, initial=0.0)), op=MPI.MAX)
    else:
        mu = 2.0 * comm.allreduce(float(np.max(v, initial=0.0)), op=MPI.MAX) / \
            comm.allreduce(float(np.min(z, initial=np.inf)), op=MPI.MIN)
    problem.friction.laws[0] = Coulomb(mu)
    problem.equations.residual(problem.snes, problem.x, problem.b)
    counts = comm.allreduce(np.array([int(active.sum()),
                                      int(problem.friction_state()[state][active].sum())]),
                            op=MPI.SUM)
    assert counts[0] > 0 and counts[1] == counts[0]
