"""Friction patch test: two non-matching blocks pressed and sheared, with an exact uniform answer.

The unit square cut at y = 0.5 into two separately meshed blocks
(dolfinx_mortar.meshes.tied_blocks, ``--ratio`` elements along the interface),
plane strain, E = 1000, nu = 0.3, linear elasticity, Coulomb friction mu =
``--mu`` on the interface. Pressure p = 10 on the top; the bottom held and the
top moved along x, both with the Poisson expansion eps_xx x of the uniform
state; on the sides a vertical shear traction tau. With ``--shear-ratio`` R:

* R < 1: tau = R mu p and the top moved by tau H / G (H = 1): the blocks stick
  and the state is uniform, sigma_xy = tau: tangential multipliers y_j = tau,
  pressure z_j = p, slip 0;
* R >= 1: tau = mu p and the top moved by R mu p H / G: the interface slips by
  (R - 1) mu p H / G with y_j = mu p at every node.

Segment-based mortar integration reproduces both to rounding on non-matching
meshes and for either slave side (``--slave upper|lower``).

``--dim 3``: the 3D patch test's blocks (tetrahedra or hexahedra, ``--ratio``
elements per side across the interface), sheared along x with the faces
y = 0, 1 free: the same uniform answers with sigma_xz = tau; the tangential
traction and slip are compared as vectors (two tangential multipliers per
node in the node's tangent frame).

Outputs (``--output DIR``): paraview/*.bp (displacement, pressure, tangential
traction, stick/slip status); ``--json FILE`` writes the summary with the keys
``max_pressure_deviation_rel``, ``max_traction_deviation_rel``
(|y_j - exact| / (mu p)), ``max_slip_deviation_rel`` (|s_j - exact| / (mu p H /
G)), ``num_sticking``, ``num_slipping``, ``newton_iterations``.

Run:  mpirun -n 3 python3 demos/friction_patch.py --ratio 3:7 --slave lower --shear-ratio 2
"""

from __future__ import annotations

import pathlib
import sys

import dolfinx
import numpy as np
import ufl
from mpi4py import MPI

from dolfinx_mortar import (
    ContactOutput,
    ContactPair,
    ContactProblem,
    Material,
    internal_work,
    meshes,
)

DEMOS = pathlib.Path(__file__).resolve().parent
if str(DEMOS) not in sys.path:  # loaded from its path (tests, benchmarks): find demos/cli.py
    sys.path.insert(0, str(DEMOS))
import cli  # noqa: E402
from cli import write_summary  # noqa: E402

E, NU, PRESSURE = 1000.0, 0.3, 10.0
SHEAR_MODULUS = E / (2.0 * (1.0 + NU))


def _sheared_form(u, v, vertical: int, side_shear: float) -> tuple[list, ufl.Form]:
    """The facets of the faces x = 0, x = 1 and of the bottom and top (coordinate
    ``vertical`` = 0 and 1), and the weak form: linear elasticity, PRESSURE on the top,
    the shear traction along ``vertical`` on the faces x = 0 (down) and x = 1 (up)."""
    mesh = u.function_space.mesh
    fdim = mesh.topology.dim - 1
    where = {1: lambda x: np.isclose(x[0], 0.0), 2: lambda x: np.isclose(x[0], 1.0),
             3: lambda x: np.isclose(x[vertical], 0.0), 4: lambda x: np.isclose(x[vertical], 1.0)}
    facets = [dolfinx.mesh.locate_entities_boundary(mesh, fdim, f) for f in where.values()]
    values = np.concatenate([np.full(f.size, tag, dtype=np.int32)
                             for tag, f in zip(where, facets, strict=True)])
    order = np.argsort(np.concatenate(facets))
    boundary = dolfinx.mesh.meshtags(mesh, fdim, np.concatenate(facets)[order], values[order])
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=boundary)
    shear = dolfinx.fem.Constant(mesh, float(side_shear))
    pressure = dolfinx.fem.Constant(mesh, PRESSURE)
    up = v[vertical]
    return facets, (internal_work(u, v, {0: Material(E, NU, "linear")})
                    - (-shear * up * ds(1) + shear * up * ds(2) - pressure * up * ds(4)))


