"""Material laws against stresses computed by hand for homogeneous deformations.

A homogeneous deformation u = (F - I) X makes P(u) constant, so its integral over
the unit square is P itself. The hand formulas are independent of the UFL code:
for the compressible neo-Hookean law W = mu/2 (I1 - 3 - 2 ln J) + lambda/2 (ln J)^2
in plane strain (F33 = 1), P = mu (F - F^-T) + lambda ln J F^-T.
"""

from __future__ import annotations

import math

import dolfinx
import numpy as np
import pytest
import ufl
from mpi4py import MPI

from dolfinx_mortar import Material, internal_work

E, NU = 6.896e8, 0.32  # the ironing block
MU = E / (2 * (1 + NU))
LAMBDA = E * NU / ((1 + NU) * (1 - 2 * NU))


def stress_at(model: str, F: np.ndarray) -> np.ndarray:
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 1, 1)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    u = dolfinx.fem.Function(V)
    G = F - np.eye(2)
    u.interpolate(lambda x: G @ x[:2])
    P = Material(E, NU, model).stress(u)
    return np.array(
        [
            [
                mesh.comm.allreduce(dolfinx.fem.assemble_scalar(dolfinx.fem.form(P[i, j] * ufl.dx)))
                for j in range(2)
            ]
            for i in range(2)
        ]
    )


def test_lame_parameters_of_the_ironing_block():
    material = Material(E, NU)
    assert material.mu == pytest.approx(2.612121212e8, rel=1e-9)
    assert material.lmbda == pytest.approx(4.643771044e8, rel=1e-9)
    # small-strain plane-strain uniaxial (oedometric) modulus lambda + 2 mu
    assert material.lmbda + 2 * material.mu == pytest.approx(
        E * (1 - NU) / ((1 + NU) * (1 - 2 * NU)), rel=1e-12
    )


@pytest.mark.parametrize("stretch", [0.7, 0.9, 1.25])
def test_neo_hookean_uniaxial_plane_strain_stretch(stretch):
    P = stress_at("neo-hookean", np.diag([stretch, 1.0]))
    expected = np.diag(
        [
            MU * (stretch - 1 / stretch) + LAMBDA * math.log(stretch) / stretch,
            LAMBDA * math.log(stretch),
        ]
    )
    assert np.allclose(P, expected, rtol=1e-12, atol=1e-12 * E)


def test_neo_hookean_simple_shear():
    gamma = 0.4
    P = stress_at("neo-hookean", np.array([[1.0, gamma], [0.0, 1.0]]))
    # J = 1: P = mu (F - F^-T) = mu [[0, gamma], [gamma, 0]]
    assert np.allclose(P, MU * np.array([[0.0, gamma], [gamma, 0.0]]), rtol=1e-12, atol=1e-12 * E)


def test_neo_hookean_small_strain_limit_is_plane_strain_hooke():
    eps = 1e-6
    F = np.eye(2) + eps * np.array([[1.0, 0.3], [0.1, -0.5]])
    P = stress_at("neo-hookean", F)
    strain = 0.5 * (F - np.eye(2) + (F - np.eye(2)).T)
    hooke = 2 * MU * strain + LAMBDA * np.trace(strain) * np.eye(2)
    assert np.allclose(P, hooke, rtol=1e-5, atol=1e-5 * eps * E)


def test_saint_venant_kirchhoff_uniaxial_plane_strain_stretch():
    stretch = 0.8
    P = stress_at("saint-venant-kirchhoff", np.diag([stretch, 1.0]))
    green = 0.5 * (stretch**2 - 1)
    S11, S22 = (2 * MU + LAMBDA) * green, LAMBDA * green
    assert np.allclose(P, np.diag([stretch * S11, S22]), rtol=1e-12, atol=1e-12 * E)


def test_hexahedra_default_to_two_by_two_by_two_gauss_points():
    """On hexahedra internal_work integrates with degree 2 unless told otherwise: exact
    for linear elasticity on a box (the same stiffness as degree 6 to rounding), and
    the Neo-Hookean form asks for 8 points per cell, not UFL's estimate."""
    import dolfinx.fem.petsc

    mesh = dolfinx.mesh.create_box(MPI.COMM_SELF, [[0, 0, 0], [1, 2, 3]], [2, 1, 1],
                                   dolfinx.mesh.CellType.hexahedron)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (3,)))
    u, v = dolfinx.fem.Function(V), ufl.TestFunction(V)
    du = ufl.TrialFunction(V)
    linear = {0: Material(3.0, 0.3, "linear")}
    stiffness = []
    for degree in (None, 6):
        F = internal_work(u, v, linear, quadrature_degree=degree)
        A = dolfinx.fem.petsc.assemble_matrix(dolfinx.fem.form(ufl.derivative(F, u, du)))
        A.assemble()
        # a copy: petsc4py 3.22's getDenseArray is a view that does not keep A alive, so
        # once the next pass rebound A the view read freed memory (usually reused by the
        # second matrix: a vacuous pass; sometimes by something else: a 5.5 difference)
        stiffness.append(A.convert("dense").getDenseArray().copy())
        A.destroy()
    assert np.abs(stiffness[0] - stiffness[1]).max() <= 1e-12 * np.abs(stiffness[1]).max()
    F = internal_work(u, v, {0: Material(3.0, 0.3, "neo-hookean")})
    assert {i.metadata()["quadrature_degree"] for i in F.integrals()} == {2}
