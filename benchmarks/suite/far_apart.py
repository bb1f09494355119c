"""Bodies that never come near: ContactProblem with one idle pair against a plain SNES."""

from __future__ import annotations

import gc
import os
import statistics
import time

import numpy as np
from mpi4py import MPI

from .common import PHASES, log
from .runner import median_timings, pair_statistics


class PlainNewton:
    """The bulk problem alone in PETSc SNES, with ContactProblem's default options.

    dolfinx_mortar.compat has no NonlinearProblem wrapper, so this is the
    baseline of the far-apart comparison: residual F(u) with lifting and
    Dirichlet rows b = u - g, Jacobian dF/du with identity rows; newtonls,
    basic line search, rtol = atol = 1e-10, MUMPS LU.
    """

    OPTIONS = {"snes_type": "newtonls", "snes_linesearch_type": "basic", "snes_rtol": 1e-10,
               "snes_atol": 1e-10, "snes_stol": 0.0, "snes_max_it": 30, "ksp_type": "preonly",
               "pc_type": "lu", "pc_factor_mat_solver_type": "mumps"}

    def __init__(self, F, u, bcs, prefix: str = "benchmark_plain_"):
        import dolfinx
        import dolfinx.fem.petsc
        import ufl
        from petsc4py import PETSc

        from dolfinx_mortar import compat

        self.u, self.bcs = u, bcs
        self.F = dolfinx.fem.form(F)
        self.J = dolfinx.fem.form(ufl.derivative(F, u, ufl.TrialFunction(u.function_space)))
        self.b = compat.create_vector(self.F)
        self.A = compat.create_matrix(self.J)
        self.x = u.x.petsc_vec.copy()
        self.timings = {"bulk assembly": 0.0}
        snes = PETSc.SNES().create(u.function_space.mesh.comm)
        snes.setOptionsPrefix(prefix)
        options = PETSc.Options()
        for key, value in self.OPTIONS.items():
            options[f"{prefix}{key}"] = value
        snes.setFunction(self._residual, self.b)
        snes.setJacobian(self._jacobian, self.A)
        try:
            snes.setFromOptions()
            snes.getKSP().setFromOptions()
        finally:
            for key in self.OPTIONS:
                options.delValue(f"{prefix}{key}")
        self.snes = snes

    def _residual(self, snes, x, b) -> None:
        import dolfinx.fem.petsc
        from petsc4py import PETSc

        from dolfinx_mortar import compat

        start = time.perf_counter()
        x.copy(self.u.x.petsc_vec)
        self.u.x.scatter_forward()
        with b.localForm() as local:
            local.set(0.0)
        dolfinx.fem.petsc.assemble_vector(b, self.F)
        dolfinx.fem.petsc.apply_lifting(b, [self.J], bcs=[self.bcs], x0=[self.u.x.petsc_vec],
                                        alpha=-1.0)
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        compat.set_bc(b, self.bcs, self.u.x.petsc_vec, -1.0)
        self.timings["bulk assembly"] += time.perf_counter() - start

    def _jacobian(self, snes, x, A, P) -> None:
        import dolfinx.fem.petsc

        start = time.perf_counter()
        A.zeroEntries()
        dolfinx.fem.petsc.assemble_matrix(A, self.J, bcs=self.bcs)
        A.assemble()
        self.timings["bulk assembly"] += time.perf_counter() - start

    def solve(self) -> dict:
        start = time.perf_counter()
        bulk = self.timings["bulk assembly"]
        self.u.x.petsc_vec.copy(self.x)
        self.snes.solve(None, self.x)
        self.x.copy(self.u.x.petsc_vec)
        self.u.x.scatter_forward()
        total = time.perf_counter() - start
        assembly = self.timings["bulk assembly"] - bulk
        return {"converged": self.snes.getConvergedReason() > 0,
                "reason": self.snes.getConvergedReason(),
                "iterations": self.snes.getIterationNumber(),
                "timings": {"bulk assembly": assembly, "contact search": 0.0,
                            "mortar integration": 0.0, "linear solve": total - assembly,
                            "total": total}}

    def destroy(self) -> None:
        for obj in (self.snes, self.A, self.b, self.x):
            obj.destroy()


def far_apart_scene(refinement: int, comm: MPI.Intracomm, lift_radii: float = 2.0,
                    body_force: float = 0.2):
    """Hertz B mesh, the cylinder lifted by 2R (Dirichlet on its top, and its start state).

    Both bodies Neo-Hookean (E = 200, nu = 0.3) under a body force (0, -f):
    the block sags on its support, the cylinder hangs from its top, and the
    bodies stay 2R apart, so contact never matters. Returns the pieces for
    ContactProblem or PlainNewton and a ``load(t)`` setter.
    """
    import dolfinx
    import ufl

    from dolfinx_mortar import ContactPair, Material, internal_work, meshes

    tagged = meshes.hertz(case="B", refinement=refinement, comm=comm)
    mesh, markers = tagged.mesh, tagged.markers
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    u = dolfinx.fem.Function(V, name="displacement")
    v = ufl.TestFunction(V)
    material = Material(200.0, 0.3, "neo-hookean")
    gravity = dolfinx.fem.Constant(mesh, np.array([0.0, 0.0]))
    # the same subdomain data as internal_work's measure (dolfinx allows one per form)
    dx = ufl.Measure("dx", domain=mesh, subdomain_data=tagged.cell_tags)
    F = internal_work(u, v, {markers["cylinder"]: material, markers["block"]: material},
                      tagged.cell_tags) - ufl.inner(gravity, v) * dx
    fdim = mesh.topology.dim - 1
    lift = lift_radii * 8.0

    def dofs(name, sub=None):
        space = V if sub is None else V.sub(sub)
        facets = tagged.facet_tags.find(markers[name])
        return dolfinx.fem.locate_dofs_topological(space, fdim, facets)

    bcs = [dolfinx.fem.dirichletbc(np.zeros(2), dofs("support"), V),
           dolfinx.fem.dirichletbc(np.array([0.0, lift]), dofs("load"), V)]
    for name in ("symmetry_slave", "symmetry_master"):
        bcs.append(dolfinx.fem.dirichletbc(np.float64(0.0), dofs(name, 0), V.sub(0)))
    cylinder = tagged.cell_tags.find(markers["cylinder"])

    def reset() -> None:
        u.x.array[:] = 0.0
        u.interpolate(lambda x: np.vstack([0.0 * x[0], lift + 0.0 * x[0]]), cylinder)
        u.x.scatter_forward()

    def load(t: float) -> None:
        gravity.value[:] = (0.0, -t * body_force)

    pair = ContactPair(tagged.facet_tags, markers["contact_slave"], markers["contact_master"],
                       name="cylinder-block")
    return {"F": F, "u": u, "bcs": bcs, "pair": pair, "reset": reset, "load": load,
            "num_dofs": V.dofmap.index_map.size_global * 2}