def sheared_blocks(ratio, slave: str, friction, top_shift: float, side_shear: float,
                   cell_type: str = "triangle", comm: MPI.Intracomm = MPI.COMM_WORLD,
                   split_at: float | None = None, **options) -> ContactProblem:
    """Two blocks [0, 1] x [0, 0.5] and [0, 1] x [0.5, 1] (meshes.tied_blocks, non-matching),
    pressed by PRESSURE on the top and sheared: the bottom held, the top moved by
    ``top_shift`` along x (both with the Poisson expansion of the uniform state), a
    vertical shear traction ``side_shear`` on the sides. With side_shear = the interface
    shear, the exact solution is uniform: sigma_yy = -PRESSURE, sigma_xy = side_shear,
    sigma_xx = 0. ``split_at``: the slave surface as two pairs, cut at that x."""
    tagged = meshes.tied_blocks(ratio=ratio, cell_type=cell_type, comm=comm)
    mesh = tagged.mesh
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    u, v = dolfinx.fem.Function(V), ufl.TestFunction(V)
    fdim = mesh.topology.dim - 1
    facets, F = _sheared_form(u, v, vertical=1, side_shear=side_shear)
    V0, V1 = V.sub(0), V.sub(1)
    X = V0.collapse()[0]
    bottom_y = dolfinx.fem.locate_dofs_topological(V1, fdim, facets[2])
    bottom_x, top = (dolfinx.fem.locate_dofs_topological((V0, X), fdim, facets[i])
                     for i in (2, 3))
    # u_x = eps_xx x (+ top_shift on the top), eps_xx the plane-strain Poisson expansion
    expansion = NU * (1.0 + NU) * PRESSURE / E
    bottom_values, top_values = dolfinx.fem.Function(X), dolfinx.fem.Function(X)
    bottom_values.interpolate(lambda x: expansion * x[0])
    top_values.interpolate(lambda x: top_shift + expansion * x[0])
    bcs = [dolfinx.fem.dirichletbc(0.0, bottom_y, V1),
           dolfinx.fem.dirichletbc(bottom_values, bottom_x, V0),
           dolfinx.fem.dirichletbc(top_values, top, V0)]
    upper, lower = tagged.markers["upper_interface"], tagged.markers["lower_interface"]
    slave_tag, master_tag = (upper, lower) if slave == "upper" else (lower, upper)
    tags = tagged.facet_tags
    if split_at is None:
        pairs = [ContactPair(tags, slave_tag, master_tag)]
    else:  # the slave surface cut at x = split_at into two pairs
        values = tags.values.copy()
        on_slave = np.flatnonzero(values == slave_tag)
        right = int(max(tagged.markers.values())) + 1
        midpoints = dolfinx.mesh.compute_midpoints(mesh, fdim, tags.indices[on_slave])
        values[on_slave[midpoints[:, 0] > split_at]] = right
        tags = dolfinx.mesh.meshtags(mesh, fdim, tags.indices, values)
        pairs = [ContactPair(tags, slave_tag, master_tag, name="left"),
                 ContactPair(tags, right, master_tag, name="right")]
    problem = ContactProblem(F, u, bcs, pairs, configuration="reference", friction=friction,
                             **options)
    return problem


def sheared_blocks_3d(ratio, slave: str, friction, top_shift: float, side_shear: float,
                      cell_type: str = "tetrahedron", comm: MPI.Intracomm = MPI.COMM_WORLD,
                      **options) -> ContactProblem:
    """The 3D patch test's blocks (meshes.patch_test_3d: [0, 1]^2 x [0, 0.5] below,
    [0, 1]^2 x [0.5, 1] above, non-matching), pressed by PRESSURE on the top and sheared
    along x: the bottom held and the top moved by ``top_shift`` along x (with the
    lateral Poisson expansion of uniaxial stress), a vertical shear traction
    ``side_shear`` on the faces x = 0 and x = 1, the faces y = 0 and y = 1 free. With
    side_shear = the interface shear the exact solution is uniform: sigma_zz =
    -PRESSURE, sigma_xz = side_shear, every other component 0."""
    tagged = meshes.patch_test_3d(ratio=ratio, slave="top" if slave == "upper" else "bottom",
                                  cell_type=cell_type, comm=comm)
    mesh = tagged.mesh
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (3,)))
    u, v = dolfinx.fem.Function(V), ufl.TestFunction(V)
    fdim = mesh.topology.dim - 1
    facets, F = _sheared_form(u, v, vertical=2, side_shear=side_shear)
    # u_x = eps x (+ top_shift on the top), u_y = eps y: eps the Poisson expansion
    expansion = NU * PRESSURE / E
    bcs = []
    for component, shift in ((0, top_shift), (1, 0.0)):
        sub = V.sub(component)
        collapsed = sub.collapse()[0]
        for facet, offset in ((facets[2], 0.0), (facets[3], shift)):
            dofs = dolfinx.fem.locate_dofs_topological((sub, collapsed), fdim, facet)
            values = dolfinx.fem.Function(collapsed)
            values.interpolate(lambda x, c=component, o=offset: o + expansion * x[c])
            bcs.append(dolfinx.fem.dirichletbc(values, dofs, sub))
    bottom_z = dolfinx.fem.locate_dofs_topological(V.sub(2), fdim, facets[2])
    bcs.append(dolfinx.fem.dirichletbc(0.0, bottom_z, V.sub(2)))
    pair = ContactPair(tagged.facet_tags, tagged.markers["contact_slave"],
                       tagged.markers["contact_master"])
    # solved to rounding: the default relative tolerance 1e-10 may stop an iterate short
    # of it (the exactness is the point here)
    options.setdefault("petsc_options", {"snes_rtol": 1e-12, "snes_atol": 0.0})
    return ContactProblem(F, u, bcs, [pair], configuration="reference", friction=friction,
                          **options)



