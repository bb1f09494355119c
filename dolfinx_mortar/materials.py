"""Materials of 2D (plane strain) and 3D bodies in UFL (total Lagrangian).

:class:`Material` holds Young's modulus, Poisson's ratio and the model; each
``*_stress`` function returns the first Piola-Kirchhoff stress P(u) of a model
(the Cauchy stress of the linear one); :func:`internal_work` is the internal
virtual work sum_b int_{Omega_b} P : grad(v) dX of several bodies with different
materials in one mesh (cell tags pick the body). The external work is the caller's.
"""

from __future__ import annotations

import dataclasses

import ufl


@dataclasses.dataclass(frozen=True)
class Material:
    """Young's modulus and Poisson's ratio of one body, and its model.

    model: ``neo-hookean`` (compressible, W = mu/2 (I1 - d - 2 ln J) +
    lambda/2 (ln J)^2 in dimension d), ``saint-venant-kirchhoff``
    (W = mu E:E + lambda/2 tr(E)^2), or ``linear`` (small strain). The values are
    checked when the material is made, not when a form is built from it.

    Examples:
        >>> Material(E=200.0, nu=0.3, model="linear").model
        'linear'
        >>> Material(E=1.0, nu=0.5)
        Traceback (most recent call last):
        ...
        ValueError: Poisson's ratio must lie in (-1, 0.5), got 0.5
    """

    E: float
    nu: float
    model: str = "neo-hookean"

    def __post_init__(self):
        if self.model not in MODELS:
            raise ValueError(f"unknown material model {self.model!r}; expected one of {MODELS}")
        if not self.E > 0:
            raise ValueError(f"Young's modulus must be positive, got {self.E}")
        if not -1.0 < self.nu < 0.5:
            raise ValueError(f"Poisson's ratio must lie in (-1, 0.5), got {self.nu}")

    @property
    def mu(self) -> float:
        """Lame's second parameter, the shear modulus: mu = E / (2 (1 + nu)).

        Examples:
            >>> Material(E=200.0, nu=0.3).mu
            76.92307692307692
        """
        return self.E / (2.0 * (1.0 + self.nu))

    @property
    def lmbda(self) -> float:
        """Lame's first parameter, lambda = E nu / ((1 + nu)(1 - 2 nu)), in 2D the
        plane-strain value (the same formula: the 2D bodies are in plane strain).

        Examples:
            >>> Material(E=200.0, nu=0.3).lmbda
            115.38461538461539
            >>> Material(E=1.0, nu=0.25).lmbda
            0.4
        """
        return self.E * self.nu / ((1.0 + self.nu) * (1.0 - 2.0 * self.nu))

    def stress(self, u):
        """First Piola-Kirchhoff stress (Cauchy stress for ``linear``)."""
        return STRESS[self.model](u, self.mu, self.lmbda)


def deformation_gradient(u):
    """F = I + grad u (UFL)."""
    return ufl.Identity(len(u)) + ufl.grad(u)


def neo_hookean_stress(u, mu: float, lmbda: float):
    """P = dW/dF of the compressible Neo-Hookean energy of :class:`Material` (UFL)."""
    F = ufl.variable(deformation_gradient(u))
    J = ufl.det(F)
    C = F.T * F
    dim = len(u)
    energy = 0.5 * mu * (ufl.tr(C) - dim - 2.0 * ufl.ln(J)) + 0.5 * lmbda * ufl.ln(J) ** 2
    return ufl.diff(energy, F)


def saint_venant_kirchhoff_stress(u, mu: float, lmbda: float):
    """P = F S, S = 2 mu E + lambda tr(E) I with the Green strain E (UFL)."""
    F = deformation_gradient(u)
    green = 0.5 * (F.T * F - ufl.Identity(len(u)))
    S = 2.0 * mu * green + lmbda * ufl.tr(green) * ufl.Identity(len(u))
    return F * S


def linear_stress(u, mu: float, lmbda: float):
    """Cauchy stress of small-strain linear elasticity, 2 mu eps + lambda tr(eps) I (UFL)."""
    strain = ufl.sym(ufl.grad(u))
    return 2.0 * mu * strain + lmbda * ufl.tr(strain) * ufl.Identity(len(u))


STRESS = {
    "neo-hookean": neo_hookean_stress,
    "saint-venant-kirchhoff": saint_venant_kirchhoff_stress,
    "linear": linear_stress,
}
MODELS = tuple(STRESS)


def internal_work(u, v, materials: dict[int, Material], cell_tags=None,
                  quadrature_degree: int | None = None):
    """sum over bodies of int P(u) : grad(v) dX; keys of ``materials`` are cell tags.

    With ``cell_tags=None`` a single material (any key) applies everywhere.
    ``quadrature_degree`` overrides UFL's estimate. On hexahedra the default is 2
    (the 2 x 2 x 2 Gauss rule of trilinear elements, exact for linear elasticity
    on parallelepipeds): there UFL's estimate for the logarithms and inverses of the
    hyperelastic laws asks for thousands of points per cell.
    """
    mesh = u.function_space.mesh
    if quadrature_degree is None and mesh.topology.cell_name() == "hexahedron":
        quadrature_degree = 2
    metadata = {} if quadrature_degree is None else {"quadrature_degree": quadrature_degree}
    if cell_tags is None:
        if len(materials) != 1:
            raise ValueError("several materials need cell_tags to say where each applies")
        (material,) = materials.values()
        dx = ufl.Measure("dx", domain=mesh, metadata=metadata)
        return ufl.inner(material.stress(u), ufl.grad(v)) * dx
    dx = ufl.Measure("dx", domain=mesh, subdomain_data=cell_tags, metadata=metadata)
    forms = [ufl.inner(m.stress(u), ufl.grad(v)) * dx(tag) for tag, m in materials.items()]
    return sum(forms[1:], forms[0])