def far_apart(refinement: int, repeats: int, steps: int = 2) -> dict:
    """ContactProblem with a pair that never comes near, against PlainNewton; interleaved."""
    from dolfinx_mortar import ContactProblem

    comm = MPI.COMM_WORLD
    scene = far_apart_scene(refinement, comm)
    samples = {"contact": [], "plain": []}
    details: dict = {}

    def run(kind: str) -> dict:
        gc.collect()
        scene["reset"]()
        scene["load"](0.0)
        start = time.perf_counter()
        if kind == "contact":
            solver = ContactProblem(scene["F"], scene["u"], scene["bcs"], [scene["pair"]])
        else:
            solver = PlainNewton(scene["F"], scene["u"], scene["bcs"])
        setup = time.perf_counter() - start
        reports = []
        cpu = time.process_time()
        for step in range(1, steps + 1):
            scene["load"](step / steps)
            if kind == "contact":
                report = solver.solve()
                reports.append({"converged": report.converged, "iterations": report.iterations,
                                "timings": report.timings, "reason": report.reason})
            else:
                reports.append(solver.solve())
        cpu = time.process_time() - cpu
        result = {"setup_s": setup, "solve_cpu_s": cpu,
                  "timings": {k: sum(r["timings"][k] for r in reports) for k in PHASES},
                  "iterations": [r["iterations"] for r in reports],
                  "converged": all(r["converged"] for r in reports),
                  "u": scene["u"].x.array.copy()}
        if kind == "contact":
            result["statistics"] = pair_statistics({"contact_statistics": solver.statistics()})
            result["multiplier_rows"] = solver.interfaces[0].num_global_multipliers
            # each new pair pattern makes ContactProblem build a new monolithic matrix
            result["pattern_versions"] = getattr(solver.interfaces[0], "_pattern_version", None)
        solver.destroy()
        return result

    run("contact")  # warm-up (JIT, first factorizations)
    run("plain")
    for repeat in range(repeats):
        for kind in ("contact", "plain") if repeat % 2 == 0 else ("plain", "contact"):
            result = run(kind)
            samples[kind].append(result)
            log(f"[far-apart {repeat + 1}/{repeats}] r{refinement} {kind}: its "
                f"{result['iterations']}, setup {result['setup_s']:.2f} s, solve "
                f"{result['timings']['total']:.2f} s, load {os.getloadavg()[0]:.2f}")
    for kind, runs in samples.items():
        details[kind] = {
            "setup_s": statistics.median(r["setup_s"] for r in runs),
            "solve_cpu_s": statistics.median(r["solve_cpu_s"] for r in runs),
            "cpu_samples": [r["solve_cpu_s"] for r in runs],
            "timings": median_timings([r["timings"] for r in runs]),
            "solve_samples": [r["timings"]["total"] for r in runs],
            "setup_samples": [r["setup_s"] for r in runs],
            "iterations": runs[0]["iterations"],
            "converged": all(r["converged"] for r in runs),
        }
    contact, plain = samples["contact"][0], samples["plain"][0]
    scale = max(float(np.max(np.abs(plain["u"]))), 1e-300)
    solve_c, solve_p = details["contact"]["timings"]["total"], details["plain"]["timings"]["total"]
    setup_c, setup_p = details["contact"]["setup_s"], details["plain"]["setup_s"]
    return {
        "refinement": refinement,
        "num_dofs": scene["num_dofs"],
        "repeats": repeats,
        "steps": steps,
        "scene": "Hertz B mesh, cylinder lifted by 2R (Dirichlet (0, 2R) on its top and as start "
                 "state), Neo-Hookean, body force (0, -0.2) in 2 steps, no contact load",
        "contact": details["contact"],
        "plain": details["plain"],
        "statistics": contact["statistics"],
        "multiplier_rows": contact["multiplier_rows"],
        "pattern_versions": contact["pattern_versions"],
        "max_displacement_difference_rel": float(np.max(np.abs(contact["u"] - plain["u"])) / scale),
        "overhead_solve": solve_c / solve_p - 1.0,
        "overhead_solve_cpu": details["contact"]["solve_cpu_s"] / details["plain"]["solve_cpu_s"]
        - 1.0,
        "overhead_setup_and_solve": (solve_c + setup_c) / (solve_p + setup_p) - 1.0,
        "overhead_solve_pairwise": [c["timings"]["total"] / p["timings"]["total"] - 1.0
                                    for c, p in zip(samples["contact"], samples["plain"],
                                                    strict=True)],
    }