def main(argv=None, comm: MPI.Intracomm = MPI.COMM_WORLD) -> dict:
    parser = cli.parser(__doc__)
    parser.add_argument("--ratio", default="3:7", help="lower:upper interface elements")
    parser.add_argument("--slave", choices=("upper", "lower"), default="upper",
                        help="which block's interface is the slave")
    parser.add_argument("--shear-ratio", type=float, default=2.0,
                        help="R: below 1 the blocks stick, from 1 on they slip")
    parser.add_argument("--dim", type=int, choices=(2, 3), default=2,
                        help="2: plane strain; 3: the 3D patch test's blocks sheared along x")
    parser.add_argument("--cell-type",
                        choices=("triangle", "quadrilateral", "tetrahedron", "hexahedron"),
                        help="cells (default triangle in 2D, tetrahedron in 3D)")
    cli.add_common_arguments(parser, mu=0.2)
    args = parser.parse_args(argv)
    if args.tresca is not None:
        parser.error("this demo is about Coulomb friction: use --mu, not --tresca")
    try:
        ratio = tuple(int(n) for n in args.ratio.split(":"))
    except ValueError:
        parser.error(f"--ratio must be A:B with integers, got {args.ratio!r}")
    if not args.mu > 0.0 or not args.shear_ratio >= 0.0:
        parser.error("--mu must be positive and --shear-ratio >= 0")
    cell_type = args.cell_type or ("triangle" if args.dim == 2 else "tetrahedron")
    if (cell_type in ("tetrahedron", "hexahedron")) != (args.dim == 3):
        parser.error(f"--cell-type {cell_type} does not fit --dim {args.dim}")
    limit = args.mu * PRESSURE
    shear = min(args.shear_ratio, 1.0) * limit
    options = cli.problem_options(args)
    build = sheared_blocks if args.dim == 2 else sheared_blocks_3d
    problem = build(ratio, args.slave, options.pop("friction"),
                    args.shear_ratio * limit / SHEAR_MODULUS, shear, cell_type, comm, **options)
    report = problem.solve()
    if not report.converged:
        raise RuntimeError(f"the friction patch test did not converge: {report}")
    if args.output:
        output = ContactOutput(problem, args.output / "paraview")
        output.write(1.0)
        output.close()
    state = problem.friction_state()
    z = problem.multipliers[0].getArray(readonly=True)
    slip = max(args.shear_ratio - 1.0, 0.0) * limit / SHEAR_MODULUS
    traction, slips = state["traction"], state["slip"]
    if args.dim == 3:
        # the vectors sum_a y^a tau^a against the uniform answer along x (tau = R n in 2D
        # points along +x under the upper block and along -x over the lower one)
        along = np.array([1.0, 0.0, 0.0]) * (1.0 if args.slave == "upper" else -1.0)
        traction = np.einsum("na,nac->nc", traction, state["frames"]) - shear * along
        slips = np.einsum("na,nac->nc", slips, state["frames"]) - slip * along
    else:
        traction, slips = traction - shear, slips - slip

    def largest(values) -> float:
        return comm.allreduce(float(np.max(np.abs(values), initial=0.0)), op=MPI.MAX)

    summary = {
        "dim": args.dim,
        "cell_type": cell_type,
        "ratio": args.ratio,
        "slave": args.slave,
        "mu": args.mu,
        "shear_ratio": args.shear_ratio,
        **options,
        "num_ranks": comm.size,
        "max_pressure_deviation_rel": largest(z - PRESSURE) / PRESSURE,
        "max_traction_deviation_rel": largest(traction) / limit,
        "max_slip_deviation_rel": largest(slips) * SHEAR_MODULUS / limit,
        "num_active": problem.num_active(),
        "num_sticking": comm.allreduce(int(state["sticking"].sum()), op=MPI.SUM),
        "num_slipping": comm.allreduce(int(state["slipping"].sum()), op=MPI.SUM),
        "num_slave_nodes": problem.interfaces[0].num_global_multipliers,
        "newton_iterations": report.iterations,
    }
    if comm.rank == 0:
        print(f"friction patch test, R = {args.shear_ratio}: {summary['num_sticking']} "
              f"sticking, {summary['num_slipping']} slipping of {summary['num_slave_nodes']}; "
              f"deviations: pressure {summary['max_pressure_deviation_rel']:.1e}, traction "
              f"{summary['max_traction_deviation_rel']:.1e}, slip "
              f"{summary['max_slip_deviation_rel']:.1e}; Newton {report.iterations}", flush=True)
        write_summary(args.json, summary)
    problem.destroy()
    return summary


if __name__ == "__main__":
    main()
